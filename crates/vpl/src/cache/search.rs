//! Nearest-record search under Georgiev's distance
//! `d(x0, x1) = |x0 − x1| + λ √(1 − n0·n1)` (thesis 4.2.5), in world space.
//!
//! For unit normals `√(1 − n0·n1) = |n0 − n1| / √2`, so `d` is the sum of two Euclidean
//! distances in the 6D space `(x, μ n)` with `μ = λ / √2`. A kd-tree over those 6D
//! points prunes a node when the sum of the distances from the query to the node's
//! position box and to its scaled-normal box exceeds the current M-th best: a true lower
//! bound of `d`, so the search is exact (tested against brute force). The thesis's
//! screen-space grid missed records near the camera or cost 10 ms (6.1); this has
//! neither problem and does not depend on the camera.
//!
//! Layout for lanes: a leaf holds its (up to 8) points in structure-of-arrays form, so
//! one pass of lane-wise arithmetic gives all their distances, and an inner node holds its
//! (up to 4) children's boxes, two levels of the median-split tree, so that one 8-lane
//! pass gives all their lower bounds. The lane loops are plain `f32` arithmetic in the
//! scalar formula's order (Rust never contracts into FMAs), compiled once for the
//! baseline and once for AVX2 + FMA after [`filtrace_core::cpu::isa`]: both give the bits
//! of [`cache_distance`].

use filtrace_core::cpu::{isa, Isa};
use filtrace_core::Vec3;
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};

/// Most records a shading point interpolates (M).
pub const MAX_NEIGHBOURS: usize = 4;
/// Points per kd-tree leaf: one 8-lane block (the median split leaves 4 to 8).
const LEAF_SIZE: usize = 8;
/// Children per inner node.
const WIDTH: usize = 4;
/// Lanes of an inner node's boxes: the children's position boxes, then their normal ones.
const BOX_LANES: usize = 2 * WIDTH;
/// Lower bounds are shrunk by this factor: the exact distances are computed another way
/// (rounding).
const BOUND_SLACK: f32 = 1.0 - 1e-5;

/// A subtree: `index` into the inner nodes, `LEAF_BIT | index` into the leaves, or
/// `EMPTY` (an unused child slot).
type NodeRef = u32;
const LEAF_BIT: NodeRef = 1 << 31;
const EMPTY: NodeRef = NodeRef::MAX;
/// Entries of the search's stack: each node pushes at most `WIDTH - 1` more than it pops
/// and a tree over at most 2³¹ points is at most 15 nodes deep.
const STACK: usize = 64;

/// Ids of built trees (see `KdTree::id`).
static NEXT_TREE_ID: AtomicU64 = AtomicU64::new(1);

thread_local! {
    /// The tree id and result of this thread's last [`KdTree::nearest`] query: the warm
    /// start of the next one.
    static LAST_QUERY: Cell<(u64, Nearest)> = Cell::new((0, Nearest::default()));
}

/// `d(x0, x1) = |x0 − x1| + λ √(1 − n0·n1)` for unit normals `n0`, `n1`.
#[inline]
pub fn cache_distance(x0: Vec3, n0: Vec3, x1: Vec3, n1: Vec3, lambda: f32) -> f32 {
    (x0 - x1).length() + lambda * (1.0 - n0.dot(n1)).max(0.0).sqrt()
}

/// Unit normal, or +z for a zero or non-finite one (a record always has a normal).
#[inline]
pub(crate) fn unit_or_z(n: Vec3) -> Vec3 {
    let n = n.normalize_or_zero();
    if n == Vec3::ZERO {
        Vec3::Z
    } else {
        n
    }
}

/// Up to [`LEAF_SIZE`] points as lanes: rows x, y, z of the positions and of the unit
/// normals; lanes past the points repeat lane 0 (computed, never inserted).
#[derive(Clone, Debug)]
struct Leaf {
    p: [[f32; LEAF_SIZE]; 3],
    n: [[f32; LEAF_SIZE]; 3],
    ids: [u32; LEAF_SIZE],
    /// Bit `l` set for a lane holding a point.
    lanes: u32,
}

