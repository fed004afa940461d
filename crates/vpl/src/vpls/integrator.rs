//! The many-light integrator (the thesis's listing 1), an integrator of the per-frame
//! renderer ([`filtrace_render::Renderer::with_integrator`]; [`super::seam`] runs it):
//! - [`Integrator::prepare`], once per frame: generate the VPLs (seed from the VPL seed,
//!   the render's seed and the frame number), trace the G-buffer through the pixel
//!   centres, place the cache points and evaluate every VPL at them; the `optimized`
//!   sampler's parameters are interpolated from the previous frame's cache;
//! - per camera sample ([`Integrator::li`]): the emission seen directly plus the
//!   sampler's estimate `offset + Σ weight_i · V_i contribution_i` of the VPL sum, or the
//!   exhaustive sum (`ground_truth`). Draws of direct VPLs go to `direct`, the rest and the
//!   control-variate offset to `indirect`, so `color = direct + indirect`;
//! - `optimized` only: each tile keeps its draws' feedback; [`Integrator::end_pass`] adds
//!   a finished pass's feedback, in tile order, to the records' [`SampleHistory`] and takes
//!   one damped Newton step per record (skipping records whose samples and parameters did
//!   not change since their last kept step), so the next pass samples with the new
//!   parameters.
//!
//! Sampler slots: 0 the pixel jitter, 1.. the VPL sampler's numbers in order.
//! Determinism: VPLs from one sequential stream, records per record, feedback in tile
//! order and pixel order within a tile: the same film whatever the thread count. Every
//! sample is unbiased for the VPL sum given the parameters it was drawn with, which depend
//! only on earlier passes, so the progressive mean is unbiased too.

use super::eval::Receiver;
use super::exhaustive::{exhaustive_pixel, full_contribution, SceneVpls};
use super::gbuffer::{CameraSurfaces, RecordReceivers};
use super::{generate_vpls, VplParams, Vpls};
use crate::cache::{
    place_on_surfaces, CacheParams, ImportanceCache, OptimizeStats, SampleFeedback, SampleHistory,
    SamplerKind, VisibilityRays,
};
use filtrace_accel::{HitPacket, RayPacket, LANES};
use filtrace_core::sampler::Sampler;
use filtrace_core::{Image, Ray, Rgb, Vec3};
use filtrace_render::film::FilmPixel;
use filtrace_render::integrator::path::visible_surface;
use filtrace_render::integrator::tiles::trace_tile;
use filtrace_render::integrator::{
    CameraSample, FrameContext, Integrator, PassEnd, PathContext, PathParams, Split, Tile, SLOT_PIXEL,
};
use filtrace_render::surface::SurfaceInteraction;
use filtrace_render::RayQueries;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Mutex, PoisonError, RwLock};
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

/// The VPL integrator (see the module docs).
pub struct VplIntegrator {
    settings: VplSettings,
    frame: VplFrameData,
    /// The optimiser's state; only `end_pass` and the tiles' hand-over lock it.
    learning: Mutex<Learning>,
}

/// What `prepare` makes for one frame.
#[derive(Default)]
struct VplFrameData {
    vpls: Vpls,
    /// Records and the `optimized` parameters, which change between passes.
    cache: RwLock<Option<ImportanceCache>>,
    /// Per pixel (row-major) the d-distance to the closest record that the search of its
    /// sample 0 (through the pixel centre) found, as `f32` bits ([`NO_DISTANCE`]: none).
    closest: Vec<AtomicU32>,
    width: usize,
    times: StageTimes,
}

/// `closest` of a pixel whose centre sample found no record (yet).
const NO_DISTANCE: u32 = u32::MAX;

/// The `optimized` sampler's memory within a frame.
#[derive(Default)]
struct Learning {
    /// This pass's feedback per tile, with the tile's index.
    tiles: Vec<(usize, Vec<SampleFeedback>)>,
    /// Emptied feedback lists of earlier passes, for the next tiles.
    spare: Vec<Vec<SampleFeedback>>,
    history: SampleHistory,
    /// The last step's summary and the milliseconds spent optimising this frame.
    last: OptimizeStats,
    optimisation_ms: f64,
    passes: u32,
}

