//! The many-light methods of `filtrace experiment` (issue 14, the thesis's 6.4-6.5): a
//! method is one frame of `filtrace render --integrator vpl` (its settings are parsed by
//! the same `VplArgs`), judged against the exhaustive VPL sum over the same VPLs and the
//! same camera samples, with the thesis's three clocks:
//!
//! - all time: the frame's stage times (`StageTimes`);
//! - time without ray queries: all time minus an estimate of the ray queries' wall-clock
//!   time: every shadow ray is counted (`filtrace_vpl::vpls::rays`) and every
//!   [`KEEP_EVERY`]-th one kept, then the kept rays are traced again alone, in parallel on
//!   the same threads (median of three), and the time scaled by `counted / kept`; the
//!   camera rays (the G-buffer's and one per sample) by timing one closest-hit query
//!   through every pixel centre right after the frame, times `spp + 1`;
//! - number of rays: shadow rays counted plus camera rays (`w·h·(spp + 1)`; the ~2k
//!   rays of the light paths that make the VPLs are left out).
//!
//! The only call into the renderer is [`render_frame`]; the ground truth is
//! `render_exhaustive` over the VPLs of `generate_vpls`, checked against the method's own
//! VPLs on every run, so a renderer that changes its VPLs fails loudly instead of being
//! judged against the wrong sum.

use std::collections::HashMap;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use clap::Parser;
use filtrace_core::{Image, Vec2};
use filtrace_eval::experiment::{ExperimentSpec, MethodRun, RayClock, VplMethod};
use filtrace_render::{RenderSettings, Renderer};
use filtrace_scene::Scene;
use filtrace_vpl::cache::DistributionSet;
use filtrace_vpl::vpls::{
    frame_vpl_seed, generate_vpls, rays, render_exhaustive, render_vpl_frame, VplFrame, VplParams,
    VplSettings, Vpls,
};
use rayon::prelude::*;

use super::render_vpl::VplArgs;

/// One of this many shadow rays is kept for the replay that times the ray queries.
pub const KEEP_EVERY: u64 = 8;

/// One VPL frame of `spp` samples per pixel, as `filtrace render --integrator vpl`
/// renders it: the one entry point of the experiments into the renderer.
pub fn render_frame(renderer: &mut Renderer, settings: &VplSettings, spp: u32) -> Result<VplFrame, String> {
    render_vpl_frame(renderer, settings, spp, &AtomicBool::new(false))?.ok_or_else(|| "cancelled".to_string())
}

/// The renderer's settings of `m`, through the CLI's own options.
pub fn vpl_settings(m: &VplMethod, scene_radius: f32) -> Result<VplSettings, String> {
    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        vpl: VplArgs,
    }
    let args = cli_args(m);
    let cli = Cli::try_parse_from(std::iter::once("filtrace".to_string()).chain(args.iter().cloned()))
        .map_err(|e| format!("{}: {e}", args.join(" ")))?;
    let mut s = cli.vpl.settings(scene_radius).map_err(|e| format!("{e:#}"))?;
    s.cache.distributions = DistributionSet::first(m.distributions as usize - 1);
    s.cache.validate()?;
    Ok(s)
}

/// Refuses `spec` when a frame of one of its many-light methods (or of its exhaustive
/// ground truth) would not fit in memory, naming the method: checked before anything
/// runs, as `render` checks its frame ([`super::render_vpl::check_frame_memory`]).
pub fn check_memory(spec: &ExperimentSpec, threads: usize) -> anyhow::Result<()> {
    let max_spp = spec.spp.iter().copied().max().unwrap_or(1);
    let truth = spec.vpl.resolve(filtrace_eval::experiment::VplSampler::Uniform, &Default::default());
    let truth = spec.is_vpl_ground_truth().then(|| ("the ground truth".to_string(), truth, true));
    let methods =
        spec.methods.iter().filter_map(|m| Some((format!("method {}", m.name), spec.vpl_method(m)?, false)));
    for (what, m, ground_truth) in methods.chain(truth) {
        // The scene's radius only scales the clamp, which costs no memory.
        let mut vs = vpl_settings(&m, 1.0).map_err(anyhow::Error::msg)?;
        vs.ground_truth = ground_truth;
        super::render_vpl::check_frame_memory(spec.width, spec.height, &vs, threads, max_spp)
            .map_err(|e| anyhow::anyhow!("{what}: {e:#}"))?;
    }
    Ok(())
}

