//! The 8-ray kernels of flat bottom levels (at most
//! [`crate::BuildParams::max_flat_triangles`] triangles, the Cornell box): group boxes
//! first, then the triangles of the touched groups, their corners sheared once per packet
//! from the mesh's vertex table where it has one. See the parent module for the
//! arithmetic shared with the BVH packet kernels (ray setup, watertight test, running
//! closest hits) and for why each lane's answer equals the single-ray query's.

use super::boxes::{cull8, LaneBoxes};
use super::lanes::{lane_mask, setup, Best8, Closest8, Regs, I8, NO_HIT};
use super::tri::{any_scalar, edges, shear, test_sheared};
use crate::avx2::{any_zero, hit_distance, mixed_signs};
use crate::flat_blas::{FlatBlas, FlatGroup, FlatNode, FlatTri, VertRow, MAX_FLAT_VERTS, SHEARED_VERT_BYTES};
use crate::ray_packet::{RayPacket, LANES};
use crate::wide::FAR_SCALE;
use filtrace_core::Vec3;
use std::arch::x86_64::*;
use std::mem::MaybeUninit;

/// Corner `c` of a flat triangle, permuted per lane: `(v[kx], v[ky], v[kz])`. One
/// permutation (`UNIFORM`, `k`): three broadcasts; else the row `[x, y, z, x]` in both
/// halves and one shuffle per coordinate (instead of two blends: Cornell, packet
/// incoherent closest 16.4 -> 19.9, shadow 17.8 -> 23.4 Mrays/CPU-s).
#[inline(always)]
unsafe fn corner_flat<const UNIFORM: bool>(
    tri: &FlatTri,
    c: usize,
    r: &Regs<'_>,
    k: [usize; 3],
) -> [__m256; 3] {
    let row = &tri.rows[c];
    if UNIFORM {
        return [_mm256_set1_ps(row[k[0]]), _mm256_set1_ps(row[k[1]]), _mm256_set1_ps(row[k[2]])];
    }
    // SAFETY: `FlatTri` rows are 16-byte aligned, 16 bytes each.
    let row = _mm256_broadcast_ps(unsafe { &*(row.as_ptr() as *const __m128) });
    [
        _mm256_permutevar_ps(row, r.kidx[0]),
        _mm256_permutevar_ps(row, r.kidx[1]),
        _mm256_permutevar_ps(row, r.kidx[2]),
    ]
}

/// A vertex permuted per lane, as [`corner_flat`].
#[inline(always)]
unsafe fn corner_row<const UNIFORM: bool>(row: &VertRow, r: &Regs<'_>, k: [usize; 3]) -> [__m256; 3] {
    if UNIFORM {
        return [_mm256_set1_ps(row.0[k[0]]), _mm256_set1_ps(row.0[k[1]]), _mm256_set1_ps(row.0[k[2]])];
    }
    // SAFETY: `VertRow` is 16-byte aligned, 16 bytes.
    let row = _mm256_broadcast_ps(unsafe { &*(row.0.as_ptr() as *const __m128) });
    [
        _mm256_permutevar_ps(row, r.kidx[0]),
        _mm256_permutevar_ps(row, r.kidx[1]),
        _mm256_permutevar_ps(row, r.kidx[2]),
    ]
}

/// Bit `g` set for each group of `groups` whose box some lane of `act` touches with `t`
/// in `[t_min, t_cull]`. Branch-free: all boxes are tested before any triangle (a branch
/// per group on incoherent packets is a coin flip).
#[inline(always)]
unsafe fn touched_groups(
    groups: &[FlatGroup],
    lb: &LaneBoxes,
    t_min: __m256,
    t_cull: __m256,
    act: __m256,
) -> u32 {
    let mut mask = 0u32;
    for (g, group) in groups.iter().enumerate() {
        let b = &group.bounds;
        let (lanes, _) = lb.touch([b[0], b[1], b[2]], [b[3], b[4], b[5]], t_min, t_cull, act);
        mask |= ((lanes != 0) as u32) << g;
    }
    mask
}

