//! Closest-hit and any-hit traversal of compressed 8-wide nodes ([`QNode8`]) with AVX2.
//!
//! Each plane of the slab test first decodes its eight grid values to floats, one
//! `vpmovzxbd` (8 bytes to 8 integers), one `vcvtdq2ps` and one fused multiply-add
//! `q s + o` (the exact [`crate::qwide::decode`] the quantisation checked), then takes the
//! fused slab distance of the uncompressed test (`avx2::RayBoxes8`, conservative as
//! Ize 2013). The decoded boxes contain the exact ones, so the test culls no box the
//! uncompressed one keeps; the leaves are the uncompressed tree's, tested by the same
//! kernels (`avx2::ClosestPairs`, `avx2::AnyPairs`), so hits are bit-identical.
//!
//! Every function here needs AVX2 and FMA (see `avx2.rs` for the inlining scheme).

use crate::avx2::{push_sorted8, AnyPairs, Children8, ClosestPairs, Ray8, RayBoxes8};
use crate::qwide::{QBvh8, QNode8};
use crate::sah::MAX_DEPTH;
use crate::triangle::WatertightRay;
use crate::wide::{cull_bound, prefetch, push_children, Entry, Leaves, FAR_SCALE};
use filtrace_core::Vec3;
use std::arch::x86_64::*;
use std::mem::MaybeUninit;

/// The eight decoded bounds of grid row `row` (byte offset `8 row`, as the float row
/// offsets of [`RayBoxes8`] for the 8-float rows of `Node8`) on axis `k`.
#[inline(always)]
unsafe fn plane(n: &QNode8, offset: usize, k: usize) -> __m256 {
    // SAFETY: `offset = 8 row`, `row < 6`: the eight bytes lie inside `q`.
    let q = unsafe { _mm_loadl_epi64(n.q.as_ptr().cast::<u8>().add(offset) as *const __m128i) };
    let q = _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(q));
    _mm256_fmadd_ps(q, _mm256_set1_ps(n.scale[k]), _mm256_set1_ps(n.origin[k]))
}

/// Slab test of a ray against the eight decoded child boxes of `n`: hit mask (bit `i` for
/// child `i`, unused slots never set) and entry distances. The operations after decoding
/// are those of `avx2::box8`.
#[inline(always)]
pub(crate) unsafe fn qbox8(n: &QNode8, r: &RayBoxes8, t_min: __m256, t_max: f32) -> (u32, __m256) {
    // SAFETY: AVX2 and FMA (the caller's target features); row offsets are below 48.
    // (Written out: a closure would not inherit the target features.)
    let (nx, fx, ny, fy, nz, fz) = unsafe {
        (
            _mm256_fmsub_ps(plane(n, r.near[0], 0), r.inv[0], r.oinv_near[0]),
            _mm256_fmsub_ps(plane(n, r.far[0], 0), r.inv[0], r.oinv_far[0]),
            _mm256_fmsub_ps(plane(n, r.near[1], 1), r.inv[1], r.oinv_near[1]),
            _mm256_fmsub_ps(plane(n, r.far[1], 1), r.inv[1], r.oinv_far[1]),
            _mm256_fmsub_ps(plane(n, r.near[2], 2), r.inv[2], r.oinv_near[2]),
            _mm256_fmsub_ps(plane(n, r.far[2], 2), r.inv[2], r.oinv_far[2]),
        )
    };
    let t_near = _mm256_max_ps(nz, _mm256_max_ps(ny, _mm256_max_ps(nx, t_min)));
    let t_far = _mm256_min_ps(fz, _mm256_min_ps(fy, _mm256_min_ps(fx, _mm256_set1_ps(cull_bound(t_max)))));
    let t_far = _mm256_mul_ps(t_far, _mm256_set1_ps(FAR_SCALE));
    let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t_near, t_far)) as u32;
    (mask & n.valid, t_near)
}

impl Children8 for QNode8 {
    #[inline(always)]
    fn entry(&self, i: usize, t: f32) -> Entry {
        Entry { child: self.child[i], count: self.count[i] as u32, t }
    }
}

