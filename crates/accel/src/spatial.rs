//! Spatial splits in the BVH build: the SBVH of Stich, Friedrich and Dietrich, "Spatial
//! splits in bounding volume hierarchies" (HPG 2009), binned as in Embree's "fast spatial
//! SAH" builder.
//!
//! An object split (`sah.rs`) puts every reference whole into one child, so the children
//! of a node with long or large triangles overlap, and rays visit both. A spatial split
//! cuts the node's box by an axis-aligned plane instead: references left of it go left,
//! those right of it go right, and a reference straddling it is split in two, each side
//! getting the box of the triangle clipped to its half ("chopped binning": the boxes
//! binned are those of the triangle clipped to each bin's slab). Per node (sec. 4):
//!
//! 1. find the best object split by binning centroids, as `sah.rs` does;
//! 2. only when its children overlap by more than `α = 1e-5` of the root's area
//!    (sec. 4.3: deep in the tree overlap is cheap and splits only add references), bin
//!    the references spatially over the node's box: each is entered in its first bin,
//!    leaves from its last, and its clipped part is grown into every bin it spans; a
//!    sweep gives the SAH cost of each plane, counting straddling references on both
//!    sides;
//! 3. take the spatial split when it is cheaper than the object split, then "unsplit"
//!    straddling references (sec. 4.4): a reference goes whole to one side when that is
//!    cheaper by the SAH than splitting it.
//!
//! Splits are limited by a budget of extra references, `spatial_split_budget * n`: each
//! node passes what it did not use to its children in proportion to their references
//! (as Embree does), so the tree does not depend on which thread built what.
//! The leaves may reference a triangle more than once; `blas.rs` stores it once per leaf.

use crate::presplit::{crossing, within};
use crate::sah::{best_object_split, bin_of, sweep, BuildNode, BuildParams, Split, MAX_DEPTH};
use filtrace_core::{Aabb, Vec3};

/// Overlap threshold `α` of the paper: spatial splits are tried only in nodes whose best
/// object split's children overlap by more than this fraction of the root's area.
const MIN_OVERLAP: f32 = 1e-5;

/// Split pieces grow by this fraction of the mesh's largest coordinate (clamped to the
/// reference's box): the padding every reference box has (`flat_blas::padded_boxes`) and
/// the slack of `presplit.rs`, so that neither the rounding of the edges' crossings nor that
/// of the watertight test leaves a sliver of a triangle outside every piece.
const PIECE_GROWTH: f32 = 2.0 / (1u32 << 20) as f32;

/// A reference: the part of triangle `id` (an index into the builder's references)
/// inside `bounds`.
#[derive(Clone, Copy, Debug)]
struct Ref {
    bounds: Aabb,
    id: u32,
}

/// Builds a binary BVH with object and spatial splits over the references `boxes`, where
/// `boxes[i]` bounds the part of triangle `corners[i]` to be found through it. Returns the
/// tree and the reference order its leaves refer to; a reference split by the builder
/// appears once for each leaf that holds a piece of it.
pub(crate) fn build_spatial(
    boxes: &[Aabb],
    corners: &[[Vec3; 3]],
    params: &BuildParams,
) -> (Option<BuildNode>, Vec<u32>) {
    let mut order = Vec::with_capacity(boxes.len());
    if boxes.is_empty() {
        return (None, order);
    }
    let refs: Vec<Ref> = boxes.iter().enumerate().map(|(i, &bounds)| Ref { bounds, id: i as u32 }).collect();
    let root = boxes.iter().copied().fold(Aabb::EMPTY, Aabb::union);
    let largest = root.min.abs().max(root.max.abs()).max_element();
    let ctx = Ctx {
        corners,
        params,
        bins: params.bins.clamp(2, 64),
        spatial_bins: params.spatial_bins.clamp(2, 64),
        min_overlap: MIN_OVERLAP * root.surface_area(),
        growth: Vec3::splat(largest * PIECE_GROWTH),
    };
    let budget = f64::from(params.spatial_split_budget.max(0.0)) * boxes.len() as f64;
    let tree = ctx.build(refs, 0, budget.min(u32::MAX as f64) as usize);
    (Some(tree.flatten(&mut order)), order)
}

/// The build tree before its leaves are laid out in one list.
enum Tree {
    Leaf { bounds: Aabb, refs: Vec<u32> },
    Inner { bounds: Aabb, children: Box<[Tree; 2]> },
}