/// What the integrator did in the current frame (`filtrace render --json`, benchmarks).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VplReport {
    pub vpls: usize,
    pub light_paths: usize,
    pub cache_records: usize,
    /// The cache's visibility rays, and the faint VPLs its records took as visible.
    pub cache_rays: VisibilityRays,
    /// VPL generation and cache stages of `prepare`, optimisation of the passes so far
    /// (shading is the passes' time, measured by whoever runs them).
    pub times: StageTimes,
    /// Passes the optimiser has learnt from, and its last step.
    pub optimised_passes: u32,
    pub last_step: OptimizeStats,
}

impl VplIntegrator {
    /// A VPL integrator; `prepare` (done by the renderer) makes its first frame. Errors
    /// name the bad parameter.
    pub fn new(settings: VplSettings) -> Result<Self, String> {
        settings.vpls.validate()?;
        settings.cache.validate()?;
        Ok(VplIntegrator { settings, frame: VplFrameData::default(), learning: Mutex::default() })
    }

    pub fn settings(&self) -> &VplSettings {
        &self.settings
    }

    /// The VPLs of the current frame.
    pub fn vpls(&self) -> &Vpls {
        &self.frame.vpls
    }

    /// A copy of the current importance cache (`None` for `uniform` and the ground truth).
    pub fn cache(&self) -> Option<ImportanceCache> {
        self.frame.cache.read().unwrap_or_else(PoisonError::into_inner).clone()
    }

    /// `f` of the current importance cache, read in place (no copy of its distributions).
    pub fn with_cache<R>(&self, f: impl FnOnce(Option<&ImportanceCache>) -> R) -> R {
        f(self.frame.cache.read().unwrap_or_else(PoisonError::into_inner).as_ref())
    }

    /// Sets the cache the next `prepare` carries the `optimized` parameters from, as if the
    /// frame before had ended with it (a resumed sequence, [`super::state`]).
    pub fn set_previous_cache(&mut self, cache: Option<ImportanceCache>) {
        *self.frame.cache.get_mut().unwrap_or_else(PoisonError::into_inner) = cache;
    }

    pub fn report(&self) -> VplReport {
        let learning = self.learning.lock().unwrap_or_else(PoisonError::into_inner);
        let mut times = self.frame.times;
        times.optimisation_ms = learning.optimisation_ms;
        let cache = self.frame.cache.read().unwrap_or_else(PoisonError::into_inner);
        VplReport {
            vpls: self.frame.vpls.len(),
            light_paths: self.frame.vpls.light_paths,
            cache_records: cache.as_ref().map_or(0, |c| c.records().len()),
            cache_rays: cache.as_ref().map(|c| c.visibility_rays()).unwrap_or_default(),
            times,
            optimised_passes: learning.passes,
            last_step: learning.last,
        }
    }

    /// Per pixel the d-distance from the surface through its centre to the closest cache
    /// record (the thesis's Figure 27), kept from the shading's own search at the pixel's
    /// sample 0 (the renderer's guide ray through the centre) instead of a second search;
    /// 0 for background, without a cache, and before the first pass.
    pub fn cache_distance(&self) -> Image {
        let f = &self.frame;
        let height = f.closest.len().checked_div(f.width).unwrap_or(0);
        let dist: Vec<f32> = f
            .closest
            .iter()
            .map(|d| match d.load(Ordering::Relaxed) {
                NO_DISTANCE => 0.0,
                bits => f32::from_bits(bits),
            })
            .collect();
        Image::from_vec(f.width, height, 1, dist).expect("one value per pixel")
    }

    fn learns(&self) -> bool {
        self.settings.sampler == SamplerKind::Optimized && !self.settings.ground_truth
    }

    /// One camera sample with the cache's sampler; its draws' feedback goes to `feedback`.
    /// Also the d-distance to the closest record its search found (`None` without one).
    fn shade(
        &self,
        cache: Option<&ImportanceCache>,
        ctx: &PathContext,
        ray: &Ray,
        sampler: &mut Sampler,
        want: bool,
        feedback: Option<&mut Vec<SampleFeedback>>,
    ) -> (CameraSample, Option<f32>) {
        match (cache, self.settings.ground_truth) {
            (Some(cache), false) => {
                let hit = ctx.intersect(ray);
                self.shade_hit(cache, ctx, ray, hit, sampler, want, feedback)
            }
            _ => {
                let (radiance, surface) = exhaustive_pixel(ctx, &self.frame.vpls, ray);
                (CameraSample { radiance, surface: want.then_some(surface) }, None)
            }
        }
    }

