//! Diffuse area light: one emissive triangle in world space with constant radiance `le`
//! from its front face (geometric normal `(p1 − p0) × (p2 − p0)`), or from both faces
//! when `two_sided`.
//!
//! Sampling picks a point uniformly on the triangle (Heitz's low-distortion map) and
//! converts the area density `1 / A` to solid angle seen from the shading point:
//! `pdf_ω = d² / (|cos θl| A)` (pbrt-v4 section 12.2, `DiffuseAreaLight`; Veach 1997
//! eq. 8.10). The density is 0 for the back face of a one-sided emitter.

use crate::integrator::lanes::{F8, M8, V8};
use filtrace_core::sampling::sample_uniform_triangle;
use filtrace_core::{luminance, Rgb, Vec2, Vec3};
use std::f32::consts::PI;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AreaLight {
    pub p0: Vec3,
    pub e1: Vec3,
    pub e2: Vec3,
    /// Unit geometric normal (front face).
    pub n: Vec3,
    pub area: f32,
    pub le: Rgb,
    pub two_sided: bool,
}

/// A point on an area light seen from a shading point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AreaSample {
    pub wi: Vec3,
    pub dist: f32,
    /// Solid-angle density (without light selection).
    pub pdf: f32,
}

impl AreaLight {
    /// The light of world-space triangle `tri`; `None` when it has no usable area
    /// (degenerate or non-finite) or emits nothing.
    pub fn new(tri: [Vec3; 3], le: Rgb, two_sided: bool) -> Option<Self> {
        let e1 = tri[1] - tri[0];
        let e2 = tri[2] - tri[0];
        let c = e1.cross(e2);
        let len = c.length();
        // A NaN channel rejects the light (f32::max would silently turn it into 0).
        if !(len > 0.0) || !len.is_finite() || !le.is_finite() || le.max_element() <= 0.0 {
            return None;
        }
        Some(AreaLight { p0: tri[0], e1, e2, n: c / len, area: 0.5 * len, le: le.max(Rgb::ZERO), two_sided })
    }

    /// Emitted power `π A lum(Le)` (× 2 when two-sided), used for light selection.
    pub fn power(&self) -> f32 {
        PI * self.area * luminance(self.le) * if self.two_sided { 2.0 } else { 1.0 }
    }

    /// Samples a point on the triangle seen from `p`; `None` for a back face or a point
    /// seen exactly edge-on.
    #[inline]
    pub fn sample(&self, p: Vec3, u: Vec2) -> Option<AreaSample> {
        let [_, b1, b2] = sample_uniform_triangle(u);
        let x = self.p0 + self.e1 * b1 + self.e2 * b2;
        let d = x - p;
        let dist2 = d.length_squared();
        if !(dist2 > 0.0) {
            return None;
        }
        let dist = dist2.sqrt();
        let wi = d / dist;
        let pdf = self.pdf_dir(wi, dist2);
        if pdf > 0.0 && pdf.is_finite() {
            Some(AreaSample { wi, dist, pdf })
        } else {
            None
        }
    }

    /// Solid-angle density of sampling point `x` (on the triangle) from `p`.
    #[inline]
    pub fn pdf(&self, p: Vec3, x: Vec3) -> f32 {
        let d = x - p;
        let dist2 = d.length_squared();
        if !(dist2 > 0.0) {
            return 0.0;
        }
        self.pdf_dir(d / dist2.sqrt(), dist2)
    }

    #[inline]
    fn pdf_dir(&self, wi: Vec3, dist2: f32) -> f32 {
        let cos_l = -self.n.dot(wi);
        if !self.two_sided && cos_l <= 0.0 {
            return 0.0;
        }
        let c = cos_l.abs();
        if c <= 0.0 {
            return 0.0;
        }
        dist2 / (c * self.area)
    }
}

/// Eight [`AreaLight`]s, one per lane, for the lockstep tracer
/// ([`crate::integrator::lanes`]).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct AreaLight8<const A: bool> {
    pub(crate) p0: V8<A>,
    pub(crate) e1: V8<A>,
    pub(crate) e2: V8<A>,
    pub(crate) n: V8<A>,
    pub(crate) area: F8<A>,
    pub(crate) le: V8<A>,
    pub(crate) two_sided: M8<A>,
}

impl<const A: bool> AreaLight8<A> {
    /// [`AreaLight::sample`] from the points `p` with `(ux, uy)`, the same operations
    /// (`sample_uniform_triangle` and `pdf_dir` inlined): `(ok, wi, dist, pdf)`, `ok`
    /// clear where the scalar code returns `None`.
    #[inline(always)]
    pub(crate) fn sample(&self, p: V8<A>, ux: F8<A>, uy: F8<A>) -> (M8<A>, V8<A>, F8<A>, F8<A>) {
        let zero = F8::splat(0.0);
        let m = F8::splat(0.5) * ux.min(uy);
        let b0 = ux - m;
        let b1 = uy - m;
        let b2 = F8::splat(1.0) - b0 - b1;
        let xp = self.p0 + self.e1 * b1 + self.e2 * b2;
        let d = xp - p;
        let dist2 = d.dot(d);
        let dist = dist2.sqrt();
        let wi = d / dist;
        let cos_l = -self.n.dot(wi);
        let c = cos_l.abs();
        let pdf = dist2 / (c * self.area);
        // Lane masks combined with `&` (a `&&` chain in a closure was left out of line,
        // compiled without AVX, 3% of the profile).
        let front = !(!self.two_sided & cos_l.le(zero));
        let ok = (dist2.gt(zero) & front) & (!c.le(zero) & (pdf.gt(zero) & pdf.is_finite()));
        (ok, wi, dist, pdf)
    }
}