/// Groups of the flat node `n` (bit `i` for slot `i`) whose boxes the ray `o + t d`
/// touches with `t` in `[t_min, t_cull]`: one 8-wide box test with the arithmetic of
/// `avx2::box8` (the BVH's conservative fused slab test).
///
/// # Safety
/// The CPU has AVX2 and FMA (inlined into such functions only).
#[inline(always)]
pub(crate) unsafe fn flat_node_touch(n: &FlatNode, o: Vec3, d: Vec3, t_min: f32, t_cull: f32) -> u32 {
    let mut t_near = _mm256_set1_ps(t_min);
    let mut t_far = _mm256_set1_ps(t_cull);
    for k in 0..3 {
        let dk = if d[k].abs() < 1e-30 { 1e-30f32.copysign(d[k]) } else { d[k] };
        let inv = 1.0 / dk;
        let c = o[k] * inv;
        let e = c.abs() * (1.0 / (1u32 << 21) as f32) + 1e-30;
        // The near plane is the min row for `inv >= 0` (index arithmetic, no branch).
        let neg = (inv < 0.0) as usize;
        let (near, far) = (k + 3 * neg, k + 3 - 3 * neg);
        let inv8 = _mm256_set1_ps(inv);
        // SAFETY: `FlatNode` is 32-byte aligned and its rows are 32 bytes.
        let (nb, fb) =
            unsafe { (_mm256_load_ps(n.bounds[near].as_ptr()), _mm256_load_ps(n.bounds[far].as_ptr())) };
        t_near = _mm256_max_ps(_mm256_fmsub_ps(nb, inv8, _mm256_set1_ps(c + e)), t_near);
        t_far = _mm256_min_ps(_mm256_fmsub_ps(fb, inv8, _mm256_set1_ps(c - e)), t_far);
    }
    let t_far = _mm256_mul_ps(t_far, _mm256_set1_ps(FAR_SCALE));
    _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t_near, t_far)) as u32
}

/// Closest hits of the lanes of `rays` set in `active` among all triangles of the flat
/// `blas` (ids are its `prim_ids` values; on equal `t` the smallest id wins, as in the
/// single-ray query). Only the triangles of groups whose (padded) box some lane touches
/// are tested.
///
/// # Safety
/// The CPU has AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn closest_flat(blas: &FlatBlas, rays: &RayPacket, active: u8) -> Closest8 {
    closest_flat_in(blas, rays, active)
}

/// [`closest_flat`] compiled for AVX-512VL (the same 256-bit operations; the compiler
/// then has 32 vector registers and mask registers).
///
/// # Safety
/// The CPU has AVX2, FMA, AVX-512F and AVX-512VL.
#[target_feature(enable = "avx2,fma,avx512f,avx512vl")]
pub(crate) unsafe fn closest_flat_avx512(blas: &FlatBlas, rays: &RayPacket, active: u8) -> Closest8 {
    closest_flat_in(blas, rays, active)
}

#[inline(always)]
unsafe fn closest_flat_in(blas: &FlatBlas, rays: &RayPacket, active: u8) -> Closest8 {
    let r = setup(rays, active as u32);
    let lb = LaneBoxes::new(rays);
    let groups = touched_groups(&blas.packet_groups, &lb, r.t_min, cull8(r.t_max), r.act);
    if r.active == 0 || groups == 0 {
        return Closest8 { id: I8([NO_HIT; LANES]), ..Closest8::default() };
    }
    if !blas.packet_verts.is_empty() {
        return match r.uniform {
            Some(k) => closest_flat_table::<true>(blas, &r, k, groups),
            None => closest_flat_table::<false>(blas, &r, [0, 1, 2], groups),
        };
    }
    match r.uniform {
        Some(k) => closest_flat_k::<true>(blas, &r, k, groups),
        None => closest_flat_k::<false>(blas, &r, [0, 1, 2], groups),
    }
}

