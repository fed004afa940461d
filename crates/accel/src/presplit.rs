//! Pre-splitting of long thin triangles before the BVH build (Karras & Aila, "Fast
//! parallel construction of high-quality bounding volume hierarchies", HPG 2013, sec. 5;
//! the idea is Ernst & Greiner's "Early split clipping for bounding volume hierarchies",
//! 2007).
//!
//! The SAH builder ([`crate::sah`]) sees only boxes. A long thin triangle lying
//! diagonally (a grass blade, a cylinder's side) has a box far larger than itself, so the
//! nodes holding it overlap and rays visit them for nothing. Before the build such
//! triangles are cut by axis-aligned planes into pieces; each piece's box is the box of
//! the triangle *clipped* to the piece's region (tight, unlike halving the box). The
//! builder then sees several small boxes of one triangle, and a leaf may reference a
//! triangle more than once (`blas.rs` stores it once per leaf).
//!
//! Which triangles, and how often (K&A 2013): only those whose box area is at least
//! [`MIN_BOX_RATIO`] times `A_ideal` (below); triangle `t` gets the priority
//! `p_t = (2^-l_t (A_box(t) - A_ideal(t)))^(1/3)`, where `A_ideal = |e1 x e2|_1` (the
//! sum of its projected areas, twice) is the least total box area any number of pieces
//! can reach, and `l_t` is the level of the coarsest plane of the dyadic grid over the
//! mesh bounds that crosses the triangle's box: coarse planes are where the top of the
//! tree splits and overlap costs most. Triangle `t` gets `floor(D p_t)` splits, `D` the
//! largest scale whose splits fit the budget. Each split cuts at the coarsest grid plane
//! crossing the piece, and the remaining splits go to the two halves in proportion to
//! their excess area `A_box - A_ideal`.

use filtrace_core::{Aabb, Vec3};

/// Most splits of one triangle (a bound on the recursion, far above what budgets give).
const MAX_SPLITS_PER_TRIANGLE: usize = 255;

/// Only triangles whose box area exceeds this multiple of their least box area
/// ([`ideal_area`]) are split. Every triangle has a ratio of about 2 or more (2 for one in
/// an axis plane), and pieces of such well-boxed triangles only add references: on the
/// suite's grass (near-vertical blades, ratio 2-4) splitting them raised the SAH cost
/// of the tree by 5-10 %; long thin diagonal triangles have ratios of 10-100.
const MIN_BOX_RATIO: f32 = 8.0;

/// Finest level of the dyadic grid searched for split planes.
const MAX_LEVEL: u32 = 24;

/// Piece boxes grow by this fraction of the mesh's largest coordinate (then are clamped
/// to the triangle's box), so that the rounding of the clipped vertices never leaves a
/// sliver of the triangle outside every piece.
const PIECE_SLACK: f32 = 1.0 / (1u32 << 20) as f32;

/// What the builder builds over: reference `k` is the part of triangle `tri[k]` (an
/// index into the caller's list) inside `boxes[k]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Refs {
    pub tri: Vec<u32>,
    pub boxes: Vec<Aabb>,
}

impl Refs {
    fn push(&mut self, tri: usize, b: Aabb) {
        self.tri.push(tri as u32);
        self.boxes.push(b);
    }
}

/// References to the triangles `corners(i)` (`i < boxes.len()`, `boxes[i]` their boxes),
/// with at most `budget * n` extra references from splits (`budget <= 0`: none, one
/// reference per triangle in order).
pub(crate) fn presplit(boxes: &[Aabb], corners: impl Fn(usize) -> [Vec3; 3], budget: f32) -> Refs {
    let n = boxes.len();
    // (At most `MAX_SPLITS_PER_TRIANGLE` per triangle can be used, whatever the budget.)
    let extra = (f64::from(budget.max(0.0)) * n as f64).min((n * MAX_SPLITS_PER_TRIANGLE) as f64) as usize;
    let grid = Grid::new(boxes.iter().copied().fold(Aabb::EMPTY, Aabb::union));
    let priority: Vec<f64> =
        if extra == 0 { Vec::new() } else { (0..n).map(|i| grid.priority(&boxes[i], &corners(i))).collect() };
    let scale = budget_scale(&priority, extra);
    let capacity = n + extra.min(n);
    let mut refs = Refs { tri: Vec::with_capacity(capacity), boxes: Vec::with_capacity(capacity) };
    for (i, &b) in boxes.iter().enumerate() {
        let splits = priority.get(i).map_or(0, |p| (scale * p) as usize).min(MAX_SPLITS_PER_TRIANGLE);
        if splits == 0 {
            refs.push(i, b);
        } else {
            let tri = corners(i);
            grid.split(&tri, b, grid.whole(&tri, b), splits, &mut |piece| refs.push(i, piece));
        }
    }
    refs
}