/// The `filtrace render` options of `m` (the distribution count has no option).
pub fn cli_args(m: &VplMethod) -> Vec<String> {
    let mut a: Vec<String> = [
        ("--integrator", "vpl".to_string()),
        ("--vpls", m.vpls.to_string()),
        ("--vpl-sampler", m.sampler.name().to_string()),
        ("--cache-points", m.cache_points.to_string()),
        ("--cache-neighbours", m.neighbours.to_string()),
        ("--cache-faint-share", m.faint_share.to_string()),
    ]
    .into_iter()
    .flat_map(|(k, v)| [k.to_string(), v])
    .collect();
    if let Some(c) = m.clamp {
        a.extend(["--vpl-clamp".to_string(), c.to_string()]);
    }
    a
}

/// A scene's renderer, its VPLs' fingerprint and the running sum of the ground truth.
struct SceneState {
    renderer: Renderer,
    /// Fingerprint of the VPLs every method must use.
    vpls: u64,
    /// Σ over camera samples `0..samples` of the exhaustive colour, per pixel and channel.
    truth_sum: Vec<f64>,
    truth_samples: u32,
}

/// The many-light half of the experiment backend.
#[derive(Default)]
pub struct VplBackend {
    /// Its own pool: the ray counters are summed over the pool's threads.
    pool: Option<Arc<rayon::ThreadPool>>,
    scenes: HashMap<String, SceneState>,
}

impl VplBackend {
    /// The pool, as many threads as the one the experiment started in.
    fn pool(&mut self) -> Result<Arc<rayon::ThreadPool>, String> {
        if self.pool.is_none() {
            let n = rayon::current_num_threads();
            let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build().map_err(|e| e.to_string())?;
            self.pool = Some(Arc::new(pool));
        }
        Ok(self.pool.clone().expect("just built"))
    }

    fn state(
        &mut self,
        spec: &ExperimentSpec,
        name: &str,
        scene: impl FnOnce() -> Result<Scene, String>,
    ) -> Result<&mut SceneState, String> {
        if !self.scenes.contains_key(name) {
            let settings = RenderSettings {
                width: spec.width,
                height: spec.height,
                spp: 1,
                max_depth: spec.max_depth,
                seed: spec.seed,
            };
            let scene = scene()?;
            let pool = self.pool()?;
            let st = pool.install(|| -> Result<SceneState, String> {
                let renderer = Renderer::new(scene, settings).map_err(|e| e.to_string())?;
                let vs = truth_settings(spec, &renderer)?;
                let vpls = fingerprint(&generate_vpls(
                    &renderer.context(),
                    &renderer.path_params(),
                    &still_vpls(&vs, spec),
                ));
                let n = (spec.width * spec.height) as usize * 3;
                Ok(SceneState { renderer, vpls, truth_sum: vec![0.0; n], truth_samples: 0 })
            })?;
            self.scenes.insert(name.to_string(), st);
        }
        Ok(self.scenes.get_mut(name).expect("inserted"))
    }

    /// The fingerprint of the VPLs of `name` (those of every method and the ground truth).
    pub fn vpl_fingerprint(
        &mut self,
        spec: &ExperimentSpec,
        name: &str,
        scene: impl FnOnce() -> Result<Scene, String>,
    ) -> Result<u64, String> {
        Ok(self.state(spec, name, scene)?.vpls)
    }