/// The groups of the flat `blas` set in `groups` (bit `g` = group `g`), in index order.
#[inline(always)]
fn touched<'a>(blas: &'a FlatBlas, groups: u32) -> impl Iterator<Item = &'a FlatGroup> + 'a {
    let mut left = groups;
    std::iter::from_fn(move || {
        if left == 0 {
            return None;
        }
        let g = left.trailing_zeros() as usize;
        left &= left - 1;
        Some(&blas.packet_groups[g])
    })
}

/// The triangles of group `g` of the flat `blas`.
#[inline(always)]
fn group_tris<'a>(blas: &'a FlatBlas, g: &FlatGroup) -> &'a [FlatTri] {
    &blas.packet_tris[g.first as usize..(g.first + g.count) as usize]
}

/// The sheared vertices of a flat mesh's vertex table that a packet needs, indexed as the
/// table (`FlatTri::corners` are byte offsets into it).
struct ShearedVerts([MaybeUninit<[__m256; 3]>; MAX_FLAT_VERTS]);

const _: () = assert!(std::mem::size_of::<[__m256; 3]>() == SHEARED_VERT_BYTES);

impl ShearedVerts {
    /// Shears the vertices of `blas.packet_verts` set in the groups' masks of `groups`.
    #[inline(always)]
    unsafe fn new<const UNIFORM: bool>(blas: &FlatBlas, r: &Regs<'_>, k: [usize; 3], groups: u32) -> Self {
        let mut needed = touched(blas, groups).fold(0u64, |m, g| m | g.verts);
        let mut table = ShearedVerts([MaybeUninit::uninit(); MAX_FLAT_VERTS]);
        while needed != 0 {
            let j = needed.trailing_zeros() as usize;
            needed &= needed - 1;
            table.0[j] = MaybeUninit::new(shear(corner_row::<UNIFORM>(&blas.packet_verts[j], r, k), r));
        }
        table
    }

    /// The vertex at byte offset `offset` (`FlatTri::corners`; one sheared by `new`).
    #[inline(always)]
    unsafe fn at(&self, offset: u16) -> &[__m256; 3] {
        // SAFETY: `new` wrote every vertex of the touched groups' triangles; the offsets
        // are multiples of `SHEARED_VERT_BYTES`, the size of an entry, below the table's.
        unsafe { &*(self.0.as_ptr().byte_add(offset as usize) as *const [__m256; 3]) }
    }
}

/// [`closest_flat`] on a mesh with a vertex table: the needed vertices sheared once
/// ([`ShearedVerts`]), then the triangles of the touched groups read from the table.
#[inline(always)]
unsafe fn closest_flat_table<const UNIFORM: bool>(
    blas: &FlatBlas,
    r: &Regs<'_>,
    k: [usize; 3],
    groups: u32,
) -> Closest8 {
    let sv = ShearedVerts::new::<UNIFORM>(blas, r, k, groups);
    let mut out = Closest8 { id: I8([NO_HIT; LANES]), ..Closest8::default() };
    let mut best = Best8::new(r.t_max);
    for g in touched(blas, groups) {
        let tris = group_tris(blas, g);
        for tri in tris {
            let [a, b, c] = tri.corners.map(|o| sv.at(o));
            closest_sheared::<UNIFORM>(&mut best, &mut out, r, tri, a, b, c);
        }
    }
    best.store(&mut out);
    out
}