/// The largest `D` (to a relative 1e-6) with `sum floor(D p_i) <= extra`.
fn budget_scale(priority: &[f64], extra: usize) -> f64 {
    let total: f64 = priority.iter().sum();
    if extra == 0 || total <= 0.0 {
        return 0.0;
    }
    let splits = |d: f64| priority.iter().map(|p| (d * p).floor()).sum::<f64>();
    // `sum floor(D p) <= sum D p`, and `>= sum (D p - 1)`: the answer lies in between.
    let (mut lo, mut hi) = (extra as f64 / total, (extra + priority.len()) as f64 / total);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if splits(mid) <= extra as f64 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-6 * lo {
            break;
        }
    }
    lo
}

/// Least total box area of pieces of the convex polygon `v`: twice the sum of its areas
/// projected onto the three axis planes.
fn ideal_area(v: &[Vec3]) -> f32 {
    let Some(&v0) = v.first() else { return 0.0 };
    let twice_area = v.windows(2).skip(1).fold(Vec3::ZERO, |a, w| a + (w[0] - v0).cross(w[1] - v0));
    twice_area.abs().element_sum()
}

/// The dyadic grid over the mesh bounds whose planes the splits follow.
struct Grid {
    bounds: Aabb,
    slack: f32,
}

impl Grid {
    fn new(bounds: Aabb) -> Self {
        let largest = bounds.min.abs().max(bounds.max.abs()).max_element();
        Self { bounds, slack: largest * PIECE_SLACK }
    }

    /// Split priority of a whole triangle (0: no plane crosses its box).
    fn priority(&self, b: &Aabb, tri: &[Vec3; 3]) -> f64 {
        let Some((level, ..)) = self.coarsest_plane(b) else { return 0.0 };
        let (area, ideal) = (b.surface_area(), ideal_area(tri));
        // (Also when the areas overflow to infinity.)
        if area.partial_cmp(&(MIN_BOX_RATIO * ideal)) != Some(std::cmp::Ordering::Greater) {
            return 0.0;
        }
        let p = (f64::from(area - ideal) * 0.5f64.powi(level as i32)).cbrt();
        if p.is_finite() {
            p
        } else {
            0.0
        }
    }

    /// The coarsest grid plane strictly inside `b`, as `(level, axis, position)`; ties go
    /// to the axis on which `b` is longest. `None` when `b` is too small to cut.
    fn coarsest_plane(&self, b: &Aabb) -> Option<(u32, usize, f32)> {
        let mut best: Option<(u32, usize, f32)> = None;
        for axis in 0..3 {
            let Some((level, pos)) = self.plane_on(b, axis) else { continue };
            let longer = |a: usize| b.max[axis] - b.min[axis] > b.max[a] - b.min[a];
            if best.is_none_or(|(l, a, _)| level < l || (level == l && longer(a))) {
                best = Some((level, axis, pos));
            }
        }
        best
    }