/// An inner node: its children's 6D boxes as 8 lanes, the position halves of children
/// 0-3 then their scaled-normal halves, row `i` holding axis `i`. An unused slot has
/// an empty box (`lo` = ∞, `hi` = −∞: its bound is ∞).
#[derive(Clone, Debug)]
struct Inner {
    lo: [[f32; BOX_LANES]; 3],
    hi: [[f32; BOX_LANES]; 3],
    children: [NodeRef; WIDTH],
    /// Bit `c` set for a used slot (slots `0..` are used first).
    used: u32,
}

/// A query in the layouts of the nodes and leaves.
struct Query {
    position: Vec3,
    normal: Vec3,
    /// Row `i`: `x_i` in the position lanes of [`Inner`], `μ n_i` in the normal ones.
    rows: [[f32; BOX_LANES]; 3],
}

/// A 6D box `(position, μ normal)`.
type Box6 = ([f32; 6], [f32; 6]);

/// A kd-tree over `(position, unit normal)` points answering k-nearest queries under
/// [`cache_distance`]. Built once per cache; queries are read-only and thread-safe.
#[derive(Clone, Debug, Default)]
pub struct KdTree {
    /// Distinct per built tree (0: empty), so a warm start never reads another tree's
    /// records.
    id: u64,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    root: Option<NodeRef>,
    inner: Vec<Inner>,
    leaves: Vec<Leaf>,
    lambda: f32,
}

