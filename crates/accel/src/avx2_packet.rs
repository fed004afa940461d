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

use crate::avx2::{any_zero, hit_distance, mixed_signs};
use crate::ray_packet::{RayPacket, LANES};
use crate::sah::MAX_DEPTH;
use crate::tri4::{Tri4, TriPackets};
use crate::triangle::{intersect_watertight, Tri, WatertightRay};
use crate::wide::Node8;
use crate::wide::{CULL_SCALE, FAR_SCALE};

/// Packet traversal stack depth: each 8-wide level pushes at most seven entries.
const STACK8: usize = 7 * MAX_DEPTH + 8;
use std::arch::x86_64::*;
use std::mem::MaybeUninit;

mod flat;
mod hybrid;
pub(crate) use flat::{
    closest_flat, closest_flat_avx512, flat_node_touch, occluded_flat, occluded_flat_avx512,
};
pub(crate) use hybrid::{closest_hybrid, occluded_hybrid, MIN_PACKET_LANES};

/// Eight lanes, 32-byte aligned (for aligned vector loads and stores).
#[repr(C, align(32))]
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct F8(pub [f32; LANES]);

#[repr(C, align(32))]
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct I8(pub [i32; LANES]);

/// Id of "no hit yet" in [`Closest8::id`] (primitive ids are below `2^31`).
pub(crate) const NO_HIT: i32 = i32::MAX;

/// Per-lane results of [`closest_flat`]: lane `i` hit primitive `prim_ids` value `id[i]`
/// (`NO_HIT`: no hit) at `t[i]` with barycentrics `u[i], v[i]`.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Closest8 {
    pub t: F8,
    pub u: F8,
    pub v: F8,
    pub id: I8,
}

/// The running closest hits of a packet, in registers: what [`Closest8`] holds.
#[derive(Clone, Copy)]
struct Best8 {
    t: __m256,
    u: __m256,
    v: __m256,
    id: __m256i,
}

impl Best8 {
    /// No hits yet, lanes searching up to `t_max`.
    #[inline(always)]
    unsafe fn new(t_max: __m256) -> Self {
        Best8 { t: t_max, u: _mm256_setzero_ps(), v: _mm256_setzero_ps(), id: _mm256_set1_epi32(NO_HIT) }
    }

    #[inline(always)]
    unsafe fn store(&self, out: &mut Closest8) {
        // SAFETY: `F8`/`I8` are 32-byte aligned.
        _mm256_store_ps(out.t.0.as_mut_ptr(), self.t);
        _mm256_store_ps(out.u.0.as_mut_ptr(), self.u);
        _mm256_store_ps(out.v.0.as_mut_ptr(), self.v);
        _mm256_store_si256(out.id.0.as_mut_ptr() as *mut __m256i, self.id);
    }

    #[inline(always)]
    unsafe fn load(out: &Closest8) -> Self {
        // SAFETY: as in `store`.
        Best8 {
            t: _mm256_load_ps(out.t.0.as_ptr()),
            u: _mm256_load_ps(out.u.0.as_ptr()),
            v: _mm256_load_ps(out.v.0.as_ptr()),
            id: _mm256_load_si256(out.id.0.as_ptr() as *const __m256i),
        }
    }

    /// Takes the hits `(t, u, v)` of triangle `id` in the lanes not rejected and in
    /// `[t_min_act, self.t]` (`t_min_act`: NaN in the lanes not to update): closer means
    /// `t < self.t`, or `t == self.t` and a smaller id.
    #[inline(always)]
    unsafe fn update(&mut self, t: __m256, u: __m256, v: __m256, reject: __m256, t_min_act: __m256, id: u32) {
        let in_range =
            _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(t, t_min_act), _mm256_cmp_ps::<_CMP_LE_OQ>(t, self.t));
        let hit = _mm256_andnot_ps(reject, in_range);
        let idv = _mm256_set1_epi32(id as i32);
        let smaller_id = _mm256_castsi256_ps(_mm256_cmpgt_epi32(self.id, idv));
        let closer = _mm256_and_ps(hit, _mm256_or_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(t, self.t), smaller_id));
        self.t = _mm256_blendv_ps(self.t, t, closer);
        self.u = _mm256_blendv_ps(self.u, u, closer);
        self.v = _mm256_blendv_ps(self.v, v, closer);
        self.id = _mm256_castps_si256(_mm256_blendv_ps(
            _mm256_castsi256_ps(self.id),
            _mm256_castsi256_ps(idv),
            closer,
        ));
    }

    /// Rare: some lane lies exactly on an edge of `tri`; the scalar test for the lanes `active`.
    #[inline(always)]
    unsafe fn update_scalar(
        &mut self,
        rays: &RayPacket,
        active: u32,
        out: &mut Closest8,
        tri: &Tri,
        id: u32,
    ) {
        self.store(out);
        closest_scalar(rays, active, out, tri, id as i32);
        *self = Best8::load(out);
    }
}

