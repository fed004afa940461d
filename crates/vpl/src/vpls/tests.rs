//! VPL tests: direct VPLs against the path tracer's direct light (z-test over seeds),
//! determinism across thread counts, the geometry bound's one-sided bias, and the VPL
//! image against the path-traced one.

use super::eval::contribution;
use super::exhaustive::gather_all;
use super::*;
use filtrace_core::luminance;
use filtrace_core::sampler::Sampler;
use filtrace_render::integrator::path::direct_light;
use filtrace_render::{RenderSettings, Renderer};
use std::sync::atomic::AtomicBool;

fn cornell(width: u32, max_depth: i32) -> Renderer {
    let scene = filtrace_scene::builtin("cornell").expect("built-in Cornell box");
    let settings = RenderSettings { width, height: width, spp: 1, max_depth, seed: 1 };
    Renderer::new(scene, settings).expect("settings")
}

/// Receivers seen through a few pixels of a 32² Cornell view (floor, walls, box tops).
fn receivers(r: &Renderer) -> Vec<(u32, u32, Receiver)> {
    let ctx = r.context();
    let mut out = Vec::new();
    for (x, y) in [(16, 28), (3, 16), (29, 16), (16, 12), (10, 22), (22, 24), (6, 26), (26, 6)] {
        let ray = r.camera().generate_ray(x, y, filtrace_core::Vec2::splat(0.5));
        if let Some(si) = ctx.intersect(&ray) {
            // Lit, not an emitter (the floor's front edge at (16, 28) faces away from the light).
            let lit = (0..64).any(|i| direct_light(&ctx, &si, &mut Sampler::new(x, y, i, 1)) != Rgb::ZERO);
            if ctx.emitted(&si) == Rgb::ZERO && lit {
                out.push((x, y, Receiver::new(si, ctx.bsdf(&si))));
            }
        }
    }
    assert!(out.len() >= 4, "the Cornell view hits its walls");
    out
}

fn mean_var(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let m = xs.iter().sum::<f64>() / n;
    (m, xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0))
}

/// The direct VPLs alone estimate the direct light: their sum, averaged over 48 seeds,
/// agrees with the path tracer's `direct_light` (light + BSDF sampling, MIS; 4096
/// samples) at every receiver within 4.5 standard errors of the difference.
#[test]
fn direct_vpls_reproduce_the_path_tracers_direct_light() {
    let r = cornell(32, 8);
    let ctx = r.context();
    for (x, y, rx) in receivers(&r) {
        let pt: Vec<f64> = (0..4096)
            .map(|i| luminance(direct_light(&ctx, &rx.si, &mut Sampler::new(x, y, i, 5))) as f64)
            .collect();
        let vpl: Vec<f64> = (0..48u64)
            .map(|seed| {
                let p = VplParams { count: 256, direct: 256, seed, ..VplParams::thesis() };
                let vpls = generate_vpls(&ctx, &r.path_params(), &p);
                assert_eq!(vpls.len(), 256, "only direct VPLs");
                luminance(gather_all(&ctx, &vpls, &rx).direct) as f64
            })
            .collect();
        let ((m_pt, v_pt), (m_vpl, v_vpl)) = (mean_var(&pt), mean_var(&vpl));
        let se = (v_pt / pt.len() as f64 + v_vpl / vpl.len() as f64).sqrt();
        let z = (m_pt - m_vpl) / se;
        assert!(
            z.abs() < 4.5,
            "pixel ({x}, {y}): path tracer {m_pt:.5} vs VPLs {m_vpl:.5} (se {se:.2e}, z {z:.2})"
        );
        assert!(m_pt > 0.0, "pixel ({x}, {y}) is lit");
    }
}