impl KdTree {
    /// Builds the tree; normals are normalised (zero ones become +z).
    pub fn new(positions: &[Vec3], normals: &[Vec3], lambda: f32) -> Self {
        assert_eq!(positions.len(), normals.len(), "one normal per position");
        assert!(positions.len() < LEAF_BIT as usize, "at most 2³¹ points");
        let normals: Vec<Vec3> = normals.iter().map(|&n| unit_or_z(n)).collect();
        let mu = lambda * std::f32::consts::FRAC_1_SQRT_2;
        let keys: Vec<[f32; 6]> = positions
            .iter()
            .zip(&normals)
            .map(|(p, n)| {
                let m = *n * mu;
                [p.x, p.y, p.z, m.x, m.y, m.z]
            })
            .collect();
        let mut tree = KdTree {
            id: NEXT_TREE_ID.fetch_add(1, Ordering::Relaxed),
            positions: positions.to_vec(),
            normals,
            lambda,
            ..KdTree::default()
        };
        if !positions.is_empty() {
            let mut ids: Vec<u32> = (0..positions.len() as u32).collect();
            tree.root = Some(tree.build(&mut ids, &keys));
        }
        tree
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// λ of the distance.
    pub fn lambda(&self) -> f32 {
        self.lambda
    }

    /// Builds the subtree over `ids`: a leaf, or a node over the (up to four) parts of two
    /// levels of median splits.
    fn build(&mut self, ids: &mut [u32], keys: &[[f32; 6]]) -> NodeRef {
        if ids.len() <= LEAF_SIZE {
            self.leaves.push(self.leaf(ids));
            return LEAF_BIT | (self.leaves.len() as u32 - 1);
        }
        let (left, right) = median_split(ids, keys);
        let mut parts: Vec<&mut [u32]> = Vec::with_capacity(WIDTH);
        for half in [left, right] {
            if half.len() <= LEAF_SIZE {
                parts.push(half);
            } else {
                let (a, b) = median_split(half, keys);
                parts.extend([a, b]);
            }
        }
        let mut node = Inner {
            lo: [[f32::INFINITY; BOX_LANES]; 3],
            hi: [[f32::NEG_INFINITY; BOX_LANES]; 3],
            children: [EMPTY; WIDTH],
            used: (1 << parts.len()) - 1,
        };
        for (c, part) in parts.into_iter().enumerate() {
            let (lo, hi) = bounding_box(part, keys);
            for half in 0..2 {
                for i in 0..3 {
                    node.lo[i][WIDTH * half + c] = lo[3 * half + i];
                    node.hi[i][WIDTH * half + c] = hi[3 * half + i];
                }
            }
            node.children[c] = self.build(part, keys);
        }
        self.inner.push(node);
        self.inner.len() as u32 - 1
    }

    /// The lanes of the points `ids` (at most [`LEAF_SIZE`]).
    fn leaf(&self, ids: &[u32]) -> Leaf {
        let mut leaf =
            Leaf { p: [[0.0; LEAF_SIZE]; 3], n: [[0.0; LEAF_SIZE]; 3], ids: [ids[0]; LEAF_SIZE], lanes: 0 };
        for lane in 0..LEAF_SIZE {
            let i = ids.get(lane).copied().unwrap_or(ids[0]);
            let (p, n) = (self.positions[i as usize], self.normals[i as usize]);
            for (a, (pa, na)) in [(p.x, n.x), (p.y, n.y), (p.z, n.z)].into_iter().enumerate() {
                leaf.p[a][lane] = pa;
                leaf.n[a][lane] = na;
            }
            leaf.ids[lane] = i;
        }
        leaf.lanes = (1 << ids.len()) - 1;
        leaf
    }

    /// The `k` nearest points to `(position, normal)` under [`cache_distance`] as
    /// `(distance, index)`, nearest first; ties by lower index (as a brute-force sort by
    /// `(distance, index)`). `k` is clamped to [`MAX_NEIGHBOURS`] + 1.
    #[inline]
    pub fn nearest(&self, position: Vec3, normal: Vec3, k: usize) -> Nearest {
        self.nearest_with(isa(), position, normal, k)
    }

    /// [`KdTree::nearest`] with the lane code of instruction set `level` (at most what
    /// this CPU runs; tests compare the levels).
    pub fn nearest_with(&self, level: Isa, position: Vec3, normal: Vec3, k: usize) -> Nearest {
        let mut out = Nearest::default();
        let k = k.min(MAX_NEIGHBOURS + 1);
        let Some(root) = self.root else { return out };
        if k == 0 || !position.is_finite() {
            return out;
        }
        let normal = unit_or_z(normal);
        let m = normal * (self.lambda * std::f32::consts::FRAC_1_SQRT_2);
        let mut rows = [[0.0; BOX_LANES]; 3];
        for (row, (x, n)) in rows.iter_mut().zip([(position.x, m.x), (position.y, m.y), (position.z, m.z)]) {
            row[..WIDTH].fill(x);
            row[WIDTH..].fill(n);
        }
        let q = Query { position, normal, rows };
        let limit = self.warm_bound(position, normal, k);
        #[cfg(target_arch = "x86_64")]
        if level.has_avx2() && isa().has_avx2() {
            // SAFETY: the CPU runs AVX2 and FMA (checked just above).
            unsafe { self.search_avx2(root, &q, k, limit, &mut out) };
            LAST_QUERY.with(|last| last.set((self.id, out)));
            return out;
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = level;
        self.search(root, &q, k, limit, &mut out);
        LAST_QUERY.with(|last| last.set((self.id, out)));
        out
    }

    /// [`KdTree::search`] compiled for AVX2 + FMA (the same source; only the instruction
    /// selection differs).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn search_avx2(&self, root: NodeRef, q: &Query, k: usize, limit: f32, out: &mut Nearest) {
        self.search(root, q, k, limit, out)
    }

    /// Depth-first search pruning subtrees whose lower bound exceeds `limit`: an upper
    /// bound of the k-th distance, lowered to the k-th distance found so far. Every point within the final k-th distance is offered to
    /// `out` exactly once (its leaf is never pruned), so `out` ends with the k smallest.
    #[inline(always)]
    fn search(&self, root: NodeRef, q: &Query, k: usize, mut limit: f32, out: &mut Nearest) {
        // Entries: subtree and the lower bound of `d` over it (0 for the root).
        let mut stack = [(0 as NodeRef, 0.0f32); STACK];
        stack[0].0 = root;
        let mut depth = 1;
        while depth > 0 {
            depth -= 1;
            let (node, bound) = stack[depth];
            if bound > limit {
                continue;
            }
            if node & LEAF_BIT != 0 {
                self.visit_leaf(&self.leaves[(node & !LEAF_BIT) as usize], q, k, limit, out);
                // NaN never lowers the limit.
                let kth = out.kth(k);
                if kth < limit {
                    limit = kth;
                }
                continue;
            }
            let node = &self.inner[node as usize];
            let bounds = child_bounds(node, &q.rows);
            push_open_children(node, &bounds, limit, &mut stack, &mut depth);
        }
    }

    /// Offers the points of `leaf` within `limit` (and any NaN) to `out`.
    #[inline(always)]
    fn visit_leaf(&self, leaf: &Leaf, q: &Query, k: usize, limit: f32, out: &mut Nearest) {
        let d = leaf_distances(leaf, q, self.lambda);
        let mut near = lanes_within(&d, limit) & leaf.lanes;
        while near != 0 {
            let l = near.trailing_zeros() as usize;
            near &= near - 1;
            out.insert(k, (d[l], leaf.ids[l]));
        }
    }

    /// An upper bound of the k-th distance: the largest exact distance of `k` records
    /// this thread's previous query of this tree found (∞ without them, or with a NaN).
    /// Neighbouring pixels share most of their records, so the search prunes from the
    /// root on with a bound close to the final one. The result does not depend on it
    /// (any upper bound gives the same k nearest), so neither on the previous query nor
    /// on the thread.
    fn warm_bound(&self, position: Vec3, normal: Vec3, k: usize) -> f32 {
        let (id, previous) = LAST_QUERY.with(Cell::get);
        if id != self.id || previous.len < k {
            return f32::INFINITY;
        }
        let mut bound = 0.0f32;
        for &(_, i) in &previous.items[..k] {
            let (x, n) = (self.positions[i as usize], self.normals[i as usize]);
            let d = cache_distance(position, normal, x, n, self.lambda);
            if d.is_nan() {
                return f32::INFINITY;
            }
            bound = bound.max(d);
        }
        bound
    }

    /// Brute-force [`KdTree::nearest`], the reference the tests compare against.
    pub fn nearest_brute_force(&self, position: Vec3, normal: Vec3, k: usize) -> Vec<(f32, u32)> {
        let normal = unit_or_z(normal);
        let mut all: Vec<(f32, u32)> = (0..self.len() as u32)
            .map(|i| {
                (
                    cache_distance(
                        position,
                        normal,
                        self.positions[i as usize],
                        self.normals[i as usize],
                        self.lambda,
                    ),
                    i,
                )
            })
            .collect();
        all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        all.truncate(k);
        all
    }
}

/// Splits `ids` at the median of their widest axis (ties by index: deterministic).
fn median_split<'a>(ids: &'a mut [u32], keys: &[[f32; 6]]) -> (&'a mut [u32], &'a mut [u32]) {
    let (lo, hi) = bounding_box(ids, keys);
    let axis = (0..6).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).unwrap_or(0);
    let mid = ids.len() / 2;
    ids.select_nth_unstable_by(mid, |&a, &b| {
        keys[a as usize][axis].total_cmp(&keys[b as usize][axis]).then(a.cmp(&b))
    });
    ids.split_at_mut(mid)
}

