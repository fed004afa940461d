//! Integrators: estimators of the radiance arriving along a camera ray.
//!
//! - [`path`]: unidirectional path tracing with next-event estimation and multiple
//!   importance sampling (the production integrator, pbrt-v4 `PathIntegrator`).
//! - [`bsdf_only`]: the same light transport with BSDF sampling only (pbrt-v4
//!   `SimplePathIntegrator` with `sampleLights = false`), kept as the naive reference the
//!   fast one is tested against.
//!
//! Both split each sample into `direct` (emission seen directly plus direct light at the
//! first hit) and `indirect` (everything after the first bounce), with
//! `color = direct + indirect` exactly (the colour is *defined* as that sum), as the filtered
//! pipeline of Bauszat et al. 2011 needs them apart.
//!
//! The [`Integrator`] trait is the renderer's seam for estimators: each frame first runs its
//! [`Integrator::prepare`] (a VPL renderer generates its virtual point lights there; the
//! path tracers do nothing), then passes of tiles ([`Integrator::render_tile`]; by default
//! [`Integrator::li`] per sample, [`tiles`]), each pass closed by [`Integrator::end_pass`]
//! (pbrt-v4 `cpu/integrators.h`, whose integrators own their `Render()` passes).
//!
//! Path depth follows Mitsuba's `max_depth` convention: the number of path *segments*
//! (camera segment included). 1 = emitters seen directly only, 2 = direct light only,
//! 8 = up to 7 bounces (the default), -1 = unbounded (Russian roulette ends paths).

pub mod bsdf_only;
pub mod lanes;
pub mod lockstep;
pub mod path;
pub mod pool;
pub mod sampler8;
pub(crate) mod sampling8;
pub mod tiles;

use crate::bsdf::SurfaceBsdf;
use crate::camera::PinholeCamera;
use crate::film::{FilmPixel, PixelSample, VisibleSurface};
use crate::lights::LightSet;
use crate::surface::{SceneGeometry, SurfaceInteraction};
use filtrace_accel::SceneAccel;
use filtrace_core::sampler::Sampler;
use filtrace_core::{Ray, Rgb};
use filtrace_scene::Scene;
use lockstep::LaneStats;
use std::any::Any;
use std::sync::atomic::AtomicBool;
pub use tiles::{Lanes, TraceMode};

/// Path-length and termination parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PathParams {
    /// Mitsuba convention (see the module docs); -1 = unbounded. Must be -1 or >= 1.
    pub max_depth: i32,
    /// Russian roulette starts once a path has this many segments (Mitsuba's `rr_depth`).
    pub rr_depth: u32,
}

impl PathParams {
    /// Mitsuba 3's defaults: `max_depth` 8, Russian roulette from depth 5.
    pub fn mitsuba() -> Self {
        Self { max_depth: 8, rr_depth: 5 }
    }
    /// Direct lighting only (`max_depth` 2).
    pub fn direct_only() -> Self {
        Self { max_depth: 2, rr_depth: 5 }
    }
    /// No depth limit; Russian roulette ends paths.
    pub fn unbounded() -> Self {
        Self { max_depth: -1, rr_depth: 5 }
    }
    /// Every named preset (tests loop over them).
    pub fn presets() -> [PathParams; 3] {
        [Self::mitsuba(), Self::direct_only(), Self::unbounded()]
    }

    /// True when a path of `segments` segments is within `max_depth`.
    #[inline]
    pub fn allows(&self, segments: u32) -> bool {
        self.max_depth < 0 || segments <= self.max_depth as u32
    }
}

impl Default for PathParams {
    fn default() -> Self {
        Self::mitsuba()
    }
}

/// What an integrator reads: the scene, its acceleration structure, its lights and the
/// per-instance normal transforms. Cheap to copy (references only).
#[derive(Clone, Copy)]
pub struct PathContext<'a> {
    pub scene: &'a Scene,
    pub accel: &'a SceneAccel,
    pub lights: &'a LightSet,
    pub geometry: &'a SceneGeometry,
}