    /// [`VplIntegrator::shade`] of a camera ray whose closest hit is `hit` (`None`: it
    /// missed), traced by the caller.
    #[allow(clippy::too_many_arguments)]
    fn shade_hit(
        &self,
        cache: &ImportanceCache,
        ctx: &PathContext,
        ray: &Ray,
        hit: Option<SurfaceInteraction>,
        sampler: &mut Sampler,
        want: bool,
        mut feedback: Option<&mut Vec<SampleFeedback>>,
    ) -> (CameraSample, Option<f32>) {
        let vpls = &self.frame.vpls;
        let Some(si) = hit else {
            let direct = ctx.lights.environment_radiance(ray.dir);
            let radiance = Split { direct, indirect: Rgb::ZERO };
            return (CameraSample { radiance, surface: want.then(Default::default) }, None);
        };
        let rx = Receiver::new(si, ctx.bsdf(&si));
        let nb = cache.neighbours(si.p, si.n_s);
        sampler.set_slot(1);
        let plan = cache.sample(self.settings.sampler, &nb, &mut || sampler.next_1d());
        let mut l = Split { direct: ctx.emitted(&si), indirect: plan.offset };
        for (i, d) in plan.draws().iter().enumerate() {
            let v = &vpls.vpls[d.vpl as usize];
            let c = if d.weight > 0.0 || feedback.is_some() {
                full_contribution(ctx, v, &rx, vpls)
            } else {
                Rgb::ZERO
            };
            if v.is_direct() {
                l.direct += d.weight * c;
            } else {
                l.indirect += d.weight * c;
            }
            if let Some(fb) = feedback.as_deref_mut() {
                fb.extend(plan.feedback(i, c));
            }
        }
        let sample = CameraSample { radiance: l, surface: want.then(|| visible_surface(ctx, &si)) };
        (sample, nb.closest_distance())
    }

    /// `trace_tile`'s loop (the pixels in order, each pixel's samples in a row, the same
    /// samplers and rays) with the camera rays traced eight at a time by the packet
    /// query, whose hits are the single-ray query's bit for bit; the samples are then
    /// shaded and added in that order, so the film and the feedback are unchanged.
    fn shade_tile(
        &self,
        cache: &ImportanceCache,
        tile: &Tile,
        pixels: &mut [FilmPixel],
        mut feedback: Option<&mut Vec<SampleFeedback>>,
    ) -> bool {
        let mut batch = CameraBatch::new();
        for i in 0..pixels.len() {
            let (x, y) = ((i % tile.width) as u32, (tile.y0 + i / tile.width) as u32);
            let key = Sampler::pixel_key(x, y, tile.seed);
            for index in tile.first..tile.end {
                if tile.cancel.load(Ordering::Relaxed) {
                    return false;
                }
                batch.push(tile, i, key, index);
                if batch.len == LANES {
                    self.shade_batch(cache, tile, &mut batch, pixels, feedback.as_deref_mut());
                }
            }
        }
        self.shade_batch(cache, tile, &mut batch, pixels, feedback);
        true
    }

    /// Traces the batch's camera rays as one packet, then shades and adds its samples in
    /// order (as `trace_tile` adds them); empties the batch.
    fn shade_batch(
        &self,
        cache: &ImportanceCache,
        tile: &Tile,
        batch: &mut CameraBatch,
        pixels: &mut [FilmPixel],
        mut feedback: Option<&mut Vec<SampleFeedback>>,
    ) {
        let ctx = &tile.ctx;
        let hits = batch.trace(tile);
        for lane in 0..std::mem::take(&mut batch.len) {
            let (ray, i, want) = (batch.rays[lane], batch.pixel[lane], batch.want & (1 << lane) != 0);
            let hit =
                hits.lane(lane).and_then(|h| SurfaceInteraction::from_hit(ctx.scene, ctx.geometry, &ray, &h));
            let sampler = &mut batch.samplers[lane];
            let (s, closest) = self.shade_hit(cache, ctx, &ray, hit, sampler, want, feedback.as_deref_mut());
            let pixel = tile.y0 * tile.width + i;
            if let (true, Some(d), Some(slot)) = (want, closest, self.frame.closest.get(pixel)) {
                slot.store(d.to_bits(), Ordering::Relaxed);
            }
            let px = &mut pixels[i];
            if let Some(surface) = s.surface {
                px.surface = surface;
            }
            px.add(&s.radiance.to_pixel_sample());
        }
    }
}

