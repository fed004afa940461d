//! # filtrace-accel
//!
//! Ray queries against a [`filtrace_scene::Scene`]: closest hit ([`SceneAccel::intersect`])
//! and any hit for shadow rays ([`SceneAccel::occluded`]).
//!
//! ## Structure
//! A **two-level BVH**: one bottom-level BVH per mesh (BLAS) over its object-space
//! triangles, and a top-level BVH (TLAS) over the world boxes of the instances. A ray that
//! reaches an instance is moved into object space by the instance's inverse affine
//! transform; the direction is *not* renormalised, so `t` keeps its meaning and the BLAS
//! hit distance is directly the world hit distance. Moving objects only need
//! [`SceneAccel::update_transforms`], which rebuilds the (small) top level. Instances that
//! do not move (those not named to [`SceneAccel::build_with_moving`]) are copied into world
//! space and merged into a single bottom level within a memory budget (`merge.rs`: the
//! Cornell box's eight identity instances, the glTF engine's 115 transformed ones), and a
//! scene with one object skips the top level altogether, so static scenes pay no
//! two-level overhead.
//!
//! Both levels are built by the same binary **binned SAH** builder ([`sah`]; MacDonald &
//! Booth 1990, Wald 2007; leaf costs count 4-triangle blocks as Embree's do), then
//! collapsed into a **4-wide BVH** (Dammertz et al. 2008), the SAH-cheapest one by
//! dynamic programming (Ylitie et al. 2017, `collapse.rs`), whose four child boxes are
//! tested with one SSE slab test (Williams et al. 2005, robust per Ize 2013). Traversal is
//! near-first for closest hits, in an order fixed at build time for any hits (likely hits
//! for little work first, `child_order.rs`), and prefetches the children it will visit. Triangles are copied into leaf order as 4-wide SoA packets and tested four
//! at a time with the **watertight** algorithm of Woop, Benthin and Wald (JCGT 2013,
//! [`triangle`]), so rays through shared edges and vertices of closed meshes never slip
//! through.
//!
//! On CPUs with AVX2 and FMA (detected at run time, [`Simd::best`]; no build flag) the
//! bottom levels are collapsed to **8-wide nodes** instead, tested with one AVX2 slab
//! test, and leaves are tested two packets (eight triangles) at a time, bit-identical to
//! the scalar test (`avx2.rs`). The SSE BVH4 stays as the path for other CPUs;
//! [`SceneAccel::build_simd`] picks either kernel explicitly (tests run both). Bottom
//! levels of at least [`BuildParams::min_quantized_triangles`] (2 M) triangles get
//! **compressed 8-wide nodes** (`qwide.rs`: child boxes as 8-bit offsets in a per-node
//! grid, rounded outwards; half the node memory; Ylitie et al. 2017). Bottom
//! levels of at most [`BuildParams::max_flat_triangles`] (40) triangles (the Cornell box) get
//! no hierarchy: their triangles fall into a few groups (SAH-clustered: walls, blocks and
//! light of the Cornell box apart) whose padded boxes are tested before the triangles
//! (`packet::flat_layout`; boxes only cull, the hits stay those of testing every triangle).
//! Optionally ([`BuildParams::split_budget`], off in the presets) long thin diagonal
//! triangles are pre-split before a bottom level is built (`presplit.rs`, Karras & Aila
//! 2013): the builder gets the boxes of clipped pieces, and a leaf stores each triangle it
//! references once. Spatial splits in the bottom-level build (`spatial.rs`, SBVH, Stich
//! et al. 2009; [`BuildParams::spatial_split_budget`]: 0.3 in `balanced`, the default,
//! up to [`BuildParams::max_spatial_split_references`], and in `high_quality`; off in
//! `fastest_build`) give a tree kept only when its SAH cost is lower than the plain one's.
//! Triangle boxes are padded a little (`packet::padded_boxes`) so that no box culls a hit
//! the watertight test's rounding puts just outside it. Measurements against Embree 4:
//! `docs/perf-accel.md` and `docs/performance.md` (1 thread, incoherent closest hits,
//! idle, 2026-11-23 18:40 UTC: 1.02-1.10x Embree on the bunny, about even on the 270k
//! sphere).
//!
//! **Closest hits do not depend on traversal order**: among hits at the same `t` the
//! smallest `(instance, prim)` wins in every kernel (shared edges, coincident triangles),
//! and boxes are culled only beyond the closest hit plus a `2^-12` relative slack
//! (`wide::CULL_SCALE`), so every box holding a tied triangle is visited.
//!
//! **8-ray packets** ([`RayPacket`], [`SceneAccel::intersect_packet`],
//! [`SceneAccel::occluded_packet`]; `packet.rs`) serve integrators that trace eight paths
//! in lockstep, per lane bit-identical to the single-ray queries. With AVX2, a single
//! flat mesh (the Cornell box) is tested 8 rays x 1 triangle per instruction, and a
//! single BVH mesh is traversed once for the whole packet (8 rays x 1 child box) when the
//! active lanes share direction signs and watertight permutation and their directions
//! lie close together (camera tiles). Scenes of several objects (instances, moving or
//! not) walk the top level once per packet, testing flat instances 8 rays x 1 triangle in
//! their object space and BVH instances per lane (`packet_two_level.rs`). Other packets
//! and CPUs without AVX2 take one single-ray query per lane.
//!
//! **Segments from one origin** ([`SegmentFan`], [`SceneAccel::occluded_fan`];
//! `shared_origin.rs`): the visibility rays of the VPL cache, grouped by [`fan_class`] so
//! that the packet kernels take them; per lane bit-identical to [`SceneAccel::occluded`].
//!
//! [`BruteForce`] answers the same queries by testing every triangle; tests compare the
//! two. [`bench::ray_bench`] measures throughput (used by `filtrace bench rays`), and
//! [`testmesh`] generates meshes for tests and benchmarks.
//!
//! ```
//! use filtrace_accel::{testmesh, SceneAccel};
//! use filtrace_core::{Ray, Vec3};
//! use filtrace_scene::Scene;
//!
//! let mut scene = Scene::default();
//! scene.add_mesh(testmesh::subdivided_cube(4)); // the cube [-1, 1]^3
//! let accel = SceneAccel::build(&scene);
//! let hit = accel.intersect(&Ray::new(Vec3::new(0.2, 0.3, -5.0), Vec3::Z)).unwrap();
//! assert!((hit.t - 4.0).abs() < 1e-5);
//! assert!(accel.occluded(&Ray::segment(Vec3::ZERO, Vec3::X, 0.0, 2.0)));
//! ```

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx2_packet;
pub mod bench;
mod blas;
mod brute;
mod child_order;
mod collapse;
mod flat_blas;
mod merge;
mod packet;
#[cfg(target_arch = "x86_64")]
mod packet_two_level;
mod presplit;
mod query;
mod qwide;
#[cfg(target_arch = "x86_64")]
mod qwide_avx2;
mod ray_packet;
mod refit;
pub mod sah;
mod shared_origin;
mod spatial;
pub mod testmesh;
mod top_level;
mod tri4;
pub mod triangle;
mod wide;

