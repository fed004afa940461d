//! The many-light integrator of one frame (the thesis's listing 1, without the temporal
//! steps): generate the VPLs (the per-frame `prepare`), trace the G-buffer, place and
//! evaluate the importance cache, shade every pixel with the chosen VPL sampler, then
//! (`optimized` only) one Newton step per record.
//!
//! Per camera sample: the emission seen directly, plus the sampler's estimate
//! `offset + Σ weight_i · V_i contribution_i` of the VPL sum (sampler slot plan: slot 0
//! the pixel jitter, slots 1.. the sampler's uniform numbers, in order). Draws of direct
//! VPLs go to `direct`, the rest and the control-variate offset to `indirect`, so
//! `color = direct + indirect` as the filters expect. `--ground-truth` replaces the
//! sampler by the exhaustive sum ([`super::exhaustive`]).
//!
//! Determinism: VPLs from one sequential stream, cache records per record, pixels per
//! row, feedback concatenated in pixel order: the same film whatever the thread count.

use super::eval::Receiver;
use super::exhaustive::{full_contribution, render_exhaustive, SceneVpls};
use super::{generate_vpls, VplParams, Vpls};
use crate::cache::{
    place_cache_points, CacheParams, GBufferView, ImportanceCache, SampleFeedback, SamplerKind,
};
use filtrace_core::sampler::Sampler;
use filtrace_core::{Image, Rgb, Vec2, Vec3};
use filtrace_render::film::{Film, FilmPixel, PixelSample};
use filtrace_render::integrator::path::visible_surface;
use filtrace_render::integrator::SLOT_PIXEL;
use filtrace_render::Renderer;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// What the VPL integrator does.
#[derive(Clone, Debug, PartialEq)]
pub struct VplSettings {
    pub vpls: VplParams,
    pub sampler: SamplerKind,
    pub cache: CacheParams,
    /// Every VPL with visibility at every sample instead of the sampler.
    pub ground_truth: bool,
}

impl Default for VplSettings {
    fn default() -> Self {
        VplSettings {
            vpls: VplParams::thesis(),
            sampler: SamplerKind::Optimized,
            cache: CacheParams::default(),
            ground_truth: false,
        }
    }
}

/// Milliseconds per stage of one frame (`filtrace bench vpl`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageTimes {
    pub vpl_generation_ms: f64,
    /// G-buffer, cache placement and evaluation of every VPL at every record.
    pub cache_ms: f64,
    pub shading_ms: f64,
    pub optimisation_ms: f64,
}

/// One rendered frame.
pub struct VplFrame {
    pub film: Film,
    /// Per pixel the d-distance from the centre's surface to the closest cache point
    /// (thesis Figure 27); 0 for background and without a cache.
    pub cache_distance: Image,
    pub vpls: Vpls,
    pub cache_records: usize,
    pub times: StageTimes,
}

