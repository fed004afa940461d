//! Eight-lane arithmetic for the lockstep integrator ([`super::lockstep`]): `f32` lanes
//! ([`F8`]), 3-vectors of lanes ([`V8`]), lane masks ([`M8`]) and the Owen-scrambled Sobol
//! sampler evaluated for eight sample keys at once ([`Sampler8`]).
//!
//! **Exactness.** Every operation is the lane-wise IEEE operation of the scalar code, in the
//! same order: Rust never contracts `a * b + c` into an FMA (also not inside functions
//! compiled with `#[target_feature(enable = "fma")]`), and `sqrt` and division are correctly
//! rounded, so a lane computes the bits the scalar code computes. The vector helpers mirror
//! glam's `Vec3` (`dot` = `(x*x' + y*y') + z*z'`, `length` = `sqrt(dot)`, `normalize` =
//! `v * (1 / length)`) and the helpers of `filtrace_core::sampling` term by term; the
//! lockstep identity test (`tests/lockstep.rs`) fails for any deviation.
//!
//! Everything is `#[inline(always)]` loops over `[_; 8]` so that, inlined into a function
//! compiled for AVX2 ([`super::lockstep`]), each loop becomes one or two ymm instructions.

use filtrace_core::sampler::{
    hash_combine, hash_u32, laine_karras_permutation, sobol_dim1_reversed, SOBOL_DIM1_REV_TABLES,
};
use filtrace_core::Vec3;
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

/// Number of lanes (paths traced in lockstep).
pub const LANES: usize = 8;

/// Eight `f32` lanes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(align(32))]
pub struct F8(pub [f32; LANES]);

/// Eight lane masks as `-1` (set) / `0` (clear) integer lanes: a comparison of two [`F8`]
/// is one `vcmpps`, `&`/`|`/`!` one integer instruction each, a [`select`] one `vblendvps`
/// (the earlier `[bool; 8]` masks packed and unpacked bytes around every operation: 3-6
/// instructions per lane op, the largest item of the lane code's instruction count).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(align(32))]
pub struct M8(pub [i32; LANES]);

impl M8 {
    /// No lane set.
    pub const NONE: M8 = M8([0; LANES]);