/// The rays of a packet prepared for the watertight test, in object space, in registers.
#[derive(Clone, Copy)]
struct Regs<'a> {
    /// The rays (for the scalar edge fallback).
    rays: &'a RayPacket,
    /// Lanes to trace: active and valid.
    active: u32,
    /// `org[kx], org[ky], org[kz]` and `S_x, S_y, S_z` per lane.
    o: [__m256; 3],
    s: [__m256; 3],
    t_min: __m256,
    t_max: __m256,
    /// All ones in active lanes.
    act: __m256,
    /// `t_min` in active lanes, NaN in the others (no `t` compares `>=` to it).
    t_min_act: __m256,
    /// `kx, ky, kz` per lane (shuffle indices).
    kidx: [__m256i; 3],
    /// All active lanes share this permutation.
    uniform: Option<[usize; 3]>,
}

/// True lanes where `x` is finite.
#[inline(always)]
unsafe fn finite(x: __m256) -> __m256 {
    let abs = _mm256_and_ps(x, _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff)));
    _mm256_cmp_ps::<_CMP_LT_OQ>(abs, _mm256_set1_ps(f32::INFINITY))
}

/// Per lane, `x`, `y` or `z` where the lane's axis is 0, 1 (`is1`) or 2 (`is2`).
#[inline(always)]
unsafe fn pick(x: __m256, y: __m256, z: __m256, is1: __m256, is2: __m256) -> __m256 {
    _mm256_blendv_ps(_mm256_blendv_ps(x, y, is1), z, is2)
}

/// Loads eight unaligned floats.
#[inline(always)]
unsafe fn ld(x: &[f32; LANES]) -> __m256 {
    // SAFETY: reads the 32 bytes of `x`.
    unsafe { _mm256_loadu_ps(x.as_ptr()) }
}