impl<'a> PathContext<'a> {
    /// The closest surface along `ray` (`None` on a miss or a degenerate triangle).
    ///
    /// Always inlined, with [`SurfaceInteraction::from_hit`]: out of line, the record went
    /// through memory twice and the loop's copy `si = next` missed store forwarding (13%
    /// of `trace_from_hit`'s samples in `perf annotate`).
    #[inline(always)]
    pub fn intersect(&self, ray: &Ray) -> Option<SurfaceInteraction> {
        let hit = self.accel.intersect(ray)?;
        SurfaceInteraction::from_hit(self.scene, self.geometry, ray, &hit)
    }

    /// The BSDF at `si` (textures evaluated at `si.uv`; pbrt's `GetBSDF`).
    #[inline]
    pub fn bsdf(&self, si: &SurfaceInteraction) -> SurfaceBsdf {
        self.geometry.bsdf(self.scene, si.material, si.uv)
    }

    /// Emitted radiance leaving the surface towards `si.wo`: the material's emission on the
    /// front face (or both faces when `two_sided_emission`).
    #[inline]
    pub fn emitted(&self, si: &SurfaceInteraction) -> Rgb {
        let m = &self.scene.materials[si.material as usize];
        if m.is_emissive() && (si.front_face || m.two_sided_emission) {
            m.emission
        } else {
            Rgb::ZERO
        }
    }
}

/// What an integrator's per-frame preparation sees: the frame's world, camera and number.
#[derive(Clone, Copy)]
pub struct FrameContext<'a> {
    pub ctx: PathContext<'a>,
    pub params: PathParams,
    /// The frame's camera at the image's resolution.
    pub camera: &'a PinholeCamera,
    /// Frame number of an animation (0 for a still).
    pub frame: i64,
    /// The render's seed (random numbers of `prepare` derive from it and `frame`).
    pub seed: u64,
}

/// One tile of a pass (pbrt-v4's image tile): the rows `y0..` of the film held by the
/// pixels handed over with it, samples `first..end` of each.
#[derive(Clone, Copy)]
pub struct Tile<'a> {
    pub ctx: PathContext<'a>,
    pub params: PathParams,
    pub camera: &'a PinholeCamera,
    pub seed: u64,
    /// Image width; the tile's pixels are whole rows of it.
    pub width: usize,
    pub y0: usize,
    /// Position of the tile in the pass, top to bottom: a key for results that must be
    /// combined in a fixed order whatever the thread count.
    pub index: usize,
    pub first: u32,
    pub end: u32,
    /// Polled between samples: the tile stops when it is set.
    pub cancel: &'a AtomicBool,
    /// How the path tracer may run in lockstep.
    pub lanes: Lanes<'a>,
}

/// How a pass ended, for [`Integrator::end_pass`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PassEnd {
    pub first: u32,
    pub count: u32,
    /// False when `cancel` cut the pass short (tiles then hold different sample counts).
    pub finished: bool,
}

/// Lets [`crate::Renderer::integrator_as`] find an integrator's own type behind the trait
/// object (blanket-implemented; trait upcasting needs Rust 1.86, the workspace supports 1.80).
pub trait AsAny {
    fn as_any(&self) -> &dyn Any;
}

impl<T: Any> AsAny for T {
    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// An estimator of the radiance along camera rays with a per-frame life cycle (pbrt-v4
/// `cpu/integrators.h`): [`Integrator::prepare`] once per frame, then passes of tiles
/// ([`Integrator::render_tile`], by default [`Integrator::li`] per sample), each pass
/// followed by [`Integrator::end_pass`]. Other crates plug theirs in with
/// [`crate::Renderer::with_integrator`].
pub trait Integrator: AsAny + Send + Sync {
    /// Work done once per frame before any pixel is traced, for the world of `frame`
    /// (after its instances, lights and camera moved). Default: nothing.
    fn prepare(&mut self, frame: &FrameContext) {
        let _ = frame;
    }

