//! The VPL integrator in the per-frame renderer, and a frame's progressive passes:
//!
//! ```no_run
//! # use std::sync::atomic::AtomicBool;
//! # use filtrace_vpl::vpls::{render_vpl_passes, use_vpl_integrator, VplSettings};
//! # fn renderer() -> filtrace_render::Renderer { unimplemented!() }
//! let mut renderer = renderer();
//! use_vpl_integrator(&mut renderer, &VplSettings::default()).unwrap(); // prepares frame 0
//! let cancel = AtomicBool::new(false);
//! let still = render_vpl_passes(&renderer, 16, u32::MAX, &cancel).unwrap().unwrap();
//! renderer.prepare_frame(1).unwrap(); // new VPLs and cache; parameters carried
//! let next = render_vpl_passes(&renderer, 16, u32::MAX, &cancel).unwrap().unwrap();
//! ```
//!
//! The passes are the path tracer's ([`progressive_passes`]: 1, 1, 2, 4, ... samples per
//! pixel), run by [`Renderer::render_pass`]; after each, the `optimized` sampler learns
//! ([`super::VplIntegrator`]'s `end_pass`). A pass stopped by `cancel` leaves every pixel
//! with a prefix of its samples, each unbiased, as for the path tracer.
//!
//! [`resume_vpl_integrator`] continues a sequence from the [`VplState`] of its last
//! finished frame. [`frame_memory`] estimates the integrator's own buffers before anything is allocated.

use super::eval::Receiver;
use super::exhaustive::QueuedLane;
use super::integrator::{StageTimes, VplIntegrator, VplSettings};
use super::state::VplState;
use super::{Vpl, Vpls};
use crate::cache::{
    CacheRecord, RecordParams, SampleFeedback, SamplerKind, StoredSample, VisibilityRays, CDF_BLOCK,
};
use filtrace_core::{Image, Vec3};
use filtrace_render::film::Film;
use filtrace_render::memory::{bytes_of, image_bytes, MemoryEstimate};
use filtrace_render::renderer::progressive_passes;
use filtrace_render::Renderer;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::time::Instant;

/// One rendered frame of the VPL integrator.
pub struct VplFrame {
    pub film: Film,
    /// Per pixel the d-distance from the centre's surface to the closest cache point
    /// (thesis Figure 27); 0 for background and without a cache.
    pub cache_distance: Image,
    pub vpls: Vpls,
    pub cache_records: usize,
    /// The cache's visibility rays, and the faint VPLs its records took as visible.
    pub cache_rays: VisibilityRays,
    /// Shading is the passes' wall time less the optimisation between them.
    pub times: StageTimes,
    /// `cancel` stopped the passes (every pixel has at least one sample).
    pub cancelled: bool,
}

/// Makes `renderer` render with the VPL integrator of `settings`, prepared (VPLs and
/// cache) for its current frame. Errors name the bad parameter.
pub fn use_vpl_integrator(renderer: &mut Renderer, settings: &VplSettings) -> Result<(), String> {
    let integrator = VplIntegrator::new(settings.clone())?;
    renderer.set_integrator(Box::new(integrator));
    Ok(())
}

/// [`use_vpl_integrator`] continuing from `state` ([`VplIntegrator::state`] of the frame
/// before, possibly written to disk and read back): the renderer's current frame is
/// prepared as it is in a sequence that rendered that frame, so it renders the same
/// image bit for bit. Errors say why the state does not fit `settings`.
pub fn resume_vpl_integrator(
    renderer: &mut Renderer,
    settings: &VplSettings,
    state: &VplState,
) -> Result<(), String> {
    let mut integrator = VplIntegrator::new(settings.clone())?;
    integrator.restore(state)?;
    renderer.set_integrator(Box::new(integrator));
    Ok(())
}