/// Renders samples `0..spp` of every pixel of `renderer`'s image with the VPLs; `None`
/// when `cancel` stopped it. Errors name the bad parameter.
pub fn render_vpl_frame(
    renderer: &Renderer,
    settings: &VplSettings,
    spp: u32,
    cancel: &AtomicBool,
) -> Result<Option<VplFrame>, String> {
    settings.vpls.validate()?;
    settings.cache.validate()?;
    let ctx = renderer.context();
    let mut times = StageTimes::default();
    let t = Instant::now();
    let vpls = generate_vpls(&ctx, &renderer.path_params(), &settings.vpls);
    times.vpl_generation_ms = ms(t);
    let (w, h) = (renderer.settings().width as usize, renderer.settings().height as usize);
    if settings.ground_truth {
        let t = Instant::now();
        let seed = renderer.settings().seed;
        let film = render_exhaustive(&ctx, renderer.camera(), &vpls, 0, spp, seed, cancel);
        times.shading_ms = ms(t);
        let cache_distance = Image::new(w, h, 1);
        return Ok(film.map(|film| VplFrame { film, cache_distance, vpls, cache_records: 0, times }));
    }

    // G-buffer and importance cache.
    let t = Instant::now();
    let receivers = gbuffer(renderer);
    let mut cache = build_cache(renderer, settings, &vpls, &receivers)?;
    times.cache_ms = ms(t);

    // Shading, rows in parallel; feedback kept in pixel order.
    let t = Instant::now();
    let mut film = Film::new(w, h);
    let mut dist = vec![0.0f32; w * h];
    let learn = settings.sampler == SamplerKind::Optimized;
    let feedback: Vec<Vec<SampleFeedback>> = film
        .pixels_mut()
        .par_chunks_mut(w)
        .zip(dist.par_chunks_mut(w))
        .enumerate()
        .map(|(y, (row, drow))| {
            let mut fb = Vec::new();
            for (x, (px, d)) in row.iter_mut().zip(drow.iter_mut()).enumerate() {
                let job = PixelJob { renderer, settings, vpls: &vpls, cache: &cache, x, y, spp, learn };
                if !shade_pixel(&job, px, d, &mut fb, cancel) {
                    break;
                }
            }
            fb
        })
        .collect();
    times.shading_ms = ms(t);
    if cancel.load(Ordering::Relaxed) {
        return Ok(None);
    }

    // One Newton step per record (optimized).
    let t = Instant::now();
    if learn {
        let all: Vec<SampleFeedback> = feedback.into_iter().flatten().collect();
        cache.optimize(&all);
    }
    times.optimisation_ms = ms(t);
    let cache_distance = Image::from_vec(w, h, 1, dist).expect("w × h values");
    Ok(Some(VplFrame { film, cache_distance, vpls, cache_records: cache.records().len(), times }))
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// The surface through each pixel centre, with its BSDF (row-major).
fn gbuffer(renderer: &Renderer) -> Vec<Option<Receiver>> {
    let ctx = renderer.context();
    let w = renderer.settings().width as usize;
    let n = w * renderer.settings().height as usize;
    (0..n)
        .into_par_iter()
        .map(|i| {
            let ray = renderer.camera().generate_ray((i % w) as u32, (i / w) as u32, Vec2::splat(0.5));
            ctx.intersect(&ray).map(|si| Receiver::new(si, ctx.bsdf(&si)))
        })
        .collect()
}

/// Places the cache points through the G-buffer and evaluates every VPL at each.
fn build_cache(
    renderer: &Renderer,
    settings: &VplSettings,
    vpls: &Vpls,
    receivers: &[Option<Receiver>],
) -> Result<ImportanceCache, String> {
    if !settings.sampler.needs_cache() {
        return Ok(ImportanceCache::empty(vpls.len(), &settings.cache));
    }
    let positions: Vec<Vec3> = receivers.iter().map(|r| r.map_or(Vec3::ZERO, |r| r.si.p)).collect();
    let normals: Vec<Vec3> = receivers.iter().map(|r| r.map_or(Vec3::ZERO, |r| r.si.n_s)).collect();
    let s = renderer.settings();
    let view = GBufferView {
        width: s.width as usize,
        height: s.height as usize,
        positions: &positions,
        normals: &normals,
    };
    let points = place_cache_points(&view, settings.cache.cache_points, s.seed)?;
    let set = SceneVpls { ctx: renderer.context(), vpls, receivers };
    let diagonal = renderer.scene().bounds().extent().length();
    ImportanceCache::build(&set, points, diagonal, &settings.cache, None)
}

/// One pixel's work.
struct PixelJob<'a> {
    renderer: &'a Renderer,
    settings: &'a VplSettings,
    vpls: &'a Vpls,
    cache: &'a ImportanceCache,
    x: usize,
    y: usize,
    spp: u32,
    learn: bool,
}

/// Adds samples `0..spp` of one pixel; false when cancelled.
fn shade_pixel(
    job: &PixelJob,
    px: &mut FilmPixel,
    dist: &mut f32,
    feedback: &mut Vec<SampleFeedback>,
    cancel: &AtomicBool,
) -> bool {
    let ctx = job.renderer.context();
    let (x, y) = (job.x as u32, job.y as u32);
    for index in 0..job.spp {
        if cancel.load(Ordering::Relaxed) {
            return false;
        }
        let mut sampler = Sampler::new(x, y, index, job.renderer.settings().seed);
        sampler.set_slot(SLOT_PIXEL);
        let ray = job.renderer.camera().sample_ray(x, y, index, sampler.next_2d());
        let Some(si) = ctx.intersect(&ray) else {
            let env = ctx.lights.environment_radiance(ray.dir);
            px.add(&PixelSample { color: env, direct: env, indirect: Rgb::ZERO });
            continue;
        };
        let rx = Receiver::new(si, ctx.bsdf(&si));
        let nb = job.cache.neighbours(si.p, si.n_s);
        if index == 0 {
            px.surface = visible_surface(&ctx, &si);
            *dist = nb.closest_distance().unwrap_or(0.0);
        }
        let plan = job.cache.sample(job.settings.sampler, &nb, &mut || sampler.next_1d());
        let (mut direct, mut indirect) = (ctx.emitted(&si), plan.offset);
        for (i, d) in plan.draws().iter().enumerate() {
            let v = &job.vpls.vpls[d.vpl as usize];
            let c = if d.weight > 0.0 || job.learn {
                full_contribution(&ctx, v, &rx, job.vpls)
            } else {
                Rgb::ZERO
            };
            if v.is_direct() {
                direct += d.weight * c;
            } else {
                indirect += d.weight * c;
            }
            if job.learn {
                feedback.extend(plan.feedback(i, c));
            }
        }
        px.add(&PixelSample { color: direct + indirect, direct, indirect });
    }
    true
}
