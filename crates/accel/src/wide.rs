//! Four-wide BVH ("BVH4"/"QBVH"): nodes hold the boxes of up to four children in
//! structure-of-arrays layout so that one SIMD box test (Williams et al., "An efficient and
//! robust ray-box intersection algorithm", 2005, slab test) covers all four.
//!
//! The wide tree is obtained by collapsing the binary SAH tree (Dammertz, Hanika and Keller,
//! "Shallow Bounding Volume Hierarchies for Fast SIMD Ray Tracing of Incoherent Rays",
//! EGSR 2008; Wald, Benthin and Boulos, "Getting rid of packets", 2008), choosing the
//! cheapest wide tree by the SAH (`collapse.rs`). Traversal visits hit children near-first
//! and skips stack entries farther than the closest hit found so far. The slab distances
//! are widened by `1 + 2 gamma_3` as in Ize, "Robust BVH Ray Traversal" (JCGT 2013), so
//! rounding never culls a box the ray touches.

use crate::sah::MAX_DEPTH;
use filtrace_core::{Aabb, Vec3};
use std::mem::MaybeUninit;

/// One node of a `W`-wide BVH: `W` child boxes (SoA) and `W` child references; the
/// 4-wide node ([`Node4`], SSE) is 128 bytes, the 8-wide one ([`Node8`], AVX2) 256.
///
/// `bounds[0..3]` are the children's minimum x, y, z, `bounds[3..6]` the maxima. A child
/// with `count[i] == 0` is the inner node `child[i]`; otherwise it is a leaf holding
/// primitives `child[i] .. child[i] + count[i]`. Unused slots hold the empty box, which
/// no ray hits.
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug)]
pub(crate) struct WideNode<const W: usize> {
    pub bounds: [[f32; W]; 6],
    pub child: [u32; W],
    pub count: [u32; W],
}

/// Four-wide node, tested with SSE.
pub(crate) type Node4 = WideNode<4>;
/// Eight-wide node, tested with AVX2 (`crate::avx2`).
pub(crate) type Node8 = WideNode<8>;

impl<const W: usize> WideNode<W> {
    pub(crate) const EMPTY: Self = Self {
        bounds: [
            [f32::INFINITY; W],
            [f32::INFINITY; W],
            [f32::INFINITY; W],
            [f32::NEG_INFINITY; W],
            [f32::NEG_INFINITY; W],
            [f32::NEG_INFINITY; W],
        ],
        child: [0; W],
        count: [0; W],
    };

    pub fn child_box(&self, i: usize) -> Aabb {
        let b = &self.bounds;
        Aabb::new(Vec3::new(b[0][i], b[1][i], b[2][i]), Vec3::new(b[3][i], b[4][i], b[5][i]))
    }

    pub(crate) fn set_child_box(&mut self, i: usize, a: &Aabb) {
        for k in 0..3 {
            self.bounds[k][i] = a.min[k];
            self.bounds[k + 3][i] = a.max[k];
        }
    }
}

/// Per-ray constants of the box test: origin, reciprocal direction and which bound row is
/// near on each axis.
///
/// A zero direction component gives an infinite reciprocal (signed like the zero). The
/// slab distance is then `±inf` when the origin is off the plane (correct: the ray never
/// crosses it) and `0 * inf = NaN` when the origin lies exactly in the plane; the box test
/// orders its `min`/`max` operands so that a NaN lane is ignored, which counts such a ray
/// as inside the slab (conservative: the triangle test decides).
#[derive(Clone, Copy, Debug)]
pub(crate) struct RayBoxes {
    org: [f32; 3],
    inv: [f32; 3],
    /// Row of `Node4::bounds` holding the near plane per axis (`k` or `k + 3`), a row of
    /// a constant table (see `octant_rows`).
    near: &'static [usize; 3],
    /// Row holding the far plane per axis.
    far: &'static [usize; 3],
}

/// Rows of `Node4::bounds` holding the near and far planes per axis, for each octant.
static ROWS4: [[[usize; 3]; 8]; 2] = [octant_rows(1, false), octant_rows(1, true)];

/// For each octant (bit `k` set: `dir[k]` negative), the offsets `stride * row` of the
/// near (`far = false`) or far bound rows per axis, for nodes that store the minima in
/// rows `0..3` and the maxima in rows `3..6`: a negative direction enters at the maximum.
pub(crate) const fn octant_rows(stride: usize, far: bool) -> [[usize; 3]; 8] {
    let mut rows = [[0; 3]; 8];
    let mut octant = 0;
    while octant < 8 {
        let mut k = 0;
        while k < 3 {
            let negative = octant & (1 << k) != 0;
            rows[octant][k] = stride * if negative != far { k + 3 } else { k };
            k += 1;
        }
        octant += 1;
    }
    rows
}