#[inline(always)]
unsafe fn closest_flat_k<const UNIFORM: bool>(
    blas: &FlatBlas,
    r: &Regs<'_>,
    k: [usize; 3],
    groups: u32,
) -> Closest8 {
    let mut out = Closest8 { id: I8([NO_HIT; LANES]), ..Closest8::default() };
    let mut best = Best8::new(r.t_max);
    for g in touched(blas, groups) {
        let tris = group_tris(blas, g);
        let mut i = 0;
        while i < tris.len() {
            let tri = &tris[i];
            let a = shear(corner_flat::<UNIFORM>(tri, 0, r, k), r);
            let b = shear(corner_flat::<UNIFORM>(tri, 1, r, k), r);
            let c = shear(corner_flat::<UNIFORM>(tri, 2, r, k), r);
            closest_sheared::<UNIFORM>(&mut best, &mut out, r, tri, &a, &b, &c);
            if tri.pair {
                // The fan pair `(a, c, d)`: one more corner.
                let next = &tris[i + 1];
                let d = shear(corner_flat::<UNIFORM>(next, 2, r, k), r);
                closest_sheared::<UNIFORM>(&mut best, &mut out, r, next, &a, &c, &d);
                i += 1;
            }
            i += 1;
        }
    }
    best.store(&mut out);
    out
}

/// Closest-hit update of `best` with the triangle `tri` (sheared corners `a, b, c`).
#[inline(always)]
unsafe fn closest_sheared<const UNIFORM: bool>(
    best: &mut Best8,
    out: &mut Closest8,
    r: &Regs<'_>,
    tri: &FlatTri,
    a: &[__m256; 3],
    b: &[__m256; 3],
    c: &[__m256; 3],
) {
    let e = edges(a, b, c);
    // Mixed signs: outside (no lane with a zero edge function gets here; see `test8v`).
    let reject = mixed_signs(e);
    // Lanes with a zero edge function (the active ones are checked as a bit mask: the
    // vector `act` need not stay in a register).
    let edge = any_zero(e);
    if UNIFORM
        && _mm256_movemask_ps(_mm256_or_ps(_mm256_andnot_ps(reject, r.act), _mm256_and_ps(r.act, edge))) == 0
    {
        // Uniform permutations are (almost only) coherent packets: skip the division when
        // no lane is inside (see `test_sheared`).
        return;
    }
    let (t, u, v) = hit_distance(e, [a[2], b[2], c[2]]);
    if _mm256_movemask_ps(edge) as u32 & r.active != 0 {
        best.update_scalar(r.rays, r.active, out, &tri.tri(), tri.id);
        return;
    }
    best.update(t, u, v, reject, r.t_min_act, tri.id);
}

/// Lanes of `rays` set in `active` that hit any triangle of the flat `blas` with `t` in
/// `[t_min, t_max]` (bit `i` for lane `i`); only groups whose box some lane touches are
/// tested.
///
/// # Safety
/// The CPU has AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn occluded_flat(blas: &FlatBlas, rays: &RayPacket, active: u8) -> u8 {
    occluded_flat_in(blas, rays, active)
}

/// [`occluded_flat`] compiled for AVX-512VL (as [`closest_flat_avx512`]).
///
/// # Safety
/// The CPU has AVX2, FMA, AVX-512F and AVX-512VL.
#[target_feature(enable = "avx2,fma,avx512f,avx512vl")]
pub(crate) unsafe fn occluded_flat_avx512(blas: &FlatBlas, rays: &RayPacket, active: u8) -> u8 {
    occluded_flat_in(blas, rays, active)
}

#[inline(always)]
unsafe fn occluded_flat_in(blas: &FlatBlas, rays: &RayPacket, active: u8) -> u8 {
    let r = setup(rays, active as u32);
    let lb = LaneBoxes::new(rays);
    let groups = touched_groups(&blas.packet_groups, &lb, r.t_min, cull8(r.t_max), r.act);
    if r.active == 0 || groups == 0 {
        return 0;
    }
    if !blas.packet_verts.is_empty() {
        return (match r.uniform {
            Some(k) => occluded_flat_table::<true>(blas, &r, k, groups),
            None => occluded_flat_table::<false>(blas, &r, [0, 1, 2], groups),
        }) as u8;
    }
    (match r.uniform {
        Some(k) => occluded_flat_k::<true>(blas, r, k, groups),
        None => occluded_flat_k::<false>(blas, r, [0, 1, 2], groups),
    }) as u8
}

