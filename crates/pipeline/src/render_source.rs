//! [`PathSource`] on filtrace's own path tracer ([`filtrace_render::Renderer`]): the camera,
//! the scene's acceleration structure and lights, and the integrator's
//! `trace_from_hit` (direct and indirect apart) and `direct_light` entry points.

use std::ops::Range;

use filtrace_core::sampler::Sampler;
use filtrace_core::{Rgb, Vec2, Vec3};
use filtrace_render::integrator::{path, SLOT_PIXEL};
use filtrace_render::Renderer;

use crate::lookup::HitGeometry;
use crate::source::{EyeSample, PathSource, SampleKey};

/// Sampler index of further eye sample `s` (>= 1) of a pixel. The guide ray's indirect
/// paths use indices `0..paths`; further samples start far above so that their light
/// samples never repeat the guide's.
pub const EYE_SAMPLE_INDEX_BASE: u32 = 1 << 24;

/// The path tracer as seen by the pipeline.
pub struct RenderSource {
    renderer: Renderer,
}

impl RenderSource {
    /// `renderer`'s resolution is the frame's; its `max_depth` bounds every path (Mitsuba
    /// convention: 2 = direct light only, 3 = one indirect bounce).
    pub fn new(renderer: Renderer) -> Self {
        Self { renderer }
    }
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }
    /// The renderer, to move it to the next frame of an animation (keep its resolution).
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
        let emitted = ctx.emitted(&si);
        if indirect_paths == 0 {
            // A further eye sample: emission and direct light only (§3.1).
            let index = EYE_SAMPLE_INDEX_BASE + key.sample;
            let mut sampler = Sampler::new(key.x, key.y, index, key.seed);
            sampler.set_slot(SLOT_PIXEL);
            let direct =
                if params.allows(2) { path::direct_light(&ctx, &si, &mut sampler) } else { Rgb::ZERO };
            return EyeSample { direct: finite_or_zero(emitted + direct), ..base };
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

fn finite_or_zero(c: Rgb) -> Rgb {
    if c.is_finite() {
        c
    } else {
        Vec3::ZERO
    }
}
