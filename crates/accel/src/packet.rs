//! Eight-ray packet queries ([`SceneAccel::intersect_packet`],
//! [`SceneAccel::occluded_packet`]) for integrators that trace eight paths in lockstep.
//!
//! Rays are stored as structure of arrays ([`RayPacket`]); an `active` bit mask selects
//! the lanes to trace. Per lane, the results are bit-identical to the single-ray queries
//! ([`SceneAccel::intersect`], [`SceneAccel::occluded`]): same hit distance, barycentrics
//! and ids, and the same answer for invalid rays (NaN or infinite components, zero
//! direction: no hit, not occluded).

#[cfg(target_arch = "x86_64")]
use crate::{avx2_packet, Simd};
use crate::{object_ray, Blas, Hit, SceneAccel, MERGED};
use filtrace_core::{Ray, Vec3};

/// Number of rays in a packet.
pub const LANES: usize = 8;

/// Fewest active lanes for which the closest-hit packet kernel beats one single-ray query
/// per lane on a flat mesh. `cargo run --release -p filtrace-accel --example packet_lanes`
/// (Cornell box, AVX2, group boxes on both paths, CPU time per ray, single / packet): 3 lanes 1.82x
/// (camera tiles) and 1.30x (incoherent), 2 lanes 1.22x and 1.10x, 1 lane 0.74x and 0.64x.
/// Cornell render (`throughput 16 1`, 3 interleaved runs, with [`MIN_LANES_ANY`]): 4 and 5
/// lanes 2.02-2.03 M samples per CPU-s, 2 and 3 lanes 2.08-2.12, 1 and 1 2.05-2.12.
const MIN_LANES_CLOSEST: u32 = 2;

/// The same for any-hit queries: 4 lanes 1.17x (shadow rays) and 1.12x (incoherent),
/// 3 lanes 0.95x and 0.97x, 2 lanes 0.73x and 0.78x; the render (above) is as fast or
/// faster with 3 as with 4.
const MIN_LANES_ANY: u32 = 3;

/// The thresholds of the packet traversal of BVH meshes (camera tiles on the bunny, single
/// / packet: 4 lanes 1.05x, 3 lanes 0.93x; docs/perf-accel.md, third pass).
const MIN_LANES_CLOSEST_BVH: u32 = 4;
const MIN_LANES_ANY_BVH: u32 = 5;

/// One triangle of a flat bottom level as the 8-ray packet kernels read it: each corner
/// a 16-byte row `[x, y, z, x]` (a ray's permuted axes are picked from it with one shuffle
/// per coordinate), and its id (a `prim_ids` value). One cache line.
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug)]
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))] // read by the AVX2 kernels
pub(crate) struct FlatTri {
    pub rows: [[f32; 4]; 3],
    pub id: u32,
    /// This triangle `(a, b, c)` and the next one of its group are a fan pair `(a, c, d)`
    /// (corners bit for bit equal): the two share the sheared corners `a` and `c`.
    pub pair: bool,
    /// The corners as byte offsets `j SHEARED_VERT_BYTES` of their vertices `j` in the
    /// kernels' table of sheared vertices (indices into [`FlatVerts`], scaled: one load
    /// each in the triangle loop instead of a multiply).
    pub corners: [u16; 3],
}

#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))] // read by the AVX2 kernels
impl FlatTri {
    /// The corners as the scalar watertight test takes them.
    pub fn tri(&self) -> crate::triangle::Tri {
        self.rows.map(|[x, y, z, _]| [x, y, z])
    }
}

/// A group of [`FlatTri`]s (`first .. first + count`) and a box around them, padded by
/// [`FLAT_BOX_PAD`] of the mesh's largest coordinate: the 8-ray kernels test the boxes
/// first and the triangles of touched groups only. `bounds` is `[min x, y, z, max x, y,
/// z, 0, 0]`.
#[repr(C, align(32))]
#[derive(Clone, Copy, Debug)]
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))] // read by the AVX2 kernels
pub(crate) struct FlatGroup {
    pub bounds: [f32; 8],
    pub first: u32,
    pub count: u32,
    /// Bit `j` set when a triangle of the group has vertex `j` of [`FlatVerts`] (0 when
    /// the mesh has no vertex table).
    pub verts: u64,
}

/// Most distinct vertices of a flat mesh's vertex table (a `u64` mask per group).
pub(crate) const MAX_FLAT_VERTS: usize = 64;

