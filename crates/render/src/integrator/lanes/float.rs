//! `f32` lanes ([`F8`]): the IEEE operations of the scalar code, lane by lane.

use super::{m, per_lane, raw_from_f, raw_from_i, raw_to_f, raw_to_i, F8, LANES, M8, U8};
#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;
use std::ops::{Add, Div, Mul, Neg, Sub};

/// Lane-wise `f(a, b)` on the array views (portable build).
#[inline(always)]
fn zip<const A: bool>(a: F8<A>, b: F8<A>, f: impl Fn(f32, f32) -> f32) -> F8<A> {
    let (a, b) = (a.to_array(), b.to_array());
    F8::from_array(per_lane(|i| f(a[i], b[i])))
}

/// Lane-wise comparison on the array views (portable build).
#[inline(always)]
fn cmp<const A: bool>(a: F8<A>, b: F8<A>, f: impl Fn(f32, f32) -> bool) -> M8<A> {
    let (a, b) = (a.to_array(), b.to_array());
    M8(raw_from_i(per_lane(|i| m(f(a[i], b[i])))))
}

impl<const A: bool> F8<A> {
    #[inline(always)]
    pub fn splat(v: f32) -> F8<A> {
        avx_or!(A, F8(_mm256_set1_ps(v)), F8(raw_from_f([v; LANES])))
    }
    /// The lanes of an array.
    #[inline(always)]
    pub fn from_array(a: [f32; LANES]) -> F8<A> {
        F8(raw_from_f(a))
    }
    /// The lanes as an array.
    #[inline(always)]
    pub fn to_array(self) -> [f32; LANES] {
        raw_to_f(self.0)
    }
    /// The lanes' bits as `u32` lanes (`f32::to_bits`).
    #[inline(always)]
    pub fn to_bits(self) -> U8<A> {
        U8(self.0)
    }
    /// Lane `i`.
    #[inline(always)]
    pub fn lane(self, i: usize) -> f32 {
        self.to_array()[i]
    }
    /// Sets lane `i` (through memory: for per-lane fallbacks only).
    #[inline(always)]
    pub fn set_lane(&mut self, i: usize, v: f32) {
        let mut a = self.to_array();
        a[i] = v;
        *self = F8::from_array(a);
    }
    /// Lane-wise `f` on the array view (not for hot code: no vector instruction).
    #[inline(always)]
    pub fn map(self, f: impl Fn(f32) -> f32) -> F8<A> {
        let a = self.to_array();
        F8::from_array(per_lane(|i| f(a[i])))
    }
    /// `f32::min` (LLVM's `minnum` lowering on x86: `isnan(self) ? o : (o < self ? o : self)`).
    #[inline(always)]
    pub fn min(self, o: F8<A>) -> F8<A> {
        avx_or!(
            A,
            F8(_mm256_blendv_ps(
                _mm256_min_ps(o.0, self.0),
                o.0,
                _mm256_cmp_ps::<_CMP_UNORD_Q>(self.0, self.0)
            )),
            zip(self, o, f32::min)
        )
    }
    /// `f32::max` (as [`F8::min`]).
    #[inline(always)]
    pub fn max(self, o: F8<A>) -> F8<A> {
        avx_or!(
            A,
            F8(_mm256_blendv_ps(
                _mm256_max_ps(o.0, self.0),
                o.0,
                _mm256_cmp_ps::<_CMP_UNORD_Q>(self.0, self.0)
            )),
            zip(self, o, f32::max)
        )
    }
    /// `f32::clamp` (`if x < lo { lo }`, then `if x > hi { hi }`: NaN stays NaN, and
    /// `-0.0` stays `-0.0` against a bound `0.0`, which `max`/`min` would not keep).
    #[inline(always)]
    pub fn clamp(self, lo: F8<A>, hi: F8<A>) -> F8<A> {
        let x = select(self.lt(lo), lo, self);
        select(x.gt(hi), hi, x)
    }
    /// `f32::abs` (clears the sign bit).
    #[inline(always)]
    pub fn abs(self) -> F8<A> {
        avx_or!(
            A,
            F8(_mm256_and_ps(self.0, _mm256_castsi256_ps(_mm256_set1_epi32(i32::MAX)))),
            self.map(f32::abs)
        )
    }
    #[inline(always)]
    pub fn sqrt(self) -> F8<A> {
        avx_or!(A, F8(_mm256_sqrt_ps(self.0)), self.map(f32::sqrt))
    }
    /// `1.0f32.copysign(self)` per lane.
    #[inline(always)]
    pub fn one_with_sign(self) -> F8<A> {
        avx_or!(
            A,
            F8(_mm256_or_ps(_mm256_and_ps(self.0, _mm256_set1_ps(-0.0)), _mm256_set1_ps(1.0))),
            self.map(|z| 1.0f32.copysign(z))
        )
    }
    /// Lane-wise `self > o`.
    #[inline(always)]
    pub fn gt(self, o: F8<A>) -> M8<A> {
        avx_or!(A, M8(_mm256_cmp_ps::<_CMP_GT_OQ>(self.0, o.0)), cmp(self, o, |a, b| a > b))
    }
    /// Lane-wise `self < o`.
    #[inline(always)]
    pub fn lt(self, o: F8<A>) -> M8<A> {
        avx_or!(A, M8(_mm256_cmp_ps::<_CMP_LT_OQ>(self.0, o.0)), cmp(self, o, |a, b| a < b))
    }
    /// Lane-wise `self <= o`.
    #[inline(always)]
    pub fn le(self, o: F8<A>) -> M8<A> {
        avx_or!(A, M8(_mm256_cmp_ps::<_CMP_LE_OQ>(self.0, o.0)), cmp(self, o, |a, b| a <= b))
    }
    /// Lane-wise `self >= o`.
    #[inline(always)]
    pub fn ge(self, o: F8<A>) -> M8<A> {
        avx_or!(A, M8(_mm256_cmp_ps::<_CMP_GE_OQ>(self.0, o.0)), cmp(self, o, |a, b| a >= b))
    }
    /// Lane-wise `self == o`.
    #[inline(always)]
    pub fn eq(self, o: F8<A>) -> M8<A> {
        avx_or!(A, M8(_mm256_cmp_ps::<_CMP_EQ_OQ>(self.0, o.0)), cmp(self, o, |a, b| a == b))
    }
    /// Lane-wise `is_finite` (`|x| < inf`, false for NaN).
    #[inline(always)]
    pub fn is_finite(self) -> M8<A> {
        self.abs().lt(F8::splat(f32::INFINITY))
    }
    /// Lane-wise `is_infinite` (`|x| == inf`).
    #[inline(always)]
    pub fn is_infinite(self) -> M8<A> {
        self.abs().eq(F8::splat(f32::INFINITY))
    }
    /// Lane-wise `is_nan`.
    #[inline(always)]
    pub fn is_nan(self) -> M8<A> {
        avx_or!(A, M8(_mm256_cmp_ps::<_CMP_UNORD_Q>(self.0, self.0)), cmp(self, self, |a, _| a.is_nan()))
    }
}

