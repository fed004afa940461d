//! Binary BVH construction with the binned surface area heuristic.
//!
//! The SAH (Goldsmith & Salmon 1987; MacDonald & Booth, "Heuristics for ray tracing using
//! space subdivision", 1990) estimates the cost of a split of node `N` into `L` and `R` as
//!
//! `C = C_trav + C_isect * (SA(L) |L| + SA(R) |R|) / SA(N)`,
//!
//! the expected work for a random ray that hits `N`. Following Wald, "On fast Construction
//! of SAH-based Bounding Volume Hierarchies" (IEEE RT 2007), candidate planes are not every
//! primitive but the boundaries of `K` equal bins over the *centroid* bounds, on each axis:
//! one pass bins the primitives, one sweep from each side evaluates all `K - 1` planes.
//! A node becomes a leaf when that is cheaper than its best split (`C_isect * |N|`) and
//! it holds at most `max_leaf_size` primitives. Subtrees above `parallel_threshold`
//! primitives are built with `rayon::join`.
//!
//! The builder sees only bounding boxes (as obvhs's does), so the same code builds the
//! per-mesh bottom levels (boxes of triangles) and the top level (boxes of instances).

use filtrace_core::{Aabb, Vec3};

/// Parameters of the binned SAH build, with named presets.
#[derive(Clone, Debug, PartialEq)]
pub struct BuildParams {
    /// Number of bins `K` per axis for object splits (Wald 2007 uses 16-32; more bins,
    /// better trees).
    pub bins: usize,
    /// Number of bins per axis for spatial splits ([`BuildParams::spatial_split_budget`]),
    /// whose binning clips every straddling triangle to the bins it crosses: the larger
    /// part of a spatial build's time.
    pub spatial_bins: usize,
    /// Largest leaf; nodes with more primitives are always split.
    pub max_leaf_size: usize,
    /// SAH cost of visiting one node, `C_trav`.
    pub traversal_cost: f32,
    /// SAH cost of one primitive test, `C_isect`.
    pub intersection_cost: f32,
    /// Primitives are tested `leaf_block` at a time (4: the SIMD triangle packets), so
    /// leaf and child costs count blocks, `ceil(n / leaf_block)`, not primitives (as
    /// Embree's SAH does for its Triangle4 leaves). The AVX2 kernels, which test two
    /// packets at once, build with blocks of `2 * leaf_block`.
    pub leaf_block: usize,
    /// Subtrees with more primitives than this are built in parallel.
    pub parallel_threshold: usize,
    /// Bottom levels of at most this many triangles get no hierarchy: every ray tests
    /// all their packets, largest triangles first (the flat path of `SceneAccel`). On
    /// tiny closed scenes such as the Cornell box (36 triangles) every box of a BVH
    /// overlaps the room, so node tests buy no culling. 40 in every preset, from the ray
    /// bench (AVX2, `docs/perf-accel.md`): Cornell box flat vs 8-wide BVH +10-20 %
    /// incoherent closest and +50 % any hit (primary -10-25 %); a 48-triangle displaced
    /// sphere even (primary -11 %); 108 triangles -18 % closest.
    pub max_flat_triangles: usize,
    /// Pre-splitting of long thin triangles in bottom levels (`presplit.rs`, Karras &
    /// Aila 2013): up to `split_budget * n` extra references to the `n` triangles, each
    /// the box of a clipped piece of a triangle whose box is much larger than it; leaves
    /// may then reference a triangle more than once. 0 turns it off.
    pub split_budget: f32,
    /// Bottom levels of at least this many triangles built for the AVX2 kernels get
    /// compressed 8-wide nodes (`qwide.rs`: child boxes as 8-bit grid offsets, 128 bytes a
    /// node instead of 256); 0: every BVH, `usize::MAX`: none. The presets use
    /// [`MIN_QUANTIZED_TRIANGLES`].
    pub min_quantized_triangles: usize,
    /// Spatial splits in bottom levels (`spatial.rs`, Stich et al. 2009, "SBVH"): besides
    /// object splits, the builder may cut a node's triangles by a plane, a triangle
    /// straddling it then referenced from both children, up to `spatial_split_budget * n`
    /// extra references to the `n` references of the mesh; the split tree is kept only
    /// where its SAH cost is lower than the plain one's. Pays on overlapping triangles
    /// (engine: -12..-20 % closest-hit instructions), nothing on grass and bunny-room, for
    /// 2.4-4.3x the build (`docs/perf-accel.md` "Stop 18"). 0 turns it off
    /// (`fastest_build`); `balanced` and `high_quality` use 0.3;
    /// [`BuildParams::default`] takes it from the environment variable
    /// [`SPATIAL_SPLITS_ENV`] when set, for measuring whole renders.
    pub spatial_split_budget: f32,
    /// Bottom levels of more references than this are built without spatial splits: the
    /// spatial builder bins each node on one thread and builds the plain tree too, which
    /// on the 1M-triangle `grass-1m` took 2 s -> 11-13 s for rays no faster (SAH -1.7 %).
    pub max_spatial_split_references: usize,
}