/// Size of one sheared vertex in the kernels' table: `x, y, z` of eight lanes.
pub(crate) const SHEARED_VERT_BYTES: usize = 3 * 8 * 4;

/// The distinct corners (bit for bit) of a flat mesh's triangles, as rows `[x, y, z, x]`:
/// the 8-ray kernels shear each vertex that a touched group needs once per packet, not
/// once per triangle corner. Empty when the mesh has more than [`MAX_FLAT_VERTS`].
pub(crate) type FlatVerts = Vec<VertRow>;

/// One vertex as a 16-byte aligned row `[x, y, z, x]` (one 128-bit broadcast).
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct VertRow(pub [f32; 4]);

/// Most groups of a flat bottom level (the kernels keep the touched ones in a `u32`).
pub(crate) const MAX_FLAT_GROUPS: usize = 32;

/// Padding of the group boxes, relative to the largest coordinate magnitude of the mesh
/// (`2^-20`: half a thousandth of a unit on the Cornell box's 559). Boxes only cull, so any
/// padding keeps the results exact. Without it a box around an axis-aligned wall is flat,
/// and a ray starting in the wall's plane, or a few ulps of the scene scale off it, would
/// be culled by the box test even where the watertight test's rounding of `t` reports a
/// hit at `t >= t_min = 0`. Kept below the renderer's ray offsets (`4 gamma(7)` of the
/// scene scale, ~9e-4 on the Cornell box): a shadow ray leaving a wall then skips that
/// wall's group (a pad of `2^-10` kept it: 5.2 instead of 2.7 groups per shadow packet in
/// the Cornell render, -5 % samples per CPU-s).
pub(crate) const FLAT_BOX_PAD: f32 = 1.0 / (1u32 << 20) as f32;

/// Cost of one 8-ray box test relative to one 8-ray triangle test, for grouping.
pub(crate) const FLAT_BOX_COST: f32 = 0.3;

/// The single-ray queries' view of a flat bottom level: its packets fall into up to eight
/// groups (`first[i] .. first[i] + count[i]`, ids ascending within each), whose padded
/// boxes are tested as one 8-wide node (`avx2_packet::flat_node_touch`) before their
/// packets. Rows of `bounds`: min x, y, z, max x, y, z; unused slots have empty boxes.
#[repr(C, align(32))]
#[derive(Clone, Copy, Debug)]
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))] // read by the AVX2 kernels
pub(crate) struct FlatNode {
    pub bounds: [[f32; 8]; 6],
    pub first: [u32; 8],
    pub count: [u32; 8],
}

impl Default for FlatNode {
    fn default() -> Self {
        let (inf, ninf) = ([f32::INFINITY; 8], [f32::NEG_INFINITY; 8]);
        Self { bounds: [inf, inf, inf, ninf, ninf, ninf], first: [0; 8], count: [0; 8] }
    }
}

/// Groups of the single-ray layout ([`FlatNode`]): at most eight, clustered for a cost of
/// one 8-triangle test per eight triangles of each group touched.
pub(crate) fn flat_node_groups(boxes: &[filtrace_core::Aabb]) -> Vec<(filtrace_core::Aabb, Vec<usize>)> {
    cluster(boxes, 8, |p, n| p * n.div_ceil(8) as f32)
}

/// `boxes`, each grown on every side by [`FLAT_BOX_PAD`] of the largest coordinate
/// magnitude of all of them.
pub(crate) fn padded_boxes(boxes: &[filtrace_core::Aabb]) -> Vec<filtrace_core::Aabb> {
    let root = boxes.iter().copied().fold(filtrace_core::Aabb::EMPTY, filtrace_core::Aabb::union);
    let pad = Vec3::splat(root.min.abs().max(root.max.abs()).max_element() * FLAT_BOX_PAD);
    boxes.iter().map(|b| filtrace_core::Aabb { min: b.min - pad, max: b.max + pad }).collect()
}

/// Most boxes [`cluster`] clusters exhaustively (flat bottom levels hold at most
/// [`crate::BuildParams::max_flat_triangles`], 40 in every preset; a larger setting gets
/// consecutive runs of triangles as groups beyond this count).
const MAX_CLUSTERED: usize = 256;

