//! # filtrace-accel
//!
//! Ray queries against a [`filtrace_scene::Scene`]: closest hit and any hit (shadow rays).
//!
//! PLACEHOLDER: brute force over all world-space triangles, so that the renderer can be
//! developed against the final API while the two-level SAH BVH is written. The BVH keeps
//! exactly this API (`SceneAccel::build`, `intersect`, `occluded`, `Hit`).

use filtrace_core::{Ray, Vec3};
use filtrace_scene::Scene;

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

/// Acceleration structure over a whole scene.
pub struct SceneAccel {
    tris: Vec<([Vec3; 3], u32, u32)>,
}

impl SceneAccel {
    pub fn build(scene: &Scene) -> Self {
        let mut tris = Vec::new();
        for (ii, inst) in scene.instances.iter().enumerate() {
            let mesh = &scene.meshes[inst.mesh as usize];
            for p in 0..mesh.triangle_count() {
                let t = mesh.triangle(p).map(|v| inst.transform.transform_point3(v));
                tris.push((t, ii as u32, p as u32));
            }
        }
        Self { tris }
    }

    /// Closest hit with `t` in `[ray.t_min, ray.t_max]`, or `None`.
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        let mut best: Option<Hit> = None;
        let mut t_max = ray.t_max;
        for (tri, inst, prim) in &self.tris {
            if let Some((t, u, v)) = intersect_triangle(ray, tri, t_max) {
                t_max = t;
                best = Some(Hit { t, u, v, instance: *inst, prim: *prim });
            }
        }
        best
    }

    /// True when anything is hit with `t` in `[ray.t_min, ray.t_max]`.
    pub fn occluded(&self, ray: &Ray) -> bool {
        ray.is_valid()
            && self.tris.iter().any(|(tri, _, _)| intersect_triangle(ray, tri, ray.t_max).is_some())
    }
}

/// Möller-Trumbore ray-triangle test. Returns `(t, u, v)` for `t` in `[t_min, t_max]`.
#[inline]
pub fn intersect_triangle(ray: &Ray, tri: &[Vec3; 3], t_max: f32) -> Option<(f32, f32, f32)> {
    let e1 = tri[1] - tri[0];
    let e2 = tri[2] - tri[0];
    let p = ray.dir.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let s = ray.origin - tri[0];
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = ray.dir.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    (t >= ray.t_min && t <= t_max).then_some((t, u, v))
}