/// Prepares the lanes of `rays` set in `active`, all eight at once, with the decisions of
/// the single-ray query, lane for lane: `Ray::is_valid` and the watertight permutation and
/// shear (`WatertightRay::new`, the same selection rules and roundings). No bounds check:
/// the callers test boxes (group boxes of flat meshes, BVH nodes), which only cull.
#[inline(always)]
unsafe fn setup(rays: &RayPacket, active: u32) -> Regs<'_> {
    let [ox, oy, oz] = [ld(&rays.origin[0]), ld(&rays.origin[1]), ld(&rays.origin[2])];
    let [dx, dy, dz] = [ld(&rays.dir[0]), ld(&rays.dir[1]), ld(&rays.dir[2])];
    let (t_min, t_max) = (ld(&rays.t_min), ld(&rays.t_max));
    let zero = _mm256_setzero_ps();
    // `Ray::is_valid`: finite origin and direction, non-zero direction, no NaN bounds.
    let finite_o = _mm256_and_ps(_mm256_and_ps(finite(ox), finite(oy)), finite(oz));
    let finite_d = _mm256_and_ps(_mm256_and_ps(finite(dx), finite(dy)), finite(dz));
    let nonzero = _mm256_or_ps(
        _mm256_or_ps(_mm256_cmp_ps::<_CMP_NEQ_OQ>(dx, zero), _mm256_cmp_ps::<_CMP_NEQ_OQ>(dy, zero)),
        _mm256_cmp_ps::<_CMP_NEQ_OQ>(dz, zero),
    );
    let valid = _mm256_and_ps(
        _mm256_and_ps(finite_o, finite_d),
        _mm256_and_ps(nonzero, _mm256_cmp_ps::<_CMP_ORD_Q>(t_min, t_max)),
    );
    let one = _mm256_set1_ps(1.0);
    let act = _mm256_and_ps(valid, lane_mask(active));
    // `WatertightRay::new`: `kz` the axis of largest |d| (first on ties), `kx, ky` the
    // next ones, swapped when `d[kz] < 0`; `S_z = 1 / d[kz]`, `S_x = d[kx] S_z`, ...
    let abs = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
    let (ax, ay, az) = (_mm256_and_ps(dx, abs), _mm256_and_ps(dy, abs), _mm256_and_ps(dz, abs));
    let x_max = _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(ax, ay), _mm256_cmp_ps::<_CMP_GE_OQ>(ax, az));
    let z_over_y = _mm256_cmp_ps::<_CMP_LT_OQ>(ay, az);
    let kz0 = x_max;
    let kz2 = _mm256_andnot_ps(x_max, z_over_y);
    let kz1 = _mm256_andnot_ps(x_max, _mm256_andnot_ps(z_over_y, _mm256_castsi256_ps(_mm256_set1_epi32(-1))));
    let dkz = pick(dx, dy, dz, kz1, kz2);
    let swap = _mm256_cmp_ps::<_CMP_LT_OQ>(dkz, zero);
    let sel = [
        [_mm256_blendv_ps(kz0, kz2, swap), _mm256_blendv_ps(kz1, kz0, swap)],
        [_mm256_blendv_ps(kz2, kz0, swap), _mm256_blendv_ps(kz0, kz1, swap)],
        [kz1, kz2],
    ];
    let sz = _mm256_div_ps(one, dkz);
    let sx = _mm256_mul_ps(pick(dx, dy, dz, sel[0][0], sel[0][1]), sz);
    let sy = _mm256_mul_ps(pick(dx, dy, dz, sel[1][0], sel[1][1]), sz);
    let o = [
        pick(ox, oy, oz, sel[0][0], sel[0][1]),
        pick(ox, oy, oz, sel[1][0], sel[1][1]),
        pick(ox, oy, oz, sel[2][0], sel[2][1]),
    ];
    let active = _mm256_movemask_ps(act) as u32;
    // One permutation for all active lanes: each axis mask is all or nothing of them.
    let bits = [
        [_mm256_movemask_ps(sel[0][0]) as u32 & active, _mm256_movemask_ps(sel[0][1]) as u32 & active],
        [_mm256_movemask_ps(sel[1][0]) as u32 & active, _mm256_movemask_ps(sel[1][1]) as u32 & active],
        [_mm256_movemask_ps(sel[2][0]) as u32 & active, _mm256_movemask_ps(sel[2][1]) as u32 & active],
    ];
    let all_or_none = |m: u32| m == 0 || m == active;
    let uniform = bits.iter().flatten().all(|&m| all_or_none(m));
    let axis = |b: [u32; 2]| {
        if b[0] != 0 {
            1
        } else if b[1] != 0 {
            2
        } else {
            0
        }
    };
    let kidx = [
        _mm256_or_si256(
            _mm256_and_si256(_mm256_castps_si256(sel[0][0]), _mm256_set1_epi32(1)),
            _mm256_and_si256(_mm256_castps_si256(sel[0][1]), _mm256_set1_epi32(2)),
        ),
        _mm256_or_si256(
            _mm256_and_si256(_mm256_castps_si256(sel[1][0]), _mm256_set1_epi32(1)),
            _mm256_and_si256(_mm256_castps_si256(sel[1][1]), _mm256_set1_epi32(2)),
        ),
        _mm256_or_si256(
            _mm256_and_si256(_mm256_castps_si256(sel[2][0]), _mm256_set1_epi32(1)),
            _mm256_and_si256(_mm256_castps_si256(sel[2][1]), _mm256_set1_epi32(2)),
        ),
    ];
    Regs {
        rays,
        kidx,
        active,
        o,
        s: [sx, sy, sz],
        t_min,
        t_max,
        act,
        t_min_act: _mm256_blendv_ps(_mm256_set1_ps(f32::NAN), t_min, act),
        uniform: uniform.then(|| [axis(bits[0]), axis(bits[1]), axis(bits[2])]),
    }
}

/// All ones in the lanes whose bit is set in `m`.
#[inline(always)]
unsafe fn lane_mask(m: u32) -> __m256 {
    let bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    let v = _mm256_and_si256(_mm256_set1_epi32(m as i32), bits);
    _mm256_castsi256_ps(_mm256_cmpeq_epi32(v, bits))
}

/// Corner `c` of lane `l` of packet `tri`, permuted by the permutation `k` of all lanes:
/// `(v[kx], v[ky], v[kz])` as three broadcasts (BVH leaves; coherent packets).
#[inline(always)]
unsafe fn corner_packet(tri: &Tri4, c: usize, l: usize, k: [usize; 3]) -> [__m256; 3] {
    let v = &tri.v[c];
    [_mm256_set1_ps(v[k[0]][l]), _mm256_set1_ps(v[k[1]][l]), _mm256_set1_ps(v[k[2]][l])]
}

