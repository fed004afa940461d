//! Eight-lane arithmetic for the lockstep integrator ([`super::lockstep`]): `f32` lanes
//! ([`F8`]), 3-vectors of lanes ([`V8`]), lane masks ([`M8`]) and `u32` lanes ([`U8`], for
//! the eight-key sampler of [`super::sampler8`]).
//!
//! **Exactness.** Every operation is the lane-wise IEEE operation of the scalar code, in the
//! same order: Rust never contracts `a * b + c` into an FMA (also not inside functions
//! compiled with `#[target_feature(enable = "fma")]`), and `sqrt` and division are correctly
//! rounded, so a lane computes the bits the scalar code computes. The vector helpers mirror
//! glam's `Vec3` (`dot` = `(x*x' + y*y') + z*z'`, `length` = `sqrt(dot)`, `normalize` =
//! `v * (1 / length)`) and the helpers of `filtrace_core::sampling` term by term; the
//! lockstep identity test (`tests/lockstep.rs`) fails for any deviation.
//!
//! **Two instruction sets, one source.** The lane types carry the const parameter `A`
//! (the `AVX2` of the tile loop). On x86-64 their storage is one `__m256` value (a ymm
//! register when LLVM can keep it there; `[f32; 8]` arrays were kept in stack slots and
//! every lane operation was a load, the operation and a store). With `A = true`, which is
//! only instantiated inside the tile loop compiled with `#[target_feature(enable =
//! "avx2,fma")]` after runtime detection, every operation is the AVX intrinsic of the same
//! IEEE operation (`vaddps`, `vcmpps`, `vblendvps`, ...); with `A = false` (the portable
//! build) it is the plain per-lane loop over the array view of the value, so the portable
//! build never executes an AVX instruction. Everything is `#[inline(always)]` free
//! functions or methods (a closure or an out-of-line helper does not inherit the AVX2
//! target feature of its caller and would compile to SSE or to a call per operation).

use filtrace_core::Vec3;
#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

/// Number of lanes (paths traced in lockstep).
pub const LANES: usize = 8;

/// Storage of eight 32-bit lanes: one `__m256` on x86-64.
#[cfg(target_arch = "x86_64")]
type Raw = __m256;
/// Storage of eight 32-bit lanes.
#[cfg(not(target_arch = "x86_64"))]
type Raw = [f32; LANES];

#[inline(always)]
fn raw_from_f(a: [f32; LANES]) -> Raw {
    // SAFETY: both types are 32 plain bytes; every bit pattern is valid.
    unsafe { std::mem::transmute::<[f32; LANES], Raw>(a) }
}
#[inline(always)]
fn raw_to_f(r: Raw) -> [f32; LANES] {
    // SAFETY: as above.
    unsafe { std::mem::transmute::<Raw, [f32; LANES]>(r) }
}
#[inline(always)]
fn raw_from_i(a: [i32; LANES]) -> Raw {
    // SAFETY: as above.
    unsafe { std::mem::transmute::<[i32; LANES], Raw>(a) }
}
#[inline(always)]
fn raw_to_i(r: Raw) -> [i32; LANES] {
    // SAFETY: as above.
    unsafe { std::mem::transmute::<Raw, [i32; LANES]>(r) }
}

/// `if A { avx } else { portable }`: the first expression (AVX/AVX2 intrinsics) only when
/// `A`, which callers instantiate only inside code compiled for AVX2 + FMA after runtime
/// detection ([`crate::renderer`]'s `render_tile_lockstep_avx2`).
macro_rules! avx_or {
    ($a:expr, $avx:expr, $portable:expr) => {{
        #[cfg(target_arch = "x86_64")]
        if $a {
            // SAFETY: `A = true` is only instantiated in the AVX2 tile loop, which runs
            // after `filtrace_core::cpu::isa().has_avx2()` (AVX2 and FMA).
            #[allow(unused_unsafe)]
            return unsafe { $avx };
        }
        $portable
    }};
}

/// Eight `f32` lanes (`A`: AVX2 instructions, see the module documentation).
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct F8<const A: bool>(Raw);

