//! The renderer: owns a scene with its acceleration structure and lights, and adds path
//! traced samples to a [`Film`] in progressive passes.
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
use crate::film::{Film, FilmPixel};
use crate::frame_state::FrameState;
use crate::integrator::lockstep::{self, LaneStats, LockstepContext, LockstepTables, RayQueries};
use crate::integrator::pool::{Pool, POOL};
pub use crate::integrator::IntegratorKind;
use crate::integrator::{self, CameraSample, PathContext, PathParams, SLOT_PIXEL};
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
/// How the path tracer ([`IntegratorKind::Path`]) walks its paths. Both give the same film,
/// bit for bit (`tests/lockstep.rs`); the choice is speed only.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TraceMode {
    /// Eight adjacent pixels of a row in lockstep ([`integrator::lockstep`]), AVX2 lane code
    /// when the CPU has AVX2 and FMA, else the portable lane code. The default: with the
    /// accel crate's packet queries it is ~20% faster per CPU second than [`TraceMode::Scalar`]
    /// on the Cornell box (docs/perf-render.md).
    #[default]
    Lockstep,
    /// [`TraceMode::Lockstep`] with the portable lane code even on AVX2 CPUs (for tests and
    /// comparisons).
    LockstepPortable,
    /// One path at a time ([`integrator::path::li`]), the reference.
    Scalar,
}

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
    integrator: IntegratorKind,
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
            integrator: IntegratorKind::Path,
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

    /// Switches the estimator (the BSDF-only one is for tests and comparisons).
    pub fn with_integrator(mut self, kind: IntegratorKind) -> Self {
        self.integrator = kind;
        self
    }

    /// Switches between the lockstep and the scalar path tracer (same film; see
    /// [`TraceMode`]). The BSDF-only integrator is always scalar.
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
        let ctx = self.context();
        let params = self.path_params();
        match self.integrator {
            IntegratorKind::Path => integrator::path::li(&ctx, &params, &ray, &mut sampler, index == 0),
            IntegratorKind::BsdfOnly => {
                integrator::bsdf_only::li(&ctx, &params, &ray, &mut sampler, index == 0)
            }
        }
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
        film.pixels_mut().par_chunks_mut(width * TILE_ROWS).enumerate().for_each(|(tile, pixels)| {
            if !self.render_tile(tile * TILE_ROWS, pixels, first_sample, end, cancel) {
                stopped.store(true, Ordering::Relaxed);
                return;
            }
            on_tile(pixels.len());
        });
        !stopped.load(Ordering::Relaxed)
    }

    /// Renders samples `[first, end)` of the pixels of the band starting at row `y0`;
    /// false when `cancel` stopped it (each pixel keeps the samples it has added).
    fn render_tile(
        &self,
        y0: usize,
        pixels: &mut [FilmPixel],
        first: u32,
        end: u32,
        cancel: &AtomicBool,
    ) -> bool {
        if self.integrator == IntegratorKind::Path {
            let mut stats = LaneStats::default();
            let tile = TileJob { y0, first, end, cancel };
            match self.trace_mode {
                TraceMode::Lockstep => return self.render_tile_lockstep(&tile, pixels, &mut stats),
                TraceMode::LockstepPortable => {
                    return self.render_tile_lockstep_portable(&tile, pixels, &mut stats)
                }
                TraceMode::Scalar => {}
            }
        }
        let width = self.settings.width as usize;
        for (i, px) in pixels.iter_mut().enumerate() {
            let (x, y) = ((i % width) as u32, (y0 + i / width) as u32);
            // The pixel's hash is shared by its samples; the sums stay in a local copy (in
            // registers) and are stored once, in the same order of additions as before.
            let key = Sampler::pixel_key(x, y, self.settings.seed);
            let mut acc = *px;
            for index in first..end {
                if cancel.load(Ordering::Relaxed) {
                    *px = acc;
                    return false;
                }
                let s = self.trace_sample_with(x, y, Sampler::from_pixel_key(key, index));
                if let Some(surface) = s.surface {
                    acc.surface = surface;
                }
                acc.add(&s.radiance.to_pixel_sample());
            }
            *px = acc;
        }
        true
    }

    /// [`Renderer::render_tile`] in lockstep, with the best lane code the CPU runs.
    fn render_tile_lockstep(&self, tile: &TileJob, pixels: &mut [FilmPixel], stats: &mut LaneStats) -> bool {
        #[cfg(target_arch = "x86_64")]
        if filtrace_core::cpu::isa().has_avx2() {
            // SAFETY: the CPU has AVX2 and FMA (checked just above).
            return unsafe { self.render_tile_lockstep_avx2(tile, pixels, stats) };
        }
        self.render_tile_lockstep_portable(tile, pixels, stats)
    }

    /// The lane code compiled for AVX2 + FMA (the same source; only instruction selection
    /// differs, as Rust never contracts into FMAs).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn render_tile_lockstep_avx2(
        &self,
        tile: &TileJob,
        pixels: &mut [FilmPixel],
        stats: &mut LaneStats,
    ) -> bool {
        self.lockstep_tile::<true>(tile, pixels, stats)
    }

    /// The portable lane code.
    fn render_tile_lockstep_portable(
        &self,
        tile: &TileJob,
        pixels: &mut [FilmPixel],
        stats: &mut LaneStats,
    ) -> bool {
        self.lockstep_tile::<false>(tile, pixels, stats)
    }

    /// Pools of [`POOL`] adjacent pixels of each row, one sample index at a time; each
    /// pixel adds its samples in index order, as in the scalar tile loop, so the film is
    /// the same bit for bit. False when `tile.cancel` stopped it.
    #[inline(always)]
    fn lockstep_tile<const AVX2: bool>(
        &self,
        tile: &TileJob,
        pixels: &mut [FilmPixel],
        stats: &mut LaneStats,
    ) -> bool {
        let TileJob { y0, first, end, cancel } = *tile;
        let width = self.settings.width as usize;
        let lc = LockstepContext {
            ctx: self.context(),
            tables: &self.lockstep_tables,
            params: self.path_params(),
            camera: &self.camera,
            queries: self.ray_queries,
        };
        let mut pool = Pool::default();
        let mut out = [CameraSample::default(); POOL];
        for (row, row_pixels) in pixels.chunks_mut(width).enumerate() {
            let y = (y0 + row) as u32;
            for (c, chunk) in row_pixels.chunks_mut(POOL).enumerate() {
                let x0 = (c * POOL) as u32;
                let n = chunk.len();
                let keys: [u32; POOL] =
                    std::array::from_fn(|j| Sampler::pixel_key(x0 + j as u32, y, self.settings.seed));
                for index in first..end {
                    // One relaxed load per pool of paths: negligible, and bounds how long a
                    // Ctrl-C waits whatever the pass size.
                    if cancel.load(Ordering::Relaxed) {
                        return false;
                    }
                    lockstep::trace_pool::<AVX2>(&lc, x0, y, &keys, n, index, &mut pool, stats, &mut out);
                    for (px, s) in chunk.iter_mut().zip(out.iter()) {
                        if let Some(surface) = s.surface {
                            px.surface = surface;
                        }
                        px.add(&s.radiance.to_pixel_sample());
                    }
                }
            }
        }
        true
    }

    /// What the lockstep tracer reads for this renderer's scene, camera and settings (for
    /// tracers of other rays, such as the filtered pipeline's, [`lockstep::trace_film_rays`]).
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
        for (tile, pixels) in film.pixels_mut().chunks_mut(width * TILE_ROWS).enumerate() {
            let job =
                TileJob { y0: tile * TILE_ROWS, first, end: first.saturating_add(count), cancel: &never };
            self.render_tile_lockstep(&job, pixels, &mut stats);
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

/// One tile's work: samples `[first, end)` of the band starting at row `y0`, stopped
/// when `cancel` is set.
#[derive(Clone, Copy)]
struct TileJob<'a> {
    y0: usize,
    first: u32,
    end: u32,
    cancel: &'a AtomicBool,
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