/// Steps 1-2 of the watertight test for one permuted corner `v` of the eight lanes:
/// translated, sheared and scaled `(x, y, S_z z)`, operation for operation as in
/// `avx2::sheared_edges` (so bit-identical to the scalar test).
#[inline(always)]
unsafe fn shear([v0, v1, v2]: [__m256; 3], r: &Regs<'_>) -> [__m256; 3] {
    let z = _mm256_sub_ps(v2, r.o[2]);
    let x = _mm256_sub_ps(_mm256_sub_ps(v0, r.o[0]), _mm256_mul_ps(r.s[0], z));
    let y = _mm256_sub_ps(_mm256_sub_ps(v1, r.o[1]), _mm256_mul_ps(r.s[1], z));
    [x, y, _mm256_mul_ps(r.s[2], z)]
}

/// Step 3: the edge functions `U, V, W` of the sheared corners `a, b, c`, as in
/// `avx2::sheared_edges`.
#[inline(always)]
unsafe fn edges(a: &[__m256; 3], b: &[__m256; 3], c: &[__m256; 3]) -> [__m256; 3] {
    let u = _mm256_sub_ps(_mm256_mul_ps(c[0], b[1]), _mm256_mul_ps(c[1], b[0]));
    let v = _mm256_sub_ps(_mm256_mul_ps(a[0], c[1]), _mm256_mul_ps(a[1], c[0]));
    let w = _mm256_sub_ps(_mm256_mul_ps(b[0], a[1]), _mm256_mul_ps(b[1], a[0]));
    [u, v, w]
}

/// The watertight test of the triangle with sheared corners `a, b, c` against the eight
/// lanes, as `avx2::test8v` per lane: `(edge, reject, t, u, v)` where `edge` marks lanes
/// with a zero edge function (their other results are meaningless: the caller redoes them
/// with the scalar test). `act`: the lanes to test. `EARLY`: `None` when none of them can
/// hit (all outside an edge).
#[inline(always)]
unsafe fn test_sheared<const EARLY: bool>(
    a: &[__m256; 3],
    b: &[__m256; 3],
    c: &[__m256; 3],
    act: __m256,
) -> Option<(__m256, __m256, __m256, __m256, __m256)> {
    let e = edges(a, b, c);
    let edge = _mm256_and_ps(act, any_zero(e));
    // Mixed signs: outside (no lane with a zero edge function gets here; see `test8v`).
    let reject = mixed_signs(e);
    if EARLY && _mm256_movemask_ps(_mm256_or_ps(_mm256_andnot_ps(reject, act), edge)) == 0 {
        // No lane inside the triangle: skip the division. Only for coherent packets
        // (camera tiles), where the branch is predictable: Cornell, packet primary closest
        // 34 -> 47 Mrays/CPU-s; for incoherent closest and shadow rays the mispredictions
        // cost more than the division (-8 to -13 %).
        return None;
    }
    let (t, u, v) = hit_distance(e, [a[2], b[2], c[2]]);
    Some((edge, reject, t, u, v))
}

/// [`test_sheared`] of the triangle with permuted corners `a, b, c`.
#[inline(always)]
unsafe fn test_tri<const EARLY: bool>(
    [a, b, c]: [[__m256; 3]; 3],
    r: &Regs<'_>,
    act: __m256,
) -> Option<(__m256, __m256, __m256, __m256, __m256)> {
    test_sheared::<EARLY>(&shear(a, r), &shear(b, r), &shear(c, r), act)
}

/// One axis of the conservative slab test, lane for lane as `avx2::RayBoxes8::new`:
/// `(inv, o inv + e, o inv - e)` with `inv = 1 / d` (components of `d` below 1e-30 in
/// magnitude replaced by +-1e-30) and `e` the rounding slack of `o inv`.
#[inline(always)]
unsafe fn slab(o: __m256, d: __m256) -> (__m256, __m256, __m256) {
    let sign = _mm256_castsi256_ps(_mm256_set1_epi32(i32::MIN));
    let abs = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
    let tiny = _mm256_set1_ps(1e-30);
    let small = _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_and_ps(d, abs), tiny);
    let d = _mm256_blendv_ps(d, _mm256_or_ps(_mm256_and_ps(d, sign), tiny), small);
    let inv = _mm256_div_ps(_mm256_set1_ps(1.0), d);
    let c = _mm256_mul_ps(o, inv);
    let e =
        _mm256_add_ps(_mm256_mul_ps(_mm256_and_ps(c, abs), _mm256_set1_ps(1.0 / (1u32 << 21) as f32)), tiny);
    (inv, _mm256_add_ps(c, e), _mm256_sub_ps(c, e))
}