/// Agglomerative clustering of `boxes` by the surface area heuristic (Walter et al. 2008,
/// "Fast agglomerative clustering for rendering"; exhaustive, for the few triangles of a
/// flat bottom level): starting from one group per box, merges the pair of groups whose
/// merge lowers `sum over groups cost(area_g / area_root, n_g)` most, until no merge
/// lowers it and at most `max_groups` remain. Groups hold indices into `boxes`,
/// ascending, and come in the order of their smallest index.
pub(crate) fn cluster(
    boxes: &[filtrace_core::Aabb],
    max_groups: usize,
    cost: impl Fn(f32, usize) -> f32,
) -> Vec<(filtrace_core::Aabb, Vec<usize>)> {
    use filtrace_core::Aabb;
    if boxes.len() > MAX_CLUSTERED {
        // Exhaustive clustering is cubic in the count: consecutive runs instead.
        let run = boxes.len().div_ceil(max_groups.max(1));
        let runs = (0..boxes.len()).collect::<Vec<_>>();
        return runs
            .chunks(run)
            .map(|c| (c.iter().map(|&i| boxes[i]).fold(Aabb::EMPTY, Aabb::union), c.to_vec()))
            .collect();
    }
    let root = boxes.iter().copied().fold(Aabb::EMPTY, Aabb::union);
    let root_area = root.surface_area().max(f32::MIN_POSITIVE);
    let sah = |b: &Aabb, n: usize| cost(b.surface_area() / root_area, n);
    let mut groups: Vec<(Aabb, Vec<usize>)> = boxes.iter().enumerate().map(|(i, b)| (*b, vec![i])).collect();
    while groups.len() > 1 {
        let mut best: Option<(f32, usize, usize)> = None;
        for i in 0..groups.len() {
            for j in i + 1..groups.len() {
                let (a, b) = (&groups[i], &groups[j]);
                let merged = sah(&a.0.union(b.0), a.1.len() + b.1.len());
                let delta = merged - sah(&a.0, a.1.len()) - sah(&b.0, b.1.len());
                if best.is_none_or(|(d, _, _)| delta < d) {
                    best = Some((delta, i, j));
                }
            }
        }
        let Some((delta, i, j)) = best else { break };
        if delta >= 0.0 && groups.len() <= max_groups {
            break;
        }
        let (b, mut members) = groups.swap_remove(j);
        groups[i].0 = groups[i].0.union(b);
        groups[i].1.append(&mut members);
    }
    for g in &mut groups {
        g.1.sort_unstable();
    }
    groups.sort_unstable_by_key(|g| g.1[0]);
    groups
}

/// Groups the triangles `tris` (ids `ids`, in id order) of a flat bottom level for the
/// 8-ray packet kernels: agglomerative clustering by the surface area heuristic
/// (Walter et al. 2008, "Fast agglomerative clustering for rendering"; exhaustive here,
/// `n <= max_flat_triangles`), merging the pair of groups whose merge lowers
/// `sum over groups (FLAT_BOX_COST + n_g area_g / area_root)` most, until no merge
/// lowers it (and at most [`MAX_FLAT_GROUPS`] remain). The two triangles of a quad share
/// a box and merge first; walls, blocks and the light of the Cornell box stay apart.
/// Groups are stored in the order of their smallest id, triangles in id order. `boxes`:
/// the triangles' boxes as [`padded_boxes`] pads them (the group boxes are their unions).
pub(crate) fn flat_layout(
    ids: &[u32],
    tris: &[crate::triangle::Tri],
    boxes: &[filtrace_core::Aabb],
) -> (Vec<FlatTri>, Vec<FlatGroup>, FlatVerts) {
    let groups = cluster(boxes, MAX_FLAT_GROUPS, |p, n| FLAT_BOX_COST + p * n as f32);
    let mut flat = Vec::with_capacity(tris.len());
    let mut out = Vec::with_capacity(groups.len());
    for (b, members) in &groups {
        let (lo, hi) = (b.min, b.max);
        out.push(FlatGroup {
            bounds: [lo.x, lo.y, lo.z, hi.x, hi.y, hi.z, 0.0, 0.0],
            first: flat.len() as u32,
            count: members.len() as u32,
            verts: 0,
        });
        let mut i = 0;
        while i < members.len() {
            let t = &tris[members[i]];
            let next = members.get(i + 1).map(|&k| &tris[k]);
            let bits = |p: &[f32; 3]| p.map(f32::to_bits);
            let pair = next.is_some_and(|n| bits(&n[0]) == bits(&t[0]) && bits(&n[1]) == bits(&t[2]));
            let tri = |k: usize| FlatTri {
                rows: tris[k].map(|[x, y, z]| [x, y, z, x]),
                id: ids[k],
                pair: false,
                corners: [0; 3],
            };
            flat.push(FlatTri { pair, ..tri(members[i]) });
            if pair {
                flat.push(tri(members[i + 1]));
                i += 1;
            }
            i += 1;
        }
    }
    let verts = vertex_table(&mut flat, &mut out);
    (flat, out, verts)
}