    /// The exhaustive VPL sum over camera samples `0..spp`, extending the running sum, or
    /// `previous` (the sum over `0..k`) when that is further along.
    pub fn ground_truth(
        &mut self,
        spec: &ExperimentSpec,
        name: &str,
        scene: impl FnOnce() -> Result<Scene, String>,
        spp: u32,
        previous: Option<(u32, &Image)>,
    ) -> Result<Image, String> {
        let pool = self.pool()?;
        let st = self.state(spec, name, scene)?;
        if spp < st.truth_samples {
            st.truth_sum.iter_mut().for_each(|v| *v = 0.0);
            st.truth_samples = 0;
        }
        if let Some((k, img)) = previous
            .filter(|(k, img)| *k > st.truth_samples && *k < spp && img.data().len() == st.truth_sum.len())
        {
            for (s, v) in st.truth_sum.iter_mut().zip(img.data()) {
                *s = *v as f64 * k as f64;
            }
            st.truth_samples = k;
        }
        let (first, count) = (st.truth_samples, spp - st.truth_samples);
        if count > 0 {
            let r = &st.renderer;
            let vs = truth_settings(spec, r)?;
            let film = pool
                .install(|| {
                    let vpls = generate_vpls(&r.context(), &r.path_params(), &still_vpls(&vs, spec));
                    render_exhaustive(
                        &r.context(),
                        r.camera(),
                        &vpls,
                        first,
                        count,
                        spec.seed,
                        &AtomicBool::new(false),
                    )
                })
                .ok_or("cancelled")?;
            let colour = film.try_aovs().map_err(|e| e.to_string())?.color;
            for (s, v) in st.truth_sum.iter_mut().zip(colour.data()) {
                *s += *v as f64 * count as f64;
            }
            st.truth_samples = spp;
        }
        let data = st.truth_sum.iter().map(|v| (*v / spp as f64) as f32).collect();
        Image::from_vec(spec.width as usize, spec.height as usize, 3, data)
            .ok_or_else(|| "image size".to_string())
    }

    /// Method `m` at `spp`: the frame, its stage times and its ray clock.
    pub fn run(
        &mut self,
        spec: &ExperimentSpec,
        name: &str,
        scene: impl FnOnce() -> Result<Scene, String>,
        m: &VplMethod,
        spp: u32,
    ) -> Result<MethodRun, String> {
        let pool = self.pool()?;
        let st = self.state(spec, name, scene)?;
        let vs = vpl_settings(m, st.renderer.lights().scene_radius())?;
        let (frame, clock) = pool.install(|| measured_frame(&mut *st, &vs, spp))?;
        if fingerprint(&frame.vpls) != st.vpls {
            return Err(format!(
                "scene {name}: the {} frame used other VPLs than the ground truth (generate_vpls with the same seed); the experiment cannot judge it",
                m.sampler.name()
            ));
        }
        let t = frame.times;
        Ok(MethodRun {
            image: frame.film.try_aovs().map_err(|e| e.to_string())?.color,
            noisy: None,
            albedo: None,
            normal: None,
            stages: vec![
                ("vpls".into(), t.vpl_generation_ms),
                ("cache".into(), t.cache_ms),
                ("shading".into(), t.shading_ms),
                ("optimisation".into(), t.optimisation_ms),
            ],
            rays: Some(clock),
        })
    }
}

/// The VPL parameters the integrator draws a still frame's VPLs with (frame 0).
fn still_vpls(vs: &VplSettings, spec: &ExperimentSpec) -> VplParams {
    VplParams { seed: frame_vpl_seed(vs.vpls.seed, spec.seed, 0), ..vs.vpls }
}

/// The VPL settings of the ground truth (the sampler does not matter: only the VPLs).
fn truth_settings(spec: &ExperimentSpec, r: &Renderer) -> Result<VplSettings, String> {
    let m = spec.vpl.resolve(filtrace_eval::experiment::VplSampler::Uniform, &Default::default());
    vpl_settings(&m, r.lights().scene_radius())
}

/// The frame with its shadow rays counted and a sample of them replayed alone.
fn measured_frame(st: &mut SceneState, vs: &VplSettings, spp: u32) -> Result<(VplFrame, RayClock), String> {
    let (before, _) = rays::pool_counts();
    rays::record_every(KEEP_EVERY);
    let frame = render_frame(&mut st.renderer, vs, spp);
    rays::record_every(0);
    let (after, kept) = rays::pool_counts();
    let frame = frame?;
    let shadow = after - before;
    let accel = st.renderer.context().accel;
    let replay_ms = median_of_3(|| {
        let t = Instant::now();
        std::hint::black_box(kept.par_iter().filter(|r| accel.occluded(r)).count());
        t.elapsed().as_secs_f64() * 1e3
    });
    let shadow_ms = if kept.is_empty() { 0.0 } else { replay_ms * shadow as f64 / kept.len() as f64 };
    let (w, h) = (st.renderer.settings().width as u64, st.renderer.settings().height as u64);
    let camera_rays = w * h * (spp as u64 + 1);
    let camera_ms = median_of_3(|| camera_pass(&st.renderer)) * (spp as f64 + 1.0);
    Ok((frame, RayClock { rays: shadow + camera_rays, ray_ms: shadow_ms + camera_ms }))
}

