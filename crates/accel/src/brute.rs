//! The naive reference: every triangle of every instance, no hierarchy.

use crate::triangle::{intersect_watertight, Tri, WatertightRay};
use crate::{invert_transform, merge, object_ray, Hit, SceneAccel};
use filtrace_core::{Affine3A, Ray};
use filtrace_scene::Scene;

/// Brute-force ray queries with the same answers as [`crate::SceneAccel`] (the same
/// object-space rays and the same watertight triangle test, only without a BVH): the
/// reference the BVH is tested against. O(triangles) per ray.
#[derive(Clone, Debug)]
pub struct BruteForce {
    /// Per instance: world-to-object transform, identity flag, object-space triangles.
    instances: Vec<(Affine3A, bool, Vec<Tri>)>,
}

impl BruteForce {
    pub fn build(scene: &Scene) -> Self {
        let instances = scene
            .instances
            .iter()
            .map(|inst| match (scene.meshes.get(inst.mesh as usize), invert_transform(&inst.transform)) {
                (Some(mesh), Some((inv, identity))) => {
                    let tris =
                        (0..mesh.triangle_count()).map(|i| mesh.triangle(i).map(|p| p.to_array())).collect();
                    (inv, identity, tris)
                }
                _ => (Affine3A::IDENTITY, true, Vec::new()),
            })
            .collect();
        Self { instances }
    }

    /// The reference for `accel` bit for bit: the instances it merged into world space
    /// ([`SceneAccel::is_merged`]) are tested as it tests them (world-space copies of their
    /// triangles against the world ray), the others as [`BruteForce::build`] tests them.
    /// `build` stays the reference for the transforms themselves (object space).
    pub fn build_like(scene: &Scene, accel: &SceneAccel) -> Self {
        let mut out = Self::build(scene);
        for (i, entry) in out.instances.iter_mut().enumerate() {
            if accel.is_merged(i as u32) {
                let n = entry.2.len() as u32;
                let world = (0..n).map(|p| merge::world_triangle(scene, i as u32, p).map(|v| v.to_array()));
                *entry = (Affine3A::IDENTITY, true, world.collect());
            }
        }
        out
    }

    /// Closest hit with `t` in `[ray.t_min, ray.t_max]`.
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        let mut best: Option<Hit> = None;
        let mut t_max = ray.t_max;
        for (ii, (inv, identity, tris)) in self.instances.iter().enumerate() {
            let Some((o, d)) = object_ray(inv, *identity, ray) else { continue };
            let wr = WatertightRay::new(o, d);
            for (p, tri) in tris.iter().enumerate() {
                if let Some((t, u, v)) = intersect_watertight(&wr, tri, ray.t_min, t_max) {
                    // Strictly closer only: among equal `t` the first in `(instance, prim)`
                    // order stays, the tie rule of the BVH (`SceneAccel::intersect`).
                    if best.is_none_or(|b| t < b.t) {
                        t_max = t;
                        best = Some(Hit { t, u, v, instance: ii as u32, prim: p as u32 });
                    }
                }
            }
        }
        best
    }

    /// True when anything is hit with `t` in `[ray.t_min, ray.t_max]`.
    pub fn occluded(&self, ray: &Ray) -> bool {
        ray.is_valid()
            && self.instances.iter().any(|(inv, identity, tris)| {
                object_ray(inv, *identity, ray).is_some_and(|(o, d)| {
                    let wr = WatertightRay::new(o, d);
                    tris.iter().any(|t| intersect_watertight(&wr, t, ray.t_min, ray.t_max).is_some())
                })
            })
    }

    /// Every triangle hit by `ray` in `[t_min, t_max]`, as `(t, instance, prim)`; tests
    /// use it to accept either triangle when a ray hits a shared edge.
    pub fn all_hits(&self, ray: &Ray) -> Vec<(f32, u32, u32)> {
        let mut out = Vec::new();
        if !ray.is_valid() {
            return out;
        }
        for (ii, (inv, identity, tris)) in self.instances.iter().enumerate() {
            let Some((o, d)) = object_ray(inv, *identity, ray) else { continue };
            let wr = WatertightRay::new(o, d);
            for (p, tri) in tris.iter().enumerate() {
                if let Some((t, _, _)) = intersect_watertight(&wr, tri, ray.t_min, ray.t_max) {
                    out.push((t, ii as u32, p as u32));
                }
            }
        }
        out
    }
}