/// Up to [`LANES`] camera samples of a tile, in `trace_tile`'s order, and their rays.
struct CameraBatch {
    len: usize,
    /// Index of each sample's pixel among the tile's pixels.
    pixel: [usize; LANES],
    /// Each sample's sampler after the pixel jitter (slot [`SLOT_PIXEL`]).
    samplers: [Sampler; LANES],
    rays: [Ray; LANES],
    /// Bit `lane` set for the pixel's sample 0 (its visible surface is asked for).
    want: u8,
}

impl CameraBatch {
    fn new() -> Self {
        let sampler = Sampler::from_pixel_key(0, 0);
        let ray = Ray::new(Vec3::ZERO, Vec3::Z);
        CameraBatch {
            len: 0,
            pixel: [0; LANES],
            samplers: [(); LANES].map(|_| sampler.clone()),
            rays: [ray; LANES],
            want: 0,
        }
    }

    /// Adds sample `index` of pixel `i` of the tile (whose `Sampler::pixel_key` is `key`):
    /// the sampler and ray `trace_tile` makes for it.
    fn push(&mut self, tile: &Tile, i: usize, key: u32, index: u32) {
        let (x, y) = ((i % tile.width) as u32, (tile.y0 + i / tile.width) as u32);
        let lane = self.len;
        let mut sampler = Sampler::from_pixel_key(key, index);
        sampler.set_slot(SLOT_PIXEL);
        let jitter = sampler.next_2d();
        self.rays[lane] = tile.camera.sample_ray(x, y, index, jitter);
        self.samplers[lane] = sampler;
        self.pixel[lane] = i;
        self.want = (self.want & !(1 << lane)) | (u8::from(index == 0) << lane);
        self.len += 1;
    }

    /// The closest hits of the batch's rays (the renderer's packet or per-lane queries).
    fn trace(&self, tile: &Tile) -> HitPacket {
        let (rays, active) = RayPacket::from_rays(&self.rays[..self.len]);
        match tile.lanes.queries {
            RayQueries::Packet => tile.ctx.accel.intersect_packet(&rays, active),
            RayQueries::PerLane => tile.ctx.accel.intersect_packet_lanes(&rays, active),
        }
    }
}

impl Integrator for VplIntegrator {
    fn prepare(&mut self, frame: &FrameContext) {
        let previous = self.frame.cache.get_mut().unwrap_or_else(PoisonError::into_inner).take();
        self.frame = prepare_frame(&self.settings, frame, previous.as_ref());
        let records = self
            .frame
            .cache
            .get_mut()
            .unwrap_or_else(PoisonError::into_inner)
            .as_ref()
            .map_or(0, |c| c.records().len());
        let capacity = self.settings.cache.optimizer.history;
        let learning = self.learning.get_mut().unwrap_or_else(PoisonError::into_inner);
        // The history's and the feedback's memory serve the next frame too.
        let (mut history, spare) =
            (std::mem::take(&mut learning.history), std::mem::take(&mut learning.spare));
        history.reset(records, capacity);
        *learning = Learning { history, spare, ..Learning::default() };
    }

    fn li(
        &self,
        ctx: &PathContext,
        _: &PathParams,
        ray: &Ray,
        sampler: &mut Sampler,
        want: bool,
    ) -> CameraSample {
        let cache = self.frame.cache.read().unwrap_or_else(PoisonError::into_inner);
        self.shade(cache.as_ref(), ctx, ray, sampler, want, None).0
    }

    /// The default tile loop with the cache locked once per tile, the camera rays traced
    /// in packets (`shade_tile`) and, for `optimized`, the tile's feedback handed over at
    /// its end. Sample 0's closest record distance is kept for `cache_distance`.
    fn render_tile(&self, tile: &Tile, pixels: &mut [FilmPixel]) -> bool {
        let learn = self.learns();
        let mut feedback = match learn {
            true => {
                self.learning.lock().unwrap_or_else(PoisonError::into_inner).spare.pop().unwrap_or_default()
            }
            false => Vec::new(),
        };
        let done = {
            let cache = self.frame.cache.read().unwrap_or_else(PoisonError::into_inner);
            match (cache.as_ref(), self.settings.ground_truth) {
                (Some(cache), false) => self.shade_tile(cache, tile, pixels, learn.then_some(&mut feedback)),
                _ => trace_tile(tile, pixels, |ray, sampler, want| {
                    self.shade(None, &tile.ctx, ray, sampler, want, None).0
                }),
            }
        };
        // The cache's lock is released first: `end_pass` takes the two the other way round.
        if learn && done {
            self.learning.lock().unwrap_or_else(PoisonError::into_inner).tiles.push((tile.index, feedback));
        }
        done
    }