    /// Lane `i` of a `bool` array.
    #[inline(always)]
    pub fn from_array(b: [bool; LANES]) -> M8 {
        M8(per_lane(|i| -(b[i] as i32)))
    }
    /// Lane `i`.
    #[inline(always)]
    pub fn get(&self, i: usize) -> bool {
        self.0[i] != 0
    }
    /// Sets lane `i` to `b`.
    #[inline(always)]
    pub fn set(&mut self, i: usize, b: bool) {
        self.0[i] = -(b as i32);
    }
    /// `m ? a : b` per lane.
    #[inline(always)]
    pub fn select(m: M8, a: M8, b: M8) -> M8 {
        (m & a) | (!m & b)
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
impl BitAnd for M8 {
    type Output = M8;
    #[inline(always)]
    fn bitand(self, o: M8) -> M8 {
        M8(per_lane(|i| self.0[i] & o.0[i]))
    }
}
impl BitOr for M8 {
    type Output = M8;
    #[inline(always)]
    fn bitor(self, o: M8) -> M8 {
        M8(per_lane(|i| self.0[i] | o.0[i]))
    }
}
impl Not for M8 {
    type Output = M8;
    #[inline(always)]
    fn not(self) -> M8 {
        M8(per_lane(|i| !self.0[i]))
    }
}

/// The mask lane of a comparison result.
#[inline(always)]
fn m(b: bool) -> i32 {
    -(b as i32)
}

/// `[f(0), ..., f(7)]` by a plain loop: `std::array::from_fn` and `<[T; N]>::map` were
/// sometimes left out of line, and an out-of-line helper is compiled without AVX2.
#[inline(always)]
pub fn per_lane<T: Copy + Default>(f: impl Fn(usize) -> T) -> [T; LANES] {
    let mut r = [T::default(); LANES];
    for (i, x) in r.iter_mut().enumerate() {
        *x = f(i);
    }
    r
}

#[inline(always)]
fn zip(a: F8, b: F8, f: impl Fn(f32, f32) -> f32) -> F8 {
    F8(per_lane(|i| f(a.0[i], b.0[i])))
}

impl F8 {
    #[inline(always)]
    pub fn splat(v: f32) -> F8 {
        F8([v; LANES])
    }
    #[inline(always)]
    pub fn map(self, f: impl Fn(f32) -> f32) -> F8 {
        F8(per_lane(|i| f(self.0[i])))
    }
    #[inline(always)]
    pub fn min(self, o: F8) -> F8 {
        zip(self, o, f32::min)
    }
    #[inline(always)]
    pub fn max(self, o: F8) -> F8 {
        zip(self, o, f32::max)
    }
    #[inline(always)]
    pub fn abs(self) -> F8 {
        self.map(f32::abs)
    }
    #[inline(always)]
    pub fn sqrt(self) -> F8 {
        self.map(f32::sqrt)
    }
    /// Lane-wise `self > o`.
    #[inline(always)]
    pub fn gt(self, o: F8) -> M8 {
        M8(per_lane(|i| m(self.0[i] > o.0[i])))
    }
    /// Lane-wise `self < o`.
    #[inline(always)]
    pub fn lt(self, o: F8) -> M8 {
        M8(per_lane(|i| m(self.0[i] < o.0[i])))
    }
    /// Lane-wise `self <= o`.
    #[inline(always)]
    pub fn le(self, o: F8) -> M8 {
        M8(per_lane(|i| m(self.0[i] <= o.0[i])))
    }
    /// Lane-wise `is_finite`.
    #[inline(always)]
    pub fn is_finite(self) -> M8 {
        M8(per_lane(|i| m(self.0[i].is_finite())))
    }
    /// Lane-wise `is_infinite`.
    #[inline(always)]
    pub fn is_infinite(self) -> M8 {
        M8(per_lane(|i| m(self.0[i].is_infinite())))
    }
    /// Lane-wise `is_nan`.
    #[inline(always)]
    pub fn is_nan(self) -> M8 {
        M8(per_lane(|i| m(self.0[i].is_nan())))
    }
    /// Lane-wise `self >= o`.
    #[inline(always)]
    pub fn ge(self, o: F8) -> M8 {
        M8(per_lane(|i| m(self.0[i] >= o.0[i])))
    }
    /// Lane-wise `self == o`.
    #[inline(always)]
    pub fn eq(self, o: F8) -> M8 {
        M8(per_lane(|i| m(self.0[i] == o.0[i])))
    }
}

/// `m ? a : b` per lane.
#[inline(always)]
pub fn select(m: M8, a: F8, b: F8) -> F8 {
    F8(per_lane(|i| if m.0[i] < 0 { a.0[i] } else { b.0[i] }))
}

/// The mask as bits (bit `i` = lane `i`).
#[inline(always)]
pub fn bits(m: M8) -> u8 {
    // Two `movmskps` (SSE, baseline on x86-64, so also in the portable build): LLVM does
    // not recognise the shift-and-or loop below as a movemask (~20 instructions).
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_castsi128_ps, _mm_load_si128, _mm_movemask_ps};
        let p = m.0.as_ptr() as *const std::arch::x86_64::__m128i;
        // SAFETY: SSE2 is part of the x86-64 baseline; `M8` is 32-byte aligned, so both
        // 16-byte halves are aligned and in bounds.
        unsafe {
            let lo = _mm_movemask_ps(_mm_castsi128_ps(_mm_load_si128(p)));
            let hi = _mm_movemask_ps(_mm_castsi128_ps(_mm_load_si128(p.add(1))));
            ((hi << 4) | lo) as u8
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let mut b = 0u32;
        for i in 0..LANES {
            b |= ((m.0[i] as u32) >> 31) << i;
        }
        b as u8
    }
}

/// The bits as a mask.
#[inline(always)]
pub fn from_bits(b: u8) -> M8 {
    M8(per_lane(|i| -(((b >> i) & 1) as i32)))
}

impl Add for F8 {
    type Output = F8;
    #[inline(always)]
    fn add(self, o: F8) -> F8 {
        zip(self, o, |a, b| a + b)
    }
}
impl Sub for F8 {
    type Output = F8;
    #[inline(always)]
    fn sub(self, o: F8) -> F8 {
        zip(self, o, |a, b| a - b)
    }
}
impl Mul for F8 {
    type Output = F8;
    #[inline(always)]
    fn mul(self, o: F8) -> F8 {
        zip(self, o, |a, b| a * b)
    }
}
impl Div for F8 {
    type Output = F8;
    #[inline(always)]
    fn div(self, o: F8) -> F8 {
        zip(self, o, |a, b| a / b)
    }
}
impl Neg for F8 {
    type Output = F8;
    #[inline(always)]
    fn neg(self) -> F8 {
        self.map(|a| -a)
    }
}

/// Eight 3-vectors, structure of arrays.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct V8 {
    pub x: F8,
    pub y: F8,
    pub z: F8,
}

