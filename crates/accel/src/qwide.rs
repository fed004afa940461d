//! Compressed eight-wide BVH nodes: the child boxes of a [`Node8`] stored as 8-bit
//! offsets in a grid spanned by the node's own box, half the bytes per node (128 instead
//! of 256: two cache lines instead of four).
//!
//! Each axis `k` of a node has an origin `o_k` (the minimum of its children's boxes) and a
//! power-of-two step `s_k` (the smallest one with `255 s_k` at least the node's extent);
//! a child's bound is the grid value `fma(q, s_k, o_k)` of an integer `q` in `0..=255`,
//! rounded down for minima and up for maxima, so every stored box contains the exact one
//! (Mahovsky and Wyvill, "Memory-conserving bounding volume hierarchies with coherent
//! raytracing", 2006; Ylitie, Karras and Laine, "Efficient incoherent ray traversal on
//! GPUs through compressed wide BVHs", HPG 2017, sec. 3.1, which also takes power-of-two
//! steps; Embree's quantised BVH8 nodes). `q s_k` is exact (a power of two times an
//! integer below 256), so the decoded bound is `o_k + q s_k` rounded once; rounding is
//! monotone, so a grid value whose exact sum lies beyond the exact bound rounds beyond it
//! too. The quantisation still checks every decoded bound with the same `fma` the
//! traversal evaluates (`qwide_avx2::qbox8`).
//!
//! The tree is the collapsed SAH tree of `blas::WideBvh<8>` node for node, with
//! its slot order (any-hit odds, [`crate::child_order`]) and its triangle packets, so the
//! leaf tests and their results are those of the uncompressed tree; only boxes are looser,
//! which can cost extra node visits and leaf tests, never a hit. Chosen per bottom level by
//! [`crate::BuildParams::min_quantized_triangles`].

use crate::child_order::Odds;
use crate::sah::MAX_DEPTH;
use crate::tri4::TriPackets;
use crate::wide::Node8;
use filtrace_core::{Aabb, Vec3};

/// One compressed 8-wide node (128 bytes, two cache lines).
///
/// `q[k][i]` (`k < 3`) is the lower and `q[k + 3][i]` the upper bound of child `i` on axis
/// `k`, as grid steps `scale[k]` above `origin[k]`. A child with `count[i] == 0` is the
/// inner node `child[i]`, otherwise a leaf of packets `child[i] .. child[i] + count[i]`;
/// slots whose bit is clear in `valid` are unused (their grid values are meaningless).
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug)]
pub(crate) struct QNode8 {
    pub q: [[u8; 8]; 6],
    pub origin: [f32; 3],
    pub scale: [f32; 3],
    pub child: [u32; 8],
    pub count: [u8; 8],
    pub valid: u32,
}

/// The bound a grid value stands for, evaluated as the AVX2 test does (one rounding).
#[inline(always)]
pub(crate) fn decode(q: u8, scale: f32, origin: f32) -> f32 {
    (q as f32).mul_add(scale, origin)
}

/// Smallest power-of-two step `s` (at least the smallest positive `f32`) with
/// `255 s >= extent`, or 0 for a flat axis; `None` when it exceeds `f32`. (The top grid
/// values of a huge node may decode to infinity, which only widens its boxes.)
fn grid_step(extent: f64) -> Option<f32> {
    if extent <= 0.0 {
        return Some(0.0);
    }
    let mut e = (extent / 255.0).log2().ceil().max(-149.0) as i32;
    while 255.0 * 2f64.powi(e) < extent {
        e += 1;
    }
    let s = 2f64.powi(e) as f32;
    s.is_finite().then_some(s)
}

/// Grid values `(lower, upper)` of the interval `[lo, hi]` on an axis with step `scale` and
/// origin `origin <= lo`: the largest grid value not above `lo` and the smallest not below
/// `hi`, checked against [`decode`]; `None` when `hi` is beyond the grid.
pub(crate) fn quantise(lo: f32, hi: f32, scale: f32, origin: f32) -> Option<(u8, u8)> {
    let steps = |x: f32| if scale > 0.0 { (x as f64 - origin as f64) / scale as f64 } else { 0.0 };
    let mut qlo = steps(lo).floor().clamp(0.0, 255.0) as u8;
    while qlo > 0 && decode(qlo, scale, origin) > lo {
        qlo -= 1;
    }
    let mut qhi = steps(hi).ceil().clamp(0.0, 255.0) as u8;
    while qhi < 255 && decode(qhi, scale, origin) < hi {
        qhi += 1;
    }
    (decode(qlo, scale, origin) <= lo && decode(qhi, scale, origin) >= hi).then_some((qlo, qhi))
}

