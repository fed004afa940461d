//! Light sources, as pbrt-v4 splits them (`base/light.h`, `base/lightsampler.h`):
//!
//! - a [`Light`] answers for itself: [`Light::sample_li`] (a direction towards it from a
//!   shading point, with its solid-angle density), [`Light::pdf_li`] (that density for a
//!   direction found otherwise, for MIS), [`Light::sample_le`] (a ray leaving it, for
//!   light tracing and virtual point lights; [`emission`]), [`Light::power`] and
//!   [`Light::bounds`];
//! - a [`LightSampler`] chooses among lights ([`PowerLightSampler`]: in proportion to
//!   power, pbrt-v4 section 12.6; an importance cache is another implementation);
//! - a [`LightSet`] gathers the lights of a scene (every emissive triangle of every
//!   instance in world space, plus the scene's explicit lights), finds the light of an
//!   emissive triangle, and keeps them up to date when instances move
//!   ([`LightSet::update_instances`]).
//!
//! The MIS density of a light found by BSDF sampling is, as in pbrt-v4's
//! `PathIntegrator::Li`, `p_l = sampler.pmf(ctx, light) * light.pdf_li(ctx, wi)`
//! ([`LightSet::pdf_area`], [`LightSet::pdf_environment`]; Veach 1997, chapter 9).
//!
//! Emitters: [`AreaLight`] (one triangle), [`PointLight`], [`SpotLight`],
//! [`DirectionalLight`] and one combined [`EnvironmentLight`] (all `Environment` entries
//! summed). Power (for selection): area `π A lum(Le)` (× 2 two-sided), point `4π lum(I)`,
//! spot `2π (1 − (cos_start + cos_width)/2) lum(I)`, directional `π R² lum(E)`,
//! environment `π R² · π · mean lum(L)`, with `R` the radius of the scene's bounding
//! sphere. Lights of zero power (black, degenerate, non-finite) are dropped at build time
//! and counted in [`LightSet::skipped`].

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN, which `x <= 0.0` lets through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod area;
pub mod directional;
pub mod emission;
pub mod environment;
pub mod point;
pub mod sampler;
mod set;
pub mod spot;

pub use area::AreaLight;
pub use directional::DirectionalLight;
pub use emission::{EmitterKind, LeSample};
pub use environment::EnvironmentLight;
pub use point::PointLight;
pub use sampler::{LightSampler, PowerLightSampler, SampledLight};
pub use set::LightSet;
pub use spot::SpotLight;

use filtrace_core::{Aabb, Rgb, Vec2, Vec3};

/// Where light arrives: the shading point a light is sampled from (pbrt-v4
/// `LightSampleContext`; a sampler that needs the normal, such as an importance cache
/// with records per hemisphere, adds it here).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightSampleContext {
    pub p: Vec3,
}

/// A sampled direction towards a light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightSample {
    /// Unit world direction from the shading point towards the light.
    pub wi: Vec3,
    /// Incident radiance (for delta lights: intensity / d², or irradiance).
    pub li: Rgb,
    /// Solid-angle density; 1 for delta lights. From [`LightSet::sample_li`] it includes
    /// the selection probability (for delta lights it is that probability alone).
    pub pdf: f32,
    /// Distance to the light point; `f32::INFINITY` for directional/environment.
    pub dist: f32,
    pub delta: bool,
}

/// What a light-sampling structure (a light BVH, an importance cache) may know of a light
/// without sampling it (pbrt-v4 `LightBounds`, section 12.6.3): it emits at most `phi`
/// from points inside `bounds`, in directions within `acos(cos_theta_o) +
/// acos(cos_theta_e)` of `w` (on both sides of `w` when `two_sided`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightBounds {
    pub bounds: Aabb,
    /// The light's power ([`Light::power`]).
    pub phi: f32,
    /// Unit principal direction of emission.
    pub w: Vec3,
    /// Cosine of the spread of the emitting normals around `w`.
    pub cos_theta_o: f32,
    /// Cosine of the spread of emission around each normal.
    pub cos_theta_e: f32,
    pub two_sided: bool,
}

/// One light: a closed set of kinds (an enum, as pbrt's `TaggedPointer`).
#[derive(Clone, Debug)]
pub enum Light {
    Area(AreaLight),
    Point(PointLight),
    Spot(SpotLight),
    Directional(DirectionalLight),
    Environment(EnvironmentLight),
}