    /// The camera sample along `ray` (unit direction): radiance split at the first bounce
    /// and, when `want_surface`, the visible surface. `sampler` is the pixel's, for this
    /// sample index, after the pixel jitter.
    fn li(
        &self,
        ctx: &PathContext,
        params: &PathParams,
        ray: &Ray,
        sampler: &mut Sampler,
        want_surface: bool,
    ) -> CameraSample;

    /// Adds the tile's samples to `pixels` (whole rows from `tile.y0`), each pixel's in
    /// index order; false when `tile.cancel` stopped it. Default: [`tiles::trace_tile`]
    /// over [`Integrator::li`]. Overridden by executors of the same estimator (the path
    /// tracer's lockstep pools) and by integrators that learn from their samples.
    fn render_tile(&self, tile: &Tile, pixels: &mut [FilmPixel]) -> bool {
        tiles::trace_tile(tile, pixels, |ray, sampler, want| {
            self.li(&tile.ctx, &tile.params, ray, sampler, want)
        })
    }

    /// Called after every tile of a pass has returned. `&self` because passes share the
    /// integrator between threads: one that adapts between passes (the importance cache's
    /// optimiser) keeps what it learns behind its own lock. Default: nothing.
    fn end_pass(&self, pass: &PassEnd) {
        let _ = pass;
    }
}

/// The path tracer of [`path`] (next-event estimation + MIS); nothing to prepare. Its
/// tiles run in lockstep unless the renderer's [`TraceMode`] is `Scalar`.
#[derive(Clone, Copy, Debug, Default)]
pub struct PathIntegrator;

impl Integrator for PathIntegrator {
    #[inline]
    fn li(
        &self,
        ctx: &PathContext,
        params: &PathParams,
        ray: &Ray,
        sampler: &mut Sampler,
        want: bool,
    ) -> CameraSample {
        path::li(ctx, params, ray, sampler, want)
    }

    fn render_tile(&self, tile: &Tile, pixels: &mut [FilmPixel]) -> bool {
        match tile.lanes.mode {
            TraceMode::Scalar => tiles::trace_tile(tile, pixels, |ray, sampler, want| {
                path::li(&tile.ctx, &tile.params, ray, sampler, want)
            }),
            _ => tiles::lockstep_tile(tile, pixels, &mut LaneStats::default()),
        }
    }
}

/// The BSDF-sampling reference of [`bsdf_only`]; nothing to prepare, always scalar.
#[derive(Clone, Copy, Debug, Default)]
pub struct BsdfOnlyIntegrator;

impl Integrator for BsdfOnlyIntegrator {
    #[inline]
    fn li(
        &self,
        ctx: &PathContext,
        params: &PathParams,
        ray: &Ray,
        sampler: &mut Sampler,
        want: bool,
    ) -> CameraSample {
        bsdf_only::li(ctx, params, ray, sampler, want)
    }
}

/// The built-in integrators by name (for options and tests); each variant runs as the
/// integrator it names.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum IntegratorKind {
    /// Next-event estimation + MIS ([`path`]).
    #[default]
    Path,
    /// BSDF sampling only ([`bsdf_only`]), the reference for tests.
    BsdfOnly,
}

impl Integrator for IntegratorKind {
    #[inline]
    fn li(
        &self,
        ctx: &PathContext,
        params: &PathParams,
        ray: &Ray,
        sampler: &mut Sampler,
        want: bool,
    ) -> CameraSample {
        match self {
            Self::Path => PathIntegrator.li(ctx, params, ray, sampler, want),
            Self::BsdfOnly => BsdfOnlyIntegrator.li(ctx, params, ray, sampler, want),
        }
    }

    fn render_tile(&self, tile: &Tile, pixels: &mut [FilmPixel]) -> bool {
        match self {
            Self::Path => PathIntegrator.render_tile(tile, pixels),
            Self::BsdfOnly => BsdfOnlyIntegrator.render_tile(tile, pixels),
        }
    }
}

