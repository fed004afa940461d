//! `u32` lanes ([`U8`]): the integer hashes of the eight-key sampler.

use super::{per_lane, Raw, F8, LANES, U8};
#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// `rev4(i) << 4` and `rev4(i)` for the nibbles `i` (bit reversal by `vpshufb`).
#[cfg(target_arch = "x86_64")]
const REV_NIBBLE_HI: [u8; 16] =
    [0x00, 0x80, 0x40, 0xc0, 0x20, 0xa0, 0x60, 0xe0, 0x10, 0x90, 0x50, 0xd0, 0x30, 0xb0, 0x70, 0xf0];
#[cfg(target_arch = "x86_64")]
const REV_NIBBLE_LO: [u8; 16] =
    [0x0, 0x8, 0x4, 0xc, 0x2, 0xa, 0x6, 0xe, 0x1, 0x9, 0x5, 0xd, 0x3, 0xb, 0x7, 0xf];

impl<const A: bool> U8<A> {
    #[inline(always)]
    pub fn from_array(a: [u32; LANES]) -> U8<A> {
        // SAFETY: 32 plain bytes either way.
        U8(unsafe { std::mem::transmute::<[u32; LANES], Raw>(a) })
    }
    #[inline(always)]
    pub fn to_array(self) -> [u32; LANES] {
        // SAFETY: as above.
        unsafe { std::mem::transmute::<Raw, [u32; LANES]>(self.0) }
    }
    #[inline(always)]
    pub fn splat(v: u32) -> U8<A> {
        avx_or!(A, U8(_mm256_castsi256_ps(_mm256_set1_epi32(v as i32))), U8::from_array([v; LANES]))
    }
    /// Lane-wise `f(a, b)` on the array views (portable build).
    #[inline(always)]
    fn zip(self, o: U8<A>, f: impl Fn(u32, u32) -> u32) -> U8<A> {
        let (a, b) = (self.to_array(), o.to_array());
        U8::from_array(per_lane(|i| f(a[i], b[i])))
    }
    /// `wrapping_add`.
    #[inline(always)]
    pub fn wrapping_add(self, o: U8<A>) -> U8<A> {
        avx_or!(
            A,
            U8(_mm256_castsi256_ps(_mm256_add_epi32(_mm256_castps_si256(self.0), _mm256_castps_si256(o.0)))),
            self.zip(o, u32::wrapping_add)
        )
    }
    /// `wrapping_sub`.
    #[inline(always)]
    pub fn wrapping_sub(self, o: U8<A>) -> U8<A> {
        avx_or!(
            A,
            U8(_mm256_castsi256_ps(_mm256_sub_epi32(_mm256_castps_si256(self.0), _mm256_castps_si256(o.0)))),
            self.zip(o, u32::wrapping_sub)
        )
    }
    /// `u32::min`.
    #[inline(always)]
    pub fn min(self, o: U8<A>) -> U8<A> {
        avx_or!(
            A,
            U8(_mm256_castsi256_ps(_mm256_min_epu32(_mm256_castps_si256(self.0), _mm256_castps_si256(o.0)))),
            self.zip(o, u32::min)
        )
    }
    /// `wrapping_mul`.
    #[inline(always)]
    pub fn wrapping_mul(self, o: U8<A>) -> U8<A> {
        avx_or!(
            A,
            U8(_mm256_castsi256_ps(_mm256_mullo_epi32(
                _mm256_castps_si256(self.0),
                _mm256_castps_si256(o.0)
            ))),
            self.zip(o, u32::wrapping_mul)
        )
    }
    #[inline(always)]
    pub fn xor(self, o: U8<A>) -> U8<A> {
        avx_or!(A, U8(_mm256_xor_ps(self.0, o.0)), self.zip(o, |a, b| a ^ b))
    }
    #[inline(always)]
    pub fn and(self, o: U8<A>) -> U8<A> {
        avx_or!(A, U8(_mm256_and_ps(self.0, o.0)), self.zip(o, |a, b| a & b))
    }
    /// `self << S`.
    #[inline(always)]
    pub fn shl<const S: i32>(self) -> U8<A> {
        avx_or!(A, U8(_mm256_castsi256_ps(_mm256_slli_epi32::<S>(_mm256_castps_si256(self.0)))), {
            let a = self.to_array();
            U8::from_array(per_lane(|i| a[i] << S))
        })
    }
    /// `self >> S` (logical).
    #[inline(always)]
    pub fn shr<const S: i32>(self) -> U8<A> {
        avx_or!(A, U8(_mm256_castsi256_ps(_mm256_srli_epi32::<S>(_mm256_castps_si256(self.0)))), {
            let a = self.to_array();
            U8::from_array(per_lane(|i| a[i] >> S))
        })
    }
    /// `u32::reverse_bits`: bytes swapped by one `vpshufb`, then each byte's nibbles
    /// reversed and swapped by two table `vpshufb`.
    #[inline(always)]
    pub fn reverse_bits(self) -> U8<A> {
        avx_or!(
            A,
            {
                let x = _mm256_castps_si256(self.0);
                let bswap = _mm256_setr_epi8(
                    3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12, 3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9,
                    8, 15, 14, 13, 12,
                );
                let x = _mm256_shuffle_epi8(x, bswap);
                let nib = _mm256_set1_epi8(0x0f);
                let lo = _mm256_and_si256(x, nib);
                let hi = _mm256_and_si256(_mm256_srli_epi16::<4>(x), nib);
                let t_hi =
                    _mm256_broadcastsi128_si256(_mm_loadu_si128(REV_NIBBLE_HI.as_ptr() as *const __m128i));
                let t_lo =
                    _mm256_broadcastsi128_si256(_mm_loadu_si128(REV_NIBBLE_LO.as_ptr() as *const __m128i));
                let r = _mm256_or_si256(_mm256_shuffle_epi8(t_hi, lo), _mm256_shuffle_epi8(t_lo, hi));
                U8(_mm256_castsi256_ps(r))
            },
            {
                let a = self.to_array();
                U8::from_array(per_lane(|i| a[i].reverse_bits()))
            }
        )
    }
    /// `x as f32` per lane for values below 2^31 (`vcvtdq2ps`).
    #[inline(always)]
    pub fn to_f32(self) -> F8<A> {
        avx_or!(A, F8(_mm256_cvtepi32_ps(_mm256_castps_si256(self.0))), {
            let a = self.to_array();
            F8::from_array(per_lane(|i| a[i] as f32))
        })
    }
    /// `to_unit_float`: `(x >> 8) as f32 * 2^-24` (exact: below 2^24).
    #[inline(always)]
    pub fn to_unit(self) -> F8<A> {
        avx_or!(
            A,
            F8(_mm256_mul_ps(
                _mm256_cvtepi32_ps(_mm256_srli_epi32::<8>(_mm256_castps_si256(self.0))),
                _mm256_set1_ps(1.0 / 16_777_216.0)
            )),
            {
                let a = self.to_array();
                F8::from_array(per_lane(|i| (a[i] >> 8) as f32 * (1.0 / 16_777_216.0)))
            }
        )
    }
}