    /// `optimized`: the finished pass's feedback (tile order) joins the history and every
    /// record takes one step; a pass cut short teaches nothing.
    fn end_pass(&self, pass: &PassEnd) {
        if !self.learns() {
            return;
        }
        let mut learning = self.learning.lock().unwrap_or_else(PoisonError::into_inner);
        let mut tiles = std::mem::take(&mut learning.tiles);
        if pass.finished {
            let t = Instant::now();
            tiles.sort_unstable_by_key(|&(index, _)| index);
            let parts: Vec<&[SampleFeedback]> = tiles.iter().map(|(_, fb)| fb.as_slice()).collect();
            learning.history.add_parts(&parts);
            let mut cache = self.frame.cache.write().unwrap_or_else(PoisonError::into_inner);
            if let Some(cache) = cache.as_mut() {
                learning.last = cache.optimize_pass(&mut learning.history);
                learning.passes += 1;
            }
            learning.optimisation_ms += t.elapsed().as_secs_f64() * 1e3;
        }
        // A pass cut short teaches nothing; either way its lists serve the next one.
        learning.spare.extend(tiles.into_iter().map(|(_, mut fb)| {
            fb.clear();
            fb
        }));
    }
}

/// The VPLs, G-buffer and cache of one frame.
fn prepare_frame(
    settings: &VplSettings,
    frame: &FrameContext,
    previous: Option<&ImportanceCache>,
) -> VplFrameData {
    let mut times = StageTimes::default();
    let t = Instant::now();
    let vpls = generate_vpls(
        &frame.ctx,
        &frame.params,
        &VplParams { seed: frame_vpl_seed(settings.vpls.seed, frame.seed, frame.frame), ..settings.vpls },
    );
    times.vpl_generation_ms = ms(t);
    let t = Instant::now();
    let (width, height) = (frame.camera.width() as usize, frame.camera.height() as usize);
    let cache = (!settings.ground_truth).then(|| build_cache(settings, frame, &vpls, previous));
    times.cache_ms = ms(t);
    let closest = (0..width * height).map(|_| AtomicU32::new(NO_DISTANCE)).collect();
    VplFrameData { vpls, cache: RwLock::new(cache), closest, width, times }
}