impl QNode8 {
    /// The compressed form of `n`; `None` when a box is not finite, its extent exceeds
    /// `f32`, or a leaf holds more than 255 packets.
    pub(crate) fn compress(n: &Node8) -> Option<Self> {
        let used: Vec<usize> = (0..8).filter(|&i| !n.child_box(i).is_empty()).collect();
        let mut out = QNode8 {
            q: [[0; 8]; 6],
            origin: [0.0; 3],
            scale: [0.0; 3],
            child: n.child,
            count: [0; 8],
            valid: used.iter().map(|&i| 1u32 << i).sum(),
        };
        for k in (0..3).filter(|_| !used.is_empty()) {
            let lo = used.iter().map(|&i| n.bounds[k][i]).fold(f32::INFINITY, f32::min);
            let hi = used.iter().map(|&i| n.bounds[k + 3][i]).fold(f32::NEG_INFINITY, f32::max);
            if !(lo.is_finite() && hi.is_finite()) {
                return None;
            }
            out.origin[k] = lo;
            out.scale[k] = grid_step(hi as f64 - lo as f64)?;
            for &i in &used {
                let (a, b) = quantise(n.bounds[k][i], n.bounds[k + 3][i], out.scale[k], lo)?;
                (out.q[k][i], out.q[k + 3][i]) = (a, b);
            }
        }
        for i in 0..8 {
            out.count[i] = u8::try_from(n.count[i]).ok()?;
            if out.valid & (1 << i) == 0 {
                (out.child[i], out.count[i]) = (0, 0);
            }
        }
        Some(out)
    }

    /// The decoded box of child `i` (empty for an unused slot).
    pub(crate) fn child_box(&self, i: usize) -> Aabb {
        if self.valid & (1 << i) == 0 {
            return Aabb::EMPTY;
        }
        let at = |row: usize| decode(self.q[row][i], self.scale[row % 3], self.origin[row % 3]);
        Aabb::new(Vec3::new(at(0), at(1), at(2)), Vec3::new(at(3), at(4), at(5)))
    }

    /// The node with its decoded boxes (validation, statistics).
    pub(crate) fn decoded(&self) -> Node8 {
        let mut n = Node8::EMPTY;
        for i in 0..8 {
            n.set_child_box(i, &self.child_box(i));
            n.child[i] = self.child[i];
            n.count[i] = self.count[i] as u32;
        }
        n
    }
}

/// An 8-wide BVH with compressed nodes over the triangle packets of the tree it was made
/// from (queries: `qwide_avx2`).
#[derive(Clone, Debug)]
pub(crate) struct QBvh8 {
    pub nodes: Vec<QNode8>,
    pub tris: TriPackets,
    /// Any-hit odds of the whole tree (those of the uncompressed tree).
    pub odds: Odds,
}

/// Every node of an 8-wide tree compressed; `None` when one cannot be
/// ([`QNode8::compress`]).
pub(crate) fn compress_nodes(nodes: &[Node8]) -> Option<Vec<QNode8>> {
    nodes.iter().map(QNode8::compress).collect()
}

impl QBvh8 {
    /// The nodes with their decoded boxes.
    pub(crate) fn decoded(&self) -> Vec<Node8> {
        self.nodes.iter().map(QNode8::decoded).collect()
    }
}

/// Checks a compressed tree over `prim_count` primitives whose boxes are given by
/// `prim_box`: every primitive in exactly one leaf, inside the decoded box of every slot on
/// its path from the root (decoded child boxes need not lie inside their parent's: each
/// node's grid is its own), every node reachable once and no deeper than `MAX_DEPTH`.
pub(crate) fn validate(
    nodes: &[QNode8],
    prim_count: usize,
    prim_box: impl Fn(usize) -> Aabb,
) -> Result<(), String> {
    if nodes.is_empty() {
        return if prim_count == 0 { Ok(()) } else { Err(format!("no nodes for {prim_count} primitives")) };
    }
    let mut walk =
        Walk { nodes, prim_box: &prim_box, seen: vec![0; prim_count], visited: vec![false; nodes.len()] };
    walk.content(0, 0)?;
    if let Some(p) = walk.seen.iter().position(|&s| s != 1) {
        return Err(format!("primitive {p} referenced {} times", walk.seen[p]));
    }
    if let Some(n) = walk.visited.iter().position(|v| !v) {
        return Err(format!("node {n} unreachable"));
    }
    Ok(())
}

struct Walk<'a, F> {
    nodes: &'a [QNode8],
    prim_box: &'a F,
    seen: Vec<u32>,
    visited: Vec<bool>,
}

