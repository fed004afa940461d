//! The watertight test (Woop et al. 2013) of one triangle against the eight rays of a
//! packet, operation for operation as the single-ray kernels (`avx2::test8v`).

use super::lanes::Regs;
use crate::avx2::{any_zero, hit_distance, mixed_signs};
use crate::ray_packet::{RayPacket, LANES};
use crate::tri4::Tri4;
use crate::triangle::{intersect_watertight, Tri, WatertightRay};
use std::arch::x86_64::*;

/// Corner `c` of lane `l` of packet `tri`, permuted by the permutation `k` of all lanes:
/// `(v[kx], v[ky], v[kz])` as three broadcasts (BVH leaves; coherent packets).
#[inline(always)]
pub(super) unsafe fn corner_packet(tri: &Tri4, c: usize, l: usize, k: [usize; 3]) -> [__m256; 3] {
    let v = &tri.v[c];
    [_mm256_set1_ps(v[k[0]][l]), _mm256_set1_ps(v[k[1]][l]), _mm256_set1_ps(v[k[2]][l])]
}

/// Steps 1-2 of the watertight test for one permuted corner `v` of the eight lanes:
/// translated, sheared and scaled `(x, y, S_z z)`, operation for operation as in
/// `avx2::sheared_edges` (so bit-identical to the scalar test).
#[inline(always)]
pub(super) unsafe fn shear([v0, v1, v2]: [__m256; 3], r: &Regs<'_>) -> [__m256; 3] {
    let z = _mm256_sub_ps(v2, r.o[2]);
    let x = _mm256_sub_ps(_mm256_sub_ps(v0, r.o[0]), _mm256_mul_ps(r.s[0], z));
    let y = _mm256_sub_ps(_mm256_sub_ps(v1, r.o[1]), _mm256_mul_ps(r.s[1], z));
    [x, y, _mm256_mul_ps(r.s[2], z)]
}

/// Step 3: the edge functions `U, V, W` of the sheared corners `a, b, c`, as in
/// `avx2::sheared_edges`.
#[inline(always)]
pub(super) unsafe fn edges(a: &[__m256; 3], b: &[__m256; 3], c: &[__m256; 3]) -> [__m256; 3] {
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
pub(super) unsafe fn test_sheared<const EARLY: bool>(
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
pub(super) unsafe fn test_tri<const EARLY: bool>(
    [a, b, c]: [[__m256; 3]; 3],
    r: &Regs<'_>,
    act: __m256,
) -> Option<(__m256, __m256, __m256, __m256, __m256)> {
    test_sheared::<EARLY>(&shear(a, r), &shear(b, r), &shear(c, r), act)
}

/// Lanes of `lanes` that hit `tri` (scalar test).
#[inline(never)]
pub(super) fn any_scalar(rays: &RayPacket, lanes: u32, tri: &Tri) -> u32 {
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
