//! Thin blades, instanced, and rays at their corners and edges, shared by the splitting
//! tests (`presplit.rs`, `spatial_splits.rs`; included with `#[path]`, beside
//! `rays.rs`, whose `check_rays` they use).

pub use crate::rays::check_rays;
use filtrace_accel::testmesh;
use filtrace_core::{Affine3A, Quat, Ray, Vec3};
use filtrace_scene::{Instance, Scene};

/// `thin_blades(300, 8)` three times: as they are and twice more, rotated and scaled
/// (two-level BVH).
pub fn instanced_blades() -> Scene {
    let mut s = Scene::default();
    s.add_mesh(testmesh::thin_blades(300, 8));
    let place = |scale: f32, rot: Quat, t: Vec3| Instance {
        mesh: 0,
        transform: Affine3A::from_scale_rotation_translation(Vec3::splat(scale), rot, t),
        material_override: None,
    };
    s.instances.push(place(0.7, Quat::from_rotation_y(0.8), Vec3::new(2.5, 0.2, 0.0)));
    s.instances.push(place(1.3, Quat::from_rotation_x(0.4), Vec3::new(-0.5, 0.5, 2.5)));
    s
}

/// Rays from above the blades at the corners, edge midpoints and centre of every triangle
/// of the scene's first mesh: where split pieces meet.
pub fn rays_at_corners_and_edges(scene: &Scene) -> Vec<Ray> {
    let mesh = &scene.meshes[0];
    let origin = Vec3::new(0.1, 3.0, -0.2);
    let mut rays = Vec::new();
    for i in 0..mesh.triangle_count() {
        let [a, b, c] = mesh.triangle(i);
        for target in [a, b, c, 0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a), (a + b + c) / 3.0] {
            rays.push(Ray::new(origin, target - origin));
        }
    }
    rays
}
