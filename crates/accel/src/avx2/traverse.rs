//! The single-ray traversal loop over 8-wide nodes, one body for every node layout
//! ([`Node8Layout`]: [`crate::wide::Node8`] and the compressed `qwide::QNode8`), and the
//! closest-hit and any-hit queries of a bottom level built on it.

use super::boxes::{Node8Layout, RayBoxes8};
use super::leaves::{AnyPairs, ClosestPairs};
use super::order::push_sorted8;
use super::tri8::Ray8;
use super::Lanes8;
use crate::sah::MAX_DEPTH;
use crate::tri4::TriPackets;
use crate::triangle::WatertightRay;
use crate::wide::{cull_bound, prefetch, push_children, Entry, Leaves};
use filtrace_core::Vec3;
use std::arch::x86_64::*;
use std::mem::MaybeUninit;

/// Traversal stack depth: each 8-wide level pushes at most seven entries.
pub(super) const STACK8: usize = 7 * MAX_DEPTH + 8;

/// Closest hit `(t, u, v, prim)` of the bottom level `nodes` over `tris` with `t` in
/// `[t_min, *t_max]`, shortening `*t_max`. Safety: the CPU has AVX2 and FMA
/// (`Simd::Avx2.available()`).
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) unsafe fn intersect8<N: Node8Layout>(
    nodes: &[N],
    tris: &TriPackets,
    o: Vec3,
    d: Vec3,
    t_min: f32,
    t_max: &mut f32,
) -> Option<(f32, f32, f32, u32)> {
    let wr = WatertightRay::new(o, d);
    let mut leaves = ClosestPairs {
        packets: &tris.packets,
        prim_ids: &tris.prim_ids,
        ray: Ray8::new(&wr, t_min),
        best: None,
    };
    let rb = RayBoxes8::new(o, d);
    traverse8::<N, _, true>(nodes, &rb, t_min, t_max, &mut leaves);
    leaves.best.map(|(t, u, v, i)| (t, u, v, tris.prim_ids[i]))
}

/// Whether the bottom level `nodes` over `tris` holds a hit with `t` in `[t_min, t_max]`.
/// Safety: as [`intersect8`].
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) unsafe fn occluded8<N: Node8Layout>(
    nodes: &[N],
    tris: &TriPackets,
    o: Vec3,
    d: Vec3,
    t_min: f32,
    t_max: f32,
) -> bool {
    let wr = WatertightRay::new(o, d);
    let mut t_max = t_max;
    let leaves = AnyPairs { packets: &tris.packets, ray: Ray8::new(&wr, t_min) };
    let rb = RayBoxes8::new(o, d);
    traverse8::<N, _, false>(nodes, &rb, t_min, &mut t_max, leaves)
}

/// Visits every leaf of the 8-wide BVH `nodes` whose box the ray `[t_min, *t_max]`
/// touches, as [`crate::wide::traverse`] does for four-wide nodes: near-first for
/// closest hits (`ORDERED`), from the last slot down for any hits (the build-time order
/// of [`crate::child_order`]); returns `true` when a visit asked to stop.
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn traverse8<N: Node8Layout, L: Leaves, const ORDERED: bool>(
    nodes: &[N],
    r: &RayBoxes8,
    t_min: f32,
    t_max: &mut f32,
    leaves: L,
) -> bool {
    let root = Entry { child: 0, count: 0, t: t_min };
    // SAFETY: AVX2 and FMA (this function's target features).
    unsafe { traversal8::<N, L, ORDERED>(nodes, root, r, t_min, t_max, leaves) }
}

/// [`traverse8`] of the subtree `start` only (a node, or a leaf range, that the caller
/// found the ray to touch): the single-ray half of the hybrid packet traversal
/// (`avx2_packet::hybrid`).
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn traverse8_from<N: Node8Layout, L: Leaves, const ORDERED: bool>(
    nodes: &[N],
    start: Entry,
    r: &RayBoxes8,
    t_min: f32,
    t_max: &mut f32,
    leaves: L,
) -> bool {
    // SAFETY: AVX2 and FMA (this function's target features).
    unsafe { traversal8::<N, L, ORDERED>(nodes, start, r, t_min, t_max, leaves) }
}