pub use brute::BruteForce;
pub use merge::{MERGE_FLOOR_TRIANGLES, MERGE_GROWTH};
pub use ray_packet::{HitPacket, RayPacket, LANES};
pub use sah::BuildParams;
pub use shared_origin::{fan_class, SegmentFan, FAN_CLASSES};

use blas::Blas;
use filtrace_core::{Aabb, Affine3A, Ray, Vec3};
use filtrace_scene::Scene;
use rayon::prelude::*;
use wide::Node4;

/// A ray-triangle hit: distance along the ray (in units of `|ray.dir|`), barycentrics of
/// the hit (`p = (1-u-v) p0 + u p1 + v p2`), and which triangle of which instance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub u: f32,
    pub v: f32,
    pub instance: u32,
    pub prim: u32,
}

/// Which SIMD kernels a [`SceneAccel`] traverses with; [`Simd::best`] picks at run time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Simd {
    /// 4-wide nodes tested with SSE, 4-triangle packets (every x86-64 CPU; portable code
    /// on other architectures).
    Sse,
    /// 8-wide nodes tested with AVX2, packets tested two at a time as 8 lanes (x86-64
    /// CPUs with AVX2 and FMA; see `avx2.rs`).
    Avx2,
}

impl Simd {
    /// The fastest kernel this CPU runs.
    pub fn best() -> Self {
        if Simd::Avx2.available() {
            Simd::Avx2
        } else {
            Simd::Sse
        }
    }

