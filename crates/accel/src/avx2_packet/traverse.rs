//! The packet traversal of 8-wide BVHs (8 rays x 1 child box per instruction, leaves 8
//! rays x 1 triangle), one loop for the coherent kernels ([`closest_bvh`],
//! [`occluded_bvh`]) and the hybrid one (`hybrid`), whose lanes may leave the packet
//! ([`PerLane`]).

use super::boxes::{cull8, direction_spread, Boxes8, ChildBoxes, MAX_SPREAD};
use super::lanes::{lane_mask, setup, Best8, Closest8, Regs, F8, I8, NO_HIT};
use super::tri::{any_scalar, corner_packet, test_tri};
use crate::ray_packet::{RayPacket, LANES};
use crate::sah::MAX_DEPTH;
use crate::tri4::TriPackets;
use crate::wide::Node8;
use std::arch::x86_64::*;
use std::mem::MaybeUninit;

/// Packet traversal stack depth: each 8-wide level pushes at most seven entries.
pub(super) const STACK8: usize = 7 * MAX_DEPTH + 8;

/// A pending subtree of the packet traversal and the lanes that entered it.
#[derive(Clone, Copy)]
pub(super) struct PacketEntry {
    pub child: u32,
    pub count: u32,
    pub lanes: u32,
    /// Entry distance of the lowest of those lanes (the visit order).
    pub t: f32,
}