/// Eight lane masks as `-1` (set) / `0` (clear) 32-bit lanes: a comparison of two [`F8`]
/// is one `vcmpps`, `&`/`|`/`!` one instruction each, a [`select`] one `vblendvps`.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct M8<const A: bool>(Raw);

impl<const A: bool> Default for F8<A> {
    #[inline(always)]
    fn default() -> Self {
        F8::splat(0.0)
    }
}
impl<const A: bool> Default for M8<A> {
    #[inline(always)]
    fn default() -> Self {
        M8::none()
    }
}
impl<const A: bool> Default for U8<A> {
    #[inline(always)]
    fn default() -> Self {
        U8::splat(0)
    }
}
impl<const A: bool> PartialEq for F8<A> {
    fn eq(&self, o: &Self) -> bool {
        self.to_array() == o.to_array()
    }
}
impl<const A: bool> PartialEq for M8<A> {
    fn eq(&self, o: &Self) -> bool {
        raw_to_i(self.0) == raw_to_i(o.0)
    }
}

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

/// Row `m`: the indices of the lanes set in `m`, in order, then the others (stream
/// compaction by one `vpermps`, [`compress_store`]).
static COMPRESS: [[u32; LANES]; 256] = compress_table();

const fn compress_table() -> [[u32; LANES]; 256] {
    let mut t = [[0u32; LANES]; 256];
    let mut m = 0;
    while m < 256 {
        let (mut j, mut i) = (0, 0);
        while i < LANES {
            if (m >> i) & 1 == 1 {
                t[m][j] = i as u32;
                j += 1;
            }
            i += 1;
        }
        i = 0;
        while i < LANES {
            if (m >> i) & 1 == 0 {
                t[m][j] = i as u32;
                j += 1;
            }
            i += 1;
        }
        m += 1;
    }
    t
}

/// The lanes of `v` set in `keep` moved to the front in lane order, the others after them
/// (one `vpermps` with AVX2).
#[inline(always)]
fn compress<const A: bool>(v: Raw, keep: u8) -> Raw {
    let idx = &COMPRESS[keep as usize];
    avx_or!(A, _mm256_permutevar8x32_ps(v, _mm256_loadu_si256(idx.as_ptr() as *const __m256i)), {
        let a = raw_to_i(v);
        raw_from_i(per_lane(|j| a[idx[j] as usize]))
    })
}

/// Stores the lanes of `v` set in `keep` at `dst[at..]`, packed in lane order; the words
/// up to `dst[at + 8]` after them are overwritten with the other lanes. `dst` may be the
/// slice `v` was loaded from (`at` at most the lane's old index: the stream compaction of
/// [`super::pool`]).
#[inline(always)]
pub fn compress_store<const A: bool>(v: F8<A>, keep: u8, dst: &mut [f32], at: usize) {
    let dst: &mut [f32; LANES] = (&mut dst[at..at + LANES]).try_into().expect("eight words");
    *dst = F8::<A>(compress::<A>(v.0, keep)).to_array();
}

/// [`compress_store`] of `u32` lanes.
#[inline(always)]
pub fn compress_store_u32<const A: bool>(v: U8<A>, keep: u8, dst: &mut [u32], at: usize) {
    let dst: &mut [u32; LANES] = (&mut dst[at..at + LANES]).try_into().expect("eight words");
    *dst = U8::<A>(compress::<A>(v.0, keep)).to_array();
}

/// `src[at..at + 8]` as lanes.
#[inline(always)]
pub fn load8<const A: bool>(src: &[f32], at: usize) -> F8<A> {
    F8::from_array(src[at..at + LANES].try_into().expect("eight words"))
}

/// `src[at..at + 8]` as `u32` lanes.
#[inline(always)]
pub fn load8_u32<const A: bool>(src: &[u32], at: usize) -> U8<A> {
    U8::from_array(src[at..at + LANES].try_into().expect("eight words"))
}

/// The mask as `u32` words (`u32::MAX` / 0; [`mask_of`] is the inverse).
#[inline(always)]
pub fn mask_words<const A: bool>(m: M8<A>) -> U8<A> {
    U8(m.0)
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

/// Eight 3-vectors, structure of arrays.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct V8<const A: bool> {
    pub x: F8<A>,
    pub y: F8<A>,
    pub z: F8<A>,
}