/// Environment variable that sets [`BuildParams::spatial_split_budget`] of
/// [`BuildParams::default`] (e.g. `FILTRACE_SPATIAL_SPLITS=0.3`): a measurement knob for
/// `filtrace bench suite` and renders. Values as [`parse_spatial_splits`] reads them; unset
/// or empty: the preset's; anything else: the preset's, with one warning per process.
pub const SPATIAL_SPLITS_ENV: &str = "FILTRACE_SPATIAL_SPLITS";

/// Extra references `balanced` and `high_quality` allow for spatial splits (a fraction of
/// the references). Release, idle machine, interleaved (`docs/perf-accel.md` "Stop 18"):
/// the engine's incoherent closest hits +20-30 %, its render +15-25 %; bunny-room and
/// grass keep their plain trees (build +0.15-0.2 s on 2 threads); the engine's build
/// 0.1 -> 0.44 s.
const SPATIAL_SPLIT_BUDGET: f32 = 0.3;

/// Largest bottom level `balanced` builds with spatial splits
/// ([`BuildParams::max_spatial_split_references`]).
const MAX_SPATIAL_SPLIT_REFERENCES: usize = 1 << 18;

/// Extra references the presets allow for split triangles (a fraction of the triangles):
/// none. On the suite's meshes (grass, engine, bunny-room, bunny, teapot) splitting with a
/// budget of 0.3 changed the SAH cost by -1..+2 % and ray speed within the noise, and
/// cost up to twice the build time; it pays on long thin diagonal triangles
/// (`testmesh::thin_blades`: SAH -13 %, closest hits +17 %), see `docs/perf-accel.md`
/// "Stop 15".
const SPLIT_BUDGET: f32 = 0.0;

/// Smallest bottom level given compressed nodes by the presets
/// ([`BuildParams::min_quantized_triangles`]): 2 M triangles. Incoherent closest hits, 1
/// thread, compressed vs uncompressed (`raybench grass:N --qnodes`, loaded machine,
/// `docs/perf-accel.md` "Stop 16"): grass 2 M and 3.3 M triangles +5 %, grass-1m even (its
/// 12 MB of nodes fit the L3; its triangles do not), 56k-82k meshes -1..-7 %, and a single
/// compressed mesh loses the 8-ray packet traversal of camera tiles.
pub const MIN_QUANTIZED_TRIANGLES: usize = 2_000_000;

impl BuildParams {
    /// Fewest bins and no spatial splits: fastest build, slightly slower traversal.
    pub fn fastest_build() -> Self {
        Self {
            bins: 8,
            spatial_bins: 8,
            spatial_split_budget: 0.0,
            max_spatial_split_references: 0,
            ..Self::balanced()
        }
    }

