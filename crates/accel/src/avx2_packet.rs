//! Eight-ray packet kernels with AVX2 ([`crate::SceneAccel::intersect_packet`],
//! [`crate::SceneAccel::occluded_packet`] on one object: the scene's only one, or, for the
//! flat kernels, each instance a packet reaches through the top level,
//! `packet_two_level.rs`).
//!
//! - **Flat bottom levels** (submodule `flat`; at most
//!   [`crate::BuildParams::max_flat_triangles`] triangles, the Cornell box): the group
//!   boxes (`flat_blas::flat_layout`) are tested against the 8 rays first (8 rays x 1 box,
//!   branch-free, a mask of the groups some lane touches); then each triangle of the
//!   touched groups against all active rays at once, one ray per lane (8 rays x 1
//!   triangle per instruction). Meshes of at most [`crate::flat_blas::MAX_FLAT_VERTS`]
//!   distinct vertices (`flat_blas::FlatVerts`; the Cornell box has 28 for 72 corners of its
//!   quads) shear each vertex the touched groups need once per packet
//!   into a table on the stack (`ShearedVerts`), and the triangle loop reads its corners
//!   from there: the per-lane permutation, origin and shear no longer compete with the
//!   running closest hit for the 16 vector registers. Larger ones shear per triangle, fan
//!   pairs `(a, b, c), (a, c, d)` sharing their two common sheared corners.
//! - **8-wide BVHs**, for coherent packets (all active lanes with the same direction signs
//!   and watertight permutation, directions within [`MAX_SPREAD`]: camera tiles): one
//!   traversal for the packet, each child
//!   box tested against the 8 rays (8 rays x 1 box), leaves as for flat meshes. Other
//!   packets are left to the caller: any hits to the hybrid packet / single-ray traversal
//!   (submodule `hybrid`, Benthin et al. 2012), closest hits to one single-ray query per
//!   lane (the hybrid lost there; docs/perf-accel.md, "Stop 16").
//!
//! Per lane the arithmetic is that of the single-ray kernels, operation for operation
//! (ray validity, bounds check, the watertight permutation and shear, the watertight test
//! of Woop et al. 2013 as in `avx2::test8v` without fused multiply-adds, the fused slab
//! test of `avx2::box8`), so each lane's hit is bit-identical to
//! [`crate::SceneAccel::intersect`]. The rays' permutation `kx, ky, kz` may differ per
//! lane: each triangle corner is then read as a row `[x, y, z, x]` and its permuted
//! components picked per lane with one shuffle each (plain broadcasts when all active
//! lanes share the permutation). A lane with an edge function exactly zero takes the
//! scalar test with its `f64` fallback, as the single-ray kernels do; ties in `t` go to
//! the smallest primitive id; boxes are culled per lane beyond its own closest hit, so the
//! visit order (which differs from the single-ray traversal) does not change the result.
//!
//! The flat kernels also come compiled for AVX-512VL (`closest_flat_avx512`,
//! `occluded_flat_avx512`: the same 256-bit operations, so the same results, with 32
//! vector registers and mask registers; the packet dispatch takes them where the CPU has
//! AVX-512F and AVX-512VL).
//!
//! As in `avx2.rs`, the kernels are `#[target_feature(enable = "avx2,fma")]` functions that
//! callers reach only when [`crate::Simd::Avx2`] is available; helpers are
//! `#[inline(always)]` and use no closures (closures do not inherit target features).
//!
//! Submodules: [`lanes`] (the rays in registers, the running closest hits), [`tri`] (one
//! triangle against eight rays), [`boxes`] (one box against eight rays), [`traverse`] (the
//! BVH packet traversal), [`hybrid`] (its lanes going on alone), [`flat`] (flat meshes).

mod boxes;
mod flat;
mod hybrid;
mod lanes;
mod traverse;
mod tri;

pub(crate) use flat::{
    closest_flat, closest_flat_avx512, flat_node_touch, occluded_flat, occluded_flat_avx512,
};
pub(crate) use hybrid::{closest_hybrid, occluded_hybrid, MIN_PACKET_LANES};
pub(crate) use lanes::{Closest8, NO_HIT};
pub(crate) use traverse::{closest_bvh, occluded_bvh};