impl RayBoxes {
    #[inline(always)]
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        let (d, mut inv, mut octant) = (dir.to_array(), [0.0; 3], 0);
        for k in 0..3 {
            inv[k] = 1.0 / d[k];
            // `inv[k] >= 0` exactly when `dir[k]` has no sign bit (valid rays have no NaN
            // components and `1 / d` never rounds to zero); testing `dir` keeps the rows
            // off the division's latency (as `avx2::RayBoxes8`).
            octant |= (d[k].is_sign_negative() as usize) << k;
        }
        Self { org: origin.to_array(), inv, near: &ROWS4[0][octant], far: &ROWS4[1][octant] }
    }
}

/// `1 + 2 gamma_3`: widening of the far slab distance (Ize 2013, sec. 3).
pub(crate) const FAR_SCALE: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

/// Relative slack of box culling against the closest hit found so far (`2^-12`).
///
/// Closest hits are independent of traversal order only if every box holding a triangle
/// hit at exactly `t_max` is still visited (ties then go to the smallest
/// `(instance, prim)`, see `SceneAccel::intersect`). Such a box's entry distance is at
/// most the triangle's exact distance, but the watertight `t` and the slab distances round
/// differently (a few ulps, more for huge triangles seen from close by), so a box is culled
/// only when its entry lies beyond `t_max (1 + 2^-12)`. The cost is an occasional extra box
/// visit whose triangles then fail the exact `t <= t_max` test.
pub(crate) const CULL_SCALE: f32 = 1.0 + 1.0 / 4096.0;

/// The distance beyond which boxes are culled for a closest hit at `t_max` (see
/// [`CULL_SCALE`]; non-positive and infinite `t_max` are kept as they are).
#[inline(always)]
pub(crate) fn cull_bound(t_max: f32) -> f32 {
    (t_max * CULL_SCALE).max(t_max)
}

/// Slab test of a ray against the four child boxes: returns the hit mask (bit `i` for
/// child `i`) and the entry distances.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn box4(n: &Node4, r: &RayBoxes, t_min: f32, t_max: f32) -> (u32, [f32; 4]) {
    use std::arch::x86_64::*;
    // SAFETY: SSE is part of the x86_64 baseline; `bounds` rows are 16-byte aligned
    // (`Node4` is 64-byte aligned and each row is 16 bytes) and `near[k], far[k] < 6`.
    unsafe {
        let b = n.bounds.as_ptr() as *const f32;
        let row = |i: usize| _mm_load_ps(b.add(4 * i));
        let slab = |k: usize| {
            let o = _mm_set1_ps(r.org[k]);
            let inv = _mm_set1_ps(r.inv[k]);
            let near = _mm_mul_ps(_mm_sub_ps(row(r.near[k]), o), inv);
            let far = _mm_mul_ps(_mm_sub_ps(row(r.far[k]), o), inv);
            (near, far)
        };
        let (nx, fx) = slab(0);
        let (ny, fy) = slab(1);
        let (nz, fz) = slab(2);
        // `_mm_max_ps(a, b)` returns `b` when either is NaN: slab distances go first so
        // that NaN lanes (origin in a slab plane, zero direction) are skipped.
        let t_near = _mm_max_ps(nz, _mm_max_ps(ny, _mm_max_ps(nx, _mm_set1_ps(t_min))));
        let t_far = _mm_min_ps(fz, _mm_min_ps(fy, _mm_min_ps(fx, _mm_set1_ps(cull_bound(t_max)))));
        let t_far = _mm_mul_ps(t_far, _mm_set1_ps(FAR_SCALE));
        let mask = _mm_movemask_ps(_mm_cmple_ps(t_near, t_far)) as u32;
        let mut out = [0.0f32; 4];
        _mm_storeu_ps(out.as_mut_ptr(), t_near);
        (mask, out)
    }
}

/// Portable fallback of the slab test (LLVM vectorises these loops on most targets).
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn box4(n: &Node4, r: &RayBoxes, t_min: f32, t_max: f32) -> (u32, [f32; 4]) {
    let mut t_near = [t_min; 4];
    let mut t_far = [cull_bound(t_max); 4];
    for k in 0..3 {
        let near = &n.bounds[r.near[k]];
        let far = &n.bounds[r.far[k]];
        for i in 0..4 {
            let a = (near[i] - r.org[k]) * r.inv[k];
            let b = (far[i] - r.org[k]) * r.inv[k];
            // NaN (origin in the slab plane, zero direction) fails the comparison: skipped.
            t_near[i] = if a > t_near[i] { a } else { t_near[i] };
            t_far[i] = if b < t_far[i] { b } else { t_far[i] };
        }
    }
    let mut mask = 0;
    for i in 0..4 {
        mask |= ((t_near[i] <= t_far[i] * FAR_SCALE) as u32) << i;
    }
    (mask, t_near)
}