/// The seed of a frame's VPLs: the VPL seed plus the render's seed, decorrelated per frame
/// (public so that a ground truth built outside the renderer draws the same VPLs).
pub fn frame_vpl_seed(base: u64, render_seed: u64, frame: i64) -> u64 {
    base.wrapping_add(render_seed) ^ (frame as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Places the cache points through the G-buffer and evaluates every VPL at each; an
/// empty cache (every sampler then draws uniformly) for `uniform` and for a scene whose
/// bounds are degenerate. The G-buffer is traced where it is read only (`vpls/gbuffer.rs`):
/// at the pixels the placement tries, and the receivers at the records' pixels.
fn build_cache(
    settings: &VplSettings,
    frame: &FrameContext,
    vpls: &Vpls,
    previous: Option<&ImportanceCache>,
) -> ImportanceCache {
    let empty = || ImportanceCache::empty(vpls.len(), &settings.cache);
    if !settings.sampler.needs_cache() {
        return empty();
    }
    let surfaces = CameraSurfaces { ctx: frame.ctx, camera: frame.camera };
    let points = place_on_surfaces(&surfaces, settings.cache.cache_points, frame.seed);
    let receivers = RecordReceivers::trace(&surfaces, &points);
    let set = SceneVpls::new(frame.ctx, vpls, &receivers);
    let diagonal = frame.ctx.scene.bounds().extent().length();
    ImportanceCache::build(&set, points, diagonal, &settings.cache, previous).unwrap_or_else(|_| empty())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vpls::render_vpl_frame;
    use filtrace_core::Vec2;
    use filtrace_render::{RenderSettings, Renderer};
    use std::sync::atomic::AtomicBool;

    /// 128 VPLs (16 direct) and 40 cache points: a frame of a small test image.
    fn small_settings(sampler: SamplerKind) -> VplSettings {
        VplSettings {
            vpls: VplParams { count: 128, direct: 16, ..VplParams::thesis() },
            sampler,
            cache: CacheParams { cache_points: 40, ..CacheParams::default() },
            ground_truth: false,
        }
    }

    /// The tile loop that traces the camera rays in packets adds every pixel's samples
    /// as `trace_tile` with one `li` per sample (a single-ray query each) does, bit for
    /// bit: an image whose width is not a multiple of 8 and several samples per pixel, so
    /// that packets span pixels and rows; per-lane queries give the same film.
    #[test]
    fn packet_camera_rays_give_the_film_of_one_ray_per_sample() {
        let (w, h, spp) = (21u32, 13u32, 3u32);
        let settings = RenderSettings { width: w, height: h, spp, max_depth: 8, seed: 5 };
        for (sampler, queries) in [
            (SamplerKind::Balance, RayQueries::Packet),
            (SamplerKind::BalanceCv, RayQueries::Packet),
            (SamplerKind::AlphaMax, RayQueries::PerLane),
        ] {
            let scene = filtrace_scene::builtin("cornell").expect("built-in Cornell box");
            let mut r = Renderer::new(scene, settings.clone()).expect("settings").with_ray_queries(queries);
            let vs = small_settings(sampler);
            let frame = render_vpl_frame(&mut r, &vs, spp, &AtomicBool::new(false)).unwrap().unwrap();
            let integrator = r.integrator_as::<VplIntegrator>().unwrap();
            let (ctx, params) = (r.context(), r.path_params());
            for (x, y) in (0..h).flat_map(|y| (0..w).map(move |x| (x, y))) {
                let mut want = FilmPixel::default();
                for index in 0..spp {
                    let mut sampler = Sampler::new(x, y, index, settings.seed);
                    sampler.set_slot(SLOT_PIXEL);
                    let ray = r.camera().sample_ray(x, y, index, sampler.next_2d());
                    let s = integrator.li(&ctx, &params, &ray, &mut sampler, index == 0);
                    if let Some(surface) = s.surface {
                        want.surface = surface;
                    }
                    want.add(&s.radiance.to_pixel_sample());
                }
                let got = frame.film.pixel(x as usize, y as usize);
                assert_eq!(format!("{got:?}"), format!("{want:?}"), "{sampler:?}, pixel ({x}, {y})");
                assert_eq!(got.sum.map(f64::to_bits), want.sum.map(f64::to_bits));
            }
        }
    }

    /// The d-distance layer kept from the shading's searches is the layer's definition, a
    /// search of its own through every pixel centre, bit for bit, whatever the spp.
    #[test]
    fn cache_distance_layer_equals_a_search_through_each_pixel_centre() {
        let scene = filtrace_scene::builtin("cornell").expect("built-in Cornell box");
        let (w, h) = (24u32, 20u32);
        let settings = RenderSettings { width: w, height: h, spp: 1, max_depth: 8, seed: 3 };
        let mut r = Renderer::new(scene, settings).expect("settings");
        for (sampler, spp) in [(SamplerKind::Balance, 1), (SamplerKind::Optimized, 3)] {
            let vs = small_settings(sampler);
            let frame = render_vpl_frame(&mut r, &vs, spp, &AtomicBool::new(false)).unwrap().unwrap();
            let cache = r.integrator_as::<VplIntegrator>().unwrap().cache().unwrap();
            let (ctx, layer) = (r.context(), frame.cache_distance);
            assert_eq!((layer.width(), layer.height()), (w as usize, h as usize));
            let mut hits = 0;
            for (x, y) in (0..h).flat_map(|y| (0..w).map(move |x| (x, y))) {
                let ray = r.camera().generate_ray(x, y, Vec2::splat(0.5));
                let want = ctx.intersect(&ray).map_or(0.0, |si| {
                    hits += 1;
                    cache.neighbours(si.p, si.n_s).closest_distance().expect("records")
                });
                let got = layer.pixel(x as usize, y as usize)[0];
                assert_eq!(got.to_bits(), want.to_bits(), "{sampler:?}, pixel ({x}, {y}): {got} vs {want}");
            }
            assert!(hits > 0 && layer.data().iter().any(|&d| d > 0.0));
        }
    }
}
