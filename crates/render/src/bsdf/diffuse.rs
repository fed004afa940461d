//! Lambertian reflection: `f = ρ / π`, sampled with the cosine-weighted hemisphere so that
//! `f cos θ / pdf = ρ` exactly (pbrt-v4 section 9.2, `DiffuseBxDF`).
//!
//! Parameter: `reflectance` ρ (per channel, in `[0, 1]` for energy conservation; the
//! scene loaders do not clamp it, so a value above 1 is the scene's choice).

use super::BsdfSample;
use filtrace_core::sampling::{cosine_hemisphere_pdf, sample_cosine_hemisphere};
use filtrace_core::{Rgb, Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Diffuse {
    pub reflectance: Rgb,
}

impl Diffuse {
    pub fn new(reflectance: Rgb) -> Self {
        Diffuse { reflectance }
    }

    #[inline]
    pub fn f(&self, wo: Vec3, wi: Vec3) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        self.reflectance * FRAC_1_PI
    }

    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        cosine_hemisphere_pdf(wi.z)
    }

    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = sample_cosine_hemisphere(u);
        let pdf = cosine_hemisphere_pdf(wi.z);
        if pdf <= 0.0 {
            return None;
        }
        Some(BsdfSample { wi, f: self.reflectance * FRAC_1_PI, pdf, specular: false })
    }
}
