//! Bottom level of the two-level BVH: the acceleration structure of one mesh in object
//! space (or of the merged static instances in world space), with its triangles copied in
//! leaf order.
//! One variant per layout, each holding only its own data: a flat list of grouped
//! triangles for tiny meshes ([`FlatBlas`]), or a wide BVH whose width is that of the
//! kernels it was built for (4 for [`Simd::Sse`], 8 for [`Simd::Avx2`]).

use crate::child_order::{self, Odds};
use crate::flat_blas::{padded_boxes, FlatBlas};
use crate::presplit::{self, presplit};
use crate::qwide::{self, QBvh8};
use crate::tri4::{self, Ray4, Tri4, TriPackets};
use crate::triangle::WatertightRay;
use crate::wide::{self, RayBoxes, WideNode};
#[cfg(target_arch = "x86_64")]
use crate::{avx2, avx2_packet};
use crate::{closer, collapse, refit, sah, spatial, BuildParams, Simd};
use filtrace_core::{Aabb, Vec3};
use filtrace_scene::Mesh;
use std::collections::HashMap;

/// The bottom level of one mesh, by layout.
#[derive(Clone, Debug, Default)]
// `Flat` holds its 256-byte group node inline: boxing it would add a pointer chase to
// every query of the Cornell box.
#[allow(clippy::large_enum_variant)]
pub(crate) enum Blas {
    /// No hittable triangle (or a mesh only merged or unused instances use).
    #[default]
    Empty,
    /// No hierarchy ([`BuildParams::max_flat_triangles`]): group boxes, then triangles.
    Flat(FlatBlas),
    /// Four-wide nodes tested with SSE ([`Simd::Sse`]).
    Bvh4(WideBvh<4>),
    /// Eight-wide nodes tested with AVX2 ([`Simd::Avx2`]).
    Bvh8(WideBvh<8>),
    /// The same eight-wide tree with compressed nodes ([`BuildParams::min_quantized_triangles`]).
    QBvh8(QBvh8),
}

/// A wide BVH over triangle packets: leaves are ranges of `tris.packets`.
#[derive(Clone, Debug)]
pub(crate) struct WideBvh<const W: usize> {
    pub nodes: Vec<WideNode<W>>,
    pub tris: TriPackets,
    /// Any-hit odds of the whole tree, relative to its bounds ([`child_order`]).
    pub odds: Odds,
}

impl Blas {
    pub(crate) fn build(mesh: &Mesh, params: &BuildParams, simd: Simd) -> Self {
        Self::build_from(mesh.triangle_count(), |i| mesh.triangle(i), params, simd)
    }

    /// Builds over triangles `tri(0) .. tri(n - 1)`; `prim_ids` then hold those indices.
    pub(crate) fn build_from(
        n: usize,
        tri: impl Fn(usize) -> [Vec3; 3],
        params: &BuildParams,
        simd: Simd,
    ) -> Self {
        // Triangles with non-finite corners can never be hit; leaving them out keeps the
        // boxes finite (a NaN box would poison every SAH cost above it).
        let (ids, boxes): (Vec<u32>, Vec<Aabb>) = (0..n)
            .filter_map(|i| {
                let t = tri(i);
                t.iter().all(|p| p.is_finite()).then(|| (i as u32, Aabb::from_points(t)))
            })
            .unzip();
        if ids.is_empty() {
            return Blas::Empty;
        }
        // Boxes padded for every layout (flat groups and BVH nodes): the watertight test
        // rounds `t` near a plane by up to a few ulps of the coordinates, so a ray starting
        // a hair behind a wall can hit it at `t = -0.0`, outside the wall's unpadded (flat)
        // box; brute force reports that hit, so the boxes must not cull it
        // (tests/flat_culling.rs).
        if ids.len() <= params.max_flat_triangles {
            return Blas::Flat(FlatBlas::build(&ids, &padded_boxes(&boxes), tri));
        }
        // The BVH is built over references: pieces of long thin triangles, or one per
        // triangle when splitting is off (`refs.tri` indexes `ids`).
        let refs = presplit(&boxes, |k| tri(ids[k] as usize), params.split_budget);
        let boxes = padded_boxes(&refs.boxes);
        let ref_ids: Vec<u32> = refs.tri.iter().map(|&k| ids[k as usize]).collect();
        let tri_count = ids.len();
        match simd {
            Simd::Sse => {
                WideBvh::build(&ref_ids, tri_count, &boxes, tri, params).map_or(Blas::Empty, Blas::Bvh4)
            }
            // The AVX2 kernels test two packets at once, so their SAH counts blocks of
            // twice the size (270k sphere, incoherent rays: +12 % closest, +15 % any hit
            // over blocks of 4; bunny +2-4 %).
            Simd::Avx2 => {
                let params = BuildParams { leaf_block: 2 * params.leaf_block, ..params.clone() };
                let Some(bvh) = WideBvh::build(&ref_ids, tri_count, &boxes, tri, &params) else {
                    return Blas::Empty;
                };
                if tri_count < params.min_quantized_triangles {
                    return Blas::Bvh8(bvh);
                }
                match qwide::compress_nodes(&bvh.nodes) {
                    Some(nodes) => Blas::QBvh8(QBvh8 { nodes, tris: bvh.tris, odds: bvh.odds }),
                    None => Blas::Bvh8(bvh),
                }
            }
        }
    }