/// One triangle against the lanes `active` with the scalar test, updating `out`.
#[inline(never)]
fn closest_scalar(rays: &RayPacket, active: u32, out: &mut Closest8, tri: &Tri, id: i32) {
    for i in (0..LANES).filter(|i| active & (1 << i) != 0) {
        let ray = rays.lane(i);
        let wr = WatertightRay::new(ray.origin, ray.dir);
        if let Some((t, u, v)) = intersect_watertight(&wr, tri, ray.t_min, out.t.0[i]) {
            if t < out.t.0[i] || id < out.id.0[i] {
                (out.t.0[i], out.u.0[i], out.v.0[i], out.id.0[i]) = (t, u, v, id);
            }
        }
    }
}

/// Lanes of `lanes` that hit `tri` (scalar test).
#[inline(never)]
fn any_scalar(rays: &RayPacket, lanes: u32, tri: &Tri) -> u32 {
    let mut hit = 0;
    for i in (0..LANES).filter(|&i| lanes & (1 << i) != 0) {
        let ray = rays.lane(i);
        let wr = WatertightRay::new(ray.origin, ray.dir);
        if intersect_watertight(&wr, tri, ray.t_min, ray.t_max).is_some() {
            hit |= 1 << i;
        }
    }
    hit
}

/// Per-lane constants of the fused 8-wide box test, lane for lane those of
/// `avx2::RayBoxes8::new`; the near/far bound rows are shared, which needs every active
/// lane to have the same direction signs.
struct Boxes8 {
    inv: [__m256; 3],
    oinv_near: [__m256; 3],
    oinv_far: [__m256; 3],
    near: [usize; 3],
    far: [usize; 3],
}

/// The packet's box test of one child (8 rays x 1 box): [`Boxes8`] for lanes of one
/// direction octant, `hybrid::LaneBoxes8` for any.
trait ChildBoxes {
    /// Lanes of `lanes` whose rays touch child `i` of `n` (the test of `avx2::box8`, lane
    /// for lane) and their entry distances.
    unsafe fn child(
        &self,
        n: &Node8,
        i: usize,
        t_min: __m256,
        t_cull: __m256,
        lanes: __m256,
    ) -> (u32, __m256);
}

impl Boxes8 {
    /// `None` when the lanes `active` differ in direction sign on some axis (lanes with
    /// NaN directions count as differing).
    #[inline(always)]
    unsafe fn new(rays: &RayPacket, active: u32) -> Option<Self> {
        // Sign bits first (incoherent packets stop here, before any division).
        for d in &rays.dir {
            let neg = _mm256_movemask_ps(ld(d)) as u32 & active;
            if neg != 0 && neg != active {
                return None;
            }
        }
        let mut b = Self {
            inv: [_mm256_setzero_ps(); 3],
            oinv_near: [_mm256_setzero_ps(); 3],
            oinv_far: [_mm256_setzero_ps(); 3],
            near: [0; 3],
            far: [0; 3],
        };
        for k in 0..3 {
            let inv;
            (inv, b.oinv_near[k], b.oinv_far[k]) = slab(ld(&rays.origin[k]), ld(&rays.dir[k]));
            b.inv[k] = inv;
            let pos =
                _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(inv, _mm256_setzero_ps())) as u32 & active;
            (b.near[k], b.far[k]) = if pos == active {
                (k, k + 3)
            } else if pos == 0 {
                (k + 3, k)
            } else {
                return None;
            };
        }
        Some(b)
    }
}