    /// True when this CPU runs the kernel ([`filtrace_core::cpu::isa`]).
    pub fn available(self) -> bool {
        match self {
            Simd::Sse => true,
            Simd::Avx2 => filtrace_core::cpu::isa().has_avx2(),
        }
    }
}

/// Size and shape of a built BVH, see [`SceneAccel::stats`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BvhStats {
    /// Wide nodes of all bottom levels.
    pub nodes: usize,
    /// Of these, compressed 8-wide nodes (128 bytes; the others take 256 bytes if 8-wide,
    /// 128 if 4-wide; [`BuildParams::min_quantized_triangles`]).
    pub compressed_nodes: usize,
    /// Leaves (wide-node children that hold triangles).
    pub leaves: usize,
    /// Four-triangle packets; `triangles / (4 packets)` is the lane occupancy.
    pub packets: usize,
    pub triangles: usize,
    /// Packet lanes in use: `triangles` plus the copies of split triangles stored in more
    /// than one leaf ([`BuildParams::split_budget`], [`BuildParams::spatial_split_budget`]).
    pub references: usize,
    pub top_level_nodes: usize,
    /// SAH cost of the wide bottom levels (node visits + leaf tests per random ray
    /// hitting the root box, relative to the root area; a leaf test is one packet 4-wide,
    /// a pair of packets 8-wide: since stop 22, before which 8-wide trees counted packets),
    /// summed over meshes.
    pub sah_cost: f64,
}

/// Whether a hit at `t` replaces the best hit so far (at `best_t`): a
/// smaller `t`, or the same `t` and a smaller id. Every closest-hit kernel keeps its best
/// hit with this rule (ids are mesh triangle indices, or `(instance, prim)` pairs in
/// order), so that ties between triangles hit at the same distance (shared edges and
/// vertices, coincident triangles) go to the same triangle whatever the traversal order,
/// node width, SIMD kernel or ray packet.
/// `smaller_id` is asked only on equal `t` (ids may be cache misses).
#[inline(always)]
pub(crate) fn closer(t: f32, best_t: Option<f32>, smaller_id: impl FnOnce() -> bool) -> bool {
    match best_t {
        None => true,
        Some(bt) => t < bt || (t == bt && smaller_id()),
    }
}

/// Per-instance data of the top level.
#[derive(Clone, Debug)]
struct InstanceRecord {
    mesh: u32,
    /// World-to-object transform (the inverse of the instance transform).
    world_to_object: Affine3A,
    /// The transform is the identity: rays are used as they are.
    identity: bool,
    /// World-space bounds; empty for instances that cannot be hit.
    bounds: Aabb,
}

/// Moves a world ray into an instance's object space; `None` when the result is not a
/// usable ray (singular or non-finite transform). Shared with [`BruteForce`].
#[inline(always)]
pub(crate) fn object_ray(world_to_object: &Affine3A, identity: bool, ray: &Ray) -> Option<(Vec3, Vec3)> {
    if identity {
        return Some((ray.origin, ray.dir));
    }
    let o = world_to_object.transform_point3(ray.origin);
    let d = world_to_object.transform_vector3(ray.dir);
    (o.is_finite() && d.is_finite() && d != Vec3::ZERO).then_some((o, d))
}

/// The inverse of an instance transform, or `None` when it is singular or not finite.
pub(crate) fn invert_transform(m: &Affine3A) -> Option<(Affine3A, bool)> {
    let identity = *m == Affine3A::IDENTITY;
    let inv = m.inverse();
    let finite = m.matrix3.is_finite()
        && m.translation.is_finite()
        && inv.matrix3.is_finite()
        && inv.translation.is_finite();
    (finite && m.matrix3.determinant() != 0.0).then_some((inv, identity))
}