    /// The triangles stored, whatever the layout (`None`: empty).
    pub(crate) fn tris(&self) -> Option<&TriPackets> {
        match self {
            Blas::Empty => None,
            Blas::Flat(f) => Some(&f.tris),
            Blas::Bvh4(b) => Some(&b.tris),
            Blas::Bvh8(b) => Some(&b.tris),
            Blas::QBvh8(b) => Some(&b.tris),
        }
    }

    /// Number of triangles stored (those with finite corners).
    pub(crate) fn tri_count(&self) -> usize {
        self.tris().map_or(0, |t| t.tri_count)
    }

    /// Object-space bounds of all triangles (empty when there are none).
    pub(crate) fn bounds(&self) -> Aabb {
        self.tris().map_or(Aabb::EMPTY, |t| t.bounds)
    }

    /// Closest hit in object space; shortens `*t_max` and returns `(t, u, v, prim)`.
    /// `AVX2`: the query runs with AVX2 and FMA (the flat layout then takes the AVX2
    /// kernels; 8-wide nodes are only built where AVX2 is available).
    #[inline(always)]
    pub(crate) fn intersect<const AVX2: bool>(
        &self,
        o: Vec3,
        d: Vec3,
        t_min: f32,
        t_max: &mut f32,
    ) -> Option<(f32, f32, f32, u32)> {
        match self {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `SceneAccel` builds 8-wide nodes only where AVX2 is available.
            Blas::Bvh8(b) => unsafe { avx2::intersect8(&b.nodes, &b.tris, o, d, t_min, t_max) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: as for `Bvh8`.
            Blas::QBvh8(b) => unsafe { avx2::intersect8(&b.nodes, &b.tris, o, d, t_min, t_max) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `AVX2` queries run only where AVX2 is available.
            Blas::Flat(f) if AVX2 => unsafe { f.intersect8(o, d, t_min, t_max) },
            Blas::Flat(f) => f.intersect4(o, d, t_min, t_max),
            Blas::Bvh4(b) => b.intersect4(o, d, t_min, t_max),
            _ => None,
        }
    }

    #[inline(always)]
    pub(crate) fn occluded<const AVX2: bool>(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> bool {
        match self {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: as in `intersect`.
            Blas::Bvh8(b) => unsafe { avx2::occluded8(&b.nodes, &b.tris, o, d, t_min, t_max) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: as in `intersect`.
            Blas::QBvh8(b) => unsafe { avx2::occluded8(&b.nodes, &b.tris, o, d, t_min, t_max) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: as in `intersect`.
            Blas::Flat(f) if AVX2 => unsafe { f.occluded8(o, d, t_min, t_max) },
            Blas::Flat(f) => f.occluded4(o, d, t_min, t_max),
            Blas::Bvh4(b) => b.occluded4(o, d, t_min, t_max),
            _ => false,
        }
    }

    /// Any-hit [`Odds`] of the whole bottom level relative to its bounds (never hit when
    /// empty; a flat one costs its group test and every packet test).
    pub(crate) fn odds(&self) -> Odds {
        match self {
            Blas::Empty => Odds::default(),
            Blas::Flat(f) => {
                let n = f.tris.packets.len() as u32;
                let o = leaf_odds(&f.tris, &f.tris.bounds, 0, n, 2);
                Odds { cost: o.cost + 1.0, ..o }
            }
            Blas::Bvh4(b) => b.odds,
            Blas::Bvh8(b) => b.odds,
            Blas::QBvh8(b) => b.odds,
        }
    }

    /// Wide nodes (0 for the flat and empty layouts).
    pub(crate) fn node_count(&self) -> usize {
        match self {
            Blas::Bvh4(b) => b.nodes.len(),
            Blas::Bvh8(b) => b.nodes.len(),
            Blas::QBvh8(b) => b.nodes.len(),
            _ => 0,
        }
    }

    /// Expected node visits plus leaf tests of a random ray through the root box
    /// (`refit::sah_cost`).
    pub(crate) fn sah_cost(&self) -> f64 {
        match self {
            Blas::Bvh4(b) => refit::sah_cost(&b.nodes),
            Blas::Bvh8(b) => refit::sah_cost(&b.nodes),
            Blas::QBvh8(b) => refit::sah_cost(&b.decoded()),
            _ => 0.0,
        }
    }

    /// Leaves: wide-node children that hold triangles (0 for the flat and empty layouts).
    pub(crate) fn leaf_count(&self) -> usize {
        match self {
            Blas::Bvh4(_) | Blas::Bvh8(_) | Blas::QBvh8(_) => {
                self.leaves().iter().filter(|&&(_, c)| c > 0).count()
            }
            _ => 0,
        }
    }

    /// `(first packet, count)` of every wide-node child (inner ones have count 0) or flat
    /// group.
    fn leaves(&self) -> Vec<(u32, u32)> {
        let of = |child: &[u32], count: &[u32]| {
            child.iter().copied().zip(count.iter().copied()).collect::<Vec<_>>()
        };
        match self {
            Blas::Empty => Vec::new(),
            Blas::Flat(f) => of(&f.node.first, &f.node.count),
            Blas::Bvh4(b) => b.nodes.iter().flat_map(|n| of(&n.child, &n.count)).collect(),
            Blas::Bvh8(b) => b.nodes.iter().flat_map(|n| of(&n.child, &n.count)).collect(),
            Blas::QBvh8(b) => b.decoded().iter().flat_map(|n| of(&n.child, &n.count)).collect(),
        }
    }

    pub(crate) fn validate(&self) -> Result<(), String> {
        let Some(tris) = self.tris() else { return Ok(()) };
        // A triangle split over several leaves (`presplit.rs`) need only have its piece
        // in each leaf's box, checked by `split_coverage`; the others lie in their leaf's.
        let copies = lane_copies(&tris.prim_ids);
        let split = |p: usize, l: usize| copies.get(&tris.prim_ids[4 * p + l]).is_some_and(|&c| c > 1);
        let whole_box = |p: usize| {
            if !(0..4).any(|l| split(p, l)) {
                return tris.packet_box(p);
            }
            (0..4).filter(|&l| tris.packets[p].used(l) && !split(p, l)).fold(Aabb::EMPTY, |b, l| {
                b.union(Aabb::from_points(tris.packets[p].lane(l).map(Vec3::from_array)))
            })
        };
        match self {
            Blas::Bvh4(b) => {
                wide::validate(&b.nodes, tris.packets.len(), whole_box)?;
                split_coverage(&b.nodes, tris, &copies)?;
            }
            Blas::Bvh8(b) => {
                wide::validate(&b.nodes, tris.packets.len(), whole_box)?;
                split_coverage(&b.nodes, tris, &copies)?;
            }
            Blas::QBvh8(b) => {
                qwide::validate(&b.nodes, tris.packets.len(), whole_box)?;
                split_coverage(&b.decoded(), tris, &copies)?;
            }
            _ => {}
        }
        // Triangles in id order within every leaf (the AVX2 closest-hit tie rule needs it).
        // (Flat: the single-ray groups; the SSE flat query tests all packets at once.)
        for (first, count) in self.leaves().into_iter().filter(|&(_, c)| c > 0) {
            let lanes = &tris.prim_ids[4 * first as usize..4 * (first + count) as usize];
            let used: Vec<u32> = lanes.iter().copied().filter(|&id| id != u32::MAX).collect();
            if used.windows(2).any(|w| w[0] >= w[1]) {
                return Err(format!("leaf {first}+{count} not in id order: {lanes:?}"));
            }
        }
        // Every stored triangle in a lane (in several only when split), unused lanes
        // marked as such.
        let mut ids: Vec<u32> = Vec::with_capacity(tris.tri_count);
        for (i, &id) in tris.prim_ids.iter().enumerate() {
            if tris.packets[i / 4].used(i % 4) != (id != u32::MAX) {
                return Err(format!("lane {i} use does not match its id {id}"));
            }
            if id != u32::MAX {
                ids.push(id);
            }
        }
        ids.sort_unstable();
        ids.dedup();
        if ids.len() != tris.tri_count {
            return Err(format!("{} distinct triangles in leaves, {} expected", ids.len(), tris.tri_count));
        }
        Ok(())
    }
}

/// How many lanes hold each triangle id (more than one: split over several leaves).
fn lane_copies(prim_ids: &[u32]) -> HashMap<u32, u32> {
    let mut copies = HashMap::new();
    for &id in prim_ids.iter().filter(|&&id| id != u32::MAX) {
        *copies.entry(id).or_insert(0) += 1;
    }
    copies
}

/// Every sampled point of a triangle stored in several leaves lies in one of their boxes.
fn split_coverage<const W: usize>(
    nodes: &[WideNode<W>],
    tris: &TriPackets,
    copies: &HashMap<u32, u32>,
) -> Result<(), String> {
    let mut leaf_boxes: HashMap<u32, ([Vec3; 3], Vec<Aabb>)> = HashMap::new();
    for n in nodes {
        for slot in (0..W).filter(|&i| n.count[i] > 0) {
            for p in n.child[slot]..n.child[slot] + n.count[slot] {
                for l in 0..4 {
                    let id = tris.prim_ids[4 * p as usize + l];
                    if copies.get(&id).is_some_and(|&c| c > 1) {
                        let corners = tris.packets[p as usize].lane(l).map(Vec3::from_array);
                        leaf_boxes.entry(id).or_insert((corners, Vec::new())).1.push(n.child_box(slot));
                    }
                }
            }
        }
    }
    for (id, (corners, boxes)) in leaf_boxes {
        if let Some(p) = presplit::uncovered_point(&corners, &boxes) {
            return Err(format!(
                "point {p} of split triangle {id} in none of its {} leaf boxes",
                boxes.len()
            ));
        }
    }
    Ok(())
}

impl<const W: usize> WideBvh<W> {
    /// The binned SAH tree over `boxes` (references to triangles `ids`, `tri(id)` the
    /// corners; `tri_count` distinct ones) collapsed to `W`-wide nodes; `None` when the
    /// builder returns no tree. With spatial splits ([`BuildParams::spatial_split_budget`])
    /// the tree with them is kept only if its SAH cost is lower than the one without:
    /// the builder's choices are greedy per node, and on meshes without overlapping
    /// boxes (bunny-room, grass) its splits raised the cost of the whole tree by 0.2-2 %.
    fn build(
        ids: &[u32],
        tri_count: usize,
        boxes: &[Aabb],
        tri: impl Fn(usize) -> [Vec3; 3],
        params: &BuildParams,
    ) -> Option<Self> {
        let plain = Self::from_tree(sah::build_binary(boxes, params), ids, tri_count, &tri, params)?;
        if params.spatial_split_budget <= 0.0 || boxes.len() > params.max_spatial_split_references {
            return Some(plain);
        }
        let corners: Vec<[Vec3; 3]> = ids.iter().map(|&i| tri(i as usize)).collect();
        let split =
            Self::from_tree(spatial::build_spatial(boxes, &corners, params), ids, tri_count, &tri, params)?;
        Some(if refit::sah_cost(&split.nodes) < refit::sah_cost(&plain.nodes) { split } else { plain })
    }

    /// The binary tree `root` over references `order` (indices into `ids`) collapsed.
    fn from_tree(
        (root, order): (Option<sah::BuildNode>, Vec<u32>),
        ids: &[u32],
        tri_count: usize,
        tri: &impl Fn(usize) -> [Vec3; 3],
        params: &BuildParams,
    ) -> Option<Self> {
        let root = root?;
        let mut tris = TriPackets { tri_count, bounds: root.bounds(), ..TriPackets::default() };
        let mut leaf = |first: u32, count: u32| {
            let start = tris.packets.len() as u32;
            // Leaf triangles in id order: the AVX2 leaf test then meets ties in id order
            // (see `avx2::closest_in`); pieces of one split triangle are stored once.
            let mut leaf: Vec<u32> =
                order[first as usize..(first + count) as usize].iter().map(|&k| ids[k as usize]).collect();
            leaf.sort_unstable();
            leaf.dedup();
            for chunk in leaf.chunks(4) {
                tris.push(chunk, |i| tri(i as usize).map(|v| v.to_array()));
            }
            (start, tris.packets.len() as u32 - start)
        };
        let mut nodes = collapse::collapse_sah(&root, params, &mut leaf);
        let odds = child_order::order_for_any_hit(&mut nodes, |b, first, count| {
            leaf_odds(&tris, b, first, count, W / 4)
        });
        Some(Self { nodes, tris, odds })
    }
}

/// [`Odds`] of the leaf of packets `first .. first + count` in box `b`, tested
/// `per_test` packets at a time.
fn leaf_odds(tris: &TriPackets, b: &Aabb, first: u32, count: u32, per_test: usize) -> Odds {
    let area: f64 = (first as usize..(first + count) as usize)
        .flat_map(|p| {
            let pk = &tris.packets[p];
            (0..4).filter(|&l| pk.used(l)).map(|l| triangle_area(pk.lane(l)))
        })
        .sum();
    Odds::of_leaf(area, b.surface_area() as f64, (count as usize).div_ceil(per_test.max(1)) as f64)
}

fn triangle_area(t: crate::triangle::Tri) -> f64 {
    let [a, b, c] = t.map(|v| Vec3::from_array(v).as_dvec3());
    0.5 * (b - a).cross(c - a).length()
}

impl WideBvh<4> {
    #[inline(always)]
    fn intersect4(&self, o: Vec3, d: Vec3, t_min: f32, t_max: &mut f32) -> Option<(f32, f32, f32, u32)> {
        let rb = RayBoxes::new(o, d);
        let mut leaves = ClosestPackets::new(&self.tris, o, d, t_min);
        wide::traverse::<_, true>(&self.nodes, &rb, t_min, t_max, &mut leaves);
        leaves.best.map(|(t, u, v, i)| (t, u, v, self.tris.prim_ids[i]))
    }

    #[inline(always)]
    fn occluded4(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> bool {
        let mut t_max = t_max;
        let leaves =
            AnyPacket { packets: &self.tris.packets, ray: Ray4::new(WatertightRay::new(o, d), t_min) };
        let rb = RayBoxes::new(o, d);
        wide::traverse::<_, false>(&self.nodes, &rb, t_min, &mut t_max, leaves)
    }
}

/// Queries of the flat layout: the single-ray path tests every packet after one box
/// test; the AVX2 path first tests the group boxes as one 8-wide node.
impl FlatBlas {
    #[inline(always)]
    fn intersect4(&self, o: Vec3, d: Vec3, t_min: f32, t_max: &mut f32) -> Option<(f32, f32, f32, u32)> {
        if !wide::ray_touches_box(o, d, t_min, *t_max, &self.tris.bounds) {
            return None;
        }
        let mut leaves = ClosestPackets::new(&self.tris, o, d, t_min);
        wide::Leaves::visit(&mut &mut leaves, 0, self.tris.packets.len() as u32, t_max);
        leaves.best.map(|(t, u, v, i)| (t, u, v, self.tris.prim_ids[i]))
    }

    #[inline(always)]
    fn occluded4(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> bool {
        let mut t_max = t_max;
        let mut leaves =
            AnyPacket { packets: &self.tris.packets, ray: Ray4::new(WatertightRay::new(o, d), t_min) };
        wide::ray_touches_box(o, d, t_min, t_max, &self.tris.bounds)
            && wide::Leaves::visit(&mut leaves, 0, self.tris.packets.len() as u32, &mut t_max)
    }

    /// Safety: the CPU has AVX2 and FMA (`Simd::Avx2.available()`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn intersect8(
        &self,
        o: Vec3,
        d: Vec3,
        t_min: f32,
        t_max: &mut f32,
    ) -> Option<(f32, f32, f32, u32)> {
        // The groups whose boxes the ray touches (one 8-wide box test); rays that touch
        // none (camera rays past a Cornell box) stop here.
        let mut groups = avx2_packet::flat_node_touch(&self.node, o, d, t_min, wide::cull_bound(*t_max));
        if groups == 0 {
            return None;
        }
        let wr = WatertightRay::new(o, d);
        let mut leaves = avx2::ClosestPairs {
            packets: &self.tris.packets,
            prim_ids: &self.tris.prim_ids,
            ray: avx2::Ray8::new(&wr, t_min),
            best: None,
        };
        while groups != 0 {
            let g = groups.trailing_zeros() as usize;
            groups &= groups - 1;
            let (first, count) = (self.node.first[g], self.node.count[g]);
            wide::Leaves::visit(&mut &mut leaves, first, count, t_max);
        }
        leaves.best.map(|(t, u, v, i)| (t, u, v, self.tris.prim_ids[i]))
    }

    /// Safety: the CPU has AVX2 and FMA (`Simd::Avx2.available()`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn occluded8(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> bool {
        let mut groups = avx2_packet::flat_node_touch(&self.node, o, d, t_min, wide::cull_bound(t_max));
        if groups == 0 {
            return false;
        }
        let wr = WatertightRay::new(o, d);
        let mut t_max = t_max;
        let mut leaves = avx2::AnyPairs { packets: &self.tris.packets, ray: avx2::Ray8::new(&wr, t_min) };
        while groups != 0 {
            let g = groups.trailing_zeros() as usize;
            groups &= groups - 1;
            let (first, count) = (self.node.first[g], self.node.count[g]);
            if wide::Leaves::visit(&mut leaves, first, count, &mut t_max) {
                return true;
            }
        }
        false
    }
}

/// Closest-hit leaf test over triangle packets; `best` holds `(t, u, v, 4 packet + lane)`.
struct ClosestPackets<'a> {
    packets: &'a [Tri4],
    /// Lane ids, prefetched on a hit (see `avx2::ClosestPairs`).
    prim_ids: &'a [u32],
    ray: Ray4,
    best: Option<(f32, f32, f32, usize)>,
}

impl<'a> ClosestPackets<'a> {
    #[inline(always)]
    fn new(tris: &'a TriPackets, o: Vec3, d: Vec3, t_min: f32) -> Self {
        Self {
            packets: &tris.packets,
            prim_ids: &tris.prim_ids,
            ray: Ray4::new(WatertightRay::new(o, d), t_min),
            best: None,
        }
    }
}

impl wide::Leaves for &mut ClosestPackets<'_> {
    #[inline(always)]
    fn visit(&mut self, first: u32, count: u32, t_max: &mut f32) -> bool {
        for i in first..first + count {
            // SAFETY: leaf ranges lie inside `packets` (checked by `validate`).
            let p = unsafe { self.packets.get_unchecked(i as usize) };
            let ids = &self.prim_ids[4 * i as usize..4 * i as usize + 4];
            if let Some((t, u, v, lane)) = tri4::intersect4(&self.ray, p, *t_max, ids) {
                let k = 4 * i as usize + lane;
                let best = self.best;
                if closer(t, best.map(|b| b.0), || {
                    best.is_some_and(|b| self.prim_ids[k] < self.prim_ids[b.3])
                }) {
                    *t_max = t;
                    wide::prefetch(self.prim_ids.as_ptr().wrapping_add(k) as *const u8, 1);
                    self.best = Some((t, u, v, k));
                }
            }
        }
        false
    }

    #[inline(always)]
    fn prefetch(&self, first: u32, count: u32) {
        tri4::prefetch_packets(self.packets, first, count);
    }
}

/// Any-hit leaf test over triangle packets.
struct AnyPacket<'a> {
    packets: &'a [Tri4],
    ray: Ray4,
}

impl wide::Leaves for AnyPacket<'_> {
    #[inline(always)]
    fn visit(&mut self, first: u32, count: u32, t_max: &mut f32) -> bool {
        (first..first + count).any(|i| {
            // SAFETY: as in `ClosestPackets`.
            let p = unsafe { self.packets.get_unchecked(i as usize) };
            tri4::occluded4(&self.ray, p, *t_max)
        })
    }

    #[inline(always)]
    fn prefetch(&self, first: u32, count: u32) {
        tri4::prefetch_packets(self.packets, first, count);
    }
}
