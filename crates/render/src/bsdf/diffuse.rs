//! Lambertian reflection: `f = ρ / π`, sampled with the cosine-weighted hemisphere so that
//! `f cos θ / pdf = ρ` exactly (pbrt-v4 section 9.2, `DiffuseBxDF`).
//!
//! Parameter: `reflectance` ρ (per channel, in `[0, 1]` for energy conservation; the
//! scene loaders do not clamp it, so a value above 1 is the scene's choice).

use super::BsdfSample;
use crate::integrator::lanes::{select, F8, M8, V8};
use crate::integrator::sampling8::sample_cosine_hemisphere8;
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

/// [`Diffuse`] in eight lanes for the lockstep tracer ([`crate::integrator::lanes`]): one
/// reflectance per lane, the operations of the scalar methods above in the same order.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Diffuse8<const A: bool> {
    pub(crate) rho: V8<A>,
}

impl<const A: bool> Diffuse8<A> {
    /// [`Diffuse::f`] and [`Diffuse::pdf`] for the local directions' `z` (both are zero
    /// unless `wo` and `wi` are above the surface).
    #[inline(always)]
    pub(crate) fn f_pdf(&self, wo_z: F8<A>, wi_z: F8<A>) -> (V8<A>, F8<A>) {
        let zero = F8::splat(0.0);
        let above = !wo_z.le(zero) & !wi_z.le(zero);
        let f = V8::select(above, self.rho * F8::splat(FRAC_1_PI), V8::default());
        (f, select(above, wi_z.max(zero) * F8::splat(FRAC_1_PI), zero))
    }

    /// [`Diffuse::sample`]: `(ok, wi, f, pdf)`, `ok` clear where the scalar code returns
    /// `None`.
    #[inline(always)]
    pub(crate) fn sample(&self, wo_z: F8<A>, ux: F8<A>, uy: F8<A>) -> (M8<A>, V8<A>, V8<A>, F8<A>) {
        let zero = F8::splat(0.0);
        let wi = sample_cosine_hemisphere8(ux, uy);
        let pdf = wi.z.max(zero) * F8::splat(FRAC_1_PI);
        let ok = !wo_z.le(zero) & !pdf.le(zero);
        (ok, wi, self.rho * F8::splat(FRAC_1_PI), pdf)
    }
}