impl<const A: bool> V8<A> {
    #[inline(always)]
    pub fn new(x: F8<A>, y: F8<A>, z: F8<A>) -> V8<A> {
        V8 { x, y, z }
    }
    #[inline(always)]
    pub fn splat(v: Vec3) -> V8<A> {
        V8 { x: F8::splat(v.x), y: F8::splat(v.y), z: F8::splat(v.z) }
    }
    /// From three coordinate arrays.
    #[inline(always)]
    pub fn from_arrays(a: &[[f32; LANES]; 3]) -> V8<A> {
        V8::new(F8::from_array(a[0]), F8::from_array(a[1]), F8::from_array(a[2]))
    }
    /// The three coordinate arrays.
    #[inline(always)]
    pub fn to_arrays(self) -> [[f32; LANES]; 3] {
        [self.x.to_array(), self.y.to_array(), self.z.to_array()]
    }
    /// Lane `i` as a `Vec3`.
    #[inline(always)]
    pub fn lane(&self, i: usize) -> Vec3 {
        Vec3::new(self.x.lane(i), self.y.lane(i), self.z.lane(i))
    }
    /// Stores `v` in lane `i` (through memory: for per-lane fallbacks only).
    #[inline(always)]
    pub fn set_lane(&mut self, i: usize, v: Vec3) {
        self.x.set_lane(i, v.x);
        self.y.set_lane(i, v.y);
        self.z.set_lane(i, v.z);
    }
    /// glam's `dot`: `(x x' + y y') + z z'`.
    #[inline(always)]
    pub fn dot(self, o: V8<A>) -> F8<A> {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// glam's `length`.
    #[inline(always)]
    pub fn length(self) -> F8<A> {
        self.dot(self).sqrt()
    }
    /// glam's `normalize`: `v * (1 / length)`.
    #[inline(always)]
    pub fn normalize(self) -> V8<A> {
        let r = F8::splat(1.0) / self.length();
        self * r
    }
    #[inline(always)]
    pub fn abs(self) -> V8<A> {
        V8::new(self.x.abs(), self.y.abs(), self.z.abs())
    }
    /// glam's `max_element`: `max(x, max(y, z))`.
    #[inline(always)]
    pub fn max_element(self) -> F8<A> {
        self.x.max(self.y.max(self.z))
    }
    /// Lane-wise `self == 0` (all three components).
    #[inline(always)]
    pub fn is_zero(self) -> M8<A> {
        let z = F8::splat(0.0);
        (self.x.eq(z) & self.y.eq(z)) & self.z.eq(z)
    }
    /// Lane-wise glam `is_finite`.
    #[inline(always)]
    pub fn is_finite(self) -> M8<A> {
        self.x.is_finite() & self.y.is_finite() & self.z.is_finite()
    }
    /// Per-lane select.
    #[inline(always)]
    pub fn select(m: M8<A>, a: V8<A>, b: V8<A>) -> V8<A> {
        V8::new(select(m, a.x, b.x), select(m, a.y, b.y), select(m, a.z, b.z))
    }
}

impl<const A: bool> Add for V8<A> {
    type Output = V8<A>;
    #[inline(always)]
    fn add(self, o: V8<A>) -> V8<A> {
        V8::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}
impl<const A: bool> Sub for V8<A> {
    type Output = V8<A>;
    #[inline(always)]
    fn sub(self, o: V8<A>) -> V8<A> {
        V8::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}
/// Component-wise product (glam `Vec3 * Vec3`).
impl<const A: bool> Mul for V8<A> {
    type Output = V8<A>;
    #[inline(always)]
    fn mul(self, o: V8<A>) -> V8<A> {
        V8::new(self.x * o.x, self.y * o.y, self.z * o.z)
    }
}
/// Per-lane scale (glam `Vec3 * f32`; the product commutes exactly, so also `f32 * Vec3`).
impl<const A: bool> Mul<F8<A>> for V8<A> {
    type Output = V8<A>;
    #[inline(always)]
    fn mul(self, s: F8<A>) -> V8<A> {
        V8::new(self.x * s, self.y * s, self.z * s)
    }
}
/// Per-lane division (glam `Vec3 / f32`).
impl<const A: bool> Div<F8<A>> for V8<A> {
    type Output = V8<A>;
    #[inline(always)]
    fn div(self, s: F8<A>) -> V8<A> {
        V8::new(self.x / s, self.y / s, self.z / s)
    }
}
impl<const A: bool> Neg for V8<A> {
    type Output = V8<A>;
    #[inline(always)]
    fn neg(self) -> V8<A> {
        V8::new(-self.x, -self.y, -self.z)
    }
}

/// Eight-word rows of a table as lanes: `out[j]` lane `i` is `table[start[i] + j]`. With
/// AVX2 one unaligned load per row and an 8 x 8 transpose (`vunpcklps`/`vunpckhps`,
/// `vshufps`, `vperm2f128`: 24 shuffles) instead of 64 scalar loads and stores, or eight
/// gathers (slower on the development machine, see docs/perf-render.md). `None` when a
/// row does not lie in `table`.
#[inline(always)]
pub fn columns<const A: bool>(table: &[f32], start: &[usize; LANES]) -> Option<[F8<A>; 8]> {
    if start.iter().any(|&s| s > table.len() || table.len() - s < 8) {
        return None;
    }
    #[cfg(target_arch = "x86_64")]
    if A {
        // SAFETY: AVX (see `avx_or!`); every row `start[i]..start[i] + 8` is in `table`
        // (checked above).
        unsafe {
            let p = table.as_ptr();
            let r: [__m256; LANES] = [
                _mm256_loadu_ps(p.add(start[0])),
                _mm256_loadu_ps(p.add(start[1])),
                _mm256_loadu_ps(p.add(start[2])),
                _mm256_loadu_ps(p.add(start[3])),
                _mm256_loadu_ps(p.add(start[4])),
                _mm256_loadu_ps(p.add(start[5])),
                _mm256_loadu_ps(p.add(start[6])),
                _mm256_loadu_ps(p.add(start[7])),
            ];
            let t0 = _mm256_unpacklo_ps(r[0], r[1]);
            let t1 = _mm256_unpackhi_ps(r[0], r[1]);
            let t2 = _mm256_unpacklo_ps(r[2], r[3]);
            let t3 = _mm256_unpackhi_ps(r[2], r[3]);
            let t4 = _mm256_unpacklo_ps(r[4], r[5]);
            let t5 = _mm256_unpackhi_ps(r[4], r[5]);
            let t6 = _mm256_unpacklo_ps(r[6], r[7]);
            let t7 = _mm256_unpackhi_ps(r[6], r[7]);
            let u0 = _mm256_shuffle_ps::<0x44>(t0, t2);
            let u1 = _mm256_shuffle_ps::<0xee>(t0, t2);
            let u2 = _mm256_shuffle_ps::<0x44>(t1, t3);
            let u3 = _mm256_shuffle_ps::<0xee>(t1, t3);
            let u4 = _mm256_shuffle_ps::<0x44>(t4, t6);
            let u5 = _mm256_shuffle_ps::<0xee>(t4, t6);
            let u6 = _mm256_shuffle_ps::<0x44>(t5, t7);
            let u7 = _mm256_shuffle_ps::<0xee>(t5, t7);
            return Some([
                F8(_mm256_permute2f128_ps::<0x20>(u0, u4)),
                F8(_mm256_permute2f128_ps::<0x20>(u1, u5)),
                F8(_mm256_permute2f128_ps::<0x20>(u2, u6)),
                F8(_mm256_permute2f128_ps::<0x20>(u3, u7)),
                F8(_mm256_permute2f128_ps::<0x31>(u0, u4)),
                F8(_mm256_permute2f128_ps::<0x31>(u1, u5)),
                F8(_mm256_permute2f128_ps::<0x31>(u2, u6)),
                F8(_mm256_permute2f128_ps::<0x31>(u3, u7)),
            ]);
        }
    }
    let mut out = [F8::splat(0.0); 8];
    for (j, c) in out.iter_mut().enumerate() {
        *c = F8::from_array(per_lane(|i| table[start[i] + j]));
    }
    Some(out)
}

/// `table[idx[i]]` for an eight-entry table (`idx` below 8): one `vpermps` with AVX2.
#[inline(always)]
pub fn lookup8<const A: bool>(table: &[f32; LANES], idx: U8<A>) -> F8<A> {
    avx_or!(A, F8(_mm256_permutevar8x32_ps(_mm256_loadu_ps(table.as_ptr()), _mm256_castps_si256(idx.0))), {
        let i = idx.to_array();
        F8::from_array(per_lane(|k| table[i[k] as usize & 7]))
    })
}

/// [`lookup8`] of a table of `u32` words.
#[inline(always)]
pub fn lookup8_u32<const A: bool>(table: &[u32; LANES], idx: U8<A>) -> U8<A> {
    avx_or!(
        A,
        U8(_mm256_castsi256_ps(_mm256_permutevar8x32_epi32(
            _mm256_loadu_si256(table.as_ptr() as *const __m256i),
            _mm256_castps_si256(idx.0)
        ))),
        {
            let i = idx.to_array();
            U8::from_array(per_lane(|k| table[i[k] as usize & 7]))
        }
    )
}

/// Lanes of `m` whose word is not zero (words `u32::MAX` / 0, as [`lookup8_u32`] of a
/// mask table returns them).
#[inline(always)]
pub fn mask_of<const A: bool>(m: U8<A>) -> M8<A> {
    avx_or!(
        A,
        M8(_mm256_castsi256_ps(_mm256_xor_si256(
            _mm256_cmpeq_epi32(_mm256_castps_si256(m.0), _mm256_setzero_si256()),
            _mm256_set1_epi32(-1)
        ))),
        {
            let a = m.to_array();
            M8(raw_from_i(per_lane(|i| -((a[i] != 0) as i32))))
        }
    )
}

/// `(x as usize).min(n - 1)` per lane (`n` at most 8; truncation, NaN and negatives to 0).
#[inline(always)]
fn trunc_below8<const A: bool>(x: F8<A>, n: u32) -> U8<A> {
    avx_or!(
        A,
        {
            let t = _mm256_cvttps_epi32(x.0);
            let t = _mm256_max_epi32(
                _mm256_min_epi32(t, _mm256_set1_epi32(n as i32 - 1)),
                _mm256_setzero_si256(),
            );
            U8(_mm256_castsi256_ps(t))
        },
        {
            let xa = x.to_array();
            U8::from_array(per_lane(|k| (xa[k] as usize).min(n as usize - 1) as u32))
        }
    )
}

/// `AliasTable::sample(u)` in lanes for a table of `n` cells, `1 <= n <= 8`, given by its
/// `q`, `alias` and `pmf` words (`SmallLights`): `x = u * n`, `i = min(x as usize, n - 1)`,
/// `f = x - i as f32`, `k = f < q[i] ? i : alias[i]` (the scalar operations, so the same
/// cell), returned with `pmf[k]`. With AVX2 three `vpermps`, no per-lane code.
#[inline(always)]
pub fn alias_pick8<const A: bool>(
    u: F8<A>,
    n: u32,
    q: &[f32; LANES],
    alias: &[u32; LANES],
    pmf: &[f32; LANES],
) -> (U8<A>, F8<A>) {
    debug_assert!((1..=8).contains(&n));
    let x = u * F8::splat(n as f32);
    let i = trunc_below8(x, n);
    let i_f = i.to_f32();
    let f = x - i_f;
    let keep = f.lt(lookup8(q, i));
    let al = lookup8_u32(alias, i);
    let k = U8(select(keep, F8(i.0), F8(al.0)).0);
    (k, lookup8(pmf, k))
}

/// Eight `u32` lanes (the sampler's integer hashes; `A` as for [`F8`]).
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct U8<const A: bool>(Raw);

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compress_store_packs_the_kept_lanes_in_order() {
        let v: [f32; LANES] = std::array::from_fn(|i| i as f32 + 0.5);
        let w: [u32; LANES] = std::array::from_fn(|i| 100 + i as u32);
        #[cfg(target_arch = "x86_64")]
        let avx2 = filtrace_core::cpu::isa().has_avx2();
        #[cfg(not(target_arch = "x86_64"))]
        let avx2 = false;
        for keep in 0..=255u8 {
            let kept: Vec<usize> = (0..LANES).filter(|&i| (keep >> i) & 1 == 1).collect();
            let mut dst = [-1.0f32; 11];
            compress_store(F8::<false>::from_array(v), keep, &mut dst, 3);
            let mut dst_u = [0u32; 9];
            compress_store_u32(U8::<false>::from_array(w), keep, &mut dst_u, 1);
            for (j, &i) in kept.iter().enumerate() {
                assert_eq!((dst[3 + j], dst_u[1 + j]), (v[i], w[i]), "mask {keep:#010b}");
            }
            assert_eq!(dst[..3], [-1.0; 3]);
            if avx2 {
                let mut a = [-1.0f32; 11];
                compress_store(F8::<true>::from_array(v), keep, &mut a, 3);
                assert_eq!(a, dst);
            }
        }
    }