/// The median of three timings (a loaded machine makes single ones noisy).
fn median_of_3(mut f: impl FnMut() -> f64) -> f64 {
    let mut t = [f(), f(), f()];
    t.sort_by(f64::total_cmp);
    t[1]
}

/// Wall-clock ms of one closest-hit query through every pixel centre.
fn camera_pass(r: &Renderer) -> f64 {
    let (w, h) = (r.settings().width, r.settings().height);
    let accel = r.context().accel;
    let t = Instant::now();
    let hits = (0..w * h)
        .into_par_iter()
        .filter(|i| accel.intersect(&r.camera().generate_ray(i % w, i / w, Vec2::splat(0.5))).is_some())
        .count();
    std::hint::black_box(hits);
    t.elapsed().as_secs_f64() * 1e3
}

/// A hash of the VPLs: positions, normals, weights, depths and the light-path count.
pub fn fingerprint(v: &Vpls) -> u64 {
    let mut bytes = Vec::with_capacity(v.len() * 44 + 8);
    bytes.extend((v.light_paths as u64).to_le_bytes());
    for l in &v.vpls {
        let w = l.weight;
        for f in [l.p.x, l.p.y, l.p.z, l.n.x, l.n.y, l.n.z, w[0], w[1], w[2]] {
            bytes.extend(f.to_bits().to_le_bytes());
        }
        bytes.extend(l.depth.to_le_bytes());
    }
    filtrace_eval::experiment::fnv1a64(&bytes)
}

#[cfg(test)]
mod tests {
    use super::super::experiment::PipelineBackend;
    use super::*;
    use filtrace_eval::experiment::{run_experiment, Clock, VplSampler};
    use filtrace_vpl::cache::{CacheParams, SamplerKind, MAX_NEIGHBOURS};
    use std::path::Path;

    fn tiny() -> (std::path::PathBuf, ExperimentSpec) {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments");
        let spec = ExperimentSpec::load(&dir.join("vpl-tiny.toml")).unwrap();
        (dir, spec)
    }

    /// The many-light experiment at 16x16 through the real renderer (fast tier): every
    /// sampler at 1 and 2 spp, its ground truth, the clocks and the report.
    #[test]
    fn vpl_tiny_spec_end_to_end() {
        let (dir, spec) = tiny();
        let out = std::env::temp_dir().join(format!("filtrace-cli-vplexp-{}", std::process::id()));
        std::fs::remove_dir_all(&out).ok();
        let mut b = PipelineBackend::new(&dir);
        let r = run_experiment(&spec, &dir, &out, &mut b, &mut |_| {}).unwrap();
        filtrace_eval::report::write_all(&out, &r).unwrap();
        assert_eq!(r.entries.len(), 10);
        for e in &r.entries {
            let err = e.errors.rel_mse_clamped;
            assert!(err.is_finite() && err > 0.0, "{e:?}");
            assert_eq!(e.errors.nonfinite, 0);
            let names: Vec<&str> = e.stages.iter().map(|s| s.0.as_str()).collect();
            assert_eq!(names, ["vpls", "cache", "shading", "optimisation"]);
            let rays = e.rays.expect("VPL methods count rays");
            // Camera rays (G-buffer + one per sample) and shadow rays.
            assert!(rays.rays > 16 * 16 * (e.spp as u64 + 1), "{e:?}");
            assert!(rays.ray_ms > 0.0 && e.clock(Clock::WithoutRays).unwrap() >= 0.0);
        }
        // α-max traces a ray per distribution: more rays than the one-sample balance heuristic.
        let rays =
            |m: &str| r.entries.iter().find(|e| e.method == m && e.spp == 1).unwrap().rays.unwrap().rays;
        assert!(rays("alpha-max") > rays("balance"));
        let html = std::fs::read_to_string(out.join("report.html")).unwrap();
        assert_eq!(html.matches("<svg").count(), 4);
        assert!(
            html.contains("cornell-2spp-reference.png") && out.join("cornell-2spp-reference.png").is_file()
        );
        std::fs::remove_dir_all(&out).ok();
    }