    /// The default: 32 object bins, 16 spatial bins. 32 object bins over 16 (1 thread,
    /// incoherent closest hits, `docs/perf-accel.md` "Stop 22"): teapot +3-7 %,
    /// bunny-room +5 %, grass-1m +5-13 %, for a build up to 25 % longer (grass). 32
    /// spatial bins would make the build of grass and bunny-room 55-65 % longer again
    /// for no measured gain.
    pub fn balanced() -> Self {
        Self {
            bins: 32,
            spatial_bins: 16,
            max_leaf_size: 8,
            traversal_cost: 1.0,
            intersection_cost: 1.0,
            leaf_block: 4,
            parallel_threshold: 4096,
            max_flat_triangles: 40,
            split_budget: SPLIT_BUDGET,
            min_quantized_triangles: MIN_QUANTIZED_TRIANGLES,
            spatial_split_budget: SPATIAL_SPLIT_BUDGET,
            max_spatial_split_references: MAX_SPATIAL_SPLIT_REFERENCES,
        }
    }

    /// 32 bins for spatial splits too, and spatial splits on meshes of any size: better
    /// trees for static scenes, about twice the build.
    pub fn high_quality() -> Self {
        Self { spatial_bins: 32, max_spatial_split_references: usize::MAX, ..Self::balanced() }
    }

    /// Every preset, for tests.
    pub fn presets() -> [(&'static str, Self); 3] {
        [
            ("fastest_build", Self::fastest_build()),
            ("balanced", Self::balanced()),
            ("high_quality", Self::high_quality()),
        ]
    }
}

impl Default for BuildParams {
    /// [`BuildParams::balanced`], with the spatial split budget from [`SPATIAL_SPLITS_ENV`]
    /// if set.
    fn default() -> Self {
        Self { spatial_split_budget: spatial_split_budget_from_env(), ..Self::balanced() }
    }
}

/// The spatial split budget a value of [`SPATIAL_SPLITS_ENV`] asks for: a number `>= 0` is
/// the budget itself (`0`: none, `1`: up to one extra reference per reference); `off`,
/// `false`, `no`: none; `on`, `true`, `yes` and the empty value: the presets' 0.3. `None`
/// for anything else (negative, not finite, not a number).
pub fn parse_spatial_splits(value: &str) -> Option<f32> {
    let value = value.trim();
    match value.to_ascii_lowercase().as_str() {
        "off" | "false" | "no" => return Some(0.0),
        "" | "on" | "true" | "yes" => return Some(SPATIAL_SPLIT_BUDGET),
        _ => {}
    }
    value.parse::<f32>().ok().filter(|b| b.is_finite() && *b >= 0.0)
}

/// [`SPATIAL_SPLITS_ENV`]'s budget, the presets' when unset. A value it cannot read is
/// not an error the builder can return (the variable is read deep inside scene loading):
/// it warns once per process, naming the value and what is used instead.
fn spatial_split_budget_from_env() -> f32 {
    let Some(raw) = std::env::var_os(SPATIAL_SPLITS_ENV) else {
        return SPATIAL_SPLIT_BUDGET;
    };
    if let Some(budget) = raw.to_str().and_then(parse_spatial_splits) {
        return budget;
    }
    static WARNED: std::sync::Once = std::sync::Once::new();
    WARNED.call_once(|| {
        eprintln!(
            "warning: {SPATIAL_SPLITS_ENV}={raw:?} is not a spatial split budget (a number >= 0, on or \
             off): using the default {SPATIAL_SPLIT_BUDGET}"
        )
    });
    SPATIAL_SPLIT_BUDGET
}

/// Deepest binary tree the builder makes; deeper nodes become leaves regardless of size
/// (only reached on pathological input), which bounds the traversal stack.
pub(crate) const MAX_DEPTH: usize = 56;

/// A node of the binary build tree. Leaves index a range of the reordered primitive list.
pub(crate) enum BuildNode {
    Leaf { bounds: Aabb, first: u32, count: u32 },
    Inner { bounds: Aabb, children: Box<[BuildNode; 2]> },
}

impl BuildNode {
    pub(crate) fn bounds(&self) -> Aabb {
        match self {
            BuildNode::Leaf { bounds, .. } | BuildNode::Inner { bounds, .. } => *bounds,
        }
    }
}

/// Builds a binary BVH over `boxes` (which must be non-empty boxes with finite corners).
/// Returns the tree and the primitive order its leaves refer to (`order[first..first+count]`).
pub(crate) fn build_binary(boxes: &[Aabb], params: &BuildParams) -> (Option<BuildNode>, Vec<u32>) {
    let mut order: Vec<u32> = (0..boxes.len() as u32).collect();
    if boxes.is_empty() {
        return (None, order);
    }
    let centroids: Vec<Vec3> = boxes.iter().map(|b| b.center()).collect();
    let ctx = Ctx { boxes, centroids: &centroids, params, bins: params.bins.clamp(2, 64) };
    let root = ctx.build(&mut order, 0, 0);
    (Some(root), order)
}

struct Ctx<'a> {
    boxes: &'a [Aabb],
    centroids: &'a [Vec3],
    params: &'a BuildParams,
    bins: usize,
}

