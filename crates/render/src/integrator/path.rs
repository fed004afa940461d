//! Unidirectional path tracing with next-event estimation and multiple importance sampling
//! (Veach 1997, ch. 9; pbrt-v4 `PathIntegrator::Li`, sec. 13.4).
//!
//! At every vertex the path (i) adds the emission it hit, weighted against light sampling
//! by the power heuristic, (ii) samples one light (chosen in proportion to power by
//! [`LightSet`](crate::lights::LightSet)) and adds its contribution if unoccluded, weighted
//! against BSDF sampling (delta lights: weight 1), (iii) samples the BSDF for the next
//! direction, and (iv) plays Russian roulette once the path has `rr_depth` segments
//! (survival probability `min(max(beta), 0.95)`, as Mitsuba 3).
//!
//! Symbols as in the papers: `beta` path throughput, `p_b` BSDF-sampling density of the
//! direction that reached a vertex, `p_l` light-sampling density of a direction (selection
//! probability included), `w_b` / `w_l` MIS weights.
//!
//! Entry points, for the plain renderer and for the filtered pipeline of Bauszat et al.
//! 2011 (which needs the first hit from a guide ray and direct/indirect apart):
//! - [`li`]: a camera ray → radiance split + visible surface.
//! - [`trace_from_hit`]: a path continuing from a given first hit → direct and indirect.
//! - [`direct_light`]: only the direct light at a surface (both strategies, MIS).
//!
//! What a miss writes: the environment radiance (zero without one) in `direct` (and so in
//! `color`), and the all-zero visible surface (albedo 0, normal 0 = "no surface", position 0,
//! depth 0).

use super::{CameraSample, PathContext, PathParams, Split, VertexSamples};
use crate::bsdf::SurfaceBsdf;
use crate::film::VisibleSurface;
use crate::surface::SurfaceInteraction;
use filtrace_core::sampler::Sampler;
use filtrace_core::sampling::{power_heuristic, Frame};
use filtrace_core::{Ray, Rgb, Vec3};

/// Radiance along the camera ray `ray` (unit direction), split at the first bounce, with
/// the visible surface when `want_surface`.
pub fn li(
    ctx: &PathContext,
    params: &PathParams,
    ray: &Ray,
    sampler: &mut Sampler,
    want_surface: bool,
) -> CameraSample {
    match ctx.intersect(ray) {
        None => CameraSample {
            radiance: Split { direct: ctx.lights.environment_radiance(ray.dir), indirect: Rgb::ZERO },
            surface: want_surface.then(VisibleSurface::default),
        },
        Some(si) => {
            let surface = want_surface.then(|| visible_surface(ctx, &si));
            CameraSample { radiance: trace_from_hit(ctx, params, &si, sampler), surface }
        }
    }
}

/// The G-buffer record of a first hit: BSDF albedo, shading normal facing the camera,
/// position, distance from the eye.
pub fn visible_surface(ctx: &PathContext, si: &SurfaceInteraction) -> VisibleSurface {
    let bsdf = ctx.bsdf(si);
    VisibleSurface { albedo: bsdf.albedo(), normal: si.n_s, position: si.p, depth: si.t }
}

/// The path starting at the first hit `first` (reached by a camera segment): emission of
/// `first` and direct light at it in `direct`, the rest in `indirect`.
///
/// One loop in the shape of pbrt-v4's `PathIntegrator::Li`. `vertex` counts path vertices
/// from the first hit (0); a path ending at vertex `vertex` has `vertex + 1` segments.
pub fn trace_from_hit(
    ctx: &PathContext,
    params: &PathParams,
    first: &SurfaceInteraction,
    sampler: &mut Sampler,
) -> Split {
    let mut l = Split::default();
    let mut beta = Rgb::ONE;
    let mut si = *first;
    let mut vertex = 0u32;
    // State of the BSDF sample that reached `si`, for MIS of emission found there.
    let mut p_b = 0.0f32;
    let mut specular_bounce = false;
    let mut prev_p = Vec3::ZERO;

    loop {
        // Emitted radiance at the vertex: seen directly (weight 1), after a specular bounce
        // (weight 1: light sampling cannot find it) or MIS-weighted against light sampling.
        let le = ctx.emitted(&si);
        if le != Rgb::ZERO {
            let w_b = if vertex == 0 || specular_bounce {
                1.0
            } else {
                let p_l = ctx.lights.pdf_area(si.instance, si.prim, prev_p, si.p, si.n_winding);
                power_heuristic(1.0, p_b, 1.0, p_l)
            };
            l.add(vertex, beta * w_b * le);
        }

        // Stop when one more segment would exceed max_depth.
        if !params.allows(vertex + 2) {
            break;
        }

        // The BSDF at the vertex, in the shading frame on the side of wo.
        let bsdf = ctx.bsdf(&si);
        let frame = Frame::from_z(si.n_s);
        let wo = frame.to_local(si.wo);
        let u = VertexSamples::draw(sampler, vertex, bsdf.has_lobe_choice());

        // Next-event estimation: one light sample, MIS-weighted against BSDF sampling. The
        // light reaches the eye over the vertices 0..=vertex, as emission found at vertex + 1
        // by BSDF sampling would, so it belongs to the component of vertex + 1.
        l.add(vertex + 1, beta * sample_one_light(ctx, &si, &bsdf, &frame, wo, u.u_select, u.u_light));

        // BSDF sampling for the next direction.
        let Some(bs) = bsdf.sample(wo, u.u_bsdf, u.u_lobe) else { break };
        let wi = frame.to_world(bs.wi);
        beta *= bs.f * (bs.wi.z.abs() / bs.pdf);
        p_b = bs.pdf;
        specular_bounce = bs.specular;
        prev_p = si.p;
        debug_assert!(beta.is_finite(), "beta {beta} from f {} pdf {}", bs.f, bs.pdf);
        if beta == Rgb::ZERO || !beta.is_finite() {
            break;
        }
        let ray = si.spawn_ray(wi);

        // Russian roulette once the path has rr_depth segments.
        if vertex + 2 >= params.rr_depth {
            let q = beta.max_element().min(0.95);
            if VertexSamples::russian_roulette(sampler, vertex) >= q {
                break;
            }
            beta /= q;
        }
        vertex += 1;

        // Find the next vertex; a miss adds the environment, MIS-weighted.
        match ctx.intersect(&ray) {
            Some(next) => si = next,
            None => {
                let le = ctx.lights.environment_radiance(wi);
                if le != Rgb::ZERO {
                    let w_b = if specular_bounce {
                        1.0
                    } else {
                        power_heuristic(1.0, p_b, 1.0, ctx.lights.pdf_environment(wi))
                    };
                    l.add(vertex, beta * w_b * le);
                }
                break;
            }
        }
    }
    l
}