/// The 6D box of the points `ids`.
fn bounding_box(ids: &[u32], keys: &[[f32; 6]]) -> Box6 {
    let (mut lo, mut hi) = ([f32::INFINITY; 6], [f32::NEG_INFINITY; 6]);
    for &i in ids {
        for a in 0..6 {
            lo[a] = lo[a].min(keys[i as usize][a]);
            hi[a] = hi[a].max(keys[i as usize][a]);
        }
    }
    (lo, hi)
}

/// Pushes the children of `node` whose lower bound is within `limit` (NaN: kept) onto
/// `stack`, the nearest last, so that it is visited next. Where the warm limit is loose
/// (grass: neighbouring pixels see blades of other normals, so the last query's records
/// are far in `d`) the nearest subtree lowers the limit soonest, and far fewer leaves are
/// visited (docs/many-light-cache.md, "Search order (stop 21)").
/// Only the nearest is placed; a full sort of the children cost more than it saved where
/// the warm limit is tight.
#[inline(always)]
fn push_open_children(
    node: &Inner,
    bounds: &[f32; WIDTH],
    limit: f32,
    stack: &mut [(NodeRef, f32); STACK],
    depth: &mut usize,
) {
    let mut open = lanes_within(bounds, limit) & node.used;
    if open == 0 {
        return;
    }
    let mut nearest = open.trailing_zeros() as usize;
    let mut rest = open & (open - 1);
    while rest != 0 {
        let c = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        if bounds[c] < bounds[nearest] {
            nearest = c;
        }
    }
    open &= !(1 << nearest);
    while open != 0 {
        let c = open.trailing_zeros() as usize;
        open &= open - 1;
        stack[*depth] = (node.children[c], bounds[c]);
        *depth += 1;
    }
    stack[*depth] = (node.children[nearest], bounds[nearest]);
    *depth += 1;
}