/// The test above has power: VPL weights off by 10% are caught.
#[test]
fn direct_vpl_test_rejects_a_ten_percent_error() {
    let r = cornell(32, 8);
    let ctx = r.context();
    let (x, y, rx) = receivers(&r)[0];
    let pt: Vec<f64> = (0..4096)
        .map(|i| luminance(direct_light(&ctx, &rx.si, &mut Sampler::new(x, y, i, 5))) as f64)
        .collect();
    let vpl: Vec<f64> = (0..48u64)
        .map(|seed| {
            let p = VplParams { count: 256, direct: 256, seed, ..VplParams::thesis() };
            let mut vpls = generate_vpls(&ctx, &r.path_params(), &p);
            vpls.vpls.iter_mut().for_each(|v| v.weight *= 1.1);
            luminance(gather_all(&ctx, &vpls, &rx).direct) as f64
        })
        .collect();
    let ((m_pt, v_pt), (m_vpl, v_vpl)) = (mean_var(&pt), mean_var(&vpl));
    let z = (m_pt - m_vpl) / (v_pt / 4096.0 + v_vpl / 48.0).sqrt();
    assert!(z.abs() > 4.5, "a 10% error went unnoticed: z {z}");
}

#[test]
fn same_seed_same_vpls_and_image_whatever_the_thread_count() {
    let r = cornell(16, 8);
    let ctx = r.context();
    let p = VplParams { count: 512, direct: 64, seed: 9, ..VplParams::thesis() };
    let a = generate_vpls(&ctx, &r.path_params(), &p);
    let b = generate_vpls(&ctx, &r.path_params(), &p);
    assert_eq!(a.vpls, b.vpls);
    assert!(a.len() >= 512 && a.direct_count() == 64, "{} VPLs, {} direct", a.len(), a.direct_count());
    let c = generate_vpls(&ctx, &r.path_params(), &VplParams { seed: 10, ..p });
    assert_ne!(a.vpls, c.vpls, "another seed, other VPLs");
    let cancel = AtomicBool::new(false);
    let render = |threads| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| render_exhaustive(&ctx, r.camera(), &a, 0, 2, 3, &cancel)).unwrap()
    };
    let (one, two) = (render(1), render(2));
    assert!(one.pixels() == two.pixels(), "films differ between 1 and 2 threads");
    assert!(one.aovs().color.mean()[0] > 0.0);
}

/// The bound only darkens: each bounded contribution is ≤ the exact one, equal beyond
/// the distance, and the bounded sum is finite where the exact one spikes.
#[test]
fn geometry_bound_only_removes_energy_below_its_distance() {
    let r = cornell(32, 8);
    let ctx = r.context();
    let vpls = generate_vpls(&ctx, &r.path_params(), &VplParams::with_count(1024));
    let d = 0.3 * ctx.lights.scene_radius();
    let bound = GeometryBound::MinDistance(d);
    let mut clipped = 0;
    for (_, _, rx) in receivers(&r) {
        for v in &vpls.vpls {
            let (exact, _, dist) = contribution(v, &rx, GeometryBound::Off);
            let (bounded, _, _) = contribution(v, &rx, bound);
            assert!(bounded.cmple(exact * (1.0 + 1e-5)).all(), "{bounded} > {exact}");
            if dist > d {
                assert!(
                    (bounded - exact).abs().max_element() <= 1e-5 * exact.max_element(),
                    "{bounded} {exact}"
                );
            } else if exact != bounded {
                clipped += 1;
            }
        }
    }
    assert!(clipped > 0, "some VPLs are closer than {d}");
    assert!(bound.validate().is_ok() && GeometryBound::MinDistance(0.0).validate().is_err());
}