/// The vertex table of the triangles `flat` (in groups `groups`): sets their corner
/// offsets and the groups' vertex masks; empty (and nothing set) beyond [`MAX_FLAT_VERTS`]
/// distinct vertices.
fn vertex_table(flat: &mut [FlatTri], groups: &mut [FlatGroup]) -> FlatVerts {
    let mut verts: FlatVerts = Vec::new();
    let mut index = std::collections::HashMap::new();
    for t in flat.iter() {
        for row in &t.rows {
            index.entry(row.map(f32::to_bits)).or_insert_with(|| {
                verts.push(VertRow(*row));
                verts.len() - 1
            });
        }
    }
    if verts.len() > MAX_FLAT_VERTS {
        return Vec::new();
    }
    for g in groups.iter_mut() {
        for t in &mut flat[g.first as usize..(g.first + g.count) as usize] {
            let verts = t.rows.map(|row| index[&row.map(f32::to_bits)]);
            t.corners = verts.map(|j| (j * SHEARED_VERT_BYTES) as u16);
            g.verts |= verts.iter().fold(0u64, |m, &j| m | 1 << j);
        }
    }
    verts
}

/// 8 rays, structure of arrays. Lane i is the ray (`origin[*][i]`, `dir[*][i]`, `t_min[i]`, `t_max[i]`).
#[derive(Clone, Copy, Debug, Default)]
pub struct RayPacket {
    pub origin: [[f32; LANES]; 3],
    pub dir: [[f32; LANES]; 3],
    pub t_min: [f32; LANES],
    pub t_max: [f32; LANES],
}

/// Closest hits of a packet: lane `i` is valid when bit `i` of `mask` is set.
#[derive(Clone, Copy, Debug, Default)]
pub struct HitPacket {
    pub mask: u8,
    pub t: [f32; LANES],
    pub u: [f32; LANES],
    pub v: [f32; LANES],
    pub instance: [u32; LANES],
    pub prim: [u32; LANES],
}

impl RayPacket {
    /// Lane `i` as a [`Ray`].
    #[inline]
    pub fn lane(&self, i: usize) -> Ray {
        Ray {
            origin: Vec3::new(self.origin[0][i], self.origin[1][i], self.origin[2][i]),
            dir: Vec3::new(self.dir[0][i], self.dir[1][i], self.dir[2][i]),
            t_min: self.t_min[i],
            t_max: self.t_max[i],
        }
    }

    /// Stores `ray` in lane `i`.
    #[inline]
    pub fn set_lane(&mut self, i: usize, ray: &Ray) {
        for k in 0..3 {
            self.origin[k][i] = ray.origin[k];
            self.dir[k][i] = ray.dir[k];
        }
        self.t_min[i] = ray.t_min;
        self.t_max[i] = ray.t_max;
    }

    /// A packet of up to eight rays (lanes past `rays.len()` stay default) and the mask of
    /// the lanes filled.
    pub fn from_rays(rays: &[Ray]) -> (Self, u8) {
        let mut p = Self::default();
        let n = rays.len().min(LANES);
        for (i, r) in rays[..n].iter().enumerate() {
            p.set_lane(i, r);
        }
        (p, ((1u32 << n) - 1) as u8)
    }
}

impl HitPacket {
    /// Lane `i` as an optional [`Hit`].
    #[inline]
    pub fn lane(&self, i: usize) -> Option<Hit> {
        (self.mask & (1 << i) != 0).then(|| Hit {
            t: self.t[i],
            u: self.u[i],
            v: self.v[i],
            instance: self.instance[i],
            prim: self.prim[i],
        })
    }