    #[test]
    fn vector_helpers_match_glam() {
        let v: Vec<Vec3> =
            (0..LANES).map(|i| Vec3::new(0.3 + i as f32, -1.7 * i as f32, 1.0 / (1.0 + i as f32))).collect();
        let mut a = V8::<false>::default();
        for (i, x) in v.iter().enumerate() {
            a.set_lane(i, *x);
        }
        let n = a.normalize();
        let d = a.dot(n);
        for (i, x) in v.iter().enumerate() {
            assert_eq!(n.lane(i), x.normalize());
            assert_eq!(d.lane(i), x.dot(x.normalize()));
            assert_eq!(a.max_element().lane(i), x.max_element());
        }
    }

    #[test]
    fn columns_transpose_rows() {
        let table: Vec<f32> = (0..200).map(|k| k as f32 * 0.5 - 7.0).collect();
        let start = [0usize, 17, 3, 192, 64, 65, 100, 8];
        let portable = columns::<false>(&table, &start).unwrap();
        for (j, c) in portable.iter().enumerate() {
            for (i, &s) in start.iter().enumerate() {
                assert_eq!(c.lane(i), table[s + j]);
            }
        }
        assert!(columns::<false>(&table, &[193; LANES]).is_none());
        assert!(columns::<false>(&table, &[usize::MAX; LANES]).is_none());
        #[cfg(target_arch = "x86_64")]
        if filtrace_core::cpu::isa().has_avx2() {
            let v = columns::<true>(&table, &start).unwrap();
            for j in 0..8 {
                assert_eq!(v[j].to_array(), portable[j].to_array());
            }
        }
    }