/// Radiance of one path split at the first bounce; `color() = direct + indirect`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Split {
    /// Emission of the first hit plus direct light at the first hit (both strategies).
    pub direct: Rgb,
    /// Light that bounced at least twice.
    pub indirect: Rgb,
}

impl Split {
    /// Adds `l`, light emitted at path vertex `vertex` (0 = first hit; for next-event
    /// estimation at vertex `k` the light's vertex is `k + 1`), to its component: emission
    /// seen directly (vertex 0) or after one bounce (vertex 1) is direct, the rest indirect.
    #[inline]
    pub fn add(&mut self, vertex: u32, l: Rgb) {
        if vertex <= 1 {
            self.direct += l;
        } else {
            self.indirect += l;
        }
    }

    #[inline]
    pub fn color(&self) -> Rgb {
        self.direct + self.indirect
    }

    #[inline]
    pub fn to_pixel_sample(self) -> PixelSample {
        PixelSample { color: self.color(), direct: self.direct, indirect: self.indirect }
    }
}

/// One camera sample: its radiance and, when asked for, the visible surface.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraSample {
    pub radiance: Split,
    /// `None` when not requested; the all-zero record on a miss.
    pub surface: Option<VisibleSurface>,
}

/// Sampler slot plan. Slot 0 is the pixel jitter; each path vertex then owns
/// [`SLOTS_PER_VERTEX`] slots at fixed offsets, so that the dimensions of a vertex never
/// depend on the branches taken before it.
pub const SLOT_PIXEL: u32 = 0;
/// Slots per vertex: see the `SLOT_*` offsets.
pub const SLOTS_PER_VERTEX: u32 = 4;
/// Offset of the light-sample position (2D).
pub const SLOT_LIGHT: u32 = 0;
/// Offset of the BSDF direction (2D).
pub const SLOT_BSDF: u32 = 1;
/// Offset of (light selection, BSDF lobe choice), one 2D slot: two 1D choices share one
/// (0,2)-sequence, which costs one slot instead of two.
pub const SLOT_CHOICES: u32 = 2;
/// Offset of the Russian-roulette decision (1D, drawn only when roulette is played).
pub const SLOT_RR: u32 = 3;

/// First sampler slot of path vertex `vertex`.
#[inline]
pub fn vertex_slot(vertex: u32) -> u32 {
    1 + vertex.saturating_mul(SLOTS_PER_VERTEX)
}

/// The random numbers of one path vertex except Russian roulette.
#[derive(Clone, Copy, Debug)]
pub struct VertexSamples {
    pub u_light: filtrace_core::Vec2,
    pub u_bsdf: filtrace_core::Vec2,
    pub u_select: f32,
    /// 0 when not drawn (see [`VertexSamples::draw`]).
    pub u_lobe: f32,
}

impl VertexSamples {
    /// Draws the samples of vertex `vertex` from `sampler`; `u_lobe` only when `lobe` (the
    /// BSDF chooses between lobes, [`crate::bsdf::SurfaceBsdf::has_lobe_choice`]), else it
    /// is 0. `u_select` is the same value either way: a 1D draw equals the `x` of the 2D
    /// draw on the same slot, and skipping `y` saves a third of that slot's cost.
    #[inline]
    pub fn draw(sampler: &mut filtrace_core::sampler::Sampler, vertex: u32, lobe: bool) -> Self {
        let base = vertex_slot(vertex);
        sampler.set_slot(base + SLOT_LIGHT);
        let u_light = sampler.next_2d();
        let u_bsdf = sampler.next_2d();
        let (u_select, u_lobe) = if lobe {
            let c = sampler.next_2d();
            (c.x, c.y)
        } else {
            (sampler.next_1d(), 0.0)
        };
        Self { u_light, u_bsdf, u_select, u_lobe }
    }