/// Light-sampling contribution at `si` (without the path throughput): one light chosen by
/// power, `f |cos| L_i w_l / p_l` if unoccluded (Veach 1997, eq. 9.12 with the power
/// heuristic eq. 9.13).
#[inline]
fn sample_one_light(
    ctx: &PathContext,
    si: &SurfaceInteraction,
    bsdf: &SurfaceBsdf,
    frame: &Frame,
    wo: Vec3,
    u_select: f32,
    u_light: filtrace_core::Vec2,
) -> Rgb {
    let Some(ls) = ctx.lights.sample_li(si.p, u_select, u_light) else { return Rgb::ZERO };
    let p_l = ls.pdf;
    // `p_l` NaN or <= 0: no usable sample.
    if p_l.is_nan() || p_l <= 0.0 || ls.li == Rgb::ZERO {
        return Rgb::ZERO;
    }
    let wi = frame.to_local(ls.wi);
    let f = bsdf.f(wo, wi) * wi.z.abs();
    if f == Rgb::ZERO || ctx.accel.occluded(&si.spawn_shadow_ray(ls.wi, ls.dist)) {
        return Rgb::ZERO;
    }
    let w_l = if ls.delta { 1.0 } else { power_heuristic(1.0, p_l, 1.0, bsdf.pdf(wo, wi)) };
    f * ls.li * (w_l / p_l)
}

/// Direct light reflected at `si` towards `si.wo` (emission of `si` itself excluded): one
/// light sample and one BSDF sample, combined with the power heuristic. Uses the sampler
/// slots of vertex 0, so with the same sampler it equals the direct light that
/// [`trace_from_hit`] computes at its first hit.
pub fn direct_light(ctx: &PathContext, si: &SurfaceInteraction, sampler: &mut Sampler) -> Rgb {
    let bsdf = ctx.bsdf(si);
    let frame = Frame::from_z(si.n_s);
    let wo = frame.to_local(si.wo);
    let u = VertexSamples::draw(sampler, 0, bsdf.has_lobe_choice());

    // Light sampling.
    let mut l_d = sample_one_light(ctx, si, &bsdf, &frame, wo, u.u_select, u.u_light);

    // BSDF sampling: emission (or environment) found by the sampled direction.
    let Some(bs) = bsdf.sample(wo, u.u_bsdf, u.u_lobe) else { return l_d };
    let wi = frame.to_world(bs.wi);
    let beta = bs.f * (bs.wi.z.abs() / bs.pdf);
    if beta == Rgb::ZERO || !beta.is_finite() {
        return l_d;
    }
    match ctx.intersect(&si.spawn_ray(wi)) {
        Some(next) => {
            let le = ctx.emitted(&next);
            if le != Rgb::ZERO {
                let w_b = if bs.specular {
                    1.0
                } else {
                    let p_l = ctx.lights.pdf_area(next.instance, next.prim, si.p, next.p, next.n_winding);
                    power_heuristic(1.0, bs.pdf, 1.0, p_l)
                };
                l_d += beta * w_b * le;
            }
        }
        None => {
            let le = ctx.lights.environment_radiance(wi);
            if le != Rgb::ZERO {
                let w_b = if bs.specular {
                    1.0
                } else {
                    power_heuristic(1.0, bs.pdf, 1.0, ctx.lights.pdf_environment(wi))
                };
                l_d += beta * w_b * le;
            }
        }
    }
    l_d
}
