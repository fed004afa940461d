//! Surface scattering (reflection only): the closed set of BSDFs a material can have,
//! evaluated in the local shading frame (`z` = shading normal, directions unit length and
//! pointing away from the surface).
//!
//! Interface (shared with the integrator):
//! - [`SurfaceBsdf::from_material`] evaluates a material's textures at a hit (`uv`).
//! - `f(wo, wi)`, `pdf(wo, wi)` (solid angle) are 0 unless both `wo.z > 0` and `wi.z > 0`:
//!   two-sided surfaces are handled by the integrator flipping the frame to `wo`'s side.
//! - `sample(wo, u, uc)` returns `wi`, `f(wo, wi)`, `pdf(wo, wi)` (never 0) and `specular`.
//!   `specular` would mark a delta lobe, for which MIS must be skipped; none of these BSDFs
//!   has one (GGX alpha is clamped to ≥ 1e-3, so even a "mirror" has finite f and pdf and
//!   MIS stays unbiased), so it is currently always false.
//! - `albedo()` feeds the albedo AOV.
//!
//! Implementations: [`Diffuse`] (Lambert), [`Conductor`] (GGX metal, complex Fresnel),
//! [`Plastic`] (GGX dielectric coat over Lambert). Microfacet machinery in [`microfacet`].
//! An enum rather than `dyn`: the set is closed and this is the hot loop (pbrt-v4's
//! `TaggedPointer` idea). References: pbrt-v4 chapters 9 (reflection models) and 13
//! (light transport), Walter et al. 2007, Heitz 2018.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN, which `x <= 0.0` lets through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod conductor;
pub mod diffuse;
pub mod microfacet;
pub mod plastic;

pub use conductor::Conductor;
pub use diffuse::Diffuse;
pub use plastic::Plastic;

use crate::texture::eval_texturable;
use filtrace_core::{Rgb, Vec2, Vec3};
use filtrace_scene::{Bsdf, Texture};
use microfacet::alpha_from_roughness;

/// A sampled incident direction with the BSDF value and density there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BsdfSample {
    /// Local incident direction, unit length, `z > 0`.
    pub wi: Vec3,
    /// `f(wo, wi)`.
    pub f: Rgb,
    /// `pdf(wo, wi)` in solid angle; never 0 (no sample is returned instead).
    pub pdf: f32,
    /// A delta lobe produced this sample: f and pdf are then Dirac weights and MIS must not
    /// be used. Always false for the current BSDFs (all lobes are finite).
    pub specular: bool,
}

/// A BSDF with its textures already evaluated at a hit point. Reflection only.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SurfaceBsdf {
    Diffuse(Diffuse),
    Conductor(Conductor),
    Plastic(Plastic),
}

/// Non-finite colours (a broken texture or material) become black rather than NaN.
#[inline]
fn finite_or_zero(c: Rgb) -> Rgb {
    if c.is_finite() {
        c
    } else {
        Rgb::ZERO
    }
}

impl SurfaceBsdf {
    /// Builds the BSDF of `bsdf` at texture coordinate `uv`.
    #[inline]
    pub fn from_material(bsdf: &Bsdf, textures: &[Texture], uv: Vec2) -> Self {
        match bsdf {
            Bsdf::Diffuse { reflectance } => {
                SurfaceBsdf::Diffuse(Diffuse::new(finite_or_zero(eval_texturable(reflectance, textures, uv))))
            }
            Bsdf::Conductor { eta, k, roughness } => {
                SurfaceBsdf::Conductor(Conductor::new(*eta, *k, alpha_from_roughness(*roughness)))
            }
            Bsdf::Plastic { diffuse, roughness, ior } => SurfaceBsdf::Plastic(Plastic::new(
                finite_or_zero(eval_texturable(diffuse, textures, uv)),
                alpha_from_roughness(*roughness),
                *ior,
            )),
        }
    }

    /// BSDF value for local `wo`, `wi` (0 unless both are above the surface).
    #[inline]
    pub fn f(&self, wo: Vec3, wi: Vec3) -> Rgb {
        match self {
            SurfaceBsdf::Diffuse(b) => b.f(wo, wi),
            SurfaceBsdf::Conductor(b) => b.f(wo, wi),
            SurfaceBsdf::Plastic(b) => b.f(wo, wi),
        }
    }

    /// Solid-angle density with which [`SurfaceBsdf::sample`] produces `wi`.
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        match self {
            SurfaceBsdf::Diffuse(b) => b.pdf(wo, wi),
            SurfaceBsdf::Conductor(b) => b.pdf(wo, wi),
            SurfaceBsdf::Plastic(b) => b.pdf(wo, wi),
        }
    }

    /// Samples `wi` for `wo`; `u` drives the direction, `uc` the lobe choice.
    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2, uc: f32) -> Option<BsdfSample> {
        match self {
            SurfaceBsdf::Diffuse(b) => b.sample(wo, u),
            SurfaceBsdf::Conductor(b) => b.sample(wo, u),
            SurfaceBsdf::Plastic(b) => b.sample(wo, u, uc),
        }
    }

    /// True when [`SurfaceBsdf::sample`] reads its lobe-choice number `uc`.
    #[inline]
    pub fn has_lobe_choice(&self) -> bool {
        matches!(self, SurfaceBsdf::Plastic(_))
    }

    /// Reflectance for the albedo AOV: ρ for Diffuse and Plastic, normal-incidence
    /// Fresnel reflectance for Conductor.
    #[inline]
    pub fn albedo(&self) -> Rgb {
        match self {
            SurfaceBsdf::Diffuse(b) => b.reflectance,
            SurfaceBsdf::Conductor(b) => b.albedo(),
            SurfaceBsdf::Plastic(b) => b.albedo(),
        }
    }
}

#[cfg(test)]
pub(crate) mod tests;