impl V8 {
    #[inline(always)]
    pub fn new(x: F8, y: F8, z: F8) -> V8 {
        V8 { x, y, z }
    }
    #[inline(always)]
    pub fn splat(v: Vec3) -> V8 {
        V8 { x: F8::splat(v.x), y: F8::splat(v.y), z: F8::splat(v.z) }
    }
    /// Lane `i` as a `Vec3`.
    #[inline(always)]
    pub fn lane(&self, i: usize) -> Vec3 {
        Vec3::new(self.x.0[i], self.y.0[i], self.z.0[i])
    }
    /// Stores `v` in lane `i`.
    #[inline(always)]
    pub fn set_lane(&mut self, i: usize, v: Vec3) {
        self.x.0[i] = v.x;
        self.y.0[i] = v.y;
        self.z.0[i] = v.z;
    }
    /// glam's `dot`: `(x x' + y y') + z z'`.
    #[inline(always)]
    pub fn dot(self, o: V8) -> F8 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// glam's `length`.
    #[inline(always)]
    pub fn length(self) -> F8 {
        self.dot(self).sqrt()
    }
    /// glam's `normalize`: `v * (1 / length)`.
    #[inline(always)]
    pub fn normalize(self) -> V8 {
        let r = F8::splat(1.0) / self.length();
        self * r
    }
    #[inline(always)]
    pub fn abs(self) -> V8 {
        V8::new(self.x.abs(), self.y.abs(), self.z.abs())
    }
    /// glam's `max_element`: `max(x, max(y, z))`.
    #[inline(always)]
    pub fn max_element(self) -> F8 {
        self.x.max(self.y.max(self.z))
    }
    /// Lane-wise `self == 0` (all three components).
    #[inline(always)]
    pub fn is_zero(self) -> M8 {
        let z = F8::splat(0.0);
        (self.x.eq(z) & self.y.eq(z)) & self.z.eq(z)
    }
    /// Lane-wise glam `is_finite`.
    #[inline(always)]
    pub fn is_finite(self) -> M8 {
        self.x.is_finite() & self.y.is_finite() & self.z.is_finite()
    }
    /// Per-lane select.
    #[inline(always)]
    pub fn select(m: M8, a: V8, b: V8) -> V8 {
        V8::new(select(m, a.x, b.x), select(m, a.y, b.y), select(m, a.z, b.z))
    }
}

