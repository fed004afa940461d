//! Rough conductor (metal): a GGX microfacet lobe with the Fresnel term of a conductor of
//! complex index of refraction `eta + i k` per RGB channel (pbrt-v4 section 9.6,
//! `ConductorBxDF`; Walter et al. 2007):
//!
//! `f(wo, wi) = D(wm) F(wo·wm) G2(wo, wi) / (4 cos θo cos θi)`, `wm = normalize(wo + wi)`.
//!
//! Sampling draws a visible normal (Heitz 2018) and reflects `wo` about it, so the density
//! is `pdf = D_wo(wm) / (4 |wo·wm|) = G1(wo) D(wm) / (4 cos θo)`; samples reflected below
//! the horizon are rejected (`sample` returns `None`), so the pdf integrates to less than 1
//! over the upper hemisphere, by exactly the rejected mass: negligible for smooth metals,
//! about half at alpha = 1 near normal incidence (measured in the tests), as in pbrt-v4.
//!
//! Parameters: `eta`, `k` (per channel; e.g. gold ≈ (0.143, 0.374, 1.442) + i (3.983,
//! 2.385, 1.603)), `alpha` from the perceptual roughness (see
//! [`super::microfacet::alpha_from_roughness`]). Single scattering only: energy lost to
//! masking at high roughness is not restored (no multiple-scattering compensation).

use super::microfacet::{fr_conductor, reflect, TrowbridgeReitz};
use super::BsdfSample;
use filtrace_core::{Rgb, Vec2, Vec3};

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Conductor {
    pub eta: Rgb,
    pub k: Rgb,
    pub distrib: TrowbridgeReitz,
}

impl Conductor {
    pub fn new(eta: Rgb, k: Rgb, alpha: f32) -> Self {
        // Non-finite indices would spread NaN: fall back to a perfect reflector (eta 0, k 1e3 ≈ F = 1).
        let fix = |v: Rgb, d: f32| if v.is_finite() { v.max(Rgb::ZERO) } else { Rgb::splat(d) };
        Conductor { eta: fix(eta, 0.0), k: fix(k, 1e3), distrib: TrowbridgeReitz::new(alpha) }
    }

    #[inline]
    pub fn f(&self, wo: Vec3, wi: Vec3) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        let wm = wo + wi;
        if wm.length_squared() == 0.0 {
            return Rgb::ZERO;
        }
        let wm = wm.normalize();
        let fr = fr_conductor(wo.dot(wm), self.eta, self.k);
        fr * (self.distrib.d(wm) * self.distrib.g(wo, wi) / (4.0 * wo.z * wi.z))
    }

    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let wm = wo + wi;
        if wm.length_squared() == 0.0 {
            return 0.0;
        }
        let wm = wm.normalize();
        self.distrib.d_visible(wo, wm) / (4.0 * wo.dot(wm))
    }

    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let wm = self.distrib.sample_wm(wo, u);
        let wi = reflect(wo, wm);
        if wi.z <= 0.0 {
            return None;
        }
        // Evaluate through f/pdf so that sample() and f()/pdf() agree to the last bit of
        // the half-vector computation.
        let pdf = self.pdf(wo, wi);
        if !(pdf > 0.0) || !pdf.is_finite() {
            return None;
        }
        // Never `specular`: alpha ≥ MIN_ALPHA keeps the lobe finite, so MIS stays valid.
        Some(BsdfSample { wi, f: self.f(wo, wi), pdf, specular: false })
    }

    /// Normal-incidence Fresnel reflectance F(1): the colour of the metal, used as the
    /// albedo AOV (a documented choice; the directional albedo would depend on wo).
    pub fn albedo(&self) -> Rgb {
        fr_conductor(1.0, self.eta, self.k)
    }
}
