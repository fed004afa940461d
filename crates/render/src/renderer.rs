//! The renderer: owns a scene with its acceleration structure and lights and an
//! [`Integrator`] (the path tracer unless another is set), prepares the integrator for each
//! frame, and adds its samples to a [`Film`] in progressive passes of tiles.
//!
//! ```no_run
//! use std::sync::atomic::AtomicBool;
//! use filtrace_render::{Renderer, RenderSettings};
//! # fn scene() -> filtrace_scene::Scene { unimplemented!() }
//! let settings = RenderSettings { width: 256, height: 256, spp: 16, ..RenderSettings::default() };
//! let renderer = Renderer::new(scene(), settings).expect("valid settings");
//! let mut film = renderer.new_film();
//! let cancel = AtomicBool::new(false);
//! renderer.render_pass(&mut film, 0, 16, &cancel);
//! let aovs = film.aovs();
//! ```
//!
//! Determinism: every sample value is a function of (pixel, sample index, dimension, seed)
//! only (see [`filtrace_core::sampler`]), and each pixel adds its samples in index order
//! within one task, so the film is bit-identical whatever the thread count or tile order.
//!
//! Parallelism: a pass splits the image into bands of [`TILE_ROWS`] rows (the tiles),
//! processed by rayon on the current thread pool.
//!
//! Cancellation: `cancel` is polled before each sample index of each pixel (each pool of
//! pixels in lockstep), so a pass stops within one sample's time however many samples it
//! was asked for. Every pixel then holds a prefix of its samples (indices `0..n`, `n`
//! counted exactly), so its mean is an unbiased estimate; pixels may differ in `n`.
//! [`progressive_passes`] gives the pass sizes that keep every pixel's `n` within a factor
//! of two of the others once the first pass is done.

use crate::camera::PinholeCamera;
use crate::film::Film;
use crate::frame_state::FrameState;
use crate::integrator::lockstep::{LaneStats, LockstepContext, LockstepTables, RayQueries};
use crate::integrator::tiles::{self, Lanes};
use crate::integrator::{
    self, FrameContext, PassEnd, PathContext, PathIntegrator, PathParams, Tile, SLOT_PIXEL,
};
pub use crate::integrator::{Integrator, IntegratorKind, TraceMode};
use crate::lights::LightSet;
pub use crate::settings::{RenderError, RenderSettings, MAX_PIXELS, MAX_SIDE};
use crate::surface::SceneGeometry;
use filtrace_accel::SceneAccel;
use filtrace_core::sampler::Sampler;
use filtrace_scene::Scene;
use rayon::prelude::*;

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Rows per tile. 4 rows of a 512-wide image at 256 spp are ~0.5 M samples: fine-grained
/// enough to balance 2-16 threads and to cancel within a fraction of a second.
pub const TILE_ROWS: usize = 4;
/// A scene ready to render.
pub struct Renderer {
    pub(crate) scene: Scene,
    pub(crate) settings: RenderSettings,
    pub(crate) accel: SceneAccel,
    pub(crate) lights: LightSet,
    pub(crate) geometry: SceneGeometry,
    pub(crate) lockstep_tables: LockstepTables,
    pub(crate) camera: PinholeCamera,
    /// The frame shown and the one before it ([`crate::frame`]).
    pub(crate) frame: FrameState,
    /// Prepared for the current frame (`prepare_integrator`).
    integrator: Box<dyn Integrator>,
    trace_mode: TraceMode,
    ray_queries: RayQueries,
    build_seconds: f64,
}

impl Renderer {
    /// Validates `settings`, builds the acceleration structure and the light set. A scene
    /// without a camera gets [`PinholeCamera::framing`] of its bounds.
    pub fn new(scene: Scene, settings: RenderSettings) -> Result<Renderer, RenderError> {
        settings.validate()?;
        let start = Instant::now();
        // Animated instances stay out of the merged bottom level: moving them is then a
        // top-level update ([`crate::frame`]).
        let accel = SceneAccel::build_with_moving(
            &scene,
            &filtrace_accel::BuildParams::default(),
            filtrace_accel::Simd::best(),
            &crate::frame_state::animated_instances(&scene),
        );
        let lights = LightSet::build(&scene);
        let geometry = SceneGeometry::new(&scene);
        let lockstep_tables = LockstepTables::new(&scene, &geometry, &lights);
        let build_seconds = start.elapsed().as_secs_f64();
        let cam = scene.camera.clone().unwrap_or_else(|| PinholeCamera::framing(&scene.bounds()));
        let camera = PinholeCamera::new(&cam, settings.width, settings.height);
        let frame = FrameState::new(&scene, cam, &camera);
        Ok(Renderer {
            scene,
            settings,
            accel,
            lights,
            geometry,
            lockstep_tables,
            camera,
            frame,
            integrator: Box::new(PathIntegrator),
            trace_mode: TraceMode::default(),
            ray_queries: RayQueries::default(),
            build_seconds,
        })
    }