/// Eight 32-byte aligned floats.
#[repr(C, align(32))]
struct Lanes8([f32; 8]);

/// Traversal stack depth: each 8-wide level pushes at most seven entries.
const STACK8: usize = 7 * MAX_DEPTH + 8;

/// Visits every leaf whose decoded box the ray `[t_min, *t_max]` touches, as
/// `avx2::traverse8` does for uncompressed nodes: near-first for closest hits (`ORDERED`),
/// from the last slot down for any hits; returns `true` when a visit asked to stop.
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn traverse_q8<L: Leaves, const ORDERED: bool>(
    nodes: &[QNode8],
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
    let mut cur = Entry { child: 0, count: 0, t: t_min };
    let mut t_near = Lanes8([0.0; 8]);
    loop {
        if cur.count == 0 {
            debug_assert!((cur.child as usize) < nodes.len());
            // SAFETY: child indices of a built tree are in range (`qwide::validate`).
            let node = unsafe { nodes.get_unchecked(cur.child as usize) };
            // SAFETY: this function runs with AVX2 and FMA.
            let (mask, tn) = unsafe { qbox8(node, r, t_min8, *t_max) };
            if mask != 0 {
                // SAFETY: `Lanes8` is 32-byte aligned.
                unsafe { _mm256_store_ps(t_near.0.as_mut_ptr(), tn) };
                let e = |i: usize| node.entry(i, t_near.0[i]);
                // Fetch every child to be visited, without a branch on node or leaf (as
                // `traverse8`): the two lines of a node, or the up to six lines of a
                // two-packet leaf.
                let mut bits = mask;
                while bits != 0 {
                    let i = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    let (c, n) = (node.child[i], node.count[i]);
                    let inner = nodes.as_ptr().wrapping_add(c as usize) as usize;
                    let leaf = leaves.leaf_addr(c) & !63;
                    let p = if n == 0 { inner } else { leaf };
                    let rest = if n == 0 { p } else { p + 256 };
                    let second = if n == 0 { p } else { p + 128 };
                    prefetch(p as *const u8, 2);
                    prefetch(second as *const u8, 2);
                    prefetch(rest as *const u8, 2);
                }
                // Closest hits: three or more children by the sorting network of `traverse8`.
                cur = if ORDERED && mask.count_ones() >= 3 {
                    // SAFETY: AVX2; at most 8 entries pushed, `STACK8` has room.
                    unsafe { push_sorted8(mask, tn, node, &mut stack, &mut sp) }
                } else {
                    push_children::<ORDERED>(mask, e, &mut stack, &mut sp)
                };
                continue;
            }
        } else if ORDERED {
            // Closest hits: the leaf test out of line (as `traverse8`).
            // SAFETY: AVX2 (this function's target features).
            unsafe {
                std::hint::black_box(visit_leaf::<L> as VisitLeaf<L>)(
                    &mut leaves,
                    cur.child,
                    cur.count,
                    t_max,
                )
            };
        } else if leaves.visit(cur.child, cur.count, t_max) {
            return true;
        }
        // Pop the nearest pending entry that can still hold a closer hit.
        loop {
            if sp == 0 {
                return false;
            }
            sp -= 1;
            // SAFETY: entries below `sp` were written before `sp` was raised past them.
            let e = unsafe { stack.get_unchecked(sp).assume_init() };
            if e.t <= cull_bound(*t_max) {
                cur = e;
                break;
            }
        }
    }
}

/// `leaves.visit` out of line for closest hits (see `avx2::visit_leaf`).
#[target_feature(enable = "avx2,fma")]
#[inline(never)]
fn visit_leaf<L: Leaves>(leaves: &mut L, first: u32, count: u32, t_max: &mut f32) -> bool {
    leaves.visit(first, count, t_max)
}

type VisitLeaf<L> = unsafe fn(&mut L, u32, u32, &mut f32) -> bool;