/// Renders samples `0..spp` of every pixel with `renderer`'s VPL integrator in progressive
/// passes of at most `max_pass` samples per pixel. `None` when `cancel` stopped it before
/// every pixel had a sample; an error when the renderer's integrator is not the VPL one.
pub fn render_vpl_passes(
    renderer: &Renderer,
    spp: u32,
    max_pass: u32,
    cancel: &AtomicBool,
) -> Result<Option<VplFrame>, String> {
    let integrator = renderer
        .integrator_as::<VplIntegrator>()
        .ok_or("the renderer's integrator is not the VPL integrator (see use_vpl_integrator)")?;
    let mut film = renderer.new_film();
    let start = Instant::now();
    for (first, count) in progressive_passes(spp, max_pass) {
        if cancel.load(Ordering::Relaxed) || !renderer.render_pass(&mut film, first, count, cancel) {
            break;
        }
    }
    let cancelled = cancel.load(Ordering::Relaxed);
    if cancelled && film.pixels_without_samples() > 0 {
        return Ok(None);
    }
    Ok(Some(collect_frame(film, integrator, start.elapsed().as_secs_f64() * 1e3, cancelled)))
}

/// The outputs of a frame rendered into `film` with `integrator` in `passes_ms`.
pub fn collect_frame(film: Film, integrator: &VplIntegrator, passes_ms: f64, cancelled: bool) -> VplFrame {
    let report = integrator.report();
    let mut times = report.times;
    times.shading_ms = (passes_ms - times.optimisation_ms).max(0.0);
    VplFrame {
        film,
        cache_distance: integrator.cache_distance(),
        vpls: integrator.vpls().clone(),
        cache_records: report.cache_records,
        cache_rays: report.cache_rays,
        times,
        cancelled,
    }
}

/// One frame from scratch: [`use_vpl_integrator`], then [`render_vpl_passes`] of `spp`
/// samples per pixel (passes 1, 1, 2, 4, ...). `None` when `cancel` stopped it before
/// every pixel had a sample.
pub fn render_vpl_frame(
    renderer: &mut Renderer,
    settings: &VplSettings,
    spp: u32,
    cancel: &AtomicBool,
) -> Result<Option<VplFrame>, String> {
    use_vpl_integrator(renderer, settings)?;
    render_vpl_passes(renderer, spp, u32::MAX, cancel)
}

/// Bytes the VPL integrator allocates for a `width x height` frame with `settings` on
/// `threads` threads, rendered in passes of at most `max_pass` samples per pixel, beside
/// the film and the outputs (the path tracer's [`filtrace_render::memory::plain_render`]):
/// - the G-buffer of the cache (`vpls/gbuffer.rs`): the placement's per-pixel flags (taken,
///   and, for a top-up, the surface mask and the list of free pixels) and one receiver per
///   record;
/// - the cache-distance layer: per pixel the closest record's distance kept while
///   shading, and the layer made from it;
/// - the VPLs, twice (the frame's report copies them);
/// - the importance cache, twice: the previous frame's stays alive while the next one
///   is built from it (its parameters are interpolated); per record three CDFs over the
///   VPLs with their coarse index, plus each thread's values of the record it evaluates;
/// - `optimized` only: each record's sample history and one pass's feedback, counted
///   twice: the tiles' lists (kept from pass to pass) and their grouping by record at the
///   end of the pass (smaller entries than the feedback's, so an upper bound).
pub fn frame_memory(
    width: u32,
    height: u32,
    settings: &VplSettings,
    threads: usize,
    max_pass: u32,
) -> MemoryEstimate {
    let pixels = width as u64 * height as u64;
    let vpls = settings.vpls.count as u64 + 16;
    let cached = !settings.ground_truth && settings.sampler.needs_cache();
    let records = if cached { (settings.cache.cache_points as u64).min(pixels) } else { 0 };
    // Three CDFs of `vpls + 1` values with a coarse index of one value per block of cells;
    // the record, its parameters and its search-tree entry (a point, a normal, ~16 bytes).
    let per_record = bytes_of::<f32>(3 * (vpls + 1 + vpls.div_ceil(CDF_BLOCK as u64)))
        + bytes_of::<CacheRecord>(1)
        + bytes_of::<RecordParams>(1)
        + bytes_of::<Vec3>(2)
        + 16;
    // `RecordValues`: three luminances, two RGB contributions and a visibility per VPL;
    // the CDFs' running sums (`f64`) while a record's distributions are built; the
    // record's queued visibility rays.
    let scratch = threads as u64 * vpls * (3 * 4 + 2 * 12 + 1 + 8 + size_of::<QueuedLane>() as u64);
    let learns = cached && settings.sampler == SamplerKind::Optimized;
    let history = records * settings.cache.optimizer.history as u64;
    let feedback = pixels * max_pass as u64;
    MemoryEstimate::new(format!("the VPL integrator at {width}x{height}"))
        .with("G-buffer", cached as u64 * gbuffer_bytes(pixels, records))
        .with("cache distance", pixels * size_of::<AtomicU32>() as u64 + image_bytes(width, height, 1))
        .with("VPLs", 2 * bytes_of::<Vpl>(vpls))
        .with("importance cache", 2 * records * per_record + scratch * cached as u64)
        .with("optimiser history", learns as u64 * bytes_of::<StoredSample>(history))
        .with("pass feedback", learns as u64 * 2 * bytes_of::<SampleFeedback>(feedback))
}

