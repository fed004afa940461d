//! The top level of [`SceneAccel`]: one record per instance, the BVH over the hittable
//! objects (instances and the merged bottom level) in any-hit order, and the invariants of
//! both levels.

use crate::blas::Blas;
use crate::{
    child_order, collapse, invert_transform, refit, sah, wide, BuildParams, InstanceRecord, SceneAccel,
    MERGED,
};
use filtrace_core::{Aabb, Affine3A};
use filtrace_scene::Scene;

impl SceneAccel {
    /// The top-level record of `inst` (merged into `merged` or not).
    pub(crate) fn instance_record(&self, inst: &filtrace_scene::Instance, merged: bool) -> InstanceRecord {
        let blas = self.blas.get(inst.mesh as usize);
        match (blas, invert_transform(&inst.transform)) {
            (Some(b), Some((inv, identity))) if b.tri_count() > 0 && !merged => InstanceRecord {
                mesh: inst.mesh,
                world_to_object: inv,
                identity,
                bounds: b.bounds().transformed(&inst.transform),
            },
            _ => InstanceRecord {
                mesh: inst.mesh,
                world_to_object: Affine3A::IDENTITY,
                identity: true,
                bounds: Aabb::EMPTY,
            },
        }
    }

    pub(crate) fn build_top_level(&mut self, scene: &Scene) {
        self.instances = scene
            .instances
            .iter()
            .zip(&self.merged_at)
            .map(|(inst, merged)| self.instance_record(inst, merged.is_some()))
            .collect();
        self.triangle_count = scene
            .instances
            .iter()
            .map(|i| scene.meshes.get(i.mesh as usize).map_or(0, |m| m.triangle_count()))
            .sum();
        self.build_tlas();
    }

    /// Builds the top level over the hittable objects' current bounds.
    pub(crate) fn build_tlas(&mut self) {
        let mut objects: Vec<u32> = (0..self.instances.len() as u32)
            .filter(|&i| !self.instances[i as usize].bounds.is_empty())
            .collect();
        if self.merged.tri_count() > 0 {
            objects.push(MERGED);
        }
        let boxes: Vec<Aabb> = objects.iter().map(|&o| self.object_bounds(o)).collect();
        let params = BuildParams { max_leaf_size: 2, leaf_block: 1, ..self.params.clone() };
        let (root, order) = sah::build_binary(&boxes, &params);
        self.tlas = root
            .as_ref()
            .map(|r| collapse::collapse_sah(r, &params, &mut |first, count| (first, count)))
            .unwrap_or_default();
        self.tlas_order = order.iter().map(|&k| objects[k as usize]).collect();
        self.order_tlas_for_any_hit();
        self.single = (objects.len() == 1).then(|| objects[0]);
        self.tlas_build_cost = refit::sah_cost(&self.tlas);
    }

    /// The any-hit order of the top level ([`child_order`]): a leaf's objects most
    /// promising first (leaves test them in order), node slots most promising last.
    fn order_tlas_for_any_hit(&mut self) {
        let (mut tlas, mut order) = (std::mem::take(&mut self.tlas), std::mem::take(&mut self.tlas_order));
        let (merged, meshes) = (self.merged.odds(), self.blas.iter().map(Blas::odds).collect::<Vec<_>>());
        let object = |o: u32| {
            let odds = if o == MERGED { merged } else { meshes[self.instances[o as usize].mesh as usize] };
            (self.object_bounds(o).surface_area() as f64, odds)
        };
        for n in &tlas {
            for s in (0..4).filter(|&s| n.count[s] > 0) {
                let area = n.child_box(s).surface_area() as f64;
                let key = |o: u32| child_order::Odds::of_objects(area, [object(o)]).priority();
                let (first, count) = (n.child[s] as usize, n.count[s] as usize);
                order[first..first + count].sort_by(|&a, &b| key(b).total_cmp(&key(a)));
            }
        }
        child_order::order_for_any_hit(&mut tlas, |b, first, count| {
            let objects = order[first as usize..(first + count) as usize].iter().map(|&o| object(o));
            child_order::Odds::of_objects(b.surface_area() as f64, objects)
        });
        (self.tlas, self.tlas_order) = (tlas, order);
    }

    pub(crate) fn object_bounds(&self, object: u32) -> Aabb {
        if object == MERGED {
            self.merged.bounds()
        } else {
            self.instances[object as usize].bounds
        }
    }

    /// Checks the BVH invariants of both levels (every primitive in exactly one leaf,
    /// child boxes inside their parents). Debug builds run it after every build.
    pub fn validate(&self) -> Result<(), String> {
        for (m, b) in self.blas.iter().enumerate() {
            b.validate().map_err(|e| format!("mesh {m}: {e}"))?;
        }
        self.merged.validate().map_err(|e| format!("merged instances: {e}"))?;
        self.validate_top_level()
    }

    /// The top-level part of [`SceneAccel::validate`] (cheap: run after every update).
    pub(crate) fn validate_top_level(&self) -> Result<(), String> {
        let live = self.instances.iter().filter(|r| !r.bounds.is_empty()).count()
            + (self.merged.tri_count() > 0) as usize;
        if self.tlas_order.len() != live {
            return Err(format!("top level holds {} objects, {live} are hittable", self.tlas_order.len()));
        }
        wide::validate(&self.tlas, self.tlas_order.len(), |k| self.object_bounds(self.tlas_order[k]))
            .map_err(|e| format!("top level: {e}"))
    }
}