/// Bit `i` set for each value not beyond `limit` (a NaN counts as within: it is kept).
#[inline(always)]
fn lanes_within(values: &[f32], limit: f32) -> u32 {
    let mut mask = 0;
    for (i, &v) in values.iter().enumerate() {
        mask |= ((!(v > limit)) as u32) << i;
    }
    mask
}

/// [`cache_distance`] from the query to every lane of `leaf`, term by term in its order
/// (glam's `dot` is `(x x' + y y') + z z'`, `length` its square root), so each lane has
/// the scalar function's bits.
#[inline(always)]
fn leaf_distances(leaf: &Leaf, q: &Query, lambda: f32) -> [f32; LEAF_SIZE] {
    let (p, n) = (q.position, q.normal);
    let mut d = [0.0f32; LEAF_SIZE];
    for (l, d) in d.iter_mut().enumerate() {
        let (dx, dy, dz) = (p.x - leaf.p[0][l], p.y - leaf.p[1][l], p.z - leaf.p[2][l]);
        let along = (dx * dx + dy * dy + dz * dz).sqrt();
        let cos = n.x * leaf.n[0][l] + n.y * leaf.n[1][l] + n.z * leaf.n[2][l];
        *d = along + lambda * (1.0 - cos).max(0.0).sqrt();
    }
    d
}

/// Lower bounds of `d` from the query to the children of `node`: per child the distance
/// to its position box plus that to its scaled-normal box (∞ for an unused slot).
#[inline(always)]
fn child_bounds(node: &Inner, rows: &[[f32; BOX_LANES]; 3]) -> [f32; WIDTH] {
    let mut s = [0.0f32; BOX_LANES];
    for ((lo, hi), q) in node.lo.iter().zip(&node.hi).zip(rows) {
        for (l, s) in s.iter_mut().enumerate() {
            // max(lo − q, q − hi, 0) as selects (plain `maxps`); a NaN gives a smaller
            // bound than `f32::max` would, never a larger one.
            let (below, above) = (lo[l] - q[l], q[l] - hi[l]);
            let e = if below > above { below } else { above };
            let e = if e > 0.0 { e } else { 0.0 };
            *s += e * e;
        }
    }
    let r = s.map(f32::sqrt);
    std::array::from_fn(|c| (r[c] + r[WIDTH + c]) * BOUND_SLACK)
}

