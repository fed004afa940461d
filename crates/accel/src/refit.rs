//! Per-frame updates of [`SceneAccel`]'s top level ([`SceneAccel::update_instances`]), and
//! refitting a wide BVH whose primitives moved: the tree keeps its shape, every box is
//! recomputed bottom-up from the primitives' new bounds (the `refit_all` of obvhs, on the
//! collapsed wide nodes). Cheaper than a rebuild, but the tree degrades as things move
//! away from where it was built; [`sah_cost`] measures by how much, so that the caller can
//! rebuild when the cost has grown too far (Kopta et al., "Fast, Effective BVH Updates for
//! Animated Scenes", I3D 2012, use the same SAH-growth trigger).

use crate::wide::WideNode;
use crate::{SceneAccel, TopLevelUpdate, MERGED, REBUILD_GROWTH};
use filtrace_core::Aabb;
use filtrace_scene::Scene;

impl SceneAccel {
    /// Everything rebuilt from `scene`, keeping the instances told to move apart, and
    /// those merged at build time that moved since (so that they move cheaply from now on).
    pub(crate) fn rebuild_all(&mut self, scene: &Scene) {
        let mut moving = std::mem::take(&mut self.moving);
        moving.resize(scene.instances.len(), false);
        for (i, m) in moving.iter_mut().enumerate() {
            *m |= self.merged_moved(scene, i);
        }
        *self = Self::build_keeping_apart(scene, &self.params.clone(), self.simd, moving);
    }

    /// The cost of a frame follows what moved: the records of the instances `moved` (whose
    /// transforms in `scene` changed) are recomputed and the top level is refit, or rebuilt
    /// when the refit degraded it (SAH cost beyond [`REBUILD_GROWTH`] times its cost when
    /// built) or an instance became (un)hittable. Like [`SceneAccel::update_transforms`],
    /// rebuilds everything when the scene's instances or meshes changed or a merged
    /// instance moved. Indices out of range also rebuild everything.
    pub fn update_instances(&mut self, scene: &Scene, moved: &[u32]) -> TopLevelUpdate {
        if moved.is_empty() {
            return TopLevelUpdate::Unchanged;
        }
        let same_structure = scene.instances.len() == self.instances.len()
            && scene.meshes.len() == self.blas.len()
            && moved.iter().all(|&i| {
                scene.instances.get(i as usize).is_some_and(|inst| {
                    inst.mesh == self.instances[i as usize].mesh && !self.merged_moved(scene, i as usize)
                })
            });
        if !same_structure {
            self.rebuild_all(scene);
            return TopLevelUpdate::Full;
        }
        let mut live_changed = false;
        for &i in moved {
            let rec = self.instance_record(&scene.instances[i as usize], self.is_merged(i));
            live_changed |= rec.bounds.is_empty() != self.instances[i as usize].bounds.is_empty();
            self.instances[i as usize] = rec;
        }
        let update = if live_changed { TopLevelUpdate::Rebuilt } else { self.refit_top_level() };
        if update == TopLevelUpdate::Rebuilt {
            self.build_tlas();
        }
        #[cfg(debug_assertions)]
        if let Err(e) = self.validate_top_level() {
            panic!("BVH invariant broken after update_instances: {e}");
        }
        update
    }

    /// Refits the top level to the instances' records; [`TopLevelUpdate::Rebuilt`] when
    /// the refit tree is too much worse than a rebuilt one would be (the caller rebuilds).
    fn refit_top_level(&mut self) -> TopLevelUpdate {
        let (order, instances, merged) = (&self.tlas_order, &self.instances, &self.merged.bounds());
        let object_bounds = |o: u32| if o == MERGED { *merged } else { instances[o as usize].bounds };
        refit(&mut self.tlas, |first, count| {
            (first..first + count).map(|k| object_bounds(order[k as usize])).fold(Aabb::EMPTY, Aabb::union)
        });
        if sah_cost(&self.tlas) > REBUILD_GROWTH * self.tlas_build_cost {
            TopLevelUpdate::Rebuilt
        } else {
            TopLevelUpdate::Refit
        }
    }
}

/// Recomputes every child box of `nodes` (a tree made by `collapse::collapse_sah`): a leaf slot
/// gets `leaf_box(first, count)`, an inner slot the union of its node's child boxes.
/// `collapse` allocates children after their parent, so one reverse sweep sees every
/// child before its parent. Boxes are unions (min/max, exact), so a refit tree holds the
/// same boxes a rebuild with the same shape would.
pub(crate) fn refit<const W: usize>(nodes: &mut [WideNode<W>], leaf_box: impl Fn(u32, u32) -> Aabb) {
    for i in (0..nodes.len()).rev() {
        for slot in 0..W {
            let (child, count) = (nodes[i].child[slot], nodes[i].count[slot]);
            let b = if count > 0 {
                leaf_box(child, count)
            } else if child == 0 {
                // The root is never a child: (0, 0) marks an unused slot.
                continue;
            } else {
                node_box(&nodes[child as usize])
            };
            set_child_box(&mut nodes[i], slot, &b);
        }
    }
}

/// The union of a node's child boxes.
pub(crate) fn node_box<const W: usize>(n: &WideNode<W>) -> Aabb {
    (0..W).map(|i| n.child_box(i)).fold(Aabb::EMPTY, Aabb::union)
}

fn set_child_box<const W: usize>(n: &mut WideNode<W>, i: usize, a: &Aabb) {
    for k in 0..3 {
        n.bounds[k][i] = a.min[k];
        n.bounds[k + 3][i] = a.max[k];
    }
}

/// SAH cost of a wide tree relative to its root box: one node visit per inner child and
/// one leaf test per `W / 4` packets of a leaf child (the 8-wide kernels test packets in
/// pairs), each weighted by the child's area over the root's (the expected work of a
/// random ray through the root box). Zero for an empty tree.
pub(crate) fn sah_cost<const W: usize>(nodes: &[WideNode<W>]) -> f64 {
    let Some(root) = nodes.first() else { return 0.0 };
    let root_area = node_box(root).surface_area() as f64;
    if !(root_area.is_finite() && root_area > 0.0) {
        return 0.0;
    }
    let mut cost = 1.0;
    for n in nodes {
        for i in 0..W {
            let b = n.child_box(i);
            if b.is_empty() {
                continue;
            }
            let work = if n.count[i] == 0 { 1.0 } else { n.count[i].div_ceil(W as u32 / 4) as f64 };
            cost += work * b.surface_area() as f64 / root_area;
        }
    }
    cost
}