    /// The backend's running ground truth over samples 0..2 equals the renderer's own
    /// `--ground-truth` frame of 2 spp (same VPLs, same camera samples).
    #[test]
    fn ground_truth_equals_the_renderers_exhaustive_frame() {
        let (_, spec) = tiny();
        let scene = || Ok(filtrace_scene::builtin("cornell").unwrap());
        let mut b = VplBackend::default();
        let one = b.ground_truth(&spec, "cornell", scene, 1, None).unwrap();
        let two = b.ground_truth(&spec, "cornell", scene, 2, None).unwrap();
        // Extending a sum handed over (as from the experiment's cache) gives the same.
        let mut fresh = VplBackend::default();
        let extended = fresh.ground_truth(&spec, "cornell", scene, 2, Some((1, &one))).unwrap();
        assert_eq!(extended.data(), two.data());
        let settings =
            RenderSettings { width: 16, height: 16, spp: 2, max_depth: spec.max_depth, seed: spec.seed };
        let mut r = Renderer::new(scene().unwrap(), settings).unwrap();
        let mut vs = truth_settings(&spec, &r).unwrap();
        vs.ground_truth = true;
        for (spp, mine) in [(1, &one), (2, &two)] {
            let frame = render_frame(&mut r, &vs, spp).unwrap();
            let theirs = frame.film.aovs().color;
            for (a, b) in mine.data().iter().zip(theirs.data()) {
                assert!((a - b).abs() <= 1e-5 * b.abs().max(1e-3), "{spp} spp: {a} vs {b}");
            }
        }
        assert_ne!(one.data(), two.data(), "the second sample moves the pixels");
    }

    /// The spec's names, ranges and defaults are the renderer's.
    #[test]
    fn spec_constants_and_names_match_the_renderer() {
        use filtrace_eval::experiment as x;
        assert_eq!(x::MAX_NEIGHBOURS as usize, MAX_NEIGHBOURS);
        let d = CacheParams::default();
        assert_eq!(x::DEFAULT_CACHE_POINTS as usize, d.cache_points);
        assert_eq!(x::DEFAULT_NEIGHBOURS as usize, d.neighbours);
        assert_eq!(x::DEFAULT_DISTRIBUTIONS as usize, d.distributions.count());
        assert_eq!(x::DEFAULT_FAINT_SHARE, d.faint_share);
        assert_eq!(x::VplSampler::ALL.len(), SamplerKind::ALL.len());
        for s in VplSampler::ALL {
            assert_eq!(s.name().parse::<SamplerKind>().unwrap().name(), s.name());
        }
    }

    /// A method's settings are those of `filtrace render` with the same options.
    #[test]
    fn vpl_settings_are_the_clis() {
        let m = VplMethod {
            sampler: VplSampler::BalanceCv,
            vpls: 1000,
            clamp: Some(0.01),
            cache_points: 77,
            neighbours: 3,
            distributions: 2,
            faint_share: 0.25,
        };
        let s = vpl_settings(&m, 2.0).unwrap();
        assert_eq!(s.sampler, SamplerKind::BalanceCv);
        assert_eq!((s.vpls.count, s.vpls.direct), (1000, 125));
        assert_eq!((s.cache.cache_points, s.cache.neighbours, s.cache.faint_share), (77, 3, 0.25));
        assert_eq!(s.cache.distributions, DistributionSet::first(1));
        assert_eq!(s.vpls.bound, filtrace_vpl::vpls::GeometryBound::MinDistance(0.02));
        assert!(!s.ground_truth);
        assert_eq!(cli_args(&m)[..4], ["--integrator", "vpl", "--vpls", "1000"]);
    }
}