/// `m ? a : b` per lane.
#[inline(always)]
pub fn select<const A: bool>(m: M8<A>, a: F8<A>, b: F8<A>) -> F8<A> {
    avx_or!(A, F8(_mm256_blendv_ps(b.0, a.0, m.0)), {
        let (mm, a, b) = (raw_to_i(m.0), a.to_array(), b.to_array());
        F8::from_array(per_lane(|i| if mm[i] < 0 { a[i] } else { b[i] }))
    })
}

impl<const A: bool> Add for F8<A> {
    type Output = F8<A>;
    #[inline(always)]
    fn add(self, o: F8<A>) -> F8<A> {
        avx_or!(A, F8(_mm256_add_ps(self.0, o.0)), zip(self, o, |a, b| a + b))
    }
}
impl<const A: bool> Sub for F8<A> {
    type Output = F8<A>;
    #[inline(always)]
    fn sub(self, o: F8<A>) -> F8<A> {
        avx_or!(A, F8(_mm256_sub_ps(self.0, o.0)), zip(self, o, |a, b| a - b))
    }
}
impl<const A: bool> Mul for F8<A> {
    type Output = F8<A>;
    #[inline(always)]
    fn mul(self, o: F8<A>) -> F8<A> {
        avx_or!(A, F8(_mm256_mul_ps(self.0, o.0)), zip(self, o, |a, b| a * b))
    }
}
impl<const A: bool> Div for F8<A> {
    type Output = F8<A>;
    #[inline(always)]
    fn div(self, o: F8<A>) -> F8<A> {
        avx_or!(A, F8(_mm256_div_ps(self.0, o.0)), zip(self, o, |a, b| a / b))
    }
}
/// Flips the sign bit (as `-x`).
impl<const A: bool> Neg for F8<A> {
    type Output = F8<A>;
    #[inline(always)]
    fn neg(self) -> F8<A> {
        avx_or!(A, F8(_mm256_xor_ps(self.0, _mm256_set1_ps(-0.0))), self.map(|a| -a))
    }
}