/// The cache's G-buffer: the placement's flags per pixel (`taken`, and for a top-up the
/// surface mask and the free pixels' indices) and the records' receivers with their pixels.
fn gbuffer_bytes(pixels: u64, records: u64) -> u64 {
    pixels * (2 * size_of::<bool>() + size_of::<usize>()) as u64
        + records * (size_of::<u32>() + size_of::<Option<Receiver>>()) as u64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::{CacheParams, ImportanceCache, Technique};
    use crate::vpls::{CameraSurfaces, RecordReceivers, VplParams};
    use filtrace_render::RenderSettings;

    fn animated_cornell() -> Renderer {
        let scene = filtrace_scene::builtin("cornell-anim").expect("built-in animated Cornell box");
        let settings = RenderSettings { width: 16, height: 16, spp: 1, max_depth: 4, seed: 1 };
        Renderer::new(scene, settings).expect("settings")
    }

    fn optimized() -> VplSettings {
        VplSettings {
            vpls: VplParams { count: 64, direct: 8, ..VplParams::thesis() },
            sampler: SamplerKind::Optimized,
            cache: CacheParams { cache_points: 8, ..CacheParams::default() },
            ground_truth: false,
        }
    }

    /// `Σ w_l θ_l` over the records of `previous` nearest to each record of `next` (a
    /// record on top of an old one copies it), computed here from the search alone.
    fn interpolated(previous: &ImportanceCache, next: &ImportanceCache) -> Vec<RecordParams> {
        let old = previous.params();
        next.records()
            .iter()
            .map(|r| {
                let nb = previous.neighbours(r.point.position, r.point.normal);
                let nearest = nb.iter().next();
                match nearest {
                    Some((l, _)) if nb.closest_distance() == Some(0.0) => old[l],
                    _ => RecordParams::blend(nb.iter().map(|(l, w)| (&old[l], w))),
                }
            })
            .collect()
    }

    /// Thesis 5.2.2: a frame starts from the parameters the frame before it learnt,
    /// interpolated at its own records. Frame 10 of the animated Cornell box learns over
    /// 32 spp; the camera moves, so frame 11's records are new points, and their
    /// parameters are the interpolation of frame 10's learnt ones, not the prior. Frame 11
    /// prepared alone starts from the prior.
    #[test]
    fn the_next_frame_starts_from_the_parameters_learnt_in_this_one() {
        let (settings, cancel) = (optimized(), AtomicBool::new(false));
        let mut r = animated_cornell();
        r.prepare_frame(10).unwrap();
        render_vpl_frame(&mut r, &settings, 32, &cancel).unwrap().unwrap();
        let learnt = r.integrator_as::<VplIntegrator>().unwrap().cache().unwrap();
        let prior = RecordParams::prior(&settings.cache);
        assert!(learnt.params().iter().any(|p| *p != prior), "the optimiser took no step in frame 10");
        r.prepare_frame(11).unwrap();
        let next = r.integrator_as::<VplIntegrator>().unwrap().cache().unwrap();
        let moved = next.records().iter().filter(|rec| {
            learnt.neighbours(rec.point.position, rec.point.normal).closest_distance() != Some(0.0)
        });
        assert!(moved.count() > 0, "the camera moves: frame 11 has records of its own");
        assert_eq!(next.params(), &interpolated(&learnt, &next)[..]);
        assert!(next.params().iter().any(|p| *p != prior), "frame 11 forgot what frame 10 learnt");

        let mut alone = animated_cornell();
        alone.prepare_frame(11).unwrap();
        use_vpl_integrator(&mut alone, &settings).unwrap();
        let fresh = alone.integrator_as::<VplIntegrator>().unwrap().cache().unwrap();
        assert_eq!(fresh.records().len(), next.records().len());
        assert!(fresh.params().iter().all(|p| *p == prior), "a frame prepared alone starts a priori");
    }

    /// Film colour bits of one frame of 16 spp.
    fn colour_bits(r: &Renderer) -> Vec<u32> {
        let cancel = AtomicBool::new(false);
        let frame = render_vpl_passes(r, 16, u32::MAX, &cancel).unwrap().unwrap();
        frame.film.aovs().color.data().iter().map(|v| v.to_bits()).collect()
    }

    /// Every number of `state` as the bits of the f32 it holds.
    fn f32_bits(state: &VplState) -> Vec<u32> {
        let mut bits = vec![(state.lambda as f32).to_bits()];
        for r in &state.records {
            let values = r.position.iter().chain(&r.normal).chain(&r.alpha).chain(&r.beta);
            bits.extend(values.chain([&r.radius, &r.normal_cone]).map(|&v| (v as f32).to_bits()));
            bits.push(r.pixel);
        }
        bits
    }

    /// The state after frame 10, written as JSON and read back into a new integrator on a
    /// renderer built anew, renders frame 11 bit for bit as the renderer that rendered
    /// frame 10 (and the state is what it learnt, not the prior, so the test means
    /// something); from the prior, frame 11 differs.
    #[test]
    fn a_state_read_back_renders_the_next_frame_bit_for_bit() {
        let (settings, cancel) = (optimized(), AtomicBool::new(false));
        let mut r = animated_cornell();
        r.prepare_frame(10).unwrap();
        render_vpl_frame(&mut r, &settings, 32, &cancel).unwrap().unwrap();
        let state = r.integrator_as::<VplIntegrator>().unwrap().state().expect("optimized carries state");
        let prior = RecordParams::prior(&settings.cache);
        let prior_alpha = prior.alpha.map(|a| a as f64);
        assert!(state.records.iter().any(|rec| rec.alpha != prior_alpha), "frame 10 learnt nothing");
        let json = serde_json::to_string(&state).unwrap();
        let read: VplState = serde_json::from_str(&json).unwrap();
        // Each value is an f32 written as f64: read back within an f64 ulp, it narrows to
        // the same f32.
        assert_eq!(f32_bits(&read), f32_bits(&state), "the JSON round trip changed the state");
        r.prepare_frame(11).unwrap();
        let carried = colour_bits(&r);

        let mut resumed = animated_cornell();
        resumed.prepare_frame(10).unwrap();
        resumed.prepare_frame(11).unwrap();
        resume_vpl_integrator(&mut resumed, &settings, &read).unwrap();
        assert!(colour_bits(&resumed) == carried, "frame 11 from the state read back differs");

        let mut fresh = animated_cornell();
        fresh.prepare_frame(11).unwrap();
        use_vpl_integrator(&mut fresh, &settings).unwrap();
        assert!(colour_bits(&fresh) != carried, "frame 11 from the prior equals the carried one");
    }

    /// A state of other settings, another version or with a non-finite value is refused
    /// with the reason; samplers that learn nothing have no state.
    #[test]
    fn a_state_that_does_not_fit_is_refused() {
        let (settings, cancel) = (optimized(), AtomicBool::new(false));
        let mut r = animated_cornell();
        render_vpl_frame(&mut r, &settings, 4, &cancel).unwrap().unwrap();
        let state = r.integrator_as::<VplIntegrator>().unwrap().state().unwrap();
        assert!(!state.records.is_empty());
        let other = VplSettings {
            cache: CacheParams { neighbours: 3, ..settings.cache.clone() },
            ..settings.clone()
        };
        let err = resume_vpl_integrator(&mut r, &other, &state).unwrap_err();
        assert!(err.contains("other VPL settings"), "{err}");
        let old = VplState { version: 0, ..state.clone() };
        assert!(resume_vpl_integrator(&mut r, &settings, &old).unwrap_err().contains("state version 0"));
        let mut nan = state.clone();
        nan.records[0].beta[1] = f64::NAN;
        assert!(resume_vpl_integrator(&mut r, &settings, &nan).unwrap_err().contains("record 0"));
        resume_vpl_integrator(&mut r, &settings, &state).unwrap();
        for kind in [SamplerKind::Balance, SamplerKind::Uniform] {
            let s = VplSettings { sampler: kind, ..settings.clone() };
            render_vpl_frame(&mut r, &s, 1, &cancel).unwrap().unwrap();
            assert!(r.integrator_as::<VplIntegrator>().unwrap().state().is_none(), "{kind:?}");
        }
    }

    /// The memory estimate grows with what the integrator allocates: the cache with
    /// VPLs x cache points, nothing of it for the ground truth, the optimiser's buffers
    /// for `optimized` only.
    #[test]
    fn frame_memory_follows_the_settings() {
        let s = VplSettings::default();
        let total = |s: &VplSettings| frame_memory(512, 512, s, 2, 4).total();
        let cache = |s: &VplSettings| frame_memory(512, 512, s, 2, 4).part("importance cache");
        let big = VplSettings { vpls: VplParams::with_count(20_000), ..s.clone() };
        assert!(cache(&big) > 9 * cache(&s), "{} vs {}", cache(&big), cache(&s));
        // 2048 records x 2048 VPLs x 3 CDFs of f32, kept twice: at least 100 MB.
        assert!(cache(&s) > 2 * 2048 * 2048 * 3 * 4);
        let truth = VplSettings { ground_truth: true, ..s.clone() };
        assert_eq!(cache(&truth), 0);
        let balance = VplSettings { sampler: SamplerKind::Balance, ..s.clone() };
        let learning = frame_memory(512, 512, &s, 2, 4);
        assert!(learning.part("optimiser history") > 0 && learning.part("pass feedback") > 0);
        assert_eq!(frame_memory(512, 512, &balance, 2, 4).part("optimiser history"), 0);
        assert!(total(&balance) < total(&s));
        // The G-buffer: a few bytes of flags per pixel, a receiver per record only.
        let gbuffer = |s: &VplSettings| frame_memory(512, 512, s, 2, 4).part("G-buffer");
        assert!(gbuffer(&s) < 512 * 512 * 12 + 2048 * 256, "{}", gbuffer(&s));
        for s in [truth, VplSettings { sampler: SamplerKind::Uniform, ..s.clone() }] {
            assert_eq!(gbuffer(&s), 0, "{:?}: no cache, no G-buffer", s.sampler);
        }
    }

    /// The estimate against the structures a frame really allocates: the cache-distance
    /// layer exactly, the records' receivers and CDFs (one cache of the two the estimate
    /// counts) within it and not far below it.
    #[test]
    fn frame_memory_covers_what_a_frame_allocates() {
        let scene = filtrace_scene::builtin("cornell").expect("built-in Cornell box");
        let (w, h) = (40u32, 32u32);
        let mut r =
            Renderer::new(scene, RenderSettings { width: w, height: h, spp: 1, max_depth: 4, seed: 5 })
                .expect("settings");
        let s = VplSettings { sampler: SamplerKind::Balance, ..optimized() };
        let frame = render_vpl_frame(&mut r, &s, 1, &AtomicBool::new(false)).unwrap().unwrap();
        let estimate = frame_memory(w, h, &s, 1, 1);
        let pixels = (w * h) as u64;
        let layer = size_of_val(frame.cache_distance.data());
        assert_eq!(estimate.part("cache distance"), pixels * 4 + layer as u64);
        let cache = r.integrator_as::<VplIntegrator>().unwrap().cache().unwrap();
        assert_eq!(cache.records().len(), s.cache.cache_points);
        let points: Vec<_> = cache.records().iter().map(|rec| rec.point).collect();
        let surfaces = CameraSurfaces { ctx: r.context(), camera: r.camera() };
        let receivers = RecordReceivers::trace(&surfaces, &points).heap_bytes() as u64;
        let flags = gbuffer_bytes(pixels, 0);
        assert!(estimate.part("G-buffer") >= flags + receivers);
        assert!(estimate.part("G-buffer") <= flags + 2 * receivers, "{}", estimate.part("G-buffer"));
        let cdfs: usize = cache
            .records()
            .iter()
            .flat_map(|rec| {
                [Technique::Full, Technique::Unoccluded, Technique::Bounded].map(|t| rec.distribution(t))
            })
            .map(|d| d.expect("a table").heap_bytes())
            .sum();
        let one_cache = cache.records().len() * (size_of::<CacheRecord>() + size_of::<RecordParams>()) + cdfs;
        let estimated = estimate.part("importance cache") / 2;
        assert!(estimated >= one_cache as u64, "{estimated} < {one_cache}");
        assert!(estimated <= 2 * one_cache as u64, "{estimated} > 2 x {one_cache}");
    }
}
