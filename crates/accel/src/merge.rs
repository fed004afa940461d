//! Static instances merged into world space. Embree's user scene for the instanced glTF
//! engine is every instance's world-space triangles in one BVH; filtrace's two levels
//! made a ray walk the top level, move into object space and walk a bottom level for
//! every instance it reached (115 on the engine), 0.57x Mitsuba's samples per second.
//! So [`SceneAccel`](crate::SceneAccel) copies the instances that never move into world
//! space and builds one bottom level over them and the identity instances (`merged`);
//! only the moving ones (an animation's, [`crate::SceneAccel::build_with_moving`]) keep
//! a top-level entry, so moving them stays a top-level update.
//!
//! Copies cost memory where a mesh has many instances, so [`merge_plan`] merges within
//! a budget: at most [`MERGE_GROWTH`] times the triangles instancing stores (one copy per
//! mesh), or [`MERGE_FLOOR_TRIANGLES`] when that is more. Merging then at most doubles
//! the bottom levels' memory (about 60 bytes a triangle: packets, nodes and the
//! `(instance, prim)` of each), and any scene up to a million world-space triangles
//! merges whole (the engine's 110k, the classroom's 38k); a forest of a thousand
//! instanced million-triangle trees stays two-level. Meshes with the fewest copies come
//! first: a mesh with one instance costs no memory at all to merge (its own bottom level
//! is then not built), a mesh with many copies the most.
//!
//! Hits keep their ids: the merged bottom level's `prim_ids` index `(instance, prim)`
//! pairs, in instance then triangle order (so ties still go to the smallest pair), and
//! barycentrics are those of the same triangle (affine maps keep them), so shading reads
//! the object's mesh as before. Only the last bits of `t`, `u`, `v` change (world-space
//! instead of object-space arithmetic); [`crate::BruteForce::build_like`] is the
//! reference with the same arithmetic, bit for bit.

use crate::invert_transform;
use filtrace_core::{Affine3A, Vec3};
use filtrace_scene::{Instance, Scene};

/// World-space triangles the merged bottom level may always hold (about 60 MB).
pub const MERGE_FLOOR_TRIANGLES: usize = 1 << 20;

/// Beyond [`MERGE_FLOOR_TRIANGLES`], the merged bottom level holds at most this many
/// times the triangles of the meshes its instances use (counted once each).
pub const MERGE_GROWTH: usize = 2;

/// Per scene instance: whether it is merged into world space. Candidates are the
/// instances not `moving` whose mesh has triangles and whose transform is invertible
/// (the others cannot be hit); whole meshes' candidates are taken, fewest copies first,
/// while the world-space triangles fit the budget (see the module docs). Fewer than two
/// merged instances merge none: one object needs no merging.
pub(crate) fn merge_plan(scene: &Scene, moving: &[bool]) -> Vec<bool> {
    let triangles = |i: &Instance| scene.meshes.get(i.mesh as usize).map_or(0, |m| m.triangle_count());
    let candidate: Vec<bool> = scene
        .instances
        .iter()
        .enumerate()
        .map(|(k, i)| {
            !moving.get(k).copied().unwrap_or(false)
                && triangles(i) > 0
                && invert_transform(&i.transform).is_some()
        })
        .collect();
    let mut copies = vec![0usize; scene.meshes.len()];
    for (i, _) in scene.instances.iter().zip(&candidate).filter(|(_, &c)| c) {
        copies[i.mesh as usize] += 1;
    }
    let mesh_triangles = |m: usize| scene.meshes[m].triangle_count();
    let instanced: usize = (0..copies.len()).filter(|&m| copies[m] > 0).map(mesh_triangles).sum();
    let budget = (MERGE_GROWTH * instanced).max(MERGE_FLOOR_TRIANGLES);
    let mut order: Vec<usize> = (0..copies.len()).filter(|&m| copies[m] > 0).collect();
    order.sort_by_key(|&m| copies[m]);
    let mut take = vec![false; copies.len()];
    let mut total = 0;
    for m in order {
        let cost = copies[m] * mesh_triangles(m);
        if total + cost <= budget {
            total += cost;
            take[m] = true;
        }
    }
    let plan: Vec<bool> =
        scene.instances.iter().zip(&candidate).map(|(i, &c)| c && take[i.mesh as usize]).collect();
    if plan.iter().filter(|&&m| m).count() < 2 {
        return vec![false; plan.len()];
    }
    plan
}

/// Triangle `prim` of instance `instance` in world space, as the merged bottom level
/// stores it (identity instances' corners as they are, bit for bit).
pub(crate) fn world_triangle(scene: &Scene, instance: u32, prim: u32) -> [Vec3; 3] {
    let inst = &scene.instances[instance as usize];
    let tri = scene.meshes[inst.mesh as usize].triangle(prim as usize);
    if inst.transform == Affine3A::IDENTITY {
        tri
    } else {
        tri.map(|p| inst.transform.transform_point3(p))
    }
}

/// `(instance, prim)` of every triangle of the instances `merged`, in instance then
/// triangle order (the merged bottom level's ids, ordered as the tie rule wants).
pub(crate) fn merged_refs(scene: &Scene, merged: &[bool]) -> Vec<(u32, u32)> {
    (0..scene.instances.len())
        .filter(|&i| merged[i])
        .flat_map(|i| {
            let n = scene.meshes[scene.instances[i].mesh as usize].triangle_count();
            (0..n).map(move |p| (i as u32, p as u32))
        })
        .collect()
}
