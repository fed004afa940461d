//! Lane masks ([`M8`]): construction, lane access, `&` / `|` / `!`, and the conversions
//! to and from bit masks.

use super::{m, per_lane, raw_from_i, raw_to_i, Raw, LANES, M8};
#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;
use std::ops::{BitAnd, BitOr, Not};

impl<const A: bool> M8<A> {
    /// No lane set.
    #[inline(always)]
    pub fn none() -> M8<A> {
        avx_or!(A, M8(_mm256_setzero_ps()), M8(raw_from_i([0; LANES])))
    }
    /// Lane `i` of a `bool` array.
    #[inline(always)]
    pub fn from_array(b: [bool; LANES]) -> M8<A> {
        M8(raw_from_i(per_lane(|i| -(b[i] as i32))))
    }
    /// Lane `i`.
    #[inline(always)]
    pub fn get(&self, i: usize) -> bool {
        (bits(*self) >> i) & 1 != 0
    }
    /// Sets lane `i` to `b` (through memory: for per-lane fallbacks only).
    #[inline(always)]
    pub fn set(&mut self, i: usize, b: bool) {
        let mut a = raw_to_i(self.0);
        a[i] = m(b);
        self.0 = raw_from_i(a);
    }
    /// `m ? a : b` per lane.
    #[inline(always)]
    pub fn select(m: M8<A>, a: M8<A>, b: M8<A>) -> M8<A> {
        avx_or!(A, M8(_mm256_blendv_ps(b.0, a.0, m.0)), (m & a) | (!m & b))
    }
    /// Any lane set.
    #[inline(always)]
    pub fn any(self) -> bool {
        bits(self) != 0
    }
    /// Number of lanes set.
    #[inline(always)]
    pub fn count(self) -> u32 {
        bits(self).count_ones()
    }
}

/// Lane-wise `a && b`, written `a & b`: a short-circuit `&&` on lane values became
/// branches, not one vector instruction (cachegrind counted 340 instructions per bounce).
impl<const A: bool> BitAnd for M8<A> {
    type Output = M8<A>;
    #[inline(always)]
    fn bitand(self, o: M8<A>) -> M8<A> {
        avx_or!(A, M8(_mm256_and_ps(self.0, o.0)), {
            let (a, b) = (raw_to_i(self.0), raw_to_i(o.0));
            M8(raw_from_i(per_lane(|i| a[i] & b[i])))
        })
    }
}
impl<const A: bool> BitOr for M8<A> {
    type Output = M8<A>;
    #[inline(always)]
    fn bitor(self, o: M8<A>) -> M8<A> {
        avx_or!(A, M8(_mm256_or_ps(self.0, o.0)), {
            let (a, b) = (raw_to_i(self.0), raw_to_i(o.0));
            M8(raw_from_i(per_lane(|i| a[i] | b[i])))
        })
    }
}
impl<const A: bool> Not for M8<A> {
    type Output = M8<A>;
    #[inline(always)]
    fn not(self) -> M8<A> {
        avx_or!(A, M8(_mm256_xor_ps(self.0, _mm256_castsi256_ps(_mm256_set1_epi32(-1)))), {
            let a = raw_to_i(self.0);
            M8(raw_from_i(per_lane(|i| !a[i])))
        })
    }
}

/// The mask as bits (bit `i` = lane `i`).
#[inline(always)]
pub fn bits<const A: bool>(m: M8<A>) -> u8 {
    avx_or!(A, _mm256_movemask_ps(m.0) as u8, {
        // Two `movmskps` (SSE, baseline on x86-64, so also in the portable build): LLVM
        // does not recognise the shift-and-or loop below as a movemask (~20 instructions).
        #[cfg(target_arch = "x86_64")]
        {
            // SAFETY: SSE is part of the x86-64 baseline; `[__m128; 2]` and `__m256` are
            // both 32 plain bytes.
            unsafe {
                let [lo, hi] = std::mem::transmute::<Raw, [__m128; 2]>(m.0);
                ((_mm_movemask_ps(hi) << 4) | _mm_movemask_ps(lo)) as u8
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let a = raw_to_i(m.0);
            let mut b = 0u32;
            for (i, x) in a.iter().enumerate() {
                b |= ((*x as u32) >> 31) << i;
            }
            b as u8
        }
    })
}

/// The bits as a mask.
#[inline(always)]
pub fn from_bits<const A: bool>(b: u8) -> M8<A> {
    avx_or!(
        A,
        {
            let lane_bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
            let v = _mm256_and_si256(_mm256_set1_epi32(b as i32), lane_bit);
            M8(_mm256_castsi256_ps(_mm256_cmpeq_epi32(v, lane_bit)))
        },
        M8(raw_from_i(per_lane(|i| -(((b >> i) & 1) as i32))))
    )
}