/// The VPL solution against the path tracer on a 24² Cornell box (max depth 4): the
/// image means agree within 3% (VPLs: thesis default 2048, exhaustive, 32 VPL sets each
/// with its own jittered camera sample: one pixel-centre sample aliases the small light,
/// ±1 light pixel is 10% of this image's mean; path tracer 256 spp). Prints both for
/// docs/many-light.md.
#[test]
#[ignore = "slow: 32 exhaustive VPL images"]
fn vpl_image_is_close_to_the_path_traced_image() {
    let r = cornell(24, 4);
    let ctx = r.context();
    let cancel = AtomicBool::new(false);
    let mut film = r.new_film();
    let mut vpls = Vpls::default();
    for seed in 0..32 {
        vpls = generate_vpls(&ctx, &r.path_params(), &VplParams { seed, ..VplParams::thesis() });
        let one = render_exhaustive(&ctx, r.camera(), &vpls, seed as u32, 1, 0, &cancel).unwrap();
        for (a, b) in film.pixels_mut().iter_mut().zip(one.pixels()) {
            for c in 0..3 {
                a.sum[c] += b.sum[c];
                a.sum_sq[c] += b.sum_sq[c];
                a.sum_direct[c] += b.sum_direct[c];
                a.sum_indirect[c] += b.sum_indirect[c];
            }
            a.samples += b.samples;
        }
    }
    let mut pt = r.new_film();
    r.render_pass(&mut pt, 0, 256, &cancel);
    let (a, b) = (film.aovs(), pt.aovs());
    let (ma, mb) = (a.color.mean(), b.color.mean());
    let (la, lb) = (
        luminance(Vec3::new(ma[0] as f32, ma[1] as f32, ma[2] as f32)),
        luminance(Vec3::new(mb[0] as f32, mb[1] as f32, mb[2] as f32)),
    );
    let rel = (la - lb) / lb;
    let (da, db) = (a.direct.mean()[1], b.direct.mean()[1]);
    let (ia, ib) = (a.indirect.mean()[1], b.indirect.mean()[1]);
    println!("VPL {la:.4} vs path tracer {lb:.4} (rel {rel:+.4}); direct G {da:.4} vs {db:.4}; indirect G {ia:.4} vs {ib:.4}; {} VPLs from {} light paths", vpls.len(), vpls.light_paths);
    assert!(rel.abs() < 0.03, "VPL image mean {la} vs path traced {lb}");
}

/// Every sampler's frame estimates the exhaustive VPL sum: on a 12² Cornell box with 256
/// VPLs the image means at 64 spp (progressive passes 1, 1, 2, ..., 32; `optimized`
/// learning after each) agree within 6 standard errors (from the per-pixel variances), and
/// the optimised frame is the same with one and two threads.
#[test]
fn every_sampler_frame_matches_the_exhaustive_mean_and_is_thread_independent() {
    use crate::cache::{CacheParams, SamplerKind};
    let mut r = cornell(12, 8);
    let cancel = AtomicBool::new(false);
    let vpls = VplParams { count: 256, direct: 32, ..VplParams::thesis() };
    let cache = CacheParams { cache_points: 32, ..CacheParams::default() };
    let mean_se = |f: &filtrace_render::Film| {
        let a = f.aovs();
        let n = (a.width * a.height) as f64;
        let m = a.color.mean()[1];
        let var: f64 = a.variance.data().chunks(3).map(|v| v[1] as f64).sum::<f64>() / (n * n);
        (m, var.sqrt())
    };
    let truth = VplSettings { vpls, sampler: SamplerKind::Uniform, cache: cache.clone(), ground_truth: true };
    // The same 64 camera rays per pixel as the samplers (same seed): only the VPL
    // sampling differs.
    let gt = render_vpl_frame(&mut r, &truth, 64, &cancel).unwrap().unwrap();
    let (m_gt, _) = mean_se(&gt.film);
    for sampler in SamplerKind::ALL {
        let s = VplSettings { vpls, sampler, cache: cache.clone(), ground_truth: false };
        let f = render_vpl_frame(&mut r, &s, 64, &cancel).unwrap().unwrap();
        let (m, se) = mean_se(&f.film);
        assert!((m - m_gt).abs() < 6.0 * se + 1e-4, "{}: {m} vs exhaustive {m_gt} (se {se})", sampler.name());
        assert_eq!(f.film.dropped_samples(), 0);
        assert_eq!(f.vpls.vpls, gt.vpls.vpls, "the same VPLs for every sampler");
        if sampler.needs_cache() {
            assert!(f.cache_records > 0 && f.cache_distance.data().iter().any(|&d| d > 0.0));
        }
        if sampler == SamplerKind::Optimized {
            let report = r.integrator_as::<VplIntegrator>().unwrap().report();
            assert_eq!(report.optimised_passes, 7, "one step after each of the 7 passes");
        }
    }
    let s = VplSettings { vpls, sampler: SamplerKind::Optimized, cache, ground_truth: false };
    let run = |threads| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let mut r = cornell(12, 8);
        pool.install(|| render_vpl_frame(&mut r, &s, 8, &cancel)).unwrap().unwrap()
    };
    let (one, two) = (run(1), run(2));
    assert!(one.film.pixels() == two.film.pixels(), "optimized frame differs between 1 and 2 threads");
}