impl QBvh8 {
    /// Closest hit `(t, u, v, prim)` with `t` in `[t_min, *t_max]`, shortening `*t_max`.
    /// Safety: the CPU has AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(crate) unsafe fn intersect8(
        &self,
        o: Vec3,
        d: Vec3,
        t_min: f32,
        t_max: &mut f32,
    ) -> Option<(f32, f32, f32, u32)> {
        let wr = WatertightRay::new(o, d);
        let mut leaves = ClosestPairs {
            packets: &self.tris.packets,
            prim_ids: &self.tris.prim_ids,
            ray: Ray8::new(&wr, t_min),
            best: None,
        };
        let rb = RayBoxes8::new(o, d);
        traverse_q8::<_, true>(&self.nodes, &rb, t_min, t_max, &mut leaves);
        leaves.best.map(|(t, u, v, i)| (t, u, v, self.tris.prim_ids[i]))
    }

    /// Whether anything is hit with `t` in `[t_min, t_max]`. Safety: AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(crate) unsafe fn occluded8(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> bool {
        let wr = WatertightRay::new(o, d);
        let mut t_max = t_max;
        let leaves = AnyPairs { packets: &self.tris.packets, ray: Ray8::new(&wr, t_min) };
        let rb = RayBoxes8::new(o, d);
        traverse_q8::<_, false>(&self.nodes, &rb, t_min, &mut t_max, leaves)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::avx2::box8;
    use crate::testmesh::SplitMix64;
    use crate::wide::Node8;
    use filtrace_core::Aabb;

    /// The compressed test keeps every box the uncompressed test keeps (its boxes contain
    /// the exact ones), on rays grazing random boxes: origins on faces, directions aimed at
    /// corners or with zero components.
    #[test]
    fn compressed_box_test_keeps_every_box_the_exact_test_keeps() {
        if !filtrace_core::cpu::isa().has_avx2() {
            println!("SKIPPED: no AVX2 on this CPU");
            return;
        }
        let mut rng = SplitMix64(5);
        let mut rnd = move || rng.next_f32();
        let (mut kept, mut extra) = (0, 0);
        for k in 0..50_000 {
            let scale = [1e-3f32, 1.0, 1e3][k % 3];
            let mut node = Node8::EMPTY;
            for slot in 0..(1 + k % 8) {
                let lo = Vec3::new(rnd(), rnd(), rnd()) * scale * 10.0;
                let hi = lo + Vec3::new(rnd(), rnd(), rnd()) * scale * if k % 11 == 0 { 0.0 } else { 1.0 };
                node.set_child_box(slot, &Aabb::new(lo, hi));
            }
            let target = node.child_box(k % (1 + k % 8));
            let corner =
                Vec3::select(glam::BVec3::new(rnd() < 0.5, rnd() < 0.5, rnd() < 0.5), target.min, target.max);
            let mut o = Vec3::new(rnd(), rnd(), rnd()) * scale * 12.0 - scale;
            if k % 4 == 0 {
                o[k % 3] = corner[k % 3];
            }
            let mut d = if k % 2 == 0 { corner - o } else { Vec3::new(rnd(), rnd(), rnd()) - 0.5 };
            if k % 5 == 0 {
                d[(k / 5) % 3] = 0.0;
            }
            if d == Vec3::ZERO {
                continue;
            }
            let t_max = if k % 7 == 0 { 1.0 } else { f32::INFINITY };
            let q = QNode8::compress(&node).unwrap();
            // SAFETY: checked `has_avx2()` above.
            let (exact, coarse) = unsafe {
                let r = RayBoxes8::new(o, d);
                (box8(&node, &r, _mm256_setzero_ps(), t_max).0, qbox8(&q, &r, _mm256_setzero_ps(), t_max).0)
            };
            assert_eq!(exact & !coarse, 0, "culled a box the exact test keeps: o {o} d {d} node {node:?}");
            assert_eq!(coarse & !q.valid, 0, "unused slots never hit");
            kept += exact.count_ones();
            extra += (coarse & !exact).count_ones();
        }
        assert!(kept > 20_000 && extra < kept, "{kept} {extra}");
    }
}