    /// The coarsest grid plane on `axis` strictly inside `b`. On the finest level the
    /// planes inside are the integers `lo..=hi`; the coarsest is the one with the most
    /// trailing zero bits.
    fn plane_on(&self, b: &Aabb, axis: usize) -> Option<(u32, f32)> {
        let origin = f64::from(self.bounds.min[axis]);
        let extent = f64::from(self.bounds.max[axis]) - origin;
        let finest = f64::from(1u32 << MAX_LEVEL);
        let cell = |x: f32| (f64::from(x) - origin) / extent * finest;
        if !(extent > 0.0 && b.max[axis] > b.min[axis]) {
            return None;
        }
        let (lo, hi) =
            (cell(b.min[axis]).floor() as u64 + 1, (cell(b.max[axis]).ceil() as u64).saturating_sub(1));
        if lo > hi || hi >= 1 << MAX_LEVEL {
            return None;
        }
        let plane = if lo == hi {
            lo
        } else {
            // Above their highest differing bit `d`, `lo` and `hi` agree; the prefix with
            // bit `d` set lies in the range, unless `lo` itself is a multiple of `2^(d+1)`.
            let d = 63 - (lo ^ hi).leading_zeros();
            if lo.trailing_zeros() > d {
                lo
            } else {
                hi >> d << d
            }
        };
        let level = MAX_LEVEL - plane.trailing_zeros().min(MAX_LEVEL);
        let pos = (origin + plane as f64 / finest * extent) as f32;
        (pos > b.min[axis] && pos < b.max[axis]).then_some((level, pos))
    }

    /// Cuts `piece`, the part of `tri` inside `region`, with `splits` planes and emits the
    /// boxes of the `splits + 1` pieces (fewer when the planes run out). Pieces are
    /// always clipped from the whole triangle by the planes bounding their region, so
    /// rounding does not pile up with depth.
    fn split(&self, tri: &[Vec3; 3], region: Aabb, piece: Piece, splits: usize, emit: &mut impl FnMut(Aabb)) {
        if splits == 0 {
            return emit(piece.bounds);
        }
        let Some((_, axis, pos)) = self.coarsest_plane(&piece.tight) else { return emit(piece.bounds) };
        let (mut below, mut above) = (region, region);
        below.max[axis] = pos;
        above.min[axis] = pos;
        match (self.clip(tri, &below), self.clip(tri, &above)) {
            (Some(l), Some(r)) => {
                let (wl, wr) = (l.excess().max(0.0), r.excess().max(0.0));
                let rest = splits - 1;
                let share = if wl + wr > 0.0 { wl / (wl + wr) } else { 0.5 };
                let left = ((rest as f32 * share).round() as usize).min(rest);
                self.split(tri, below, l, left, emit);
                self.split(tri, above, r, rest - left, emit);
            }
            // The plane only grazes the triangle (rounding): go on with the side it is on.
            (Some(l), None) => self.split(tri, below, l, splits - 1, emit),
            (None, Some(r)) => self.split(tri, above, r, splits - 1, emit),
            (None, None) => emit(piece.bounds),
        }
    }

    /// The whole triangle as a piece.
    fn whole(&self, tri: &[Vec3; 3], b: Aabb) -> Piece {
        Piece { tight: b, bounds: b, ideal: ideal_area(tri) }
    }

    /// The part of `tri` inside `region` (`None` when empty).
    fn clip(&self, tri: &[Vec3; 3], region: &Aabb) -> Option<Piece> {
        let poly = clip_triangle(tri, region)?;
        let tight = poly.bounds_within(tri, region);
        let grown = Aabb { min: tight.min - self.slack, max: tight.max + self.slack };
        Some(Piece {
            tight,
            bounds: within(grown, &Aabb::from_points(*tri)),
            ideal: ideal_area(poly.vertices()),
        })
    }
}

/// A piece of a triangle: its box, the box grown by the slack (what the builder gets),
/// and the least area of its boxes.
struct Piece {
    tight: Aabb,
    bounds: Aabb,
    ideal: f32,
}

impl Piece {
    fn excess(&self) -> f32 {
        self.tight.surface_area() - self.ideal
    }
}

/// A triangle clipped by six planes has at most nine vertices; rounding can add a few
/// (a nearly parallel edge whose ends fall on both sides of a plane more than once).
const MAX_VERTICES: usize = 16;

/// A convex polygon, vertices in order.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Polygon {
    v: [Vec3; MAX_VERTICES],
    n: usize,
    /// Vertices were dropped for want of room: the vertices no longer bound the part.
    overflow: bool,
}