    /// [`Renderer::set_camera`] with new settings (resolution, max depth, seed), validated
    /// as in [`Renderer::new`]; the scene, BVH and lights are kept. On error nothing changes.
    pub fn set_view(
        &mut self,
        cam: &filtrace_scene::Camera,
        settings: RenderSettings,
    ) -> Result<(), RenderError> {
        settings.validate()?;
        self.apply_size(settings);
        self.set_camera(cam);
        Ok(())
    }

    /// Renders with `integrator` (prepared here for the current frame, and again at every
    /// frame update): the path tracer by default, [`IntegratorKind::BsdfOnly`] for tests,
    /// or another crate's (the many-light renderer).
    pub fn with_integrator(mut self, integrator: impl Integrator + 'static) -> Self {
        self.set_integrator(Box::new(integrator));
        self
    }

    /// [`Renderer::with_integrator`] on a renderer in place.
    pub fn set_integrator(&mut self, integrator: Box<dyn Integrator>) {
        self.integrator = integrator;
        self.prepare_integrator();
    }

    /// The integrator, for what it reports besides the film.
    pub fn integrator(&self) -> &dyn Integrator {
        &*self.integrator
    }

    /// The integrator as its own type, when it is a `T`.
    pub fn integrator_as<T: Integrator + 'static>(&self) -> Option<&T> {
        (*self.integrator).as_any().downcast_ref()
    }

    /// Runs the integrator's per-frame [`Integrator::prepare`] on the current world and
    /// camera; every frame update calls it ([`crate::frame`]).
    pub(crate) fn prepare_integrator(&mut self) {
        let ctx = PathContext {
            scene: &self.scene,
            accel: &self.accel,
            lights: &self.lights,
            geometry: &self.geometry,
        };
        let frame = FrameContext {
            ctx,
            params: self.settings.path_params(),
            camera: &self.camera,
            frame: self.frame.desc.index,
            seed: self.settings.seed,
        };
        self.integrator.prepare(&frame);
    }

    /// Switches between the lockstep and the scalar path tracer (same film; see
    /// [`TraceMode`]). Integrators without a lane version are always scalar.
    pub fn with_trace_mode(mut self, mode: TraceMode) -> Self {
        self.trace_mode = mode;
        self
    }

    /// How the lockstep tracer queries the BVH (packet kernels or one query per lane; same
    /// film).
    pub fn with_ray_queries(mut self, q: RayQueries) -> Self {
        self.ray_queries = q;
        self
    }

    pub fn ray_queries(&self) -> RayQueries {
        self.ray_queries
    }

    pub fn trace_mode(&self) -> TraceMode {
        self.trace_mode
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }
    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }
    pub fn camera(&self) -> &PinholeCamera {
        &self.camera
    }
    pub fn accel(&self) -> &SceneAccel {
        &self.accel
    }
    pub fn lights(&self) -> &LightSet {
        &self.lights
    }
    /// Seconds spent building the acceleration structure and light set.
    pub fn build_seconds(&self) -> f64 {
        self.build_seconds
    }
    pub fn triangle_count(&self) -> usize {
        self.scene.triangle_count()
    }
    pub fn path_params(&self) -> PathParams {
        self.settings.path_params()
    }

    /// What the integrator functions need (for pipelines that trace their own paths).
    pub fn context(&self) -> PathContext<'_> {
        PathContext { scene: &self.scene, accel: &self.accel, lights: &self.lights, geometry: &self.geometry }
    }

    /// An empty film of the settings' resolution.
    pub fn new_film(&self) -> Film {
        Film::new(self.settings.width as usize, self.settings.height as usize)
    }

    /// The sampler of sample `index` of pixel `(x, y)` under the settings' seed.
    #[inline]
    pub fn sampler(&self, x: u32, y: u32, index: u32) -> Sampler {
        Sampler::new(x, y, index, self.settings.seed)
    }

    /// Traces sample `index` of pixel `(x, y)`; the visible surface is recorded for sample 0.
    #[inline]
    pub fn trace_sample(&self, x: u32, y: u32, index: u32) -> integrator::CameraSample {
        self.trace_sample_with(x, y, self.sampler(x, y, index))
    }

    /// [`Renderer::trace_sample`] with the pixel's sampler for the sample already made.
    #[inline]
    fn trace_sample_with(&self, x: u32, y: u32, mut sampler: Sampler) -> integrator::CameraSample {
        let index = sampler.index();
        sampler.set_slot(SLOT_PIXEL);
        let jitter = sampler.next_2d();
        let ray = self.camera.sample_ray(x, y, index, jitter);
        self.integrator.li(&self.context(), &self.path_params(), &ray, &mut sampler, index == 0)
    }

    /// Adds samples `[first_sample, first_sample + count)` of every pixel to `film`, in
    /// parallel on the current rayon pool. Polls `cancel` between samples and returns false
    /// when it stopped early; every pixel then holds an exact count of a prefix of its
    /// samples (see the module docs), so a stopped render can be saved. Panics if `film`
    /// is not of the settings' resolution (a film from another renderer).
    pub fn render_pass(&self, film: &mut Film, first_sample: u32, count: u32, cancel: &AtomicBool) -> bool {
        self.render_pass_with_progress(film, first_sample, count, cancel, &|_| {})
    }

    /// [`Renderer::render_pass`] calling `on_tile(pixels)` after each finished tile (for
    /// progress bars; called from worker threads; not called for a tile cut short).
    pub fn render_pass_with_progress(
        &self,
        film: &mut Film,
        first_sample: u32,
        count: u32,
        cancel: &AtomicBool,
        on_tile: &(dyn Fn(usize) + Sync),
    ) -> bool {
        let width = self.settings.width as usize;
        assert!(
            film.width() == width && film.height() == self.settings.height as usize,
            "film {}x{} does not match the renderer's {}x{}",
            film.width(),
            film.height(),
            width,
            self.settings.height
        );
        let end = first_sample.saturating_add(count);
        let stopped = AtomicBool::new(false);
        film.pixels_mut().par_chunks_mut(width * TILE_ROWS).enumerate().for_each(|(index, pixels)| {
            let tile = self.tile(index, first_sample, end, cancel);
            if !self.integrator.render_tile(&tile, pixels) {
                stopped.store(true, Ordering::Relaxed);
                return;
            }
            on_tile(pixels.len());
        });
        let finished = !stopped.load(Ordering::Relaxed);
        self.integrator.end_pass(&PassEnd { first: first_sample, count, finished });
        finished
    }

    /// Tile `index` (rows from `index * TILE_ROWS`) of a pass of samples `[first, end)`.
    fn tile<'a>(&'a self, index: usize, first: u32, end: u32, cancel: &'a AtomicBool) -> Tile<'a> {
        Tile {
            ctx: self.context(),
            params: self.path_params(),
            camera: &self.camera,
            seed: self.settings.seed,
            width: self.settings.width as usize,
            y0: index * TILE_ROWS,
            index,
            first,
            end,
            cancel,
            lanes: Lanes { tables: &self.lockstep_tables, mode: self.trace_mode, queries: self.ray_queries },
        }
    }

    /// What the lockstep tracer reads for this renderer's scene, camera and settings (for
    /// tracers of other rays, such as the filtered pipeline's, [`crate::integrator::lockstep::trace_film_rays`]).
    pub fn lockstep_context(&self) -> LockstepContext<'_> {
        LockstepContext {
            ctx: self.context(),
            tables: &self.lockstep_tables,
            params: self.path_params(),
            camera: &self.camera,
            queries: self.ray_queries,
        }
    }

    /// Lane utilisation of the lockstep tracer for samples `[first, first + count)` of every
    /// pixel (renders on the current thread into a scratch film).
    pub fn lane_stats(&self, first: u32, count: u32) -> LaneStats {
        let mut film = self.new_film();
        let mut stats = LaneStats::default();
        let width = self.settings.width as usize;
        let never = AtomicBool::new(false);
        for (index, pixels) in film.pixels_mut().chunks_mut(width * TILE_ROWS).enumerate() {
            let mut tile = self.tile(index, first, first.saturating_add(count), &never);
            tile.lanes.mode = TraceMode::Lockstep;
            tiles::lockstep_tile(&tile, pixels, &mut stats);
        }
        stats
    }

    /// A full render of `settings.spp` samples per pixel in one pass.
    pub fn render(&self, cancel: &AtomicBool) -> Film {
        let mut film = self.new_film();
        self.render_pass(&mut film, 0, self.settings.spp, cancel);
        film
    }
}