/// [`occluded_flat`] on a mesh with a vertex table (as [`closest_flat_table`]).
#[inline(always)]
unsafe fn occluded_flat_table<const UNIFORM: bool>(
    blas: &FlatBlas,
    r: &Regs<'_>,
    k: [usize; 3],
    groups: u32,
) -> u32 {
    let sv = ShearedVerts::new::<UNIFORM>(blas, r, k, groups);
    // Occluded lanes stay in the test (their hits only set bits already set): no
    // per-triangle update of the active lanes, and the inactive ones are masked by
    // `t_min_act`. The packet stops once per group when all lanes are occluded.
    let mut occluded = _mm256_setzero_ps();
    for g in touched(blas, groups) {
        for tri in group_tris(blas, g) {
            let [a, b, c] = tri.corners.map(|o| sv.at(o));
            occluded = _mm256_or_ps(occluded, any_hits(r, tri, a, b, c));
        }
        if _mm256_movemask_ps(occluded) as u32 == r.active {
            break;
        }
    }
    _mm256_movemask_ps(occluded) as u32
}

/// Lanes of `r.active` that hit the triangle `tri` (sheared corners `a, b, c`) with `t`
/// in `[t_min, t_max]`, as [`any_sheared`] for all active lanes.
#[inline(always)]
unsafe fn any_hits(r: &Regs<'_>, tri: &FlatTri, a: &[__m256; 3], b: &[__m256; 3], c: &[__m256; 3]) -> __m256 {
    let e = edges(a, b, c);
    if _mm256_movemask_ps(any_zero(e)) as u32 & r.active != 0 {
        return lane_mask(any_scalar(r.rays, r.active, &tri.tri()));
    }
    // Mixed signs: outside (no lane with a zero edge function gets here; see `test8v`).
    let reject = mixed_signs(e);
    let (t, _, _) = hit_distance(e, [a[2], b[2], c[2]]);
    let in_range =
        _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(t, r.t_min_act), _mm256_cmp_ps::<_CMP_LE_OQ>(t, r.t_max));
    _mm256_andnot_ps(reject, in_range)
}

#[inline(always)]
unsafe fn occluded_flat_k<const UNIFORM: bool>(
    blas: &FlatBlas,
    r: Regs<'_>,
    k: [usize; 3],
    groups: u32,
) -> u32 {
    // Branch-free per triangle (a lane's hit is found at an unpredictable triangle: a
    // branch on it mispredicted about once per lane); lanes that hit leave `act`, and
    // the packet stops once per group when all have.
    let mut act = r.act;
    let mut occluded = _mm256_setzero_ps();
    for g in touched(blas, groups) {
        let tris = group_tris(blas, g);
        let mut i = 0;
        while i < tris.len() {
            let tri = &tris[i];
            let a = shear(corner_flat::<UNIFORM>(tri, 0, &r, k), &r);
            let b = shear(corner_flat::<UNIFORM>(tri, 1, &r, k), &r);
            let c = shear(corner_flat::<UNIFORM>(tri, 2, &r, k), &r);
            let hit = any_sheared(&r, tri, &a, &b, &c, act);
            occluded = _mm256_or_ps(occluded, hit);
            act = _mm256_andnot_ps(hit, act);
            if tri.pair {
                // The fan pair `(a, c, d)`: one more corner.
                let next = &tris[i + 1];
                let d = shear(corner_flat::<UNIFORM>(next, 2, &r, k), &r);
                let hit = any_sheared(&r, next, &a, &c, &d, act);
                occluded = _mm256_or_ps(occluded, hit);
                act = _mm256_andnot_ps(hit, act);
                i += 1;
            }
            i += 1;
        }
        if _mm256_movemask_ps(act) == 0 {
            break;
        }
    }
    _mm256_movemask_ps(occluded) as u32
}

