//! The VPLs behind the renderer's [`Integrator`] seam: `prepare` generates the frame's
//! VPLs (seed from the render's seed and the frame number), `li` shades one camera sample
//! with every VPL (`Exhaustive`, the ground truth) or with one VPL drawn uniformly
//! (`Uniform`, Keller's estimator, pmf 1/N, sampler slot 1). The cache samplers need the
//! whole frame's G-buffer first, so they run through [`super::render_vpl_frame`].

use super::eval::Receiver;
use super::exhaustive::{exhaustive_pixel, full_contribution};
use super::{generate_vpls, VplParams, Vpls};
use filtrace_core::sampler::Sampler;
use filtrace_core::{Ray, Rgb};
use filtrace_render::integrator::path::visible_surface;
use filtrace_render::integrator::{CameraSample, FrameContext, Integrator, PathContext, PathParams, Split};

/// Which VPL estimator [`VplIntegrator::li`] uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VplEstimator {
    Exhaustive,
    Uniform,
}

/// The VPL integrator of the renderer's seam.
#[derive(Clone, Debug)]
pub struct VplIntegrator {
    pub params: VplParams,
    pub estimator: VplEstimator,
    /// The VPLs of the last `prepare`.
    pub vpls: Vpls,
}

impl VplIntegrator {
    pub fn new(params: VplParams, estimator: VplEstimator) -> Self {
        VplIntegrator { params, estimator, vpls: Vpls::default() }
    }
}

impl Integrator for VplIntegrator {
    fn prepare(&mut self, frame: &FrameContext) {
        let seed = frame.seed ^ (frame.frame as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        self.vpls = generate_vpls(&frame.ctx, &frame.params, &VplParams { seed, ..self.params });
    }

    fn li(
        &self,
        ctx: &PathContext,
        _: &PathParams,
        ray: &Ray,
        sampler: &mut Sampler,
        want: bool,
    ) -> CameraSample {
        if self.estimator == VplEstimator::Exhaustive {
            let (radiance, surface) = exhaustive_pixel(ctx, &self.vpls, ray);
            return CameraSample { radiance, surface: want.then_some(surface) };
        }
        let Some(si) = ctx.intersect(ray) else {
            let direct = ctx.lights.environment_radiance(ray.dir);
            let surface = want.then(Default::default);
            return CameraSample { radiance: Split { direct, indirect: Rgb::ZERO }, surface };
        };
        let mut l = Split { direct: ctx.emitted(&si), indirect: Rgb::ZERO };
        let n = self.vpls.len();
        if n > 0 {
            sampler.set_slot(1);
            let j = ((sampler.next_1d() * n as f32) as usize).min(n - 1);
            let v = &self.vpls.vpls[j];
            let c = full_contribution(ctx, v, &Receiver::new(si, ctx.bsdf(&si)), &self.vpls) * n as f32;
            if v.is_direct() {
                l.direct += c;
            } else {
                l.indirect += c;
            }
        }
        CameraSample { radiance: l, surface: want.then(|| visible_surface(ctx, &si)) }
    }
}
