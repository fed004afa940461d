//! The helpers of [`filtrace_core::sampling`] in eight lanes ([`super::lanes`]): shading
//! frames, the power heuristic and cosine-weighted hemisphere sampling, each the same IEEE
//! operations in the same order as the scalar function it names, so a lane computes the
//! scalar bits.

use super::lanes::{select, F8, V8};
use std::f32::consts::FRAC_PI_4;

/// `Frame::from_z(n)` in lanes (Duff et al. 2017), as `(x, y)` (`z = n`).
#[inline(always)]
pub(crate) fn frame_from_z<const A: bool>(n: V8<A>) -> (V8<A>, V8<A>) {
    let sign = n.z.one_with_sign();
    let a = F8::splat(-1.0) / (sign + n.z);
    let b = n.x * n.y * a;
    let x = V8::new(F8::splat(1.0) + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let y = V8::new(b, sign + n.y * n.y * a, -n.y);
    (x, y)
}

/// `Frame::to_local`.
#[inline(always)]
pub(crate) fn to_local<const A: bool>(fx: &V8<A>, fy: &V8<A>, n: &V8<A>, v: V8<A>) -> V8<A> {
    V8::new(v.dot(*fx), v.dot(*fy), v.dot(*n))
}

/// `Frame::to_world`.
#[inline(always)]
pub(crate) fn to_world<const A: bool>(fx: &V8<A>, fy: &V8<A>, n: &V8<A>, v: V8<A>) -> V8<A> {
    *fx * v.x + *fy * v.y + *n * v.z
}

/// `power_heuristic(1, f_pdf, 1, g_pdf)` in lanes.
#[inline(always)]
pub(crate) fn power_heuristic8<const A: bool>(f_pdf: F8<A>, g_pdf: F8<A>) -> F8<A> {
    let f = F8::splat(1.0) * f_pdf;
    let g = F8::splat(1.0) * g_pdf;
    let f2 = f * f;
    let denom = f2 + g * g;
    let w = select(denom.gt(F8::splat(0.0)), f2 / denom, F8::splat(0.0));
    select(f2.is_infinite(), F8::splat(1.0), w)
}

/// `sin_cos_quarter_pi` in lanes (same Horner polynomials).
#[inline(always)]
pub(crate) fn sin_cos_quarter_pi8<const A: bool>(x: F8<A>) -> (F8<A>, F8<A>) {
    let k = F8::<A>::splat;
    let x2 = x * x;
    let s = x
        * (k(1.0)
            + x2 * (k(-1.0 / 6.0)
                + x2 * (k(1.0 / 120.0) + x2 * (k(-1.0 / 5040.0) + x2 * k(1.0 / 362_880.0)))));
    let c = k(1.0)
        + x2 * (k(-0.5)
            + x2 * (k(1.0 / 24.0)
                + x2 * (k(-1.0 / 720.0) + x2 * (k(1.0 / 40_320.0) + x2 * k(-1.0 / 3_628_800.0)))));
    (s, c)
}

/// `sample_cosine_hemisphere` in lanes: the concentric disk's two branches become a
/// select of numerator, denominator and the roles of sine and cosine.
#[inline(always)]
pub(crate) fn sample_cosine_hemisphere8<const A: bool>(ux: F8<A>, uy: F8<A>) -> V8<A> {
    let ox = F8::splat(2.0) * ux - F8::splat(1.0);
    let oy = F8::splat(2.0) * uy - F8::splat(1.0);
    let zero = F8::splat(0.0);
    let origin = ox.eq(zero) & oy.eq(zero);
    let first = ox.abs().gt(oy.abs());
    let num = select(first, oy, ox);
    let den = select(first, ox, oy);
    let (s, c) = sin_cos_quarter_pi8(F8::splat(FRAC_PI_4) * (num / den));
    let dx = select(origin, zero, den * select(first, c, s));
    let dy = select(origin, zero, den * select(first, s, c));
    let z = (F8::splat(1.0) - dx * dx - dy * dy).max(zero).sqrt();
    V8::new(dx, dy, z)
}