/// Through the renderer: the integrator is prepared when set and at every frame update
/// (new VPLs per frame, parameters carried); its `li` is the exhaustive sum for the
/// ground truth; a renderer without it is refused by `render_vpl_passes`.
#[test]
fn vpl_integrator_in_the_renderer() {
    use crate::cache::SamplerKind;
    let mut r = cornell(8, 8);
    let cancel = AtomicBool::new(false);
    assert!(render_vpl_passes(&r, 1, 1, &cancel).is_err(), "the path tracer is not the VPL integrator");
    let vpls = VplParams { count: 128, direct: 16, ..VplParams::thesis() };
    let truth = VplSettings { vpls, ground_truth: true, ..VplSettings::default() };
    use_vpl_integrator(&mut r, &truth).unwrap();
    let ctx = r.context();
    let integrator = r.integrator_as::<VplIntegrator>().unwrap();
    assert!(integrator.vpls().len() >= 128);
    for (x, y) in [(0, 0), (3, 5), (7, 7)] {
        let ray = r.camera().generate_ray(x, y, filtrace_core::Vec2::splat(0.5));
        let want = exhaustive_pixel(&ctx, integrator.vpls(), &ray).0;
        assert_eq!(r.trace_sample(x, y, 0).radiance, want);
    }
    let first = integrator.vpls().vpls.clone();
    let s = VplSettings { vpls, sampler: SamplerKind::Optimized, ..VplSettings::default() };
    use_vpl_integrator(&mut r, &s).unwrap();
    assert_eq!(r.integrator_as::<VplIntegrator>().unwrap().vpls().vpls, first, "same frame, same VPLs");
    render_vpl_passes(&r, 4, u32::MAX, &cancel).unwrap().unwrap();
    let learnt = r.integrator_as::<VplIntegrator>().unwrap().cache().unwrap().params().to_vec();
    r.prepare_frame(3).unwrap();
    let next = r.integrator_as::<VplIntegrator>().unwrap();
    assert_ne!(next.vpls().vpls, first, "frame 3 has its own VPLs");
    assert_eq!(next.report().optimised_passes, 0);
    // The camera did not move: the same cache points, each keeping its parameters.
    assert_eq!(next.cache().unwrap().params(), &learnt[..]);
}

/// Ctrl-C during the passes keeps an exact prefix of every pixel's samples, as the path
/// tracer does: cancelled after the first pass, the film equals a one-sample render.
#[test]
fn a_cancelled_vpl_render_keeps_whole_passes() {
    use crate::cache::SamplerKind;
    let mut r = cornell(8, 8);
    let s = VplSettings {
        vpls: VplParams { count: 64, direct: 8, ..VplParams::thesis() },
        sampler: SamplerKind::BalanceCv,
        ..VplSettings::default()
    };
    use_vpl_integrator(&mut r, &s).unwrap();
    let cancel = AtomicBool::new(false);
    let one = render_vpl_passes(&r, 1, 1, &cancel).unwrap().unwrap();
    let mut film = r.new_film();
    assert!(r.render_pass(&mut film, 0, 1, &cancel));
    cancel.store(true, std::sync::atomic::Ordering::Relaxed);
    assert!(!r.render_pass(&mut film, 1, 1, &cancel));
    assert!(film.pixels() == one.film.pixels() && !one.cancelled);
    assert!(render_vpl_passes(&r, 4, 1, &cancel).unwrap().is_none(), "cancelled before any sample");
}