impl<F: Fn(usize) -> Aabb> Walk<'_, F> {
    /// The union of the primitive boxes under node `ni`, after checking that each slot's
    /// decoded box holds its own.
    fn content(&mut self, ni: usize, depth: usize) -> Result<Aabb, String> {
        let n = *self.nodes.get(ni).ok_or_else(|| format!("child index {ni} out of range"))?;
        if std::mem::replace(&mut self.visited[ni], true) {
            return Err(format!("node {ni} reached twice"));
        }
        if depth > MAX_DEPTH {
            return Err(format!("node {ni} deeper than {MAX_DEPTH}"));
        }
        let mut all = Aabb::EMPTY;
        for i in (0..8).filter(|&i| n.valid & (1 << i) != 0) {
            let inner = if n.count[i] == 0 {
                self.content(n.child[i] as usize, depth + 1)?
            } else {
                let (first, end) = (n.child[i] as usize, n.child[i] as usize + n.count[i] as usize);
                if end > self.seen.len() {
                    return Err(format!("leaf range {first}..{end} beyond {} primitives", self.seen.len()));
                }
                (first..end).fold(Aabb::EMPTY, |b, p| {
                    self.seen[p] += 1;
                    b.union((self.prim_box)(p))
                })
            };
            let b = n.child_box(i);
            if !(inner.is_empty() || inner.min.cmpge(b.min).all() && inner.max.cmple(b.max).all()) {
                return Err(format!("node {ni} slot {i}: content {inner:?} outside decoded box {b:?}"));
            }
            all = all.union(inner);
        }
        Ok(all)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A finite `f32` spread over many magnitudes (both signs, tiny to huge).
    fn coord() -> impl Strategy<Value = f32> {
        prop_oneof![
            -1.0e3f32..1.0e3,
            -1.0f32..1.0,
            (-30i32..30, -1.0f32..1.0).prop_map(|(e, m)| m * 2f32.powi(e)),
            Just(0.0f32),
        ]
    }

    proptest! {
        /// Every compressed child box contains the exact one, and the node's slots,
        /// children and counts are kept.
        #[test]
        fn compressed_boxes_contain_the_exact_ones(
            boxes in prop::collection::vec((coord(), coord(), coord(), coord(), coord(), coord()), 1..=8),
            empty_slot in 0usize..8,
        ) {
            let mut n = Node8::EMPTY;
            for (i, &(a, b, c, d, e, f)) in boxes.iter().enumerate() {
                let slot = if boxes.len() < 8 && i >= empty_slot { i + 1 } else { i };
                let (p, q) = (Vec3::new(a, b, c), Vec3::new(d, e, f));
                n.set_child_box(slot, &Aabb::new(p.min(q), p.max(q)));
                n.child[slot] = 10 + slot as u32;
                n.count[slot] = slot as u32 % 3;
            }
            let c = QNode8::compress(&n).expect("finite boxes compress");
            for i in 0..8 {
                let (exact, coarse) = (n.child_box(i), c.child_box(i));
                prop_assert_eq!(exact.is_empty(), coarse.is_empty(), "slot {}", i);
                if !exact.is_empty() {
                    prop_assert!(coarse.min.cmple(exact.min).all() && coarse.max.cmpge(exact.max).all(),
                        "slot {}: {:?} does not contain {:?}", i, coarse, exact);
                    prop_assert_eq!((c.child[i], c.count[i] as u32), (n.child[i], n.count[i]));
                }
            }
        }
    }

    /// Two cache lines a node (half of `Node8`'s four).
    #[test]
    fn a_node_is_two_cache_lines() {
        assert_eq!(std::mem::size_of::<QNode8>(), 128);
        assert_eq!(std::mem::size_of::<Node8>(), 256);
    }

    /// The grid is tight: a box spanning the whole node decodes to the node's box (up to
    /// one step), and a child of a large node costs at most one step per side.
    #[test]
    fn quantised_boxes_are_at_most_one_step_larger() {
        let mut n = Node8::EMPTY;
        n.set_child_box(0, &Aabb::new(Vec3::new(-1.0, 0.0, 5.0), Vec3::new(3.0, 0.0, 7.5)));
        n.set_child_box(1, &Aabb::new(Vec3::new(0.1, 0.0, 5.2), Vec3::new(0.2, 0.0, 5.3)));
        let c = QNode8::compress(&n).unwrap();
        assert_eq!(c.scale[1], 0.0, "a flat axis needs no grid");
        for i in 0..2 {
            let (e, q) = (n.child_box(i), c.child_box(i));
            for k in 0..3 {
                assert!(
                    e.min[k] - q.min[k] <= c.scale[k] && q.max[k] - e.max[k] <= c.scale[k],
                    "{e:?} {q:?}"
                );
            }
        }
        assert_eq!(c.child_box(0).min, Vec3::new(-1.0, 0.0, 5.0));
        assert_eq!(c.valid, 0b11);
    }

    /// Nodes whose extent overflows `f32` still get boxes containing the exact ones;
    /// non-finite boxes are refused (the bottom level keeps its uncompressed nodes).
    #[test]
    fn huge_and_non_finite_boxes() {
        let mut n = Node8::EMPTY;
        n.set_child_box(0, &Aabb::new(Vec3::splat(-3e38), Vec3::splat(-2e38)));
        n.set_child_box(1, &Aabb::new(Vec3::splat(2e38), Vec3::splat(f32::MAX)));
        let c = QNode8::compress(&n).expect("finite boxes compress");
        for i in 0..2 {
            let (e, q) = (n.child_box(i), c.child_box(i));
            assert!(q.min.cmple(e.min).all() && q.max.cmpge(e.max).all(), "{e:?} {q:?}");
        }
        n.set_child_box(2, &Aabb::new(Vec3::ZERO, Vec3::new(1.0, f32::INFINITY, 1.0)));
        assert!(QNode8::compress(&n).is_none());
        assert_eq!(quantise(1.0, 2.0, 0.0, 1.0), None, "a zero step spans only the origin");
    }
}