/// Whether the ray `o + t d`, `t` in `[t_min, t_max]`, can touch box `b`: the scalar
/// form of the slab test (conservative in the same way: NaN slabs are skipped and the far
/// distance widened by `1 + 2 gamma_3`). A ray starting inside the box answers at once.
#[inline(always)]
pub(crate) fn ray_touches_box(o: Vec3, d: Vec3, t_min: f32, t_max: f32, b: &Aabb) -> bool {
    if o.cmpge(b.min).all() && o.cmple(b.max).all() {
        return true;
    }
    let (mut t_near, mut t_far) = (t_min, cull_bound(t_max));
    for k in 0..3 {
        let inv = 1.0 / d[k];
        let (lo, hi) = ((b.min[k] - o[k]) * inv, (b.max[k] - o[k]) * inv);
        let (near, far) = if inv >= 0.0 { (lo, hi) } else { (hi, lo) };
        // NaN (origin in the slab plane, zero direction) fails the comparison: skipped.
        t_near = if near > t_near { near } else { t_near };
        t_far = if far < t_far { far } else { t_far };
    }
    t_near <= t_far * FAR_SCALE
}

/// Software prefetch of `lines` cache lines from `p` into L1 (no-op off x86_64). Never
/// faults, whatever the address.
#[inline(always)]
pub(crate) fn prefetch(p: *const u8, lines: usize) {
    #[cfg(target_arch = "x86_64")]
    for l in 0..lines {
        // SAFETY: prefetching is a hint and never faults.
        unsafe {
            std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
                p.wrapping_add(64 * l) as *const i8
            )
        };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (p, lines);
}

#[derive(Clone, Copy)]
pub(crate) struct Entry {
    pub child: u32,
    pub count: u32,
    pub t: f32,
}

/// Traversal stack depth: each wide level pushes at most three entries.
pub(crate) const STACK: usize = 3 * MAX_DEPTH + 4;

/// What traversal does at a leaf: test primitives `first .. first + count`, shorten
/// `*t_max` on a hit (closest hit) or return `true` to stop (any hit).
pub(crate) trait Leaves {
    fn visit(&mut self, first: u32, count: u32, t_max: &mut f32) -> bool;

    /// Hint that the leaf `first .. first + count` will be visited soon.
    #[inline(always)]
    fn prefetch(&self, _first: u32, _count: u32) {}

    /// Address of the first byte of leaf `first` (the 8-wide traversal prefetches the
    /// cache lines from there without a branch on leaf or node); 0 where unknown.
    #[inline(always)]
    fn leaf_addr(&self, _first: u32) -> usize {
        0
    }
}

impl<F: FnMut(u32, u32, &mut f32) -> bool> Leaves for F {
    #[inline(always)]
    fn visit(&mut self, first: u32, count: u32, t_max: &mut f32) -> bool {
        self(first, count, t_max)
    }
}

/// The hit children `mask` (non-zero) of a node, `e(i)` the entry of child `i`: pushes
/// all but one onto `stack` and returns the one to visit next. `ORDERED` (closest hits):
/// near-first, the farther entries deepest (two hits, the most common case: one compare;
/// more: insertion-sorted straight onto the stack), equal distances from the last slot
/// down; else from the last slot down, the any-hit order of [`crate::child_order`]. Shared by the 4-wide and 8-wide traversals.
#[inline(always)]
pub(crate) fn push_children<const ORDERED: bool>(
    mask: u32,
    e: impl Fn(usize) -> Entry,
    stack: &mut [MaybeUninit<Entry>],
    sp: &mut usize,
) -> Entry {
    if !ORDERED {
        let last = 31 - mask.leading_zeros() as usize;
        let mut bits = mask & !(1 << last);
        while bits != 0 {
            let i = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            // SAFETY: a node pushes at most `width - 1` entries and the stacks hold that
            // many per level of `MAX_DEPTH`, which built trees do not exceed (`validate`).
            unsafe { *stack.get_unchecked_mut(*sp) = MaybeUninit::new(e(i)) };
            *sp += 1;
        }
        return e(last);
    }
    let first = mask.trailing_zeros() as usize;
    let rest = mask & (mask - 1);
    if rest == 0 {
        return e(first);
    }
    if rest & (rest - 1) == 0 {
        let (a, b) = (e(first), e(rest.trailing_zeros() as usize));
        // Equal distances (both boxes around the origin): the later slot, the more
        // likely hit (`crate::child_order`), first.
        let (near, far) = if b.t <= a.t { (b, a) } else { (a, b) };
        stack[*sp] = MaybeUninit::new(far);
        *sp += 1;
        return near;
    }
    debug_assert!(*sp + mask.count_ones() as usize <= stack.len(), "BVH deeper than MAX_DEPTH");
    let base = *sp;
    let mut bits = mask;
    while bits != 0 {
        let i = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        let h = e(i);
        let mut j = *sp;
        // SAFETY: entries `base..sp` were written in this loop.
        while j > base && unsafe { stack[j - 1].assume_init() }.t < h.t {
            stack[j] = stack[j - 1];
            j -= 1;
        }
        stack[j] = MaybeUninit::new(h);
        *sp += 1;
    }
    *sp -= 1;
    // SAFETY: written just above.
    unsafe { stack[*sp].assume_init() }
}