    /// Stores `hit` in lane `i` (clears the lane's bit for `None`).
    #[inline]
    pub fn set_lane(&mut self, i: usize, hit: Option<Hit>) {
        match hit {
            Some(h) => {
                self.mask |= 1 << i;
                self.t[i] = h.t;
                self.u[i] = h.u;
                self.v[i] = h.v;
                self.instance[i] = h.instance;
                self.prim[i] = h.prim;
            }
            None => self.mask &= !(1 << i),
        }
    }
}

impl SceneAccel {
    /// Closest hits of the lanes whose bit is set in `active`; bit i of the result's `mask`
    /// is set iff lane i is active and hit; per lane identical to `intersect`.
    pub fn intersect_packet(&self, rays: &RayPacket, active: u8) -> HitPacket {
        #[cfg(target_arch = "x86_64")]
        if self.simd == Simd::Avx2 && active.count_ones() >= MIN_LANES_CLOSEST {
            if let Some((object, transformed)) = self.single_object() {
                let mut local = None;
                let (rays, active) = self.object_rays(object, transformed, rays, active, &mut local);
                // SAFETY: `build_simd` keeps `Simd::Avx2` only where the CPU has AVX2 and FMA.
                unsafe {
                    if self.object_blas(object).flat {
                        // Returned as it is (an `Option` around it was a 164-byte copy).
                        return self.intersect_flat_avx2(object, rays, active);
                    }
                    if active.count_ones() >= MIN_LANES_CLOSEST_BVH {
                        if let Some(hits) = self.intersect_bvh_avx2(object, rays, active) {
                            return hits;
                        }
                    }
                }
            }
        }
        // (The lane loops check each active lane's validity, as the single-ray queries do.)
        self.intersect_packet_lanes(rays, active)
    }

    /// Bit i set iff lane i is active and occluded; per lane identical to `occluded`.
    pub fn occluded_packet(&self, rays: &RayPacket, active: u8) -> u8 {
        #[cfg(target_arch = "x86_64")]
        if self.simd == Simd::Avx2 && active.count_ones() >= MIN_LANES_ANY {
            if let Some((object, transformed)) = self.single_object() {
                let mut local = None;
                let (rays, active) = self.object_rays(object, transformed, rays, active, &mut local);
                let blas = self.object_blas(object);
                // SAFETY: as in `intersect_packet`.
                let occluded = unsafe {
                    if blas.flat && avx512() {
                        Some(avx2_packet::occluded_flat_avx512(blas, rays, active))
                    } else if blas.flat {
                        Some(avx2_packet::occluded_flat(blas, rays, active))
                    } else if active.count_ones() >= MIN_LANES_ANY_BVH {
                        avx2_packet::occluded_bvh(blas, rays, active)
                    } else {
                        None
                    }
                };
                if let Some(o) = occluded {
                    return o;
                }
            }
        }
        self.occluded_packet_lanes(rays, active)
    }

    /// [`SceneAccel::intersect_packet`] as one single-ray query per active lane (the
    /// reference of the tests, and the path of scenes without a packet kernel).
    pub fn intersect_packet_lanes(&self, rays: &RayPacket, active: u8) -> HitPacket {
        #[cfg(target_arch = "x86_64")]
        if self.simd == Simd::Avx2 {
            // SAFETY: as in `intersect_packet`.
            return unsafe { self.intersect_lanes_avx2(rays, active) };
        }
        let mut out = HitPacket::default();
        for i in (0..LANES).filter(|i| active & (1 << i) != 0) {
            out.set_lane(i, self.intersect(&rays.lane(i)));
        }
        out
    }

    /// [`SceneAccel::occluded_packet`] as one single-ray query per active lane (the
    /// reference of the tests, and the path of scenes without a packet kernel).
    pub fn occluded_packet_lanes(&self, rays: &RayPacket, active: u8) -> u8 {
        #[cfg(target_arch = "x86_64")]
        if self.simd == Simd::Avx2 {
            // SAFETY: as in `intersect_packet`.
            return unsafe { self.occluded_lanes_avx2(rays, active) };
        }
        (0..LANES)
            .filter(|&i| active & (1 << i) != 0 && self.occluded(&rays.lane(i)))
            .fold(0, |m, i| m | (1 << i))
    }

