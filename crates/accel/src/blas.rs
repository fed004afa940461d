//! Bottom level of the two-level BVH: the acceleration structure of one mesh (or of the
//! merged identity instances) in object space, with its triangles copied in leaf order.

use crate::tri4::{self, Ray4, Tri4};
use crate::triangle::{self, WatertightRay};
use crate::wide::{self, Node4, Node8, RayBoxes, WideNode};
#[cfg(target_arch = "x86_64")]
use crate::{avx2, avx2_packet};
use crate::{closer, packet, sah, BuildParams, Simd};
use filtrace_core::{Aabb, Vec3};
use filtrace_scene::Mesh;

/// Bottom level: the wide BVH of one mesh, with its triangles copied in leaf order.
#[derive(Clone, Debug, Default)]
pub(crate) struct Blas {
    /// Four-wide nodes ([`Simd::Sse`]); empty when `nodes8` is used.
    pub(crate) nodes: Vec<Node4>,
    /// Eight-wide nodes ([`Simd::Avx2`]); empty when `nodes` is used.
    pub(crate) nodes8: Vec<Node8>,
    /// Triangles in leaf order, four to a packet; a leaf is a range of packets.
    pub(crate) packets: Vec<Tri4>,
    /// Mesh triangle index of lane `l` of packet `p` at `4 p + l` (`u32::MAX`: unused).
    pub(crate) prim_ids: Vec<u32>,
    /// Number of triangles stored (those with finite corners).
    pub(crate) tri_count: usize,
    /// Object-space bounds of all triangles.
    pub(crate) bounds: Aabb,
    /// No hierarchy ([`BuildParams::max_flat_triangles`]): `nodes` and `nodes8` are empty,
    /// queries test the group boxes of `flat_node` / `flat_groups`, then the triangles
    /// of the groups touched.
    pub(crate) flat: bool,
    /// Flat bottom levels only: the triangles as the 8-ray packet kernels read them,
    /// grouped (`flat_groups`, boxes tested before the triangles; `packet::flat_layout`).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    pub(crate) flat_tris: Vec<packet::FlatTri>,
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    pub(crate) flat_groups: Vec<packet::FlatGroup>,
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    pub(crate) flat_verts: packet::FlatVerts,
    /// Flat bottom levels only: the groups of `packets` and their boxes, for single rays.
    pub(crate) flat_node: packet::FlatNode,
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
            return Self::default();
        }
        // Boxes padded for every layout (flat groups and BVH nodes): the watertight test
        // rounds `t` near a plane by up to a few ulps of the coordinates, so a ray starting
        // a hair behind a wall can hit it at `t = -0.0`, outside the wall's unpadded (flat)
        // box; brute force reports that hit, so the boxes must not cull it
        // (tests/flat_culling.rs).
        let boxes = packet::padded_boxes(&boxes);
        if ids.len() <= params.max_flat_triangles {
            return Self::build_flat(&ids, &boxes, tri);
        }
        // The AVX2 kernels test two packets at once, so their SAH counts blocks of twice
        // the size (270k sphere, incoherent rays: +12 % closest, +15 % any hit over
        // blocks of 4; bunny +2-4 %).
        let block = match simd {
            Simd::Sse => params.leaf_block,
            Simd::Avx2 => 2 * params.leaf_block,
        };
        let (root, order) = sah::build_binary(&boxes, &BuildParams { leaf_block: block, ..params.clone() });
        let Some(root) = root else { return Self::default() };
        let mut packets = Vec::new();
        let mut prim_ids = Vec::new();
        let mut leaf = |first: u32, count: u32| {
            let start = packets.len() as u32;
            // Leaf triangles in id order: the AVX2 leaf test then meets ties in id order
            // (see `avx2::closest_in`).
            let mut leaf = order[first as usize..(first + count) as usize].to_vec();
            leaf.sort_unstable_by_key(|&k| ids[k as usize]);
            for chunk in leaf.chunks(4) {
                let tris: Vec<_> =
                    chunk.iter().map(|&k| tri(ids[k as usize] as usize).map(|v| v.to_array())).collect();
                packets.push(Tri4::pack(&tris));
                prim_ids.extend((0..4).map(|l| chunk.get(l).map_or(u32::MAX, |&k| ids[k as usize])));
            }
            (start, packets.len() as u32 - start)
        };
        let (nodes, nodes8) = match simd {
            Simd::Sse => (wide::collapse(&root, &mut leaf), Vec::new()),
            Simd::Avx2 => (Vec::new(), wide::collapse(&root, &mut leaf)),
        };
        Self {
            nodes,
            nodes8,
            packets,
            prim_ids,
            tri_count: ids.len(),
            bounds: root.bounds(),
            flat: false,
            flat_tris: Vec::new(),
            flat_groups: Vec::new(),
            flat_verts: Vec::new(),
            flat_node: packet::FlatNode::default(),
        }
    }

    /// The flat bottom level of a tiny mesh: triangles `ids` (boxes `boxes`, ids
    /// ascending). Single rays: packets in up to eight groups (`flat_node`, ids ascending
    /// within each group, see `avx2::closest_in`); 8-ray packets: `flat_tris` in groups of
    /// their own (`packet::flat_layout`). Both only cull by boxes: the hits are those of
    /// testing every triangle.
    fn build_flat(ids: &[u32], boxes: &[Aabb], tri: impl Fn(usize) -> [Vec3; 3]) -> Self {
        let tris: Vec<triangle::Tri> = ids.iter().map(|&i| tri(i as usize).map(|v| v.to_array())).collect();
        let mut flat_node = packet::FlatNode::default();
        let (mut packets, mut prim_ids) = (Vec::new(), Vec::new());
        for (g, (b, members)) in packet::flat_node_groups(boxes).iter().enumerate() {
            for k in 0..3 {
                flat_node.bounds[k][g] = b.min[k];
                flat_node.bounds[k + 3][g] = b.max[k];
            }
            flat_node.first[g] = packets.len() as u32;
            for c in members.chunks(4) {
                packets.push(Tri4::pack(&c.iter().map(|&k| tris[k]).collect::<Vec<_>>()));
                prim_ids.extend((0..4).map(|l| c.get(l).map_or(u32::MAX, |&k| ids[k])));
            }
            flat_node.count[g] = packets.len() as u32 - flat_node.first[g];
        }
        let (flat_tris, flat_groups, flat_verts) = packet::flat_layout(ids, &tris, boxes);
        Self {
            nodes: Vec::new(),
            nodes8: Vec::new(),
            packets,
            prim_ids,
            tri_count: ids.len(),
            bounds: boxes.iter().copied().fold(Aabb::EMPTY, Aabb::union),
            flat: true,
            flat_tris,
            flat_groups,
            flat_verts,
            flat_node,
        }
    }

    /// Closest hit in object space; shortens `*t_max` and returns `(t, u, v, prim)`.
    /// `AVX2`: use the 8-wide nodes (only called on such a BVH, on an AVX2 CPU).
    #[inline(always)]
    pub(crate) fn intersect<const AVX2: bool>(
        &self,
        o: Vec3,
        d: Vec3,
        t_min: f32,
        t_max: &mut f32,
    ) -> Option<(f32, f32, f32, u32)> {
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            // SAFETY: `SceneAccel` builds 8-wide nodes only where AVX2 is available.
            return unsafe { self.intersect8(o, d, t_min, t_max) };
        }
        if self.flat {
            if !wide::ray_touches_box(o, d, t_min, *t_max, &self.bounds) {
                return None;
            }
            let mut leaves = ClosestPackets {
                packets: &self.packets,
                prim_ids: &self.prim_ids,
                ray: Ray4::new(WatertightRay::new(o, d), t_min),
                best: None,
            };
            wide::Leaves::visit(&mut &mut leaves, 0, self.packets.len() as u32, t_max);
            return leaves.best.map(|(t, u, v, i)| (t, u, v, self.prim_ids[i]));
        }
        let rb = RayBoxes::new(o, d);
        let mut leaves = ClosestPackets {
            packets: &self.packets,
            prim_ids: &self.prim_ids,
            ray: Ray4::new(WatertightRay::new(o, d), t_min),
            best: None,
        };
        wide::traverse::<_, true>(&self.nodes, &rb, t_min, t_max, &mut leaves);
        leaves.best.map(|(t, u, v, i)| (t, u, v, self.prim_ids[i]))
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    /// Safety: the CPU has AVX2 and FMA (`Simd::Avx2.available()`).
    unsafe fn intersect8(
        &self,
        o: Vec3,
        d: Vec3,
        t_min: f32,
        t_max: &mut f32,
    ) -> Option<(f32, f32, f32, u32)> {
        // Flat: the groups whose boxes the ray touches (one 8-wide box test); rays that
        // touch none (camera rays past a Cornell box) stop here.
        let mut groups = if self.flat {
            avx2_packet::flat_node_touch(&self.flat_node, o, d, t_min, wide::cull_bound(*t_max))
        } else {
            0
        };
        if self.flat && groups == 0 {
            return None;
        }
        let wr = WatertightRay::new(o, d);
        let mut leaves = avx2::ClosestPairs {
            packets: &self.packets,
            prim_ids: &self.prim_ids,
            ray: avx2::Ray8::new(&wr, t_min),
            best: None,
        };
        if self.flat {
            while groups != 0 {
                let g = groups.trailing_zeros() as usize;
                groups &= groups - 1;
                let (first, count) = (self.flat_node.first[g], self.flat_node.count[g]);
                wide::Leaves::visit(&mut &mut leaves, first, count, t_max);
            }
        } else {
            let rb = avx2::RayBoxes8::new(o, d);
            avx2::traverse8::<_, true>(&self.nodes8, &rb, t_min, t_max, &mut leaves);
        }
        leaves.best.map(|(t, u, v, i)| (t, u, v, self.prim_ids[i]))
    }

    #[inline(always)]
    pub(crate) fn occluded<const AVX2: bool>(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> bool {
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            // SAFETY: as in `intersect`.
            return unsafe { self.occluded8(o, d, t_min, t_max) };
        }
        let mut t_max = t_max;
        let mut leaves =
            AnyPacket { packets: &self.packets, ray: Ray4::new(WatertightRay::new(o, d), t_min) };
        if self.flat {
            return wide::ray_touches_box(o, d, t_min, t_max, &self.bounds)
                && wide::Leaves::visit(&mut leaves, 0, self.packets.len() as u32, &mut t_max);
        }
        let rb = RayBoxes::new(o, d);
        wide::traverse::<_, false>(&self.nodes, &rb, t_min, &mut t_max, leaves)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    /// Safety: the CPU has AVX2 and FMA (`Simd::Avx2.available()`).
    unsafe fn occluded8(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> bool {
        let mut groups = if self.flat {
            avx2_packet::flat_node_touch(&self.flat_node, o, d, t_min, wide::cull_bound(t_max))
        } else {
            0
        };
        if self.flat && groups == 0 {
            return false;
        }
        let wr = WatertightRay::new(o, d);
        let mut t_max = t_max;
        let mut leaves = avx2::AnyPairs { packets: &self.packets, ray: avx2::Ray8::new(&wr, t_min) };
        if self.flat {
            while groups != 0 {
                let g = groups.trailing_zeros() as usize;
                groups &= groups - 1;
                let (first, count) = (self.flat_node.first[g], self.flat_node.count[g]);
                if wide::Leaves::visit(&mut leaves, first, count, &mut t_max) {
                    return true;
                }
            }
            return false;
        }
        let rb = avx2::RayBoxes8::new(o, d);
        avx2::traverse8::<_, false>(&self.nodes8, &rb, t_min, &mut t_max, leaves)
    }

    /// Expected node visits plus packet tests of a random ray through the root box.
    pub(crate) fn sah_cost(&self) -> f64 {
        Self::sah_cost_of(&self.nodes) + Self::sah_cost_of(&self.nodes8)
    }

    fn sah_cost_of<const W: usize>(nodes: &[WideNode<W>]) -> f64 {
        let Some(root) = nodes.first() else { return 0.0 };
        let area = |n: &WideNode<W>, i: usize| n.child_box(i).surface_area() as f64;
        let root_area: f64 =
            (0..W).map(|i| root.child_box(i)).fold(Aabb::EMPTY, Aabb::union).surface_area() as f64;
        let mut cost = 1.0;
        for n in nodes {
            for i in 0..W {
                if n.child_box(i).is_empty() {
                    continue;
                }
                let w = area(n, i) / root_area.max(f64::MIN_POSITIVE);
                cost += w * if n.count[i] == 0 { 1.0 } else { n.count[i] as f64 };
            }
        }
        cost
    }

    pub(crate) fn leaf_count(&self) -> usize {
        let four = self.nodes.iter().flat_map(|n| n.count).filter(|&c| c > 0).count();
        four + self.nodes8.iter().flat_map(|n| n.count).filter(|&c| c > 0).count()
    }

    pub(crate) fn validate(&self) -> Result<(), String> {
        let packet_box = |p: usize| {
            let pk = &self.packets[p];
            (0..4)
                .filter(|&l| pk.used(l))
                .fold(Aabb::EMPTY, |b, l| b.union(Aabb::from_points(pk.lane(l).map(Vec3::from_array))))
        };
        if self.flat {
            if !self.nodes.is_empty() || !self.nodes8.is_empty() {
                return Err("flat bottom level with nodes".into());
            }
        } else if self.nodes8.is_empty() {
            wide::validate(&self.nodes, self.packets.len(), packet_box)?;
        } else if self.nodes.is_empty() {
            wide::validate(&self.nodes8, self.packets.len(), packet_box)?;
        } else {
            return Err("both 4-wide and 8-wide nodes".into());
        }
        // Triangles in id order within every leaf (the AVX2 closest-hit tie rule needs it).
        let mut leaves: Vec<(u32, u32)> =
            self.nodes.iter().flat_map(|n| n.child.into_iter().zip(n.count)).collect();
        leaves.extend(self.nodes8.iter().flat_map(|n| n.child.into_iter().zip(n.count)));
        if self.flat {
            leaves.extend(self.flat_node.first.into_iter().zip(self.flat_node.count));
        }
        for (first, count) in leaves.into_iter().filter(|&(_, c)| c > 0) {
            let lanes = &self.prim_ids[4 * first as usize..4 * (first + count) as usize];
            let used: Vec<u32> = lanes.iter().copied().filter(|&id| id != u32::MAX).collect();
            if used.windows(2).any(|w| w[0] >= w[1]) {
                return Err(format!("leaf {first}+{count} not in id order: {lanes:?}"));
            }
        }
        // Every stored triangle in exactly one lane, unused lanes marked as such.
        let mut ids: Vec<u32> = Vec::with_capacity(self.tri_count);
        for (i, &id) in self.prim_ids.iter().enumerate() {
            if self.packets[i / 4].used(i % 4) != (id != u32::MAX) {
                return Err(format!("lane {i} use does not match its id {id}"));
            }
            if id != u32::MAX {
                ids.push(id);
            }
        }
        ids.sort_unstable();
        ids.dedup();
        if ids.len() != self.tri_count {
            return Err(format!("{} distinct triangles in leaves, {} expected", ids.len(), self.tri_count));
        }
        Ok(())
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