/// Visits every leaf whose box the ray `[t_min, *t_max]` touches, calling
/// `leaves.visit(first, count, t_max)`; returns `true` when a visit asked to stop.
/// `ORDERED`: visit hit children near-first (closest hit); any-hit queries skip the sort.
#[inline(always)]
pub(crate) fn traverse<L: Leaves, const ORDERED: bool>(
    nodes: &[Node4],
    r: &RayBoxes,
    t_min: f32,
    t_max: &mut f32,
    mut leaves: L,
) -> bool {
    if nodes.is_empty() {
        return false;
    }
    let mut stack = [MaybeUninit::<Entry>::uninit(); STACK];
    let mut sp = 0usize;
    let mut cur = Entry { child: 0, count: 0, t: t_min };
    loop {
        if cur.count == 0 {
            let node = &nodes[cur.child as usize];
            let (mask, t_near) = box4(node, r, t_min, *t_max);
            if mask != 0 {
                let e = |i: usize| Entry { child: node.child[i], count: node.count[i], t: t_near[i] };
                // Start fetching every child to be visited while the order is worked out.
                let mut bits = mask;
                while bits != 0 {
                    let i = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    if node.count[i] == 0 {
                        prefetch(nodes.as_ptr().wrapping_add(node.child[i] as usize) as *const u8, 2);
                    } else {
                        leaves.prefetch(node.child[i], node.count[i]);
                    }
                }
                cur = push_children::<ORDERED>(mask, e, &mut stack, &mut sp);
                continue;
            }
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
            let e = unsafe { stack[sp].assume_init() };
            if e.t <= cull_bound(*t_max) {
                cur = e;
                break;
            }
        }
    }
}

/// Checks the invariants of a wide BVH over `prim_count` primitives whose boxes are given
/// by `prim_box`: every primitive in exactly one leaf, every child box inside its parent's
/// slot, every node reachable once. Used by debug builds and tests.
pub(crate) fn validate<const W: usize>(
    nodes: &[WideNode<W>],
    prim_count: usize,
    prim_box: impl Fn(usize) -> Aabb,
) -> Result<(), String> {
    if nodes.is_empty() {
        return if prim_count == 0 { Ok(()) } else { Err(format!("no nodes for {prim_count} primitives")) };
    }
    let mut seen = vec![0u32; prim_count];
    let mut visited = vec![false; nodes.len()];
    let inside =
        |inner: &Aabb, outer: &Aabb| inner.min.cmpge(outer.min).all() && inner.max.cmple(outer.max).all();
    let mut todo = vec![(0usize, None::<Aabb>, 0usize)];
    while let Some((ni, parent, depth)) = todo.pop() {
        if ni >= nodes.len() {
            return Err(format!("child index {ni} out of range"));
        }
        if std::mem::replace(&mut visited[ni], true) {
            return Err(format!("node {ni} reached twice"));
        }
        if depth > MAX_DEPTH {
            return Err(format!("node {ni} deeper than {MAX_DEPTH}"));
        }
        let n = &nodes[ni];
        for i in 0..W {
            let b = n.child_box(i);
            if b.is_empty() {
                continue;
            }
            if let Some(p) = parent {
                if !inside(&b, &p) {
                    return Err(format!("node {ni} child {i} box {b:?} outside parent {p:?}"));
                }
            }
            if n.count[i] == 0 {
                todo.push((n.child[i] as usize, Some(b), depth + 1));
            } else {
                let first = n.child[i] as usize;
                let end = first + n.count[i] as usize;
                if end > prim_count {
                    return Err(format!("leaf range {first}..{end} beyond {prim_count} primitives"));
                }
                for (p, s) in seen.iter_mut().enumerate().take(end).skip(first) {
                    *s += 1;
                    if !inside(&prim_box(p), &b) {
                        return Err(format!("primitive {p} outside its leaf box"));
                    }
                }
            }
        }
    }
    if let Some(p) = seen.iter().position(|&s| s != 1) {
        return Err(format!("primitive {p} referenced {} times", seen[p]));
    }
    if let Some(n) = visited.iter().position(|v| !v) {
        return Err(format!("node {n} unreachable"));
    }
    Ok(())
}