impl Add for V8 {
    type Output = V8;
    #[inline(always)]
    fn add(self, o: V8) -> V8 {
        V8::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}
impl Sub for V8 {
    type Output = V8;
    #[inline(always)]
    fn sub(self, o: V8) -> V8 {
        V8::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}
/// Component-wise product (glam `Vec3 * Vec3`).
impl Mul for V8 {
    type Output = V8;
    #[inline(always)]
    fn mul(self, o: V8) -> V8 {
        V8::new(self.x * o.x, self.y * o.y, self.z * o.z)
    }
}
/// Per-lane scale (glam `Vec3 * f32`; the product commutes exactly, so also `f32 * Vec3`).
impl Mul<F8> for V8 {
    type Output = V8;
    #[inline(always)]
    fn mul(self, s: F8) -> V8 {
        V8::new(self.x * s, self.y * s, self.z * s)
    }
}
/// Per-lane division (glam `Vec3 / f32`).
impl Div<F8> for V8 {
    type Output = V8;
    #[inline(always)]
    fn div(self, s: F8) -> V8 {
        V8::new(self.x / s, self.y / s, self.z / s)
    }
}
impl Neg for V8 {
    type Output = V8;
    #[inline(always)]
    fn neg(self) -> V8 {
        V8::new(-self.x, -self.y, -self.z)
    }
}

/// Eight `u32` lanes, lane-wise.
#[inline(always)]
fn u8x(f: impl Fn(usize) -> u32) -> [u32; LANES] {
    per_lane(f)
}

/// [`filtrace_core::sampler::Sampler`] for eight sample keys at once: lane `i` is the
/// sampler of pixel key `key[i]` (a [`Sampler::pixel_key`]) and the common sample index.
/// `next_2d(slot)` equals `Sampler::set_slot(slot); Sampler::next_2d()` of each lane, bit
/// for bit (same integer hashes, lane-wise: `vpmulld`, shifts and xors; the byte tables of
/// Sobol dimension 1 become gathers).
///
/// [`Sampler::pixel_key`]: filtrace_core::sampler::Sampler::pixel_key
#[derive(Clone, Copy, Debug)]
///
/// `AVX2 = true` (only inside code compiled for AVX2, such as the AVX2 tile loop) looks up
/// the Sobol byte tables with four `vpgatherdd` instead of 32 scalar loads.
pub struct Sampler8<const AVX2: bool> {
    pub key: [u32; LANES],
    index_rev: u32,
}

/// 0.32 fixed point to `[0, 1)` (as `filtrace_core::sampler::to_unit_float`).
#[inline(always)]
fn unit8(x: [u32; LANES]) -> F8 {
    F8(per_lane(|i| (x[i] >> 8) as f32 * (1.0 / 16_777_216.0)))
}

/// [`sobol_dim1_reversed`] of eight lanes: table gathers when `AVX2` (the caller must be
/// code compiled with AVX2 enabled), else scalar lookups.
#[inline(always)]
fn sobol_dim1_reversed8<const AVX2: bool>(i_rev: [u32; LANES]) -> [u32; LANES] {
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        // SAFETY: `AVX2 = true` is only instantiated inside the AVX2 tile loop, which runs
        // after runtime detection of AVX2 (`Renderer::render_tile_lockstep`).
        return unsafe { sobol_dim1_reversed8_avx2(i_rev) };
    }
    u8x(|i| sobol_dim1_reversed(i_rev[i]))
}

/// The four byte lookups of [`sobol_dim1_reversed`] as `vpgatherdd` (same table entries,
/// so the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn sobol_dim1_reversed8_avx2(i_rev: [u32; LANES]) -> [u32; LANES] {
    use std::arch::x86_64::*;
    let t = &SOBOL_DIM1_REV_TABLES;
    let v = _mm256_loadu_si256(i_rev.as_ptr() as *const __m256i);
    let ff = _mm256_set1_epi32(0xff);
    let b0 = _mm256_and_si256(v, ff);
    let b1 = _mm256_and_si256(_mm256_srli_epi32::<8>(v), ff);
    let b2 = _mm256_and_si256(_mm256_srli_epi32::<16>(v), ff);
    let b3 = _mm256_srli_epi32::<24>(v);
    let g0 = _mm256_i32gather_epi32::<4>(t[0].as_ptr() as *const i32, b0);
    let g1 = _mm256_i32gather_epi32::<4>(t[1].as_ptr() as *const i32, b1);
    let g2 = _mm256_i32gather_epi32::<4>(t[2].as_ptr() as *const i32, b2);
    let g3 = _mm256_i32gather_epi32::<4>(t[3].as_ptr() as *const i32, b3);
    let r = _mm256_xor_si256(_mm256_xor_si256(g0, g1), _mm256_xor_si256(g2, g3));
    let mut out = [0u32; LANES];
    _mm256_storeu_si256(out.as_mut_ptr() as *mut __m256i, r);
    out
}

