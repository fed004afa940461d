//! The flat bottom level: a mesh of at most [`crate::BuildParams::max_flat_triangles`]
//! triangles (the Cornell box) gets no hierarchy. Its triangles fall into a few groups,
//! clustered by the surface area heuristic, whose padded boxes are tested before the
//! triangles: up to eight groups of 4-triangle packets for single rays ([`FlatNode`]),
//! and up to [`MAX_FLAT_GROUPS`] groups of [`FlatTri`]s with a shared vertex table for the
//! 8-ray packet kernels (`avx2_packet::flat`). Boxes only cull: the hits stay those of
//! testing every triangle.

use crate::tri4::TriPackets;
use crate::triangle::Tri;
use filtrace_core::{Aabb, Vec3};

/// A flat bottom level: no nodes, only grouped triangles.
#[derive(Clone, Debug)]
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))] // `packet_*` read by the AVX2 kernels
pub(crate) struct FlatBlas {
    /// The single-ray queries' groups of `tris` and their boxes.
    pub node: FlatNode,
    /// Packets in the groups of `node`, ids ascending within each group.
    pub tris: TriPackets,
    /// The triangles as the 8-ray packet kernels read them, in groups of their own
    /// ([`flat_layout`]), and the mesh's vertex table.
    pub packet_tris: Vec<FlatTri>,
    pub packet_groups: Vec<FlatGroup>,
    pub packet_verts: FlatVerts,
}

impl FlatBlas {
    /// The flat bottom level of a tiny mesh: triangles `ids` (boxes `boxes` as
    /// [`padded_boxes`] pads them, ids ascending; `tri(id)` the corners). Single rays:
    /// packets in up to eight groups (`node`, ids ascending within each group, see
    /// `avx2::closest_in`); 8-ray packets: `packet_tris` in groups of their own
    /// ([`flat_layout`]). Both only cull by boxes: the hits are those of testing every
    /// triangle.
    pub fn build(ids: &[u32], boxes: &[Aabb], tri: impl Fn(usize) -> [Vec3; 3]) -> Self {
        let corners = |i: u32| tri(i as usize).map(|v| v.to_array());
        let mut node = FlatNode::default();
        let mut tris = TriPackets {
            tri_count: ids.len(),
            bounds: boxes.iter().copied().fold(Aabb::EMPTY, Aabb::union),
            ..TriPackets::default()
        };
        for (g, (b, members)) in flat_node_groups(boxes).iter().enumerate() {
            for k in 0..3 {
                node.bounds[k][g] = b.min[k];
                node.bounds[k + 3][g] = b.max[k];
            }
            node.first[g] = tris.packets.len() as u32;
            for c in members.chunks(4) {
                tris.push(&c.iter().map(|&k| ids[k]).collect::<Vec<_>>(), corners);
            }
            node.count[g] = tris.packets.len() as u32 - node.first[g];
        }
        let all: Vec<Tri> = ids.iter().map(|&i| corners(i)).collect();
        let (packet_tris, packet_groups, packet_verts) = flat_layout(ids, &all, boxes);
        Self { node, tris, packet_tris, packet_groups, packet_verts }
    }
}

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
    pub fn tri(&self) -> Tri {
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
pub(crate) fn flat_node_groups(boxes: &[Aabb]) -> Vec<(Aabb, Vec<usize>)> {
    cluster(boxes, 8, |p, n| p * n.div_ceil(8) as f32)
}

/// `boxes`, each grown on every side by [`FLAT_BOX_PAD`] of the largest coordinate
/// magnitude of all of them.
pub(crate) fn padded_boxes(boxes: &[Aabb]) -> Vec<Aabb> {
    let root = boxes.iter().copied().fold(Aabb::EMPTY, Aabb::union);
    let pad = Vec3::splat(root.min.abs().max(root.max.abs()).max_element() * FLAT_BOX_PAD);
    boxes.iter().map(|b| Aabb { min: b.min - pad, max: b.max + pad }).collect()
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
    boxes: &[Aabb],
    max_groups: usize,
    cost: impl Fn(f32, usize) -> f32,
) -> Vec<(Aabb, Vec<usize>)> {
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
    tris: &[Tri],
    boxes: &[Aabb],
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

#[cfg(test)]
mod flat_tests {
    use super::*;

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
        let boxes: Vec<_> = tris.iter().map(|t| Aabb::from_points(t.map(Vec3::from_array))).collect();
        let node = flat_node_groups(&boxes);
        assert!(node.len() <= 8);
        let mut ids: Vec<usize> = node.iter().flat_map(|g| g.1.iter().copied()).collect();
        ids.sort_unstable();
        assert_eq!(ids, (0..tris.len()).collect::<Vec<_>>());
        println!("single-ray groups: {:?}", node.iter().map(|g| &g.1).collect::<Vec<_>>());
    }
}