impl Tree {
    fn leaf(bounds: Aabb, refs: &[Ref]) -> Self {
        Tree::Leaf { bounds, refs: refs.iter().map(|r| r.id).collect() }
    }

    /// The [`BuildNode`] tree, its leaves' references appended to `order`.
    fn flatten(self, order: &mut Vec<u32>) -> BuildNode {
        match self {
            Tree::Leaf { bounds, refs } => {
                let first = order.len() as u32;
                order.extend_from_slice(&refs);
                BuildNode::Leaf { bounds, first, count: refs.len() as u32 }
            }
            Tree::Inner { bounds, children } => {
                let [l, r] = *children;
                let l = l.flatten(order);
                BuildNode::Inner { bounds, children: Box::new([l, r.flatten(order)]) }
            }
        }
    }
}

struct Ctx<'a> {
    corners: &'a [[Vec3; 3]],
    params: &'a BuildParams,
    /// Object-split bins.
    bins: usize,
    /// Spatial-split bins.
    spatial_bins: usize,
    /// `α` times the root's area.
    min_overlap: f32,
    growth: Vec3,
}

/// The best spatial split: the plane `x[axis] = pos` and its SAH cost (as [`Split::cost`]).
struct SpatialSplit {
    axis: usize,
    pos: f32,
    cost: f32,
}

/// The two children of a node and the references split to make them.
struct Children {
    left: Vec<Ref>,
    right: Vec<Ref>,
    split: usize,
}