impl Polygon {
    pub(crate) fn vertices(&self) -> &[Vec3] {
        &self.v[..self.n]
    }

    /// The box of this part of `tri` clipped to `region`, within `region` (the triangle's
    /// box within it when vertices overflowed).
    pub(crate) fn bounds_within(&self, tri: &[Vec3; 3], region: &Aabb) -> Aabb {
        if self.overflow {
            within(*region, &Aabb::from_points(*tri))
        } else {
            within(Aabb::from_points(self.vertices().iter().copied()), region)
        }
    }

    fn push(&mut self, p: Vec3) {
        if self.n < MAX_VERTICES {
            self.v[self.n] = p;
            self.n += 1;
        } else {
            self.overflow = true;
        }
    }

    /// Sutherland-Hodgman: the part on one side of the plane `x[axis] = pos` (`keep_below`:
    /// `x[axis] <= pos`). Crossing points lie exactly on the plane.
    fn clip(&self, axis: usize, pos: f32, keep_below: bool) -> Polygon {
        let inside = |p: Vec3| if keep_below { p[axis] <= pos } else { p[axis] >= pos };
        let mut out = Polygon { v: [Vec3::ZERO; MAX_VERTICES], n: 0, overflow: self.overflow };
        for i in 0..self.n {
            let (a, b) = (self.v[i], self.v[(i + 1) % self.n]);
            if inside(a) {
                out.push(a);
            }
            if inside(a) != inside(b) {
                out.push(crossing(a, b, axis, pos));
            }
        }
        out
    }
}

/// Where the segment `ab` crosses the plane `x[axis] = pos`, computed from its lower end
/// so that both orientations of an edge give the same point.
pub(crate) fn crossing(a: Vec3, b: Vec3, axis: usize, pos: f32) -> Vec3 {
    let (a, b) = if a[axis] <= b[axis] { (a, b) } else { (b, a) };
    let t = ((pos - a[axis]) / (b[axis] - a[axis])).clamp(0.0, 1.0);
    let mut p = a + (b - a) * t;
    p[axis] = pos;
    p
}

/// `b` cut down to `outer`.
pub(crate) fn within(b: Aabb, outer: &Aabb) -> Aabb {
    Aabb { min: b.min.max(outer.min), max: b.max.min(outer.max) }
}

/// The part of triangle `tri` inside the box `region` (`None` when empty).
pub(crate) fn clip_triangle(tri: &[Vec3; 3], region: &Aabb) -> Option<Polygon> {
    let mut poly = Polygon { v: [Vec3::ZERO; MAX_VERTICES], n: 3, overflow: false };
    poly.v[..3].copy_from_slice(tri);
    for axis in 0..3 {
        if tri.iter().any(|p| p[axis] < region.min[axis]) {
            poly = poly.clip(axis, region.min[axis], false);
        }
        if tri.iter().any(|p| p[axis] > region.max[axis]) {
            poly = poly.clip(axis, region.max[axis], true);
        }
        if poly.n == 0 {
            return None;
        }
    }
    Some(poly)
}

/// A point of `tri` (on a grid of barycentric coordinates, vertices and edges included)
/// inside none of `boxes`: `None` when they cover the triangle (as far as sampled).
pub(crate) fn uncovered_point(tri: &[Vec3; 3], boxes: &[Aabb]) -> Option<Vec3> {
    const STEPS: u32 = 12;
    let inside = |p: Vec3, b: &Aabb| p.cmpge(b.min).all() && p.cmple(b.max).all();
    (0..=STEPS)
        .flat_map(|i| (0..=STEPS - i).map(move |j| (i, j)))
        .map(|(i, j)| {
            let (u, v) = (i as f32 / STEPS as f32, j as f32 / STEPS as f32);
            tri[0] + (tri[1] - tri[0]) * u + (tri[2] - tri[0]) * v
        })
        .find(|&p| !boxes.iter().any(|b| inside(p, b)))
}

#[cfg(test)]
#[path = "presplit_tests.rs"]
mod tests;
