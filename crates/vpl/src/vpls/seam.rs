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

use super::integrator::{StageTimes, VplIntegrator, VplSettings};
use super::Vpls;
use filtrace_core::Image;
use filtrace_render::film::Film;
use filtrace_render::renderer::progressive_passes;
use filtrace_render::Renderer;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// One rendered frame of the VPL integrator.
pub struct VplFrame {
    pub film: Film,
    /// Per pixel the d-distance from the centre's surface to the closest cache point
    /// (thesis Figure 27); 0 for background and without a cache.
    pub cache_distance: Image,
    pub vpls: Vpls,
    pub cache_records: usize,
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