impl ChildBoxes for Boxes8 {
    #[inline(always)]
    unsafe fn child(
        &self,
        n: &Node8,
        i: usize,
        t_min: __m256,
        t_cull: __m256,
        lanes: __m256,
    ) -> (u32, __m256) {
        let b = &n.bounds;
        let nx = _mm256_fmsub_ps(_mm256_set1_ps(b[self.near[0]][i]), self.inv[0], self.oinv_near[0]);
        let fx = _mm256_fmsub_ps(_mm256_set1_ps(b[self.far[0]][i]), self.inv[0], self.oinv_far[0]);
        let ny = _mm256_fmsub_ps(_mm256_set1_ps(b[self.near[1]][i]), self.inv[1], self.oinv_near[1]);
        let fy = _mm256_fmsub_ps(_mm256_set1_ps(b[self.far[1]][i]), self.inv[1], self.oinv_far[1]);
        let nz = _mm256_fmsub_ps(_mm256_set1_ps(b[self.near[2]][i]), self.inv[2], self.oinv_near[2]);
        let fz = _mm256_fmsub_ps(_mm256_set1_ps(b[self.far[2]][i]), self.inv[2], self.oinv_far[2]);
        let t_near = _mm256_max_ps(nz, _mm256_max_ps(ny, _mm256_max_ps(nx, t_min)));
        let t_far = _mm256_min_ps(fz, _mm256_min_ps(fy, _mm256_min_ps(fx, t_cull)));
        let t_far = _mm256_mul_ps(t_far, _mm256_set1_ps(FAR_SCALE));
        let hit = _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t_near, t_far), lanes);
        (_mm256_movemask_ps(hit) as u32, t_near)
    }
}

/// Largest spread of the active lanes' directions: the maximum over the axes of
/// `max - min` of the normalised direction component. Only decides between the packet
/// traversal and per-lane queries (never the result).
#[inline(always)]
unsafe fn direction_spread(rays: &RayPacket, active: u32) -> f32 {
    let [dx, dy, dz] = [ld(&rays.dir[0]), ld(&rays.dir[1]), ld(&rays.dir[2])];
    let len2 =
        _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)), _mm256_mul_ps(dz, dz));
    let inv = _mm256_rsqrt_ps(len2);
    let act = lane_mask(active);
    let (inf, neg_inf) = (_mm256_set1_ps(f32::INFINITY), _mm256_set1_ps(f32::NEG_INFINITY));
    // Per lane the largest spread is found after the horizontal min and max of each axis.
    let (mut lo, mut hi) = ([inf; 3], [neg_inf; 3]);
    for (k, d) in [dx, dy, dz].into_iter().enumerate() {
        let n = _mm256_mul_ps(d, inv);
        let (l, h) = (_mm256_blendv_ps(inf, n, act), _mm256_blendv_ps(neg_inf, n, act));
        let l = _mm256_min_ps(l, _mm256_permute2f128_ps::<1>(l, l));
        let h = _mm256_max_ps(h, _mm256_permute2f128_ps::<1>(h, h));
        let l = _mm256_min_ps(l, _mm256_permute_ps::<0b01_00_11_10>(l));
        let h = _mm256_max_ps(h, _mm256_permute_ps::<0b01_00_11_10>(h));
        lo[k] = _mm256_min_ps(l, _mm256_permute_ps::<0b10_11_00_01>(l));
        hi[k] = _mm256_max_ps(h, _mm256_permute_ps::<0b10_11_00_01>(h));
    }
    let spread = _mm256_max_ps(
        _mm256_sub_ps(hi[0], lo[0]),
        _mm256_max_ps(_mm256_sub_ps(hi[1], lo[1]), _mm256_sub_ps(hi[2], lo[2])),
    );
    _mm256_cvtss_f32(spread)
}

/// Widest direction spread ([`direction_spread`]) for which a packet is traversed as one.
/// `packet_lanes bunny.obj` (camera tiles of 4x2 pixels `s` pixels apart, 1024^2 image,
/// 45 degree fov, single / packet CPU time): s = 1: 2.17x, 2: 2.15x, 4: 1.84x,
/// 8: 1.35x (spread ~0.02), 16: 0.80x (~0.04), 32: 0.73x, 64: 0.63x.
const MAX_SPREAD: f32 = 0.03;

/// A pending subtree of the packet traversal and the lanes that entered it.
#[derive(Clone, Copy)]
struct PacketEntry {
    child: u32,
    count: u32,
    lanes: u32,
    /// Entry distance of the lowest of those lanes (the visit order).
    t: f32,
}

/// `cull_bound` of every lane.
#[inline(always)]
unsafe fn cull8(t_max: __m256) -> __m256 {
    _mm256_max_ps(_mm256_mul_ps(t_max, _mm256_set1_ps(CULL_SCALE)), t_max)
}