    /// The lane loop compiled with AVX2, so that the single-ray queries inline into it
    /// (calling `intersect` per lane cost ~10 % on the bunny).
    ///
    /// Safety: the CPU has AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn intersect_lanes_avx2(&self, rays: &RayPacket, active: u8) -> HitPacket {
        let mut out = HitPacket::default();
        let mut left = active;
        while left != 0 {
            let i = left.trailing_zeros() as usize;
            left &= left - 1;
            let ray = rays.lane(i);
            if ray.is_valid() {
                out.set_lane(i, self.intersect_with::<true>(&ray));
            }
        }
        out
    }

    /// As [`SceneAccel::intersect_lanes_avx2`].
    ///
    /// Safety: the CPU has AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn occluded_lanes_avx2(&self, rays: &RayPacket, active: u8) -> u8 {
        let mut out = 0;
        let mut left = active;
        while left != 0 {
            let i = left.trailing_zeros() as usize;
            left &= left - 1;
            let ray = rays.lane(i);
            if ray.is_valid() && self.occluded_with::<true>(&ray) {
                out |= 1 << i;
            }
        }
        out
    }

    /// When the scene is a single object (no top level): that object, and whether rays
    /// must be moved into its object space ([`Self::object_space_rays`]; not for the merged
    /// meshes and untransformed instances, whose rays are used as they are, without a copy).
    #[inline]
    fn single_object(&self) -> Option<(u32, bool)> {
        let object = self.single?;
        Some((object, object != MERGED && !self.instances[object as usize].identity))
    }

    /// The single object's rays and lanes to trace: `rays` as they are, or (`transformed`)
    /// moved into its object space, in `local`.
    #[inline(always)]
    fn object_rays<'a>(
        &self,
        object: u32,
        transformed: bool,
        rays: &'a RayPacket,
        active: u8,
        local: &'a mut Option<(RayPacket, u8)>,
    ) -> (&'a RayPacket, u8) {
        if !transformed {
            return (rays, active);
        }
        let (local_rays, ok) = local.insert(self.object_space_rays(object, rays, active));
        (local_rays, *ok)
    }

    /// The rays of instance `object`'s object space, and the lanes to trace there: lanes
    /// whose rays are invalid or cannot be moved into object space are dropped, as in the
    /// single-ray query (the kernels drop invalid rays themselves).
    fn object_space_rays(&self, object: u32, rays: &RayPacket, active: u8) -> (RayPacket, u8) {
        let rec = &self.instances[object as usize];
        let active = active & valid_lanes(rays);
        let mut local = *rays;
        let mut ok = 0u8;
        for i in (0..LANES).filter(|i| active & (1 << i) != 0) {
            let ray = rays.lane(i);
            if let Some((o, d)) = object_ray(&rec.world_to_object, rec.identity, &ray) {
                local.set_lane(i, &Ray { origin: o, dir: d, ..ray });
                ok |= 1 << i;
            }
        }
        (local, ok)
    }

    pub(crate) fn object_blas(&self, object: u32) -> &Blas {
        if object == MERGED {
            &self.merged
        } else {
            &self.blas[self.instances[object as usize].mesh as usize]
        }
    }

    /// The closest-hit packet query on a single flat object with AVX2 (the AVX-512VL
    /// build where the CPU has it).
    ///
    /// Safety: the CPU has AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn intersect_flat_avx2(&self, object: u32, rays: &RayPacket, active: u8) -> HitPacket {
        let blas = self.object_blas(object);
        // SAFETY: this function runs with AVX2 and FMA.
        let c = unsafe {
            if avx512() {
                avx2_packet::closest_flat_avx512(blas, rays, active)
            } else {
                avx2_packet::closest_flat(blas, rays, active)
            }
        };
        self.hit_packet(object, &c)
    }

    /// The closest-hit packet traversal of a single object's BVH with AVX2 (`None` for
    /// packets it does not take: lanes with different direction signs or permutations).
    ///
    /// Safety: the CPU has AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn intersect_bvh_avx2(&self, object: u32, rays: &RayPacket, active: u8) -> Option<HitPacket> {
        // SAFETY: this function runs with AVX2 and FMA.
        let c = unsafe { avx2_packet::closest_bvh(self.object_blas(object), rays, active)? };
        Some(self.hit_packet(object, &c))
    }

    /// The kernels' closest hits `c` on `object` as a [`HitPacket`], with vector selects
    /// instead of a branch per lane (whether a lane hit is a coin flip on some packets);
    /// lanes without a hit keep zeros, as `HitPacket::default`.
    ///
    /// Safety: the CPU has AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn hit_packet(&self, object: u32, c: &avx2_packet::Closest8) -> HitPacket {
        use std::arch::x86_64::*;
        let mut out = HitPacket::default();
        let mut refs = [[0u32; LANES]; 2];
        // SAFETY: unaligned loads and stores of 8 lanes within the arrays named.
        unsafe {
            let id = _mm256_loadu_si256(c.id.0.as_ptr() as *const __m256i);
            let miss = _mm256_cmpeq_epi32(id, _mm256_set1_epi32(avx2_packet::NO_HIT));
            let keep = |x: __m256i| _mm256_andnot_si256(miss, x);
            let ps = |x: &[f32; LANES]| _mm256_castps_si256(_mm256_loadu_ps(x.as_ptr()));
            let store = |dst: *mut __m256i, x: __m256i| _mm256_storeu_si256(dst, keep(x));
            out.mask = !(_mm256_movemask_ps(_mm256_castsi256_ps(miss)) as u8);
            store(out.t.as_mut_ptr() as *mut __m256i, ps(&c.t.0));
            store(out.u.as_mut_ptr() as *mut __m256i, ps(&c.u.0));
            store(out.v.as_mut_ptr() as *mut __m256i, ps(&c.v.0));
            if object == MERGED {
                let mut k = [0u32; LANES];
                _mm256_storeu_si256(k.as_mut_ptr() as *mut __m256i, keep(id));
                for i in 0..LANES {
                    (refs[0][i], refs[1][i]) = self.merged_refs[k[i] as usize];
                }
            } else {
                refs[0] = [object; LANES];
                _mm256_storeu_si256(refs[1].as_mut_ptr() as *mut __m256i, id);
            }
            store(
                out.instance.as_mut_ptr() as *mut __m256i,
                _mm256_loadu_si256(refs[0].as_ptr() as *const __m256i),
            );
            store(
                out.prim.as_mut_ptr() as *mut __m256i,
                _mm256_loadu_si256(refs[1].as_ptr() as *const __m256i),
            );
        }
        out
    }
}