/// Acceleration structure over a whole scene: a two-level wide BVH (see the crate docs).
#[derive(Clone, Debug)]
pub struct SceneAccel {
    /// One bottom level per mesh (empty for meshes only merged or unused instances use).
    blas: Vec<Blas>,
    /// One bottom level over the world-space triangles of the instances merged at build
    /// time (`merge::merge_plan`: static ones within a memory budget, when there are at
    /// least two): a static scene then costs one BVH, not a top level plus one per
    /// instance. Its `prim_ids` index `merged_refs`.
    merged: Blas,
    /// `(instance, prim)` of each triangle of `merged`.
    merged_refs: Vec<(u32, u32)>,
    /// Per scene instance: its transform when it was merged into `merged` (copied into
    /// world space, `merge.rs`), `None` when it has its own top-level entry.
    merged_at: Vec<Option<Affine3A>>,
    /// Per scene instance: told to move ([`SceneAccel::build_with_moving`]), so never
    /// merged (moving it then costs a top-level update, not a full rebuild).
    moving: Vec<bool>,
    /// [`refit::sah_cost`] of the top level when it was last built: refits that let it
    /// grow past [`REBUILD_GROWTH`] times this rebuild it.
    tlas_build_cost: f64,
    /// One record per scene instance, in scene order.
    instances: Vec<InstanceRecord>,
    /// Top level over the hittable instances.
    tlas: Vec<Node4>,
    /// Objects in top-level leaf order: an instance index, or [`MERGED`].
    tlas_order: Vec<u32>,
    /// The only hittable object, when there is exactly one: the top level is skipped.
    single: Option<u32>,
    triangle_count: usize,
    params: BuildParams,
    /// Kernels of the bottom levels (the top level is always 4-wide).
    simd: Simd,
}

/// Top-level object id of the merged instances.
const MERGED: u32 = u32::MAX;

/// A refit top level whose SAH cost grew past this factor of its cost when built is
/// rebuilt instead (Kopta et al. 2012 rebuild on SAH growth too).
pub const REBUILD_GROWTH: f64 = 1.3;

/// What [`SceneAccel::update_instances`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum TopLevelUpdate {
    /// Nothing moved.
    Unchanged,
    /// The moved instances' records and the top-level boxes recomputed, tree kept.
    Refit,
    /// The top level rebuilt: a refit would have grown its SAH cost past
    /// [`REBUILD_GROWTH`], or an instance became hittable or unhittable.
    Rebuilt,
    /// Everything rebuilt: instances or meshes were added or removed, or an instance
    /// merged at build time moved (see [`SceneAccel::update_transforms`]).
    Full,
}

impl SceneAccel {
    /// Builds with the default parameters ([`BuildParams::balanced`]). Every instance is
    /// taken to stay where it is (merged into world space where the budget allows); a
    /// scene that will move instances names them to [`SceneAccel::build_with_moving`].
    pub fn build(scene: &Scene) -> Self {
        Self::build_with(scene, &BuildParams::default())
    }

    /// Builds both levels with `params` for the fastest kernels of this CPU
    /// ([`Simd::best`]). Bottom levels of different meshes are built in parallel, and
    /// large meshes build their subtrees in parallel.
    pub fn build_with(scene: &Scene, params: &BuildParams) -> Self {
        Self::build_simd(scene, params, Simd::best())
    }

    /// Builds for the kernels `simd` (tests and benchmarks use it to run the SSE path on
    /// an AVX2 CPU); a kernel this CPU lacks falls back to [`Simd::Sse`] (see
    /// [`SceneAccel::simd`]).
    pub fn build_simd(scene: &Scene, params: &BuildParams, simd: Simd) -> Self {
        Self::build_with_moving(scene, params, simd, &[])
    }

    /// [`SceneAccel::build_simd`] for a scene whose instances `moving` will move (an
    /// animation's): they are never merged into the static instances' bottom level, so
    /// that moving them is a top-level update ([`SceneAccel::update_instances`]). Indices
    /// out of range are ignored.
    pub fn build_with_moving(scene: &Scene, params: &BuildParams, simd: Simd, moving: &[u32]) -> Self {
        let mut keep_apart = vec![false; scene.instances.len()];
        for &i in moving {
            if let Some(m) = keep_apart.get_mut(i as usize) {
                *m = true;
            }
        }
        Self::build_keeping_apart(scene, params, simd, keep_apart)
    }