    #[test]
    fn alias_pick8_matches_alias_table_sample() {
        use filtrace_core::sampling::AliasTable;
        let weights = [3.0f32, 0.0, 1.5, 7.25, 0.5, 2.0, 0.0, 9.0];
        for n in 1..=8usize {
            let table = AliasTable::new(&weights[..n]);
            let (mut q, mut alias, mut pmf) = ([0.0f32; LANES], [0u32; LANES], [0.0f32; LANES]);
            for i in 0..n {
                let (qi, ai) = table.bin(i).unwrap();
                (q[i], alias[i], pmf[i]) = (qi, if n == 1 { 0 } else { ai }, table.pmf(i));
            }
            for step in 0..64u32 {
                let u: [f32; LANES] =
                    std::array::from_fn(|i| ((step * 8 + i as u32) as f32 * 0.618_034).fract());
                let (k, pm) = alias_pick8::<false>(F8::from_array(u), n as u32, &q, &alias, &pmf);
                #[cfg(target_arch = "x86_64")]
                if filtrace_core::cpu::isa().has_avx2() {
                    let (k2, pm2) = alias_pick8::<true>(F8::from_array(u), n as u32, &q, &alias, &pmf);
                    assert_eq!((k2.to_array(), pm2.to_array()), (k.to_array(), pm.to_array()));
                }
                for (i, &ui) in u.iter().enumerate() {
                    let (ks, ps) = table.sample(ui);
                    assert_eq!(
                        (k.to_array()[i] as usize, pm.lane(i).to_bits()),
                        (ks, ps.to_bits()),
                        "n {n} u {ui}"
                    );
                }
            }
        }
    }
}
