//! Rough plastic: a GGX dielectric coating (index `ior`) over a Lambertian base.
//!
//! Model (a simplified form of Mitsuba's `roughplastic` and pbrt-v3's coated diffuse):
//!
//! `f(wo, wi) = D(wm) F(wo·wm) G2(wo, wi) / (4 cos θo cos θi)`            — specular coat
//! `        + (1 − F(cos θo)) (1 − F(cos θi)) ρ / π`                       — diffuse base
//!
//! `F` is the dielectric Fresnel term (`ior` relative to the outside). Light reaches the
//! base only through the fraction `1 − F(cos θi)` that enters the coating, and leaves
//! through `1 − F(cos θo)`. Unlike Mitsuba we do not add the light reflected back inside
//! the coating (Mitsuba's `1 / (η² (1 − ρ F_dr))` factor): that keeps the model
//! reciprocal and the directional albedo ≤ `F_coat + (1 − F(cos θo)) ρ ≤ 1` for ρ ≤ 1
//! (checked by Monte Carlo in the tests), at the cost of a slightly different base
//! brightness from Mitsuba (darker for ρ near 1, brighter for ρ below ~0.7 at ior 1.5).
//!
//! Sampling picks the coat with probability `p_s = F(cos θo) / (F(cos θo) + (1 −
//! F(cos θo)) lum(ρ))` clamped to `[0.05, 0.95]` (Fresnel-weighted lobe selection, as
//! Mitsuba's `specular_sampling_weight` adjusted by Fresnel), otherwise the base (cosine
//! hemisphere). The returned pdf is always the mixture `p_s pdf_coat + (1 − p_s) pdf_base`
//! and f is the full BSDF (one-sample MIS over the two lobes, Veach 1997 section 9.2.4).
//!
//! Parameters: `diffuse` ρ (textured), perceptual `roughness` → `alpha`, `ior` (≥ 1; a
//! value ≤ 1 or non-finite is replaced by 1.5).

use super::microfacet::{fr_dielectric, reflect, TrowbridgeReitz};
use super::BsdfSample;
use filtrace_core::sampling::{cosine_hemisphere_pdf, sample_cosine_hemisphere};
use filtrace_core::{luminance, Rgb, Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// Bounds on the coat-selection probability, so neither lobe is starved.
const MIN_LOBE_PROB: f32 = 0.05;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plastic {
    pub diffuse: Rgb,
    pub eta: f32,
    pub distrib: TrowbridgeReitz,
}

impl Plastic {
    pub fn new(diffuse: Rgb, alpha: f32, ior: f32) -> Self {
        let eta = if ior.is_finite() && ior > 1.0 { ior } else { 1.5 };
        Plastic { diffuse, eta, distrib: TrowbridgeReitz::new(alpha) }
    }

    /// Probability of sampling the coat for outgoing cosine `cos_o`.
    #[inline]
    fn coat_prob(&self, cos_o: f32) -> f32 {
        let fo = fr_dielectric(cos_o, self.eta);
        let d = (1.0 - fo) * luminance(self.diffuse).max(0.0);
        let p = if fo + d > 0.0 { fo / (fo + d) } else { 1.0 };
        p.clamp(MIN_LOBE_PROB, 1.0 - MIN_LOBE_PROB)
    }

    #[inline]
    fn coat_f(&self, wo: Vec3, wi: Vec3) -> f32 {
        let wm = wo + wi;
        if wm.length_squared() == 0.0 {
            return 0.0;
        }
        let wm = wm.normalize();
        let fr = fr_dielectric(wo.dot(wm), self.eta);
        fr * self.distrib.d(wm) * self.distrib.g(wo, wi) / (4.0 * wo.z * wi.z)
    }

    #[inline]
    fn coat_pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let wm = wo + wi;
        if wm.length_squared() == 0.0 {
            return 0.0;
        }
        let wm = wm.normalize();
        self.distrib.d_visible(wo, wm) / (4.0 * wo.dot(wm))
    }

    #[inline]
    pub fn f(&self, wo: Vec3, wi: Vec3) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        let base = (1.0 - fr_dielectric(wo.z, self.eta)) * (1.0 - fr_dielectric(wi.z, self.eta)) * FRAC_1_PI;
        Rgb::splat(self.coat_f(wo, wi)) + self.diffuse * base
    }

    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let ps = self.coat_prob(wo.z);
        ps * self.coat_pdf(wo, wi) + (1.0 - ps) * cosine_hemisphere_pdf(wi.z)
    }

    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2, uc: f32) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let ps = self.coat_prob(wo.z);
        let coat = uc < ps;
        let wi = if coat { reflect(wo, self.distrib.sample_wm(wo, u)) } else { sample_cosine_hemisphere(u) };
        if wi.z <= 0.0 {
            return None;
        }
        let pdf = self.pdf(wo, wi);
        if !(pdf > 0.0) || !pdf.is_finite() {
            return None;
        }
        Some(BsdfSample { wi, f: self.f(wo, wi), pdf, specular: false })
    }

    /// The base reflectance ρ (the albedo AOV shows the textured colour, as Mitsuba's
    /// `albedo` AOV does for the diffuse part).
    pub fn albedo(&self) -> Rgb {
        self.diffuse
    }
}