    fn build_keeping_apart(scene: &Scene, params: &BuildParams, simd: Simd, moving: Vec<bool>) -> Self {
        let simd = if simd.available() { simd } else { Simd::Sse };
        let is_merged = merge::merge_plan(scene, &moving);
        let merged_at =
            scene.instances.iter().zip(&is_merged).map(|(i, &m)| m.then_some(i.transform)).collect();
        let merged_refs = merge::merged_refs(scene, &is_merged);
        let merged = Blas::build_from(
            merged_refs.len(),
            |k| merge::world_triangle(scene, merged_refs[k].0, merged_refs[k].1),
            params,
            simd,
        );
        let mut used = vec![false; scene.meshes.len()];
        for (inst, _) in scene.instances.iter().zip(&is_merged).filter(|(_, &m)| !m) {
            if let Some(u) = used.get_mut(inst.mesh as usize) {
                *u = true;
            }
        }
        let blas: Vec<Blas> = scene
            .meshes
            .par_iter()
            .zip(used.par_iter())
            .map(|(m, &u)| if u { Blas::build(m, params, simd) } else { Blas::Empty })
            .collect();
        let mut accel = Self {
            blas,
            merged,
            merged_refs,
            merged_at,
            moving,
            tlas_build_cost: 0.0,
            instances: Vec::new(),
            tlas: Vec::new(),
            tlas_order: Vec::new(),
            single: None,
            triangle_count: 0,
            params: params.clone(),
            simd,
        };
        accel.build_top_level(scene);
        #[cfg(debug_assertions)]
        if let Err(e) = accel.validate() {
            panic!("BVH invariant broken after build: {e}");
        }
        accel
    }

    /// Rebuilds only the top level from the instances' current transforms. When instances
    /// were added, removed or re-pointed at other meshes, or an instance merged at build
    /// time (not told to move) moved, everything is rebuilt instead; after that rebuild
    /// the moved instance has its own entry and later moves are top-level only again.
    /// Mesh geometry is assumed unchanged since the build (deforming meshes need
    /// [`SceneAccel::build`]).
    pub fn update_transforms(&mut self, scene: &Scene) {
        let same_structure = scene.instances.len() == self.instances.len()
            && scene.meshes.len() == self.blas.len()
            && scene.instances.iter().zip(&self.instances).all(|(a, b)| a.mesh == b.mesh)
            && (0..scene.instances.len()).all(|i| !self.merged_moved(scene, i));
        if !same_structure {
            self.rebuild_all(scene);
            return;
        }
        self.build_top_level(scene);
        #[cfg(debug_assertions)]
        if let Err(e) = self.validate() {
            panic!("BVH invariant broken after update_transforms: {e}");
        }
    }

    /// True when instance `i` was merged into world space at build time (it was not told
    /// to move, [`SceneAccel::build_with_moving`]; see `merge.rs`).
    pub fn is_merged(&self, i: u32) -> bool {
        self.merged_at.get(i as usize).is_some_and(|m| m.is_some())
    }

    /// True when instance `i` of `scene` was merged and its transform is no longer the
    /// one its world-space copy was made with.
    pub(crate) fn merged_moved(&self, scene: &Scene, i: usize) -> bool {
        let now = scene.instances.get(i).map(|inst| inst.transform);
        self.merged_at.get(i).copied().flatten().is_some_and(|t| Some(t) != now)
    }

    /// Size and shape of the bottom levels, summed over meshes (for benchmarks and tuning).
    pub fn stats(&self) -> BvhStats {
        let mut st = BvhStats { top_level_nodes: self.tlas.len(), ..BvhStats::default() };
        for b in self.blas.iter().chain([&self.merged]) {
            st.nodes += b.node_count();
            st.compressed_nodes += if matches!(b, Blas::QBvh8(_)) { b.node_count() } else { 0 };
            st.packets += b.tris().map_or(0, |t| t.packets.len());
            st.triangles += b.tri_count();
            st.references += b.tris().map_or(0, |t| t.prim_ids.iter().filter(|&&id| id != u32::MAX).count());
            st.leaves += b.leaf_count();
            st.sah_cost += b.sah_cost();
        }
        st
    }

    /// Number of triangles over all instances (as [`Scene::triangle_count`]).
    pub fn triangle_count(&self) -> usize {
        self.triangle_count
    }

    /// The kernels this BVH was built for.
    pub fn simd(&self) -> Simd {
        self.simd
    }
}