/// Lanes of `act` that hit the triangle `tri` (sheared corners `a, b, c`) with `t` in
/// `[t_min, t_max]`.
#[inline(always)]
unsafe fn any_sheared(
    r: &Regs<'_>,
    tri: &FlatTri,
    a: &[__m256; 3],
    b: &[__m256; 3],
    c: &[__m256; 3],
    act: __m256,
) -> __m256 {
    let Some((edge, reject, t, _, _)) = test_sheared::<false>(a, b, c, act) else {
        return _mm256_setzero_ps();
    };
    if _mm256_movemask_ps(edge) != 0 {
        return lane_mask(any_scalar(r.rays, _mm256_movemask_ps(act) as u32, &tri.tri()));
    }
    let in_range =
        _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(t, r.t_min), _mm256_cmp_ps::<_CMP_LE_OQ>(t, r.t_max));
    _mm256_and_ps(_mm256_andnot_ps(reject, in_range), act)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::{incoherent_rays, packets_of, shadow_rays, surface_rays};
    use crate::SceneAccel;

    /// The AVX-512VL builds of the flat kernels give the AVX2 builds' answers bit for bit
    /// (on CPUs with both; the integration tests compare whichever `SceneAccel` runs with
    /// single rays, so this covers the other one).
    #[test]
    fn flat_kernels_agree_across_builds() {
        if !filtrace_core::cpu::isa().has_avx512() {
            return;
        }
        let cornell = filtrace_scene::builtin("cornell").expect("cornell");
        let mut cube = filtrace_scene::Scene::default();
        cube.add_mesh(crate::testmesh::subdivided_cube(6));
        let big_flat = crate::BuildParams { max_flat_triangles: usize::MAX, ..Default::default() };
        // The Cornell box (vertex table) and a flat mesh of 432 triangles (no table).
        for (scene, params, table) in [(&cornell, Default::default(), true), (&cube, big_flat, false)] {
            flat_kernels_agree(scene, &params, table);
        }
    }

    fn flat_kernels_agree(scene: &filtrace_scene::Scene, params: &crate::BuildParams, table: bool) {
        let accel = SceneAccel::build_with(scene, params);
        let crate::blas::Blas::Flat(blas) = accel.object_blas(accel.single.expect("one object")) else {
            panic!("a flat bottom level expected");
        };
        assert!(blas.packet_verts.is_empty() != table);
        let (bounce, shadow) = surface_rays(scene, &accel, 4096, 3);
        let mut rays = incoherent_rays(scene, 4096, 5);
        rays.extend(shadow_rays(scene, 4096, 5));
        rays.extend(bounce);
        rays.extend(shadow);
        let mut hits = 0;
        for (i, (p, _)) in packets_of(&rays).iter().enumerate() {
            let active = [0xff, 0x7f, 0b1010_0101, 0b11][i % 4];
            // SAFETY: the caller detected the features.
            let (a, b) = unsafe { (closest_flat(blas, p, active), closest_flat_avx512(blas, p, active)) };
            let bits = |c: &Closest8| {
                (c.t.0.map(f32::to_bits), c.u.0.map(f32::to_bits), c.v.0.map(f32::to_bits), c.id.0)
            };
            assert_eq!(bits(&a), bits(&b), "packet {i}");
            hits += a.id.0.iter().filter(|&&id| id != NO_HIT).count();
            // SAFETY: as above.
            let (a, b) = unsafe { (occluded_flat(blas, p, active), occluded_flat_avx512(blas, p, active)) };
            assert_eq!(a, b, "packet {i}");
        }
        assert!(hits > rays.len() / 4, "{hits} hits of {} rays", rays.len());
    }
}