impl Light {
    /// A direction towards the light from `ctx.p` with the incident radiance and the
    /// solid-angle density (1 for delta lights), without light selection. `None` when the
    /// light cannot be seen from `ctx.p` (back face, outside a spot's cone, black
    /// environment).
    #[inline]
    pub fn sample_li(&self, ctx: &LightSampleContext, u: Vec2) -> Option<LightSample> {
        let p = ctx.p;
        let delta = |(wi, li, dist): (Vec3, Rgb, f32)| LightSample { wi, li, pdf: 1.0, dist, delta: true };
        match self {
            Light::Area(a) => {
                let s = a.sample(p, u)?;
                Some(LightSample { wi: s.wi, li: a.le, pdf: s.pdf, dist: s.dist, delta: false })
            }
            Light::Point(l) => l.sample(p).map(delta),
            Light::Spot(l) => l.sample(p).map(delta),
            Light::Directional(l) => Some(delta((l.to_light, l.irradiance, f32::INFINITY))),
            Light::Environment(env) => {
                let (wi, pdf) = env.sample(u)?;
                Some(LightSample { wi, li: env.radiance(wi), pdf, dist: f32::INFINITY, delta: false })
            }
        }
    }

    /// Solid-angle density with which [`Light::sample_li`] from `ctx.p` gives the direction
    /// `wi` that met the light at `x` (a point on an area light; ignored by the
    /// environment, which reads `wi`). 0 for delta lights and for the back face of a
    /// one-sided emitter. The area light computes the direction again from `x`, as its
    /// sampling does, so the two densities agree bit for bit.
    #[inline]
    pub fn pdf_li(&self, ctx: &LightSampleContext, wi: Vec3, x: Vec3) -> f32 {
        match self {
            Light::Area(a) => a.pdf(ctx.p, x),
            Light::Environment(e) => e.pdf(wi),
            Light::Point(_) | Light::Spot(_) | Light::Directional(_) => 0.0,
        }
    }

    /// A ray leaving the light with its position and direction densities ([`emission`]);
    /// distant lights start it on the disk of the scene's bounding sphere (`scene_center`,
    /// `scene_radius`) facing them. `pmf` is 1 (no selection).
    #[inline]
    pub fn sample_le(
        &self,
        u_pos: Vec2,
        u_dir: Vec2,
        scene_center: Vec3,
        scene_radius: f32,
    ) -> Option<LeSample> {
        let (c, r) = (scene_center, scene_radius);
        match self {
            Light::Area(a) => a.sample_le(u_pos, u_dir),
            Light::Point(l) => l.sample_le(u_dir),
            Light::Spot(l) => l.sample_le(u_dir),
            Light::Directional(l) => l.sample_le(u_pos, c, r),
            Light::Environment(e) => e.sample_le(u_pos, u_dir, c, r),
        }
    }

    /// The light's kind.
    pub fn kind(&self) -> EmitterKind {
        match self {
            Light::Area(_) => EmitterKind::Area,
            Light::Point(_) => EmitterKind::Point,
            Light::Spot(_) => EmitterKind::Spot,
            Light::Directional(_) => EmitterKind::Directional,
            Light::Environment(_) => EmitterKind::Environment,
        }
    }

    /// Emitted power (luminance, watts) for light selection; distant lights count what
    /// crosses the disk of the scene's bounding sphere of radius `scene_radius`.
    pub fn power(&self, scene_radius: f32) -> f32 {
        match self {
            Light::Area(a) => a.power(),
            Light::Point(l) => l.power(),
            Light::Spot(l) => l.power(),
            Light::Directional(l) => l.power(scene_radius),
            Light::Environment(e) => e.power(scene_radius),
        }
    }

    /// Where and in which directions the light emits; `None` for lights at infinity.
    pub fn bounds(&self, scene_radius: f32) -> Option<LightBounds> {
        let phi = self.power(scene_radius);
        match self {
            Light::Area(a) => Some(LightBounds {
                bounds: Aabb::from_points([a.p0, a.p0 + a.e1, a.p0 + a.e2]),
                phi,
                w: a.n,
                cos_theta_o: 1.0,
                cos_theta_e: 0.0,
                two_sided: a.two_sided,
            }),
            Light::Point(l) => Some(LightBounds {
                bounds: Aabb::from_point(l.position),
                phi,
                w: Vec3::Z,
                cos_theta_o: -1.0,
                cos_theta_e: 0.0,
                two_sided: false,
            }),
            Light::Spot(l) => Some(LightBounds {
                bounds: Aabb::from_point(l.position),
                phi,
                w: l.axis,
                cos_theta_o: l.cos_falloff_start,
                // pbrt-v4 `SpotLight::Bounds`: the falloff band's angular width.
                cos_theta_e: (l.cos_total_width.acos() - l.cos_falloff_start.acos()).cos(),
                two_sided: false,
            }),
            Light::Directional(_) | Light::Environment(_) => None,
        }
    }

    /// The light as an area light.
    #[inline]
    pub fn as_area(&self) -> Option<&AreaLight> {
        match self {
            Light::Area(a) => Some(a),
            _ => None,
        }
    }

    /// True for lights described by a delta distribution (point, spot, directional): BSDF
    /// sampling never finds them.
    pub fn is_delta(&self) -> bool {
        matches!(self, Light::Point(_) | Light::Spot(_) | Light::Directional(_))
    }
}

#[cfg(test)]
mod environment_tests;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod update_tests;
