//! Eight-wide traversal with AVX2, chosen at run time ([`crate::Simd::Avx2`]).
//!
//! The same binary SAH tree as the SSE path, collapsed to 8-wide nodes
//! ([`crate::wide::Node8`], Dammertz et al. 2008 with eight children; Embree's BVH8 on AVX CPUs): one
//! 8-lane slab test (Williams et al. 2005, far distance widened by `1 + 2 gamma_3` as in
//! Ize 2013, the operations of the SSE test in the same order) covers all eight children,
//! so an incoherent ray visits about half as many nodes as with four-wide nodes. Leaves
//! are ranges of the 4-triangle packets ([`crate::tri4::Tri4`]) that the SSE path uses; two adjacent
//! packets are tested at once as eight lanes of the watertight test (Woop et al. 2013),
//! bit-identical to the scalar test (no fused multiply-adds: the sheared corners and edge
//! functions round exactly as [`crate::triangle::intersect_watertight`] does).
//!
//! Every function here needs AVX2 and FMA; callers check `filtrace_core::cpu::isa()`
//! first. The small kernels are `#[inline(always)] unsafe fn`s without target features (a
//! function with target features cannot be forced inline): they are only called from
//! functions compiled with `avx2,fma` (`traverse8`, `SceneAccel::intersect_avx2`), into
//! which they are inlined together with their intrinsics. Calling one elsewhere is unsafe
//! on CPUs without AVX2 and slow everywhere.
//!
//! - [`boxes`]: the 8-lane slab test and the node layouts ([`Node8Layout`]);
//! - [`order`]: near-first child order by a sorting network;
//! - [`traverse`]: the traversal loop, one body for both layouts, and the bottom-level
//!   queries;
//! - [`tri8`]: the 8-lane triangle test; [`leaves`]: the leaf tests built on it.

mod boxes;
mod leaves;
mod order;
mod traverse;
mod tri8;

#[cfg(test)]
pub(crate) use boxes::box8;
pub(crate) use boxes::{Node8Layout, RayBoxes8};
pub(crate) use leaves::{AnyPairs, ClosestPairs};
pub(crate) use traverse::{intersect8, occluded8, traverse8_from};
pub(crate) use tri8::{any_zero, hit_distance, mixed_signs, Ray8};

/// Eight 32-byte aligned floats (stored by one aligned store, read back one at a time).
#[repr(C, align(32))]
struct Lanes8([f32; 8]);
