//! Reference path tracer with BSDF sampling only: no next-event estimation, no MIS
//! (pbrt-v4 `SimplePathIntegrator` with `sampleLights = false`).
//!
//! It is slow and noisy but has almost nothing that can go wrong, so the production
//! integrator ([`super::path`]) is tested against it: both must converge to the same image.
//! Delta lights (point, spot, directional) cannot be hit by a sampled direction, so this
//! integrator ignores them; compare only on scenes lit by emissive geometry and
//! environments. Same depth convention, Russian roulette and direct/indirect split as
//! [`super::path`].

use super::{CameraSample, PathContext, PathParams, Split, VertexSamples};
use crate::film::VisibleSurface;
use crate::integrator::path::visible_surface;
use filtrace_core::sampler::Sampler;
use filtrace_core::sampling::Frame;
use filtrace_core::{Ray, Rgb};

/// Radiance along the camera ray `ray`, estimated by BSDF sampling alone.
pub fn li(
    ctx: &PathContext,
    params: &PathParams,
    ray: &Ray,
    sampler: &mut Sampler,
    want_surface: bool,
) -> CameraSample {
    let Some(mut si) = ctx.intersect(ray) else {
        return CameraSample {
            radiance: Split { direct: ctx.lights.environment_radiance(ray.dir), indirect: Rgb::ZERO },
            surface: want_surface.then(VisibleSurface::default),
        };
    };
    let surface = want_surface.then(|| visible_surface(ctx, &si));
    let mut l = Split::default();
    let mut beta = Rgb::ONE;
    let mut vertex = 0u32;
    loop {
        // Emission found by the path, always with weight 1.
        l.add(vertex, beta * ctx.emitted(&si));
        if !params.allows(vertex + 2) {
            break;
        }
        // Sample the BSDF (same slots as the NEE integrator's BSDF sample).
        let bsdf = ctx.bsdf(&si);
        let frame = Frame::from_z(si.n_s);
        let wo = frame.to_local(si.wo);
        let u = VertexSamples::draw(sampler, vertex, bsdf.has_lobe_choice());
        let Some(bs) = bsdf.sample(wo, u.u_bsdf, u.u_lobe) else { break };
        beta *= bs.f * (bs.wi.z.abs() / bs.pdf);
        if beta == Rgb::ZERO || !beta.is_finite() {
            break;
        }
        let wi = frame.to_world(bs.wi);
        let ray = si.spawn_ray(wi);
        // Russian roulette.
        if vertex + 2 >= params.rr_depth {
            let q = beta.max_element().min(0.95);
            if VertexSamples::russian_roulette(sampler, vertex) >= q {
                break;
            }
            beta /= q;
        }
        vertex += 1;
        match ctx.intersect(&ray) {
            Some(next) => si = next,
            None => {
                l.add(vertex, beta * ctx.lights.environment_radiance(wi));
                break;
            }
        }
    }
    CameraSample { radiance: l, surface }
}
