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
//!
//! **Layout.** The lane types and their storage are defined here; `mask.rs` holds the mask
//! operations, `float.rs` the `f32` lane arithmetic, `vec3.rs` the 3-vectors, `uint.rs` the
//! integer lanes and `gather.rs` the loads, stores, table lookups and stream compaction.

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

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

// After `avx_or!`: macros are in scope only in the text below their definition.
mod float;
mod gather;
mod mask;
#[cfg(test)]
mod tests;
mod uint;
mod vec3;

pub use float::select;
pub use gather::{
    alias_pick8, columns, compress_store, compress_store_u32, gather, gather_u32, load8, load8_u32, lookup,
    lookup8, lookup8_u32, lookup_u32, mask_of, mask_words, trunc_below,
};
pub use mask::{bits, from_bits};
pub use vec3::V8;

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

/// Eight `u32` lanes (the sampler's integer hashes; `A` as for [`F8`]).
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct U8<const A: bool>(Raw);

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
