//! [`PathSource`] on filtrace's own path tracer ([`filtrace_render::Renderer`]): the camera,
//! the scene's acceleration structure and lights, and the integrator's `trace_from_hit`
//! (direct and indirect apart). A guide ray's path is `trace_from_hit` from its hit; a
//! further eye sample's is the same with two segments ([`eye_sample_params`]: emission and
//! direct light, both strategies, MIS).
//!
//! Two ways of running the same paths, chosen by the renderer's
//! [`TraceMode`](filtrace_render::TraceMode): the per-key methods (`trace`, `trace_paths`,
//! `first_hit`) run the scalar integrator, the reference; the batch methods run the
//! lockstep tracer ([`lanes`], `filtrace_render::integrator::lockstep`) on the batches the
//! pipeline hands over, bit for bit the same (`tests/lockstep_source.rs`), or the scalar
//! code one key at a time in [`TraceMode::Scalar`](filtrace_render::TraceMode::Scalar).

use std::ops::Range;
use std::sync::Mutex;

use filtrace_core::sampler::Sampler;
use filtrace_core::{Rgb, Vec2, Vec3};
use filtrace_render::integrator::lockstep::{LaneCode, LaneStats};
use filtrace_render::integrator::{path, PathParams};
use filtrace_render::{Renderer, TraceMode};

use crate::lookup::HitGeometry;
use crate::source::{self, EyeRay, EyeSample, PathSlot, PathSource, SampleKey};

mod lanes;

/// Sampler index of further eye sample `s` (>= 1) of a pixel. The guide ray's indirect
/// paths use indices `0..paths`; further samples start far above so that their light
/// samples never repeat the guide's.
pub const EYE_SAMPLE_INDEX_BASE: u32 = 1 << 24;

/// The paths of further eye samples: the first two segments of the renderer's paths
/// (`max_depth` 2, or 1 when the renderer's is 1), without Russian roulette before them, so
/// that `trace_from_hit` returns the emission at the hit plus one light sample and one BSDF
/// sample, MIS-weighted, all in `direct`.
pub fn eye_sample_params(p: PathParams) -> PathParams {
    PathParams { max_depth: if p.allows(2) { 2 } else { p.max_depth }, rr_depth: p.rr_depth.max(3) }
}

/// The path tracer as seen by the pipeline.
pub struct RenderSource {
    renderer: Renderer,
    /// Lane utilisation of the lockstep batches traced so far.
    lane_stats: Mutex<LaneStats>,
}

impl RenderSource {
    /// `renderer`'s resolution is the frame's; its `max_depth` bounds every path (Mitsuba
    /// convention: 2 = direct light only, 3 = one indirect bounce); its trace mode says
    /// whether batches run in lockstep.
    pub fn new(renderer: Renderer) -> Self {
        Self { renderer, lane_stats: Mutex::new(LaneStats::default()) }
    }

    /// The lane code the batches run on; `None`: the scalar code, one key at a time.
    pub fn lane_code(&self) -> Option<LaneCode> {
        match self.renderer.trace_mode() {
            TraceMode::Lockstep => Some(LaneCode::Best),
            TraceMode::LockstepPortable => Some(LaneCode::Portable),
            TraceMode::Scalar => None,
        }
    }

    /// Lane utilisation of the lockstep batches traced since the last call (then reset).
    pub fn take_lane_stats(&self) -> LaneStats {
        std::mem::take(&mut *self.lane_stats.lock().unwrap_or_else(|e| e.into_inner()))
    }
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }
    /// The renderer, to move its camera or change its settings between frames
    /// ([`Renderer::set_view`]) without rebuilding the BVH.
    pub fn renderer_mut(&mut self) -> &mut Renderer {
        &mut self.renderer
    }
    /// The scene's bounding-box diagonal, the scale filters divide positions by.
    pub fn scene_scale(&self) -> f32 {
        let d = self.renderer.scene().bounds().extent().length();
        if d.is_finite() && d > 0.0 {
            d
        } else {
            1.0
        }
    }
}

impl PathSource for RenderSource {
    fn resolution(&self) -> Option<(u32, u32)> {
        let s = self.renderer.settings();
        Some((s.width, s.height))
    }