impl Ctx<'_> {
    fn build(&self, refs: Vec<Ref>, depth: usize, budget: usize) -> Tree {
        let (bounds, cbounds) = refs.iter().fold((Aabb::EMPTY, Aabb::EMPTY), |(b, c), r| {
            (b.union(r.bounds), c.grow_point(r.bounds.center()))
        });
        let n = refs.len();
        if n == 1 || depth >= MAX_DEPTH {
            return Tree::leaf(bounds, &refs);
        }
        let p = self.params;
        let object =
            best_object_split(refs.iter().map(|r| (r.bounds, r.bounds.center())), &cbounds, self.bins, |c| {
                self.blocks(c)
            });
        let spatial = self.spatial_candidate(&refs, &bounds, &cbounds, object.as_ref(), budget);
        let best_cost = match (&object, &spatial) {
            (_, Some(s)) => Some(s.cost),
            (Some(o), None) => Some(o.cost),
            (None, None) => None,
        };
        if n <= p.max_leaf_size {
            let leaf_cost = p.intersection_cost * self.blocks(n as u32);
            let split_cost = best_cost.map(|c| {
                p.traversal_cost + p.intersection_cost * c / bounds.surface_area().max(f32::MIN_POSITIVE)
            });
            if split_cost.is_none_or(|c| leaf_cost <= c) {
                return Tree::leaf(bounds, &refs);
            }
        }
        let children = match spatial {
            Some(s) => self.split_spatially(refs, &s),
            None => Err(refs),
        }
        .unwrap_or_else(|refs| self.split_by_objects(refs, &cbounds, object.as_ref()));
        // (The plane's straddlers may differ from the bins' by rounding.)
        let rest = budget.saturating_sub(children.split);
        let (nl, nr) = (children.left.len(), children.right.len());
        let left_budget = (rest as f64 * nl as f64 / (nl + nr) as f64) as usize;
        let (l, r) = if n > p.parallel_threshold {
            rayon::join(
                || self.build(children.left, depth + 1, left_budget),
                || self.build(children.right, depth + 1, rest - left_budget),
            )
        } else {
            (
                self.build(children.left, depth + 1, left_budget),
                self.build(children.right, depth + 1, rest - left_budget),
            )
        };
        Tree::Inner { bounds, children: Box::new([l, r]) }
    }

    /// Number of `leaf_block`-sized blocks needed for `n` references.
    #[inline]
    fn blocks(&self, n: u32) -> f32 {
        n.div_ceil(self.params.leaf_block.max(1) as u32) as f32
    }

    /// The spatial split to take instead of `object`, if any: only when the budget allows
    /// a split, the object split's children overlap by more than `α` (or no object split
    /// exists), and the spatial one is cheaper.
    fn spatial_candidate(
        &self,
        refs: &[Ref],
        bounds: &Aabb,
        cbounds: &Aabb,
        object: Option<&Split>,
        budget: usize,
    ) -> Option<SpatialSplit> {
        if budget == 0 {
            return None;
        }
        if let Some(o) = object {
            let (l, r) = self.object_children_bounds(refs, cbounds, o);
            let overlap = within(l, &r);
            if overlap.is_empty() || overlap.surface_area() <= self.min_overlap {
                return None;
            }
        }
        let s = self.best_spatial_split(refs, bounds, budget)?;
        object.is_none_or(|o| s.cost < o.cost).then_some(s)
    }

    /// Bounds of the two children of the object split `s`.
    fn object_children_bounds(&self, refs: &[Ref], cbounds: &Aabb, s: &Split) -> (Aabb, Aabb) {
        let (lo, scale) = (cbounds.min[s.axis], self.bins as f32 / cbounds.extent()[s.axis]);
        refs.iter().fold((Aabb::EMPTY, Aabb::EMPTY), |(l, r), x| {
            if bin_of(x.bounds.center()[s.axis], lo, scale, self.bins) <= s.bin {
                (l.union(x.bounds), r)
            } else {
                (l, r.union(x.bounds))
            }
        })
    }

    /// Chopped spatial binning over `bounds` on every axis (sec. 4.2) and the cheapest
    /// plane that splits at most `budget` references.
    fn best_spatial_split(&self, refs: &[Ref], bounds: &Aabb, budget: usize) -> Option<SpatialSplit> {
        let k = self.spatial_bins;
        let n = refs.len() as u32;
        let extent = bounds.extent();
        let mut best: Option<SpatialSplit> = None;
        let (mut bin_box, mut enter, mut exit) = ([Aabb::EMPTY; 64], [0u32; 64], [0u32; 64]);
        for axis in 0..3 {
            if extent[axis] <= 0.0 {
                continue;
            }
            let (lo, scale) = (bounds.min[axis], k as f32 / extent[axis]);
            let plane = |j: usize| lo + extent[axis] * (j as f32 / k as f32);
            bin_box[..k].fill(Aabb::EMPTY);
            enter[..k].fill(0);
            exit[..k].fill(0);
            for r in refs {
                let first = bin_of(r.bounds.min[axis], lo, scale, k);
                let last = bin_of(r.bounds.max[axis], lo, scale, k).max(first);
                enter[first] += 1;
                exit[last] += 1;
                if first == last {
                    bin_box[first] = bin_box[first].union(r.bounds);
                    continue;
                }
                // Chop the reference bin by bin, left to right.
                let mut rest = r.bounds;
                for (j, b) in bin_box.iter_mut().enumerate().take(last).skip(first) {
                    let (left, right) = split_bounds(&self.corners[r.id as usize], axis, plane(j + 1), &rest);
                    if !left.is_empty() {
                        *b = b.union(left);
                    }
                    rest = right;
                }
                if !rest.is_empty() {
                    bin_box[last] = bin_box[last].union(rest);
                }
            }
            let fits = |l: u32, r: u32| (l + r).saturating_sub(n) as usize <= budget;
            let Some((j, cost)) = sweep(&bin_box[..k], &enter[..k], &exit[..k], |c| self.blocks(c), fits)
            else {
                continue;
            };
            if best.as_ref().is_none_or(|b| cost < b.cost) {
                best = Some(SpatialSplit { axis, pos: plane(j + 1), cost });
            }
        }
        best
    }

    /// Partitions `refs` by the plane of `s`, splitting or unsplitting those that straddle
    /// it; `Err(refs)` when a side would be empty.
    fn split_spatially(&self, refs: Vec<Ref>, s: &SpatialSplit) -> Result<Children, Vec<Ref>> {
        let (axis, pos) = (s.axis, s.pos);
        let (mut left, mut right, mut straddling) = (Vec::new(), Vec::new(), Vec::new());
        for r in refs {
            if r.bounds.max[axis] <= pos {
                left.push(r);
            } else if r.bounds.min[axis] >= pos {
                right.push(r);
            } else {
                straddling.push((r, self.pieces(&r, axis, pos)));
            }
        }
        let fold = |side: &[Ref]| side.iter().fold(Aabb::EMPTY, |b, r| b.union(r.bounds));
        let (mut lbox, mut rbox) = (fold(&left), fold(&right));
        for (_, (l, r)) in &straddling {
            lbox = l.map_or(lbox, |b| lbox.union(b));
            rbox = r.map_or(rbox, |b| rbox.union(b));
        }
        let mut nl = (left.len() + straddling.iter().filter(|s| s.1 .0.is_some()).count()) as f32;
        let mut nr = (right.len() + straddling.iter().filter(|s| s.1 .1.is_some()).count()) as f32;
        let mut split = 0;
        for (r, halves) in straddling {
            match halves {
                (Some(lb), Some(rb)) => {
                    // Reference unsplitting (sec. 4.4), with the paper's per-triangle costs.
                    let c_split = lbox.surface_area() * nl + rbox.surface_area() * nr;
                    let (l_whole, r_whole) = (lbox.union(r.bounds), rbox.union(r.bounds));
                    let c_left = l_whole.surface_area() * nl + rbox.surface_area() * (nr - 1.0);
                    let c_right = lbox.surface_area() * (nl - 1.0) + r_whole.surface_area() * nr;
                    if c_left < c_split && c_left <= c_right {
                        (lbox, nr) = (l_whole, nr - 1.0);
                        left.push(r);
                    } else if c_right < c_split {
                        (rbox, nl) = (r_whole, nl - 1.0);
                        right.push(r);
                    } else {
                        left.push(Ref { bounds: lb, ..r });
                        right.push(Ref { bounds: rb, ..r });
                        split += 1;
                    }
                }
                // The box crosses the plane, the triangle only touches it (or not).
                (_, None) => left.push(r),
                (None, Some(_)) => right.push(r),
            }
        }
        if left.is_empty() || right.is_empty() {
            left.append(&mut right);
            return Err(left);
        }
        Ok(Children { left, right, split })
    }

    /// The boxes of the parts of `r`'s triangle on either side of the plane `x[axis] =
    /// pos`, grown by [`PIECE_GROWTH`] within `r`'s box (`None`: no part on that side).
    fn pieces(&self, r: &Ref, axis: usize, pos: f32) -> (Option<Aabb>, Option<Aabb>) {
        let (left, right) = split_bounds(&self.corners[r.id as usize], axis, pos, &r.bounds);
        let grow = |b: Aabb| {
            (!b.is_empty())
                .then(|| within(Aabb { min: b.min - self.growth, max: b.max + self.growth }, &r.bounds))
        };
        (grow(left), grow(right))
    }

    /// The object split `s` (none: halves, as `sah.rs` does when all centroids coincide).
    fn split_by_objects(&self, mut refs: Vec<Ref>, cbounds: &Aabb, s: Option<&Split>) -> Children {
        let Some(s) = s else {
            let right = refs.split_off(refs.len() / 2);
            return Children { left: refs, right, split: 0 };
        };
        let (lo, scale) = (cbounds.min[s.axis], self.bins as f32 / cbounds.extent()[s.axis]);
        let (left, right): (Vec<Ref>, Vec<Ref>) =
            refs.into_iter().partition(|r| bin_of(r.bounds.center()[s.axis], lo, scale, self.bins) <= s.bin);
        debug_assert!(!left.is_empty() && !right.is_empty(), "binned split left one side empty");
        Children { left, right, split: 0 }
    }
}

/// The boxes of the parts of triangle `tri` below and above the plane `x[axis] = pos`,
/// each cut down to its side of `region` (empty where the triangle has no part there).
/// As Embree's spatial splits do, from the corners and the edges' crossings of the plane:
/// for a reference to a piece of the triangle (`region` its box) the result bounds the
/// piece's parts, if not tightly.
fn split_bounds(tri: &[Vec3; 3], axis: usize, pos: f32, region: &Aabb) -> (Aabb, Aabb) {
    let (mut below, mut above) = (Aabb::EMPTY, Aabb::EMPTY);
    for i in 0..3 {
        let (a, b) = (tri[i], tri[(i + 1) % 3]);
        if a[axis] <= pos {
            below = below.grow_point(a);
        }
        if a[axis] >= pos {
            above = above.grow_point(a);
        }
        if (a[axis] < pos && b[axis] > pos) || (a[axis] > pos && b[axis] < pos) {
            let p = crossing(a, b, axis, pos);
            (below, above) = (below.grow_point(p), above.grow_point(p));
        }
    }
    let (mut below_region, mut above_region) = (*region, *region);
    below_region.max[axis] = pos;
    above_region.min[axis] = pos;
    (within(below, &below_region), within(above, &above_region))
}