/// Pushes the children of `node` that some lane of `lanes` touches onto `stack` (the
/// farthest deepest when `ORDERED`, by the entry distance of each child's lowest lane) and
/// returns the one to visit next.
#[inline(always)]
unsafe fn expand<const ORDERED: bool, B: ChildBoxes>(
    node: &Node8,
    b: &B,
    t_min: __m256,
    t_cull: __m256,
    lanes: u32,
    stack: &mut [MaybeUninit<PacketEntry>; STACK8],
    sp: &mut usize,
) -> Option<PacketEntry> {
    let lane_vec = lane_mask(lanes);
    let base = *sp;
    let mut t_near = F8::default();
    for i in 0..8 {
        if node.count[i] == 0 && node.child[i] == 0 {
            continue; // empty slot (node 0 is the root, never a child)
        }
        let (m, tn) = b.child(node, i, t_min, t_cull, lane_vec);
        if m == 0 {
            continue;
        }
        let mut e = PacketEntry { child: node.child[i], count: node.count[i], lanes: m, t: 0.0 };
        if ORDERED {
            // SAFETY: `F8` is 32-byte aligned.
            _mm256_store_ps(t_near.0.as_mut_ptr(), tn);
            e.t = t_near.0[m.trailing_zeros() as usize];
        }
        let mut j = *sp;
        // SAFETY: entries in `base..*sp` were written above.
        while ORDERED && j > base && stack[j - 1].assume_init().t < e.t {
            stack[j] = stack[j - 1];
            j -= 1;
        }
        stack[j] = MaybeUninit::new(e);
        *sp += 1;
    }
    if *sp == base {
        return None;
    }
    *sp -= 1;
    // SAFETY: entries below `sp` were written before `sp` was raised past them.
    Some(stack[*sp].assume_init())
}

/// Closest hits of the lanes of `rays` set in `active` in the 8-wide BVH of `blas`, with
/// one traversal for the whole packet (8 rays x 1 child box per instruction, leaves
/// tested 8 rays x 1 triangle): `None` (nothing done) unless the active lanes share their
/// direction signs and watertight permutation, as coherent packets do.
///
/// Per lane the answer is that of the single-ray traversal: every lane tests every box
/// with its own distances (`avx2::box8`'s arithmetic) and keeps, among the triangles it
/// tests, the smallest `(t, id)`; boxes are culled only beyond its own closest hit
/// (`cull_bound`), so the visit order does not change the result.
///
/// # Safety
/// The CPU has AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn closest_bvh(
    nodes: &[Node8],
    tris: &TriPackets,
    rays: &RayPacket,
    active: u8,
) -> Option<Closest8> {
    // Direction signs first: the cheapest test of coherence.
    let b = Boxes8::new(rays, active as u32)?;
    if direction_spread(rays, active as u32) > MAX_SPREAD {
        return None;
    }
    let r = setup(rays, active as u32);
    let mut out = Closest8 { id: I8([NO_HIT; LANES]), ..Closest8::default() };
    if r.active == 0 || nodes.is_empty() {
        return Some(out);
    }
    let k = r.uniform?;
    // Uninitialised: zeroing its 6.4 KB per query cost D1 write misses (packet_two_level.rs).
    let mut stack = [MaybeUninit::<PacketEntry>::uninit(); STACK8];
    let mut sp = 0usize;
    let mut best = Best8::new(r.t_max);
    let mut cur = PacketEntry { child: 0, count: 0, lanes: r.active, t: 0.0 };
    loop {
        if cur.count == 0 {
            let node = &nodes[cur.child as usize];
            if let Some(next) =
                expand::<true, _>(node, &b, r.t_min, cull8(best.t), cur.lanes, &mut stack, &mut sp)
            {
                cur = next;
                continue;
            }
        } else {
            closest_leaf::<true>(tris, &r, k, &cur, &mut best, &mut out);
        }
        // Next pending subtree (its box tests cull the lanes that found closer hits).
        if sp == 0 {
            best.store(&mut out);
            return Some(out);
        }
        sp -= 1;
        // SAFETY: as in `expand`.
        cur = stack[sp].assume_init();
    }
}