    fn trace(&self, key: SampleKey, film: Vec2, indirect_paths: u32) -> EyeSample {
        let ctx = self.renderer.context();
        let params = self.renderer.path_params();
        let offset = film - Vec2::new(key.x as f32, key.y as f32);
        let ray = self.renderer.camera().generate_ray(key.x, key.y, offset);
        let Some(si) = ctx.intersect(&ray) else {
            let env = ctx.lights.environment_radiance(ray.dir);
            return EyeSample { direct: finite_or_zero(env), ..Default::default() };
        };
        let vs = path::visible_surface(&ctx, &si);
        let hit = Some(HitGeometry { normal: vs.normal, depth: vs.depth });
        let base = EyeSample { hit, albedo: vs.albedo, position: vs.position, ..Default::default() };
        if indirect_paths == 0 {
            // A further eye sample: emission and direct light only (§3.1).
            let mut sampler = Sampler::new(key.x, key.y, EYE_SAMPLE_INDEX_BASE + key.sample, key.seed);
            let split = path::trace_from_hit(&ctx, &eye_sample_params(params), &si, &mut sampler);
            return EyeSample { direct: finite_or_zero(split.direct), ..base };
        }
        // The guide ray: `indirect_paths` paths from its hit, direct and indirect apart
        // (`trace_path` is one term of this sum: keep them in step).
        let (mut direct, mut indirect) = (Rgb::ZERO, Rgb::ZERO);
        for k in 0..indirect_paths {
            let mut sampler = Sampler::new(key.x, key.y, k, key.seed);
            let split = path::trace_from_hit(&ctx, &params, &si, &mut sampler);
            // A non-finite path is dropped (counted as zero), as the film drops it.
            if split.direct.is_finite() && split.indirect.is_finite() {
                direct += split.direct;
                indirect += split.indirect;
            }
        }
        let inv = 1.0 / indirect_paths as f32;
        EyeSample { direct: direct * inv, indirect: indirect * inv, ..base }
    }

    fn first_hit(&self, key: SampleKey, film: Vec2) -> EyeSample {
        // The eye ray of `trace`, its first hit and visible surface; no light sample.
        let ctx = self.renderer.context();
        let offset = film - Vec2::new(key.x as f32, key.y as f32);
        let ray = self.renderer.camera().generate_ray(key.x, key.y, offset);
        let Some(si) = ctx.intersect(&ray) else { return EyeSample::default() };
        let vs = path::visible_surface(&ctx, &si);
        let hit = Some(HitGeometry { normal: vs.normal, depth: vs.depth });
        EyeSample { hit, albedo: vs.albedo, position: vs.position, ..Default::default() }
    }

    fn traces_single_paths(&self) -> bool {
        true
    }

    fn trace_batch(&self, rays: &[EyeRay], out: &mut [EyeSample]) {
        match self.lanes() {
            Some(lanes) => lanes.trace_batch(rays, out),
            None => source::trace_each(self, rays, out),
        }
    }

    fn first_hits(&self, rays: &[EyeRay], out: &mut [EyeSample]) {
        match self.lanes() {
            Some(lanes) => lanes.first_hits(rays, out),
            None => {
                for (o, r) in out.iter_mut().zip(rays) {
                    *o = self.first_hit(r.key, r.film);
                }
            }
        }
    }

    fn trace_path_batch(&self, slots: &[PathSlot], out: &mut [EyeSample]) {
        match self.lanes() {
            Some(lanes) => lanes.trace_path_batch(slots, out),
            None => source::trace_path_runs(self, slots, out),
        }
    }

    fn trace_path(&self, key: SampleKey, film: Vec2, path_index: u32) -> EyeSample {
        let mut out = [EyeSample::default()];
        self.trace_paths(key, film, path_index..path_index + 1, &mut out);
        out[0]
    }

    fn trace_paths(&self, key: SampleKey, film: Vec2, paths: Range<u32>, out: &mut [EyeSample]) {
        assert_eq!(out.len(), paths.len(), "one output per path");
        let ctx = self.renderer.context();
        let params = self.renderer.path_params();
        let offset = film - Vec2::new(key.x as f32, key.y as f32);
        let ray = self.renderer.camera().generate_ray(key.x, key.y, offset);
        let Some(si) = ctx.intersect(&ray) else {
            let env = ctx.lights.environment_radiance(ray.dir);
            out.fill(EyeSample { direct: finite_or_zero(env), ..Default::default() });
            return;
        };
        let vs = path::visible_surface(&ctx, &si);
        let hit = Some(HitGeometry { normal: vs.normal, depth: vs.depth });
        let base = EyeSample { hit, albedo: vs.albedo, position: vs.position, ..Default::default() };
        for (o, k) in out.iter_mut().zip(paths) {
            // The same sampler stream as term `k` of `trace`'s sum.
            let mut sampler = Sampler::new(key.x, key.y, k, key.seed);
            let split = path::trace_from_hit(&ctx, &params, &si, &mut sampler);
            *o = if split.direct.is_finite() && split.indirect.is_finite() {
                EyeSample { direct: split.direct, indirect: split.indirect, ..base }
            } else {
                base
            };
        }
    }
}

impl RenderSource {
    fn lanes(&self) -> Option<lanes::LaneTracer<'_>> {
        let code = self.lane_code()?;
        Some(lanes::LaneTracer { renderer: &self.renderer, code, stats: &self.lane_stats })
    }
}

/// The hit record of an eye ray's visible surface.
fn surface_sample(vs: &filtrace_render::film::VisibleSurface) -> EyeSample {
    let hit = Some(HitGeometry { normal: vs.normal, depth: vs.depth });
    EyeSample { hit, albedo: vs.albedo, position: vs.position, ..Default::default() }
}

fn finite_or_zero(c: Rgb) -> Rgb {
    if c.is_finite() {
        c
    } else {
        Vec3::ZERO
    }
}