    /// The Russian-roulette number of vertex `vertex`.
    #[inline]
    pub fn russian_roulette(sampler: &mut filtrace_core::sampler::Sampler, vertex: u32) -> f32 {
        sampler.set_slot(vertex_slot(vertex) + SLOT_RR);
        sampler.next_1d()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::renderer::{RenderSettings, Renderer};
    use std::sync::atomic::{AtomicU32, Ordering};

    /// A plug-in integrator whose `li` gives what `prepare` computed from the frame (as a
    /// VPL renderer's lights do), and which counts the passes it was told about.
    #[derive(Default)]
    struct Prepared {
        value: Option<Rgb>,
        prepared: u32,
        passes: AtomicU32,
    }

    impl Integrator for Prepared {
        fn prepare(&mut self, frame: &FrameContext) {
            let size = frame.camera.width() as f32;
            self.value = Some(Rgb::splat(frame.ctx.lights.len() as f32 * (frame.frame + 1) as f32 + size));
            self.prepared += 1;
        }
        fn li(&self, _: &PathContext, _: &PathParams, _: &Ray, _: &mut Sampler, _: bool) -> CameraSample {
            let direct = self.value.expect("prepare runs before li");
            CameraSample { radiance: Split { direct, indirect: Rgb::ZERO }, surface: None }
        }
        fn end_pass(&self, pass: &PassEnd) {
            assert!(pass.finished);
            self.passes.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// The built-in integrators through the trait give what the renderer gives with them.
    #[test]
    fn built_in_integrators_through_the_trait() {
        let scene = filtrace_scene::builtin("cornell").unwrap();
        let settings = RenderSettings { width: 8, height: 8, spp: 1, max_depth: 8, seed: 1 };
        let r = Renderer::new(scene, settings.clone()).unwrap();
        let (ctx, params) = (r.context(), r.path_params());
        for kind in [IntegratorKind::Path, IntegratorKind::BsdfOnly] {
            let reference = Renderer::new(r.scene().clone(), settings.clone()).unwrap().with_integrator(kind);
            for (x, y) in [(3, 4), (0, 0), (7, 2)] {
                let want = reference.trace_sample(x, y, 0);
                let mut sampler = r.sampler(x, y, 0);
                sampler.set_slot(SLOT_PIXEL);
                let ray = r.camera().sample_ray(x, y, 0, sampler.next_2d());
                assert_eq!(kind.li(&ctx, &params, &ray, &mut sampler, true), want, "{kind:?}");
            }
        }
    }

    /// A plug-in integrator is prepared when it is set (a still render needs no frame
    /// update) and again at every frame update, before its pixels are traced, and hears the
    /// end of every pass.
    #[test]
    fn the_renderer_drives_a_plug_in_integrator() {
        let scene = filtrace_scene::builtin("cornell").unwrap();
        let settings = RenderSettings { width: 8, height: 4, spp: 1, max_depth: 8, seed: 1 };
        let mut r = Renderer::new(scene, settings).unwrap().with_integrator(Prepared::default());
        let lights = r.lights().len() as f32;
        let cancel = AtomicBool::new(false);
        for (frame, want_prepared) in [(None, 1), (Some(2), 2), (Some(5), 3)] {
            if let Some(f) = frame {
                r.prepare_frame(f).unwrap();
            }
            let mut film = r.new_film();
            assert!(r.render_pass(&mut film, 0, 1, &cancel) && r.render_pass(&mut film, 1, 2, &cancel));
            let want = lights * (frame.unwrap_or(0) + 1) as f32 + 8.0;
            assert_eq!(film.aovs().color.mean(), [want as f64; 3], "frame {frame:?}");
            let p = r.integrator_as::<Prepared>().expect("the integrator set");
            assert_eq!(p.prepared, want_prepared);
            assert_eq!(p.passes.swap(0, Ordering::Relaxed), 2);
        }
        assert!(r.integrator_as::<PathIntegrator>().is_none());
        r.set_resolution(16, 4).unwrap();
        assert_eq!(r.integrator_as::<Prepared>().unwrap().value, Some(Rgb::splat(lights * 6.0 + 16.0)));
    }
}