/// The passes of a progressive render of `spp` samples per pixel, as `(first_sample,
/// count)`: 1, 1, 2, 4, 8, ... samples, each pass at most the samples already done and at
/// most `max_pass` (at least 1). The first pass (1 sample) ends quickly, so a render cut
/// short after it has every pixel sampled, and a pass cut short leaves each pixel with
/// between `n` and `2n` samples.
pub fn progressive_passes(spp: u32, max_pass: u32) -> impl Iterator<Item = (u32, u32)> {
    let max_pass = max_pass.max(1);
    let mut first = 0u32;
    std::iter::from_fn(move || {
        if first >= spp {
            return None;
        }
        let count = first.clamp(1, max_pass).min(spp - first);
        let pass = (first, count);
        first += count;
        Some(pass)
    })
}

/// Timing of [`render_bench`].
#[derive(Clone, Debug, PartialEq)]
pub struct BenchResult {
    pub threads: usize,
    pub samples: u64,
    pub seconds: f64,
    pub samples_per_second: f64,
    /// Mean colour of the image (a sanity check that the right thing was timed).
    pub mean_color: [f64; 3],
}

/// Renders `settings.spp` samples per pixel on a local pool of `threads` threads and
/// reports samples per second (build time excluded).
pub fn render_bench(renderer: &Renderer, threads: usize) -> BenchResult {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("thread pool");
    let cancel = AtomicBool::new(false);
    let start = Instant::now();
    let film = pool.install(|| renderer.render(&cancel));
    let seconds = start.elapsed().as_secs_f64();
    let samples = film.total_samples() + film.dropped_samples();
    let mean = film.aovs().color.mean();
    BenchResult {
        threads,
        samples,
        seconds,
        samples_per_second: samples as f64 / seconds.max(1e-9),
        mean_color: [mean[0], mean[1], mean[2]],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::film::FilmPixel;
    use std::sync::{mpsc, Arc};
    use std::time::Duration;

    #[test]
    fn progressive_passes_cover_every_sample_once_starting_with_one() {
        for (spp, max) in [(1, 1), (4, 1), (64, 4), (1000, 64), (7, 100), (u32::MAX, u32::MAX / 16), (5, 0)] {
            let passes: Vec<_> = progressive_passes(spp, max).collect();
            assert_eq!(passes[0], (0, 1), "spp {spp}");
            let mut next = 0u64;
            for &(first, count) in &passes {
                assert_eq!(first as u64, next, "contiguous, spp {spp}");
                assert!(count >= 1 && count <= max.max(1) && count <= first.max(1), "{first} {count}");
                next += count as u64;
            }
            assert_eq!(next, spp as u64);
        }
        assert_eq!(progressive_passes(0, 4).count(), 0);
        let sizes: Vec<u32> = progressive_passes(40, 8).map(|p| p.1).collect();
        assert_eq!(sizes, [1, 1, 2, 4, 8, 8, 8, 8]);
    }

    /// A pass of (practically) endless samples cancelled from another thread returns soon
    /// after (issue 17: one long tile ignored Ctrl-C), and every pixel holds exactly its
    /// samples `0..n` for its own `n`, bit for bit, so its mean is unbiased.
    #[test]
    fn a_huge_pass_stops_soon_after_cancel_and_keeps_exact_sample_prefixes() {
        for mode in [TraceMode::Lockstep, TraceMode::Scalar] {
            let scene = filtrace_scene::builtin("cornell").expect("built-in Cornell box");
            let settings = RenderSettings { width: 16, height: 8, spp: 1, max_depth: 4, seed: 3 };
            let r = Arc::new(Renderer::new(scene, settings).unwrap().with_trace_mode(mode));
            let cancel = Arc::new(AtomicBool::new(false));
            let (tx, rx) = mpsc::channel();
            let (r2, cancel2) = (r.clone(), cancel.clone());
            // Detached: if the pass ignored `cancel`, the test fails at the timeout below
            // instead of hanging.
            std::thread::spawn(move || {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
                let mut film = r2.new_film();
                let finished = pool.install(|| r2.render_pass(&mut film, 0, u32::MAX, &cancel2));
                let _ = tx.send((finished, film));
            });
            std::thread::sleep(Duration::from_millis(100));
            cancel.store(true, Ordering::Relaxed);
            let (finished, film) = rx
                .recv_timeout(Duration::from_secs(20))
                .expect("{mode:?}: the pass stops within 20 s of cancel");
            assert!(!finished, "{mode:?}");
            assert!(film.max_samples() > 0, "{mode:?}: no sample in 100 ms");
            for (i, px) in film.pixels().iter().enumerate().filter(|(_, p)| p.traced() > 0) {
                let (x, y) = ((i % 16) as u32, (i / 16) as u32);
                let mut want = FilmPixel::default();
                for index in 0..px.traced() {
                    let s = r.trace_sample(x, y, index);
                    if let Some(surface) = s.surface {
                        want.surface = surface;
                    }
                    want.add(&s.radiance.to_pixel_sample());
                }
                assert_eq!(*px, want, "{mode:?}: pixel ({x}, {y}) with {} samples", px.traced());
            }
        }
    }
}