/// The loop of [`traverse8`] and [`traverse8_from`], inlined into each: as one function
/// called from both, it was no longer inlined into `traverse8`, and incoherent any hits
/// lost 7-9 % on the bunny (stop 16). Safety: the caller runs with AVX2 and FMA.
#[inline(always)]
unsafe fn traversal8<N: Node8Layout, L: Leaves, const ORDERED: bool>(
    nodes: &[N],
    start: Entry,
    r: &RayBoxes8,
    t_min: f32,
    t_max: &mut f32,
    mut leaves: L,
) -> bool {
    if nodes.is_empty() {
        return false;
    }
    let t_min8 = _mm256_set1_ps(t_min);
    let mut stack = [MaybeUninit::<Entry>::uninit(); STACK8];
    let mut sp = 0usize;
    let mut cur = start;
    let mut t_near = Lanes8([0.0; 8]);
    // The cull bound of `t_max`, which only a closest-hit leaf visit shortens (any hits
    // never do; a stale bound would only keep more boxes).
    let mut cull = cull_bound(*t_max);
    let mut cull8 = _mm256_set1_ps(cull);
    loop {
        if cur.count == 0 {
            debug_assert!((cur.child as usize) < nodes.len());
            // SAFETY: child indices of a built tree are in range (`wide::validate`,
            // `qwide::validate`).
            let node = unsafe { nodes.get_unchecked(cur.child as usize) };
            // SAFETY: this function runs with AVX2 (its target features).
            let (mask, tn) = unsafe { node.boxes(r, t_min8, cull8) };
            if mask != 0 {
                // Any hits keep no distances, as Embree's occlusion stack (see the pop).
                if ORDERED {
                    // SAFETY: `Lanes8` is 32-byte aligned.
                    unsafe { _mm256_store_ps(t_near.0.as_mut_ptr(), tn) };
                }
                let e = |i: usize| node.entry(i, if ORDERED { t_near.0[i] } else { 0.0 });
                prefetch_children(nodes, node, mask, &leaves);
                cur = if ORDERED && three_or_more(mask) {
                    // SAFETY: AVX2 (this function's target features); at most 8 entries
                    // are pushed and `STACK8` leaves room for 7 per level.
                    unsafe { push_sorted8(mask, tn, node, &mut stack, &mut sp) }
                } else {
                    push_children::<ORDERED>(mask, e, &mut stack, &mut sp)
                };
                continue;
            }
        } else if ORDERED {
            // Closest hits: the leaf test out of line (see `visit_leaf`).
            // SAFETY: AVX2 (this function's target features).
            unsafe {
                std::hint::black_box(visit_leaf::<L> as VisitLeaf<L>)(
                    &mut leaves,
                    cur.child,
                    cur.count,
                    t_max,
                )
            };
            cull = cull_bound(*t_max);
            cull8 = _mm256_set1_ps(cull);
        } else if leaves.visit(cur.child, cur.count, t_max) {
            return true;
        }
        // Pop the nearest pending entry that can still hold a closer hit.
        loop {
            if sp == 0 {
                return false;
            }
            sp -= 1;
            // SAFETY: entries below `sp` were written before `sp` was raised past them
            // (and `sp < STACK8`).
            let e = unsafe { stack.get_unchecked(sp).assume_init() };
            // Any hits: no distance test. `t_max` never shrinks; a box kept only by the
            // far-distance widening holds no hit in range, so the answer is the same.
            if !ORDERED || e.t <= cull {
                cur = e;
                break;
            }
        }
    }
}

/// Whether `mask` has three or more bits set, without `count_ones` (a multiply chain
/// where the `popcnt` feature is not enabled).
#[inline(always)]
fn three_or_more(mask: u32) -> bool {
    let rest = mask & mask.wrapping_sub(1);
    rest & rest.wrapping_sub(1) != 0
}

/// Starts fetching every child in `mask` while the order is worked out, without a branch
/// on node or leaf (it was mispredicted near the leaves): the `N::LINES` lines of a node,
/// or the up to 6 lines of a two-packet leaf from the line holding its first byte (a
/// four-line node gets its first two lines again, a two-line node its lines three times).
/// The `LINES` test is resolved at compile time; the four-line form is the one `Node8`
/// had before the layouts shared this loop (one add fewer per child than the general one).
#[inline(always)]
fn prefetch_children<N: Node8Layout, L: Leaves>(nodes: &[N], node: &N, mask: u32, leaves: &L) {
    let mut bits = mask;
    while bits != 0 {
        let i = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        let (c, n) = node.child(i);
        let inner = nodes.as_ptr().wrapping_add(c as usize) as usize;
        let leaf = leaves.leaf_addr(c) & !63;
        let p = if n == 0 { inner } else { leaf };
        let rest = if n == 0 { p } else { p + 256 };
        if N::LINES == 4 {
            prefetch(p as *const u8, 4);
        } else {
            let second = if n == 0 { p } else { p + 128 };
            prefetch(p as *const u8, 2);
            prefetch(second as *const u8, 2);
        }
        prefetch(rest as *const u8, 2);
    }
}

/// `leaves.visit(first, count, t_max)` out of line, for closest hits: the traversal loop
/// then keeps its ray constants in registers (the triangle test needs most of the 16
/// vector registers). Bunny, 1 thread: primary rays +3 %, incoherent closest hits even;
/// any-hit queries stay inline (a call per leaf cost them 9 %). Called through a
/// `black_box`ed pointer: `#[inline(never)]` on a `#[target_feature]` function was
/// ignored (rustc 1.95), and the function was inlined all the same.
#[target_feature(enable = "avx2,fma")]
#[inline(never)]
fn visit_leaf<L: Leaves>(leaves: &mut L, first: u32, count: u32, t_max: &mut f32) -> bool {
    leaves.visit(first, count, t_max)
}

type VisitLeaf<L> = unsafe fn(&mut L, u32, u32, &mut f32) -> bool;

#[cfg(test)]
mod tests {
    use super::three_or_more;

    #[test]
    fn three_or_more_is_a_count_of_at_least_three() {
        for mask in 0..=u16::MAX as u32 {
            assert_eq!(three_or_more(mask), mask.count_ones() >= 3, "{mask:#b}");
        }
    }
}