/// The result of [`KdTree::nearest`]: up to [`MAX_NEIGHBOURS`] + 1 `(distance, index)`
/// pairs sorted by `(distance, index)`, on the stack.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Nearest {
    items: [(f32, u32); MAX_NEIGHBOURS + 1],
    len: usize,
}

impl Nearest {
    pub fn as_slice(&self) -> &[(f32, u32)] {
        &self.items[..self.len]
    }

    /// The k-th distance, ∞ while there are fewer than `k`.
    #[inline(always)]
    fn kth(&self, k: usize) -> f32 {
        if self.len == k {
            self.items[k - 1].0
        } else {
            f32::INFINITY
        }
    }

    /// Inserts `c` (a point not there yet), keeping the `k` smallest.
    #[inline]
    fn insert(&mut self, k: usize, c: (f32, u32)) {
        let less = |a: &(f32, u32), b: &(f32, u32)| a.0 < b.0 || (a.0 == b.0 && a.1 < b.1);
        if self.len == k && !less(&c, &self.items[k - 1]) {
            return;
        }
        // Shift every item not less than `c` (NaN included) one place on.
        let mut at = self.len.min(k - 1);
        while at > 0 && !less(&self.items[at - 1], &c) {
            self.items[at] = self.items[at - 1];
            at -= 1;
        }
        self.items[at] = c;
        self.len = (self.len + 1).min(k);
    }
}

/// The records a shading point interpolates, with weights that sum to 1.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Neighbours {
    ids: [u32; MAX_NEIGHBOURS],
    weights: [f32; MAX_NEIGHBOURS],
    distances: [f32; MAX_NEIGHBOURS],
    len: u8,
}

impl Neighbours {
    /// Weights from the `(distance, id)` list of the M + 1 nearest records (nearest
    /// first): `w_l ∝ 1 − d_l / d_{M+1}`, so a record's weight falls to 0 just as it
    /// leaves the M nearest and the interpolated distributions change continuously
    /// (for M ≥ 2). The thesis's `w_l = d_l / Σ d` (5.2.2) would weigh the farthest
    /// record most, surely a slip. With no (M+1)-th record the radius is twice the M-th
    /// distance; if all weights vanish (ties), equal weights.
    pub fn from_nearest(nearest: &[(f32, u32)], m: usize) -> Self {
        let m = m.min(MAX_NEIGHBOURS);
        let mut nb = Neighbours::default();
        let take = nearest.len().min(m);
        if take == 0 {
            return nb;
        }
        let radius = nearest.get(m).map_or(2.0 * nearest[take - 1].0, |c| c.0);
        let mut sum = 0.0;
        for (s, &(d, id)) in nearest[..take].iter().enumerate() {
            let w = if radius > 0.0 { (1.0 - d / radius).max(0.0) } else { 0.0 };
            nb.ids[s] = id;
            nb.distances[s] = d;
            nb.weights[s] = w;
            sum += w;
        }
        nb.len = take as u8;
        for w in &mut nb.weights[..take] {
            *w = if sum > 0.0 { *w / sum } else { 1.0 / take as f32 };
        }
        nb
    }

    pub fn len(&self) -> usize {
        self.len as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// `(record id, weight)` pairs, nearest first.
    pub fn iter(&self) -> impl Iterator<Item = (usize, f32)> + '_ {
        (0..self.len()).map(|s| (self.ids[s] as usize, self.weights[s]))
    }

    /// d-distance to the closest record (the thesis's Figure 27 layer); `None` when the
    /// cache is empty.
    pub fn closest_distance(&self) -> Option<f32> {
        (self.len > 0).then(|| self.distances[0])
    }
}

#[cfg(test)]
mod tests;