/// The best split found by binning: axis, last bin on the left, its SAH cost (the sum of
/// `SA(child) * blocks(child)`, not yet divided by the node's area).
pub(crate) struct Split {
    pub axis: usize,
    pub bin: usize,
    pub cost: f32,
}

/// Bin of coordinate `c` among `bins` equal bins from `lo`, `scale = bins / extent`.
#[inline]
pub(crate) fn bin_of(c: f32, lo: f32, scale: f32, bins: usize) -> usize {
    (((c - lo) * scale) as usize).min(bins - 1)
}

/// Bins `(box, centroid)` items by centroid in `k` bins over `cbounds` on every axis and
/// sweeps for the cheapest plane (Wald 2007, sec. 3); `blocks(n)` is the cost of a child
/// of `n` items.
pub(crate) fn best_object_split(
    items: impl Iterator<Item = (Aabb, Vec3)> + Clone,
    cbounds: &Aabb,
    k: usize,
    blocks: impl Fn(u32) -> f32,
) -> Option<Split> {
    let extent = cbounds.extent();
    let mut best: Option<Split> = None;
    let mut bin_box = [Aabb::EMPTY; 64];
    let mut bin_count = [0u32; 64];
    for axis in 0..3 {
        if extent[axis] <= 0.0 {
            continue;
        }
        let lo = cbounds.min[axis];
        let scale = k as f32 / extent[axis];
        bin_box[..k].fill(Aabb::EMPTY);
        bin_count[..k].fill(0);
        for (b, c) in items.clone() {
            let j = bin_of(c[axis], lo, scale, k);
            bin_box[j] = bin_box[j].union(b);
            bin_count[j] += 1;
        }
        if let Some((bin, cost)) =
            sweep(&bin_box[..k], &bin_count[..k], &bin_count[..k], &blocks, |_, _| true)
        {
            if best.as_ref().is_none_or(|b| cost < b.cost) {
                best = Some(Split { axis, bin, cost });
            }
        }
    }
    best
}

/// The cheapest plane between bins: `(last bin on the left, cost)`. A child left of the
/// plane after bin `j` holds `enter[0..=j]` items, one right of it `exit[j+1..]` (equal
/// counts for object bins; entries and exits of references for spatial bins).
/// Planes where `fits(left count, right count)` is false are skipped.
pub(crate) fn sweep(
    bin_box: &[Aabb],
    enter: &[u32],
    exit: &[u32],
    blocks: impl Fn(u32) -> f32,
    fits: impl Fn(u32, u32) -> bool,
) -> Option<(usize, f32)> {
    let k = bin_box.len();
    let mut right_area = [0f32; 64];
    let mut right_count = [0u32; 64];
    // Sweep from the right: area and count of bins (j+1)..k.
    let (mut acc, mut cnt) = (Aabb::EMPTY, 0);
    for j in (1..k).rev() {
        acc = acc.union(bin_box[j]);
        cnt += exit[j];
        right_area[j - 1] = acc.surface_area();
        right_count[j - 1] = cnt;
    }
    // Sweep from the left, evaluating the plane after bin j.
    let (mut acc, mut cnt) = (Aabb::EMPTY, 0);
    let mut best: Option<(usize, f32)> = None;
    for j in 0..k - 1 {
        acc = acc.union(bin_box[j]);
        cnt += enter[j];
        if cnt == 0 || right_count[j] == 0 || !fits(cnt, right_count[j]) {
            continue;
        }
        let cost = acc.surface_area() * blocks(cnt) + right_area[j] * blocks(right_count[j]);
        if best.is_none_or(|(_, c)| cost < c) {
            best = Some((j, cost));
        }
    }
    best
}