/// The CPU has AVX-512F and AVX-512VL (the flat kernels' builds for 32 registers).
#[cfg(target_arch = "x86_64")]
#[inline]
fn avx512() -> bool {
    std::arch::is_x86_feature_detected!("avx512f") && std::arch::is_x86_feature_detected!("avx512vl")
}

/// Lanes whose rays are valid ([`Ray::is_valid`]: finite, non-zero direction, no NaN
/// bounds); the others never hit, as in the single-ray queries.
#[inline]
fn valid_lanes(rays: &RayPacket) -> u8 {
    (0..LANES).filter(|&i| rays.lane(i).is_valid()).fold(0, |m, i| m | (1 << i))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh;
    use filtrace_scene::Scene;

    #[test]
    fn lanes_round_trip() {
        let mut p = RayPacket::default();
        let r = Ray::segment(Vec3::new(1.0, 2.0, 3.0), Vec3::new(-1.0, 0.5, 0.25), 0.1, 7.0);
        p.set_lane(5, &r);
        assert_eq!(p.lane(5), r);
        let (q, m) = RayPacket::from_rays(&[r, r, r]);
        assert_eq!(m, 0b111);
        assert_eq!(q.lane(2), r);
    }

    #[test]
    fn packet_equals_single_rays_on_a_cube() {
        let mut scene = Scene::default();
        scene.add_mesh(testmesh::subdivided_cube(4));
        let accel = SceneAccel::build(&scene);
        let mut p = RayPacket::default();
        for i in 0..LANES {
            let o = Vec3::new(-0.9 + 0.25 * i as f32, 0.3, -5.0);
            p.set_lane(i, &Ray::new(o, Vec3::Z));
        }
        p.dir[2][3] = f32::NAN;
        let h = accel.intersect_packet(&p, 0b1011_1101);
        let occ = accel.occluded_packet(&p, 0b1011_1101);
        for i in 0..LANES {
            let active = 0b1011_1101 & (1 << i) != 0;
            let single = if active { accel.intersect(&p.lane(i)) } else { None };
            assert_eq!(h.lane(i), single);
            assert_eq!(occ & (1 << i) != 0, active && accel.occluded(&p.lane(i)));
        }
        assert_ne!(h.mask, 0);
    }
}