/// Pushes the children of `node` that some lane of `lanes` touches onto `stack` (the
/// farthest deepest when `ORDERED`, by the entry distance of each child's lowest lane) and
/// returns the one to visit next.
#[inline(always)]
pub(super) unsafe fn expand<const ORDERED: bool, B: ChildBoxes>(
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

/// Where a packet traversal lets its lanes go on one by one: below `min_lanes` lanes per
/// subtree and at leaves whose lanes differ in their watertight permutation. The hybrid
/// traversal runs the single-ray kernel per lane there (`hybrid::Alone`); the coherent
/// kernels never get there ([`Together`]).
pub(super) trait PerLane {
    /// Each lane of `e` traverses the subtree `e` alone, from its closest hit in `out`.
    fn closest(&mut self, e: &PacketEntry, out: &mut Closest8);
    /// The lanes of `e` whose traversal of the subtree `e` alone hits something.
    fn occluded(&mut self, e: &PacketEntry) -> u32;
}

/// The coherent kernels' [`PerLane`]: their packets share one permutation and take no
/// lane count (`min_lanes` 0), so they never split.
pub(super) struct Together;

impl PerLane for Together {
    #[inline(always)]
    fn closest(&mut self, _: &PacketEntry, _: &mut Closest8) {
        debug_assert!(false, "a coherent packet split");
    }

    #[inline(always)]
    fn occluded(&mut self, _: &PacketEntry) -> u32 {
        debug_assert!(false, "a coherent packet split");
        0
    }
}

/// Closest hits of the lanes `r` in the 8-wide BVH `nodes`/`tris`: one traversal for the
/// packet while at least `min_lanes` lanes share a subtree, `per_lane` below that and at
/// leaves of mixed permutations. `EARLY`: as in `tri::test_sheared`.
///
/// Per lane the answer is that of the single-ray traversal: every lane tests every box
/// with its own distances (`avx2::box8`'s arithmetic) and keeps, among the triangles it
/// tests, the smallest `(t, id)`; boxes are culled only beyond its own closest hit
/// (`cull_bound`), so the visit order does not change the result.
#[inline(always)]
pub(super) unsafe fn closest_packet<B: ChildBoxes, P: PerLane, const EARLY: bool>(
    nodes: &[Node8],
    tris: &TriPackets,
    r: &Regs<'_>,
    b: &B,
    per_lane: &mut P,
    min_lanes: u32,
) -> Closest8 {
    let mut best = Best8::new(r.t_max);
    let mut out = Closest8 { id: I8([NO_HIT; LANES]), ..Closest8::default() };
    if r.active == 0 || nodes.is_empty() {
        return out;
    }
    // Uninitialised: zeroing its 6.4 KB per query cost D1 write misses (packet_two_level.rs).
    let mut stack = [MaybeUninit::<PacketEntry>::uninit(); STACK8];
    let mut sp = 0usize;
    let mut cur = PacketEntry { child: 0, count: 0, lanes: r.active, t: 0.0 };
    loop {
        match r.uniform {
            _ if cur.lanes.count_ones() < min_lanes => {
                best.store(&mut out);
                per_lane.closest(&cur, &mut out);
                best = Best8::load(&out);
            }
            _ if cur.count == 0 => {
                let node = &nodes[cur.child as usize];
                if let Some(next) =
                    expand::<true, _>(node, b, r.t_min, cull8(best.t), cur.lanes, &mut stack, &mut sp)
                {
                    cur = next;
                    continue;
                }
            }
            Some(k) => closest_leaf::<EARLY>(tris, r, k, &cur, &mut best, &mut out),
            None => {
                best.store(&mut out);
                per_lane.closest(&cur, &mut out);
                best = Best8::load(&out);
            }
        }
        // Next pending subtree (its box tests cull the lanes that found closer hits).
        if sp == 0 {
            best.store(&mut out);
            return out;
        }
        sp -= 1;
        // SAFETY: entries below `sp` were written by `expand` before `sp` was raised past them.
        cur = stack[sp].assume_init();
    }
}

/// Lanes of `r` that hit any triangle of the 8-wide BVH `nodes`/`tris` with `t` in
/// `[t_min, t_max]`: as [`closest_packet`], lanes leaving the packet as soon as they hit.
#[inline(always)]
pub(super) unsafe fn occluded_packet<B: ChildBoxes, P: PerLane>(
    nodes: &[Node8],
    tris: &TriPackets,
    r: &Regs<'_>,
    b: &B,
    per_lane: &mut P,
    min_lanes: u32,
) -> u8 {
    if r.active == 0 || nodes.is_empty() {
        return 0;
    }
    // Uninitialised, as in `closest_packet`.
    let mut stack = [MaybeUninit::<PacketEntry>::uninit(); STACK8];
    let mut sp = 0usize;
    let t_cull = cull8(r.t_max);
    let mut left = r.active;
    let mut cur = PacketEntry { child: 0, count: 0, lanes: r.active, t: 0.0 };
    loop {
        match r.uniform {
            _ if cur.lanes.count_ones() < min_lanes => left &= !per_lane.occluded(&cur),
            _ if cur.count == 0 => {
                let node = &nodes[cur.child as usize];
                if let Some(next) =
                    expand::<false, _>(node, b, r.t_min, t_cull, cur.lanes, &mut stack, &mut sp)
                {
                    cur = next;
                    continue;
                }
            }
            Some(k) => left &= !occluded_leaf(tris, r, k, &cur),
            None => left &= !per_lane.occluded(&cur),
        }
        if left == 0 {
            return r.active as u8;
        }
        loop {
            if sp == 0 {
                return (r.active & !left) as u8;
            }
            sp -= 1;
            // SAFETY: as in `closest_packet`.
            cur = stack[sp].assume_init();
            cur.lanes &= left;
            if cur.lanes != 0 {
                break;
            }
        }
    }
}

/// Closest hits of the lanes of `rays` set in `active` in the 8-wide BVH of `blas`, with
/// one traversal for the whole packet ([`closest_packet`]): `None` (nothing done) unless
/// the active lanes share their direction signs and watertight permutation and their
/// directions lie within [`MAX_SPREAD`], as coherent packets do.
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
    let (r, b) = coherent(nodes, rays, active)?;
    Some(closest_packet::<_, _, true>(nodes, tris, &r, &b, &mut Together, 0))
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
    let (r, b) = coherent(nodes, rays, active)?;
    Some(occluded_packet(nodes, tris, &r, &b, &mut Together, 0))
}

/// The registers and boxes of the lanes of `rays` set in `active` when they are coherent
/// enough for one traversal of `nodes` (the criterion of [`closest_bvh`]), else `None`.
#[inline(always)]
unsafe fn coherent<'a>(nodes: &[Node8], rays: &'a RayPacket, active: u8) -> Option<(Regs<'a>, Boxes8)> {
    // Direction signs first: the cheapest test of coherence.
    let b = Boxes8::new(rays, active as u32)?;
    if direction_spread(rays, active as u32) > MAX_SPREAD {
        return None;
    }
    let r = setup(rays, active as u32);
    if r.active != 0 && !nodes.is_empty() {
        r.uniform?;
    }
    Some((r, b))
}

/// The leaf `cur` of a packet traversal (its triangle ids `cur.child..+cur.count` packets)
/// against the lanes `cur.lanes`, all of permutation `k`, updating the closest hits `best`
/// (`out`: scratch for the scalar edge fallback). `EARLY`: as in `tri::test_sheared`.
#[inline(always)]
pub(super) unsafe fn closest_leaf<const EARLY: bool>(
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
pub(super) unsafe fn occluded_leaf(tris: &TriPackets, r: &Regs<'_>, k: [usize; 3], cur: &PacketEntry) -> u32 {
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