/// Lanes of `rays` set in `active` that hit any triangle of the 8-wide BVH of `blas`
/// with `t` in `[t_min, t_max]`, with one traversal for the packet; `None` as in
/// [`closest_bvh`].
///
/// # Safety
/// The CPU has AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn occluded_bvh(
    nodes: &[Node8],
    tris: &TriPackets,
    rays: &RayPacket,
    active: u8,
) -> Option<u8> {
    let b = Boxes8::new(rays, active as u32)?;
    if direction_spread(rays, active as u32) > MAX_SPREAD {
        return None;
    }
    let r = setup(rays, active as u32);
    if r.active == 0 || nodes.is_empty() {
        return Some(0);
    }
    let k = r.uniform?;
    // Uninitialised: zeroing its 6.4 KB per query cost D1 write misses (packet_two_level.rs).
    let mut stack = [MaybeUninit::<PacketEntry>::uninit(); STACK8];
    let mut sp = 0usize;
    let t_cull = cull8(r.t_max);
    let mut left = r.active;
    let mut cur = PacketEntry { child: 0, count: 0, lanes: r.active, t: 0.0 };
    loop {
        if cur.count == 0 {
            let node = &nodes[cur.child as usize];
            if let Some(next) = expand::<false, _>(node, &b, r.t_min, t_cull, cur.lanes, &mut stack, &mut sp)
            {
                cur = next;
                continue;
            }
        } else {
            left &= !occluded_leaf(tris, &r, k, &cur);
            if left == 0 {
                return Some(r.active as u8);
            }
        }
        loop {
            if sp == 0 {
                return Some((r.active & !left) as u8);
            }
            sp -= 1;
            // SAFETY: as in `expand`.
            cur = stack[sp].assume_init();
            cur.lanes &= left;
            if cur.lanes != 0 {
                break;
            }
        }
    }
}

/// The leaf `cur` of a packet traversal (its triangle ids `cur.child..+cur.count` packets)
/// against the lanes `cur.lanes`, all of permutation `k`, updating the closest hits `best`
/// (`out`: scratch for the scalar edge fallback). `EARLY`: as in [`test_sheared`].
#[inline(always)]
unsafe fn closest_leaf<const EARLY: bool>(
    tris: &TriPackets,
    r: &Regs<'_>,
    k: [usize; 3],
    cur: &PacketEntry,
    best: &mut Best8,
    out: &mut Closest8,
) {
    let act = lane_mask(cur.lanes);
    let t_min_act = _mm256_blendv_ps(_mm256_set1_ps(f32::NAN), r.t_min, act);
    for j in cur.child as usize..(cur.child + cur.count) as usize {
        let tri = &tris.packets[j];
        for l in 0..4 {
            let id = tris.prim_ids[4 * j + l];
            if id == u32::MAX {
                continue;
            }
            let corners =
                [corner_packet(tri, 0, l, k), corner_packet(tri, 1, l, k), corner_packet(tri, 2, l, k)];
            let Some((edge, reject, t, u, v)) = test_tri::<EARLY>(corners, r, act) else {
                continue;
            };
            if _mm256_movemask_ps(edge) != 0 {
                best.update_scalar(r.rays, cur.lanes, out, &tri.lane(l), id);
                continue;
            }
            best.update(t, u, v, reject, t_min_act, id);
        }
    }
}

/// The lanes of `cur.lanes` (all of permutation `k`) that hit a triangle of the leaf
/// `cur` with `t` in `[t_min, t_max]`.
#[inline(always)]
unsafe fn occluded_leaf(tris: &TriPackets, r: &Regs<'_>, k: [usize; 3], cur: &PacketEntry) -> u32 {
    let mut act = lane_mask(cur.lanes);
    let mut hits = 0;
    for j in cur.child as usize..(cur.child + cur.count) as usize {
        let tri = &tris.packets[j];
        for l in 0..4 {
            if tris.prim_ids[4 * j + l] == u32::MAX {
                continue;
            }
            let corners =
                [corner_packet(tri, 0, l, k), corner_packet(tri, 1, l, k), corner_packet(tri, 2, l, k)];
            let Some((edge, reject, t, _, _)) = test_tri::<false>(corners, r, act) else {
                continue;
            };
            let hit = if _mm256_movemask_ps(edge) != 0 {
                lane_mask(any_scalar(r.rays, _mm256_movemask_ps(act) as u32, &tri.lane(l)))
            } else {
                let in_range = _mm256_and_ps(
                    _mm256_cmp_ps::<_CMP_GE_OQ>(t, r.t_min),
                    _mm256_cmp_ps::<_CMP_LE_OQ>(t, r.t_max),
                );
                _mm256_and_ps(_mm256_andnot_ps(reject, in_range), act)
            };
            act = _mm256_andnot_ps(hit, act);
            hits |= _mm256_movemask_ps(hit) as u32;
        }
    }
    hits
}