#[cfg(test)]
mod flat_tests {
    use super::*;
    use crate::triangle::Tri;
    use filtrace_core::Aabb;

    fn cornell() -> (Vec<u32>, Vec<Tri>) {
        let scene = filtrace_scene::builtin("cornell").expect("cornell");
        let tris: Vec<Tri> = scene
            .instances
            .iter()
            .flat_map(|i| {
                let m = &scene.meshes[i.mesh as usize];
                (0..m.triangle_count()).map(move |p| m.triangle(p).map(|v| v.to_array()))
            })
            .collect();
        ((0..tris.len() as u32).collect(), tris)
    }

    /// Beyond `MAX_CLUSTERED` boxes: consecutive runs, at most `max_groups` of them.
    #[test]
    fn many_boxes_cluster_into_runs() {
        use filtrace_core::{Aabb, Vec3};
        let boxes: Vec<Aabb> = (0..300)
            .map(|i| Aabb::from_points([Vec3::splat(i as f32), Vec3::splat(i as f32 + 1.0)]))
            .collect();
        let groups = cluster(&boxes, MAX_FLAT_GROUPS, |p, n| p * n as f32);
        assert!(groups.len() <= MAX_FLAT_GROUPS);
        let all: Vec<usize> = groups.iter().flat_map(|g| g.1.iter().copied()).collect();
        assert_eq!(all, (0..300).collect::<Vec<_>>());
        assert!(groups.iter().all(|g| g.1.iter().all(|&i| g.0.union(boxes[i]) == g.0)));
    }

    /// Every triangle lands in exactly one group whose padded box holds it; groups hold
    /// ascending ids.
    #[test]
    fn flat_layout_partitions_the_cornell_box() {
        let (ids, tris) = cornell();
        let boxes: Vec<Aabb> = tris.iter().map(|t| Aabb::from_points(t.map(Vec3::from_array))).collect();
        let (flat, groups, verts) = flat_layout(&ids, &tris, &padded_boxes(&boxes));
        println!("cornell vertex table: {} vertices", verts.len());
        for t in &flat {
            assert_eq!(t.corners.map(|o| verts[o as usize / SHEARED_VERT_BYTES].0), t.rows);
        }
        assert_eq!(flat.len(), tris.len());
        assert!(groups.len() > 4 && groups.len() <= MAX_FLAT_GROUPS, "{} groups", groups.len());
        let mut seen = vec![0; tris.len()];
        let mut next = 0;
        for g in &groups {
            assert_eq!(g.first, next);
            next += g.count;
            let members = &flat[g.first as usize..(g.first + g.count) as usize];
            assert!(members.windows(2).all(|w| w[0].id < w[1].id));
            for t in members {
                seen[t.id as usize] += 1;
                assert_eq!(t.tri(), tris[t.id as usize]);
                for p in t.tri() {
                    for k in 0..3 {
                        assert!(g.bounds[k] < p[k] && p[k] < g.bounds[k + 3], "{p:?} outside {:?}", g.bounds);
                    }
                }
            }
        }
        assert!(seen.iter().all(|&n| n == 1));
        // Fan pairs: the Cornell box is 18 quads split as (0, 1, 2), (0, 2, 3).
        for g in &groups {
            let members = &flat[g.first as usize..(g.first + g.count) as usize];
            for (i, t) in members.iter().enumerate().filter(|(_, t)| t.pair) {
                let n = members.get(i + 1).expect("a pair's second triangle in the same group");
                assert!(!n.pair && n.rows[0] == t.rows[0] && n.rows[1] == t.rows[2]);
            }
        }
        assert_eq!(flat.iter().filter(|t| t.pair).count(), 18);
        let sizes: Vec<u32> = groups.iter().map(|g| g.count).collect();
        println!("cornell groups: {sizes:?}");
        let boxes: Vec<_> = tris
            .iter()
            .map(|t| filtrace_core::Aabb::from_points(t.map(filtrace_core::Vec3::from_array)))
            .collect();
        let node = flat_node_groups(&boxes);
        assert!(node.len() <= 8);
        let mut ids: Vec<usize> = node.iter().flat_map(|g| g.1.iter().copied()).collect();
        ids.sort_unstable();
        assert_eq!(ids, (0..tris.len()).collect::<Vec<_>>());
        println!("single-ray groups: {:?}", node.iter().map(|g| &g.1).collect::<Vec<_>>());
    }
}