impl<const AVX2: bool> Sampler8<AVX2> {
    #[inline(always)]
    pub fn new(key: [u32; LANES], index: u32) -> Self {
        Sampler8 { key, index_rev: index.reverse_bits() }
    }

    /// Per-lane seed of `slot` and the reversed shuffled index.
    #[inline(always)]
    fn seed_and_index(&self, slot: u32) -> ([u32; LANES], [u32; LANES]) {
        let seed = u8x(|i| hash_u32(hash_combine(self.key[i], slot)));
        let i_rev = u8x(|i| laine_karras_permutation(self.index_rev, seed[i]));
        (seed, i_rev)
    }

    /// The 2D sample of dimension slot `slot` of every lane.
    #[inline(always)]
    pub fn next_2d(&self, slot: u32) -> (F8, F8) {
        let (seed, i_rev) = self.seed_and_index(slot);
        let x = u8x(|i| {
            laine_karras_permutation(i_rev[i].reverse_bits(), hash_combine(seed[i], 0)).reverse_bits()
        });
        let d1 = sobol_dim1_reversed8::<AVX2>(i_rev);
        let y = u8x(|i| laine_karras_permutation(d1[i], hash_combine(seed[i], 1)).reverse_bits());
        (unit8(x), unit8(y))
    }

    /// The 1D sample of dimension slot `slot` of every lane (the `x` of `next_2d`).
    #[inline(always)]
    pub fn next_1d(&self, slot: u32) -> F8 {
        let (seed, i_rev) = self.seed_and_index(slot);
        unit8(u8x(|i| {
            laine_karras_permutation(i_rev[i].reverse_bits(), hash_combine(seed[i], 0)).reverse_bits()
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use filtrace_core::sampler::Sampler;

    #[test]
    fn sampler8_matches_the_scalar_sampler() {
        let keys: [u32; LANES] = std::array::from_fn(|i| Sampler::pixel_key(i as u32 * 7, 3, 11));
        for index in [0u32, 1, 2, 5, 255, 1 << 20, u32::MAX] {
            let s8 = Sampler8::<false>::new(keys, index);
            #[cfg(target_arch = "x86_64")]
            let avx2 = std::arch::is_x86_feature_detected!("avx2");
            #[cfg(not(target_arch = "x86_64"))]
            let avx2 = false;
            for slot in [0u32, 1, 4, 33] {
                let (x, y) = s8.next_2d(slot);
                let one = s8.next_1d(slot);
                if avx2 {
                    // The gather version (called here outside AVX2 code: correct, just
                    // not inlined).
                    let (gx, gy) = Sampler8::<true>::new(keys, index).next_2d(slot);
                    assert_eq!((gx, gy), (x, y));
                }
                for (i, &key) in keys.iter().enumerate() {
                    let mut s = Sampler::from_pixel_key(key, index);
                    s.set_slot(slot);
                    let u = s.next_2d();
                    assert_eq!((x.0[i].to_bits(), y.0[i].to_bits()), (u.x.to_bits(), u.y.to_bits()));
                    s.set_slot(slot);
                    assert_eq!(one.0[i].to_bits(), s.next_1d().to_bits());
                }
            }
        }
    }

    #[test]
    fn vector_helpers_match_glam() {
        let v: Vec<Vec3> =
            (0..LANES).map(|i| Vec3::new(0.3 + i as f32, -1.7 * i as f32, 1.0 / (1.0 + i as f32))).collect();
        let mut a = V8::default();
        for (i, x) in v.iter().enumerate() {
            a.set_lane(i, *x);
        }
        let n = a.normalize();
        let d = a.dot(n);
        for (i, x) in v.iter().enumerate() {
            assert_eq!(n.lane(i), x.normalize());
            assert_eq!(d.0[i], x.dot(x.normalize()));
            assert_eq!(a.max_element().0[i], x.max_element());
        }
    }
}