impl Ctx<'_> {
    fn build(&self, prims: &mut [u32], offset: usize, depth: usize) -> BuildNode {
        let (bounds, cbounds) = prims.iter().fold((Aabb::EMPTY, Aabb::EMPTY), |(b, c), &i| {
            (b.union(self.boxes[i as usize]), c.grow_point(self.centroids[i as usize]))
        });
        let n = prims.len();
        let leaf = BuildNode::Leaf { bounds, first: offset as u32, count: n as u32 };
        if n == 1 || depth >= MAX_DEPTH {
            return leaf;
        }
        let p = self.params;
        let leaf_cost = p.intersection_cost * self.blocks(n as u32);
        let split = self.find_split(prims, &cbounds);
        let mid = match split {
            Some(s) => {
                let split_cost = p.traversal_cost
                    + p.intersection_cost * s.cost / bounds.surface_area().max(f32::MIN_POSITIVE);
                if n <= p.max_leaf_size && leaf_cost <= split_cost {
                    return leaf;
                }
                self.partition(prims, &cbounds, &s)
            }
            // All centroids coincide: no plane separates them.
            None if n <= p.max_leaf_size => return leaf,
            None => n / 2,
        };
        let (left, right) = prims.split_at_mut(mid);
        let (l, r) = if n > p.parallel_threshold {
            rayon::join(|| self.build(left, offset, depth + 1), || self.build(right, offset + mid, depth + 1))
        } else {
            (self.build(left, offset, depth + 1), self.build(right, offset + mid, depth + 1))
        };
        BuildNode::Inner { bounds, children: Box::new([l, r]) }
    }

    /// Number of `leaf_block`-sized blocks needed for `n` primitives.
    #[inline]
    fn blocks(&self, n: u32) -> f32 {
        let b = self.params.leaf_block.max(1) as u32;
        n.div_ceil(b) as f32
    }

    /// Bins the centroids on every axis and sweeps for the cheapest plane (Wald 2007, sec. 3).
    fn find_split(&self, prims: &[u32], cbounds: &Aabb) -> Option<Split> {
        let items = prims.iter().map(|&i| (self.boxes[i as usize], self.centroids[i as usize]));
        best_object_split(items, cbounds, self.bins, |n| self.blocks(n))
    }

    /// Moves primitives whose centroid falls in bins `0..=split.bin` to the front.
    fn partition(&self, prims: &mut [u32], cbounds: &Aabb, s: &Split) -> usize {
        let lo = cbounds.min[s.axis];
        let scale = self.bins as f32 / cbounds.extent()[s.axis];
        let mut i = 0;
        let mut j = prims.len();
        while i < j {
            if bin_of(self.centroids[prims[i] as usize][s.axis], lo, scale, self.bins) <= s.bin {
                i += 1;
            } else {
                j -= 1;
                prims.swap(i, j);
            }
        }
        debug_assert!(i > 0 && i < prims.len(), "binned split left one side empty");
        i
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spatial_splits_values_are_budgets_switches_or_rejected() {
        for (value, want) in [
            ("0", 0.0),
            ("0.3", 0.3),
            (" 1 ", 1.0),
            ("2", 2.0),
            ("off", 0.0),
            ("OFF", 0.0),
            ("false", 0.0),
            ("no", 0.0),
            ("on", SPATIAL_SPLIT_BUDGET),
            ("True", SPATIAL_SPLIT_BUDGET),
            ("yes", SPATIAL_SPLIT_BUDGET),
            ("", SPATIAL_SPLIT_BUDGET),
        ] {
            assert_eq!(parse_spatial_splits(value), Some(want), "{value:?}");
        }
        for value in ["-0.5", "nan", "inf", "abc", "0.3x", "o n"] {
            assert_eq!(parse_spatial_splits(value), None, "{value:?}");
        }
    }
}
