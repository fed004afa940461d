//! The surface record of a ray hit, and spawning rays from it without self-intersection.
//!
//! [`SurfaceInteraction::from_hit`] recomputes the hit point from the barycentrics on the
//! world-space triangle (more accurate than `origin + t * dir` far along a ray), computes
//! the geometric normal from the winding (`(p1 - p0) x (p2 - p0)`), interpolates the shading
//! normal when the mesh has vertex normals (falling back to the geometric one) and the uv.
//!
//! Orientation: the shading normal `n_s` is first flipped into the hemisphere of the
//! geometric normal `n_g`; then, since every BSDF in filtrace is two-sided, both are
//! flipped together to the side of the outgoing direction `wo` ([`SurfaceInteraction::
//! facing`]). `front_face` remembers whether the ray hit the winding's front face (used for
//! one-sided emission).
//!
//! Self-intersection: spawned rays start at `p` offset along `n_g` to the side of the new
//! direction by a scale-aware epsilon in the spirit of pbrt-v4's error bounds (sec. 6.8.6):
//! `gamma(7) * OFFSET_SAFETY * max|coordinate of the triangle| + OFFSET_FLOOR` in every
//! component. pbrt's per-component bound `gamma(6) (|b0 p0| + |b1 p1| + |b2 p2|)` covers the
//! error of `p` itself but not that of the BVH's watertight ray-triangle test, which is
//! relative to the largest coordinate (see the test `wall_at_zero_does_not_self_intersect`). Shadow rays towards a point stop
//! [`SHADOW_END_FRACTION`] short of it, so that they do not hit the light's own triangle.

use crate::bsdf::SurfaceBsdf;
use filtrace_accel::Hit;
use filtrace_core::{Mat3A, Ray, Vec2, Vec3};
use filtrace_scene::{Bsdf, MaterialId, Scene, Texturable};

/// `gamma(n) = n eps / (1 - n eps)` for `eps = 2^-24` (pbrt's rounding-error bound).
#[inline]
pub const fn gamma(n: i32) -> f32 {
    let e = f32::EPSILON * 0.5 * n as f32;
    e / (1.0 - e)
}

/// Multiplier on the error bound: covers the Möller-Trumbore `t` error we do not track.
pub const OFFSET_SAFETY: f32 = 4.0;
/// Smallest offset (in world units), for hits at the origin.
pub const OFFSET_FLOOR: f32 = 1e-6;
/// Shadow rays to a point end at `(1 - SHADOW_END_FRACTION)` of the distance.
pub const SHADOW_END_FRACTION: f32 = 1e-4;

/// World-space data the integrator reads at every hit, computed once per scene: one
/// [`TriangleRecord`] per triangle (world corners by the same `transform_point3` the BVH
/// uses, so the values are those it intersected; winding normal; offset scale; material with
/// overrides applied) and per instance its normal transform and whether its mesh has
/// vertex normals or uvs. One record per triangle is one bounds check and one or two cache
/// lines per hit, where four parallel arrays were four.
///
/// It also keeps the [`SurfaceBsdf`] of every material without textures, evaluated once:
/// building it per vertex (a match, a texture-enum match, Fresnel/roughness set-up) was
/// ~2.5% of the Cornell box's instructions (cachegrind).
#[derive(Clone, Debug)]
pub struct SceneGeometry {
    instances: Vec<InstanceRecord>,
    tris: Vec<TriangleRecord>,
    /// Per material: its BSDF when it does not depend on `uv`, else `None`.
    constant_bsdfs: Vec<Option<SurfaceBsdf>>,
}

/// Per-instance data of [`SceneGeometry`].
#[derive(Clone, Copy, Debug)]
struct InstanceRecord {
    /// Inverse transpose of the instance's linear part.
    normal_xf: Mat3A,
    /// Index in `tris` of the instance's first triangle.
    first_tri: u32,
    /// The mesh has one normal (uv) per vertex, so shading normals (uvs) are interpolated.
    has_normals: bool,
    has_uvs: bool,
}

/// An instance's vertex data as [`SceneGeometry::vertex_attributes`] gives it.
pub(crate) struct VertexAttributes<'s> {
    pub(crate) mesh: &'s filtrace_scene::Mesh,
    /// Inverse transpose of the instance's linear part.
    pub(crate) normal_xf: &'s Mat3A,
    pub(crate) has_normals: bool,
    pub(crate) has_uvs: bool,
}

/// Per-triangle data of [`SceneGeometry`]; `repr(C)`: the lockstep integrator reads the
/// records as rows of [`TRI_FLOATS`] 32-bit words ([`SceneGeometry::tri_words`]).
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub(crate) struct TriangleRecord {
    /// World-space corners.
    pub(crate) p: [Vec3; 3],
    /// Unit winding normal `normalize((p1 - p0) x (p2 - p0))`, zero for degenerate or
    /// non-finite triangles (so that a hit needs neither a cross product nor a square root).
    pub(crate) n: Vec3,
    /// Largest absolute coordinate of the corners (the scale of the offset bound).
    pub(crate) scale: f32,
    pub(crate) material: MaterialId,
}

impl TriangleRecord {
    /// The record of triangle `prim` of instance `instance` of `scene`.
    fn new(scene: &Scene, instance: u32, prim: u32) -> Self {
        let inst = &scene.instances[instance as usize];
        let mesh = &scene.meshes[inst.mesh as usize];
        let [p0, p1, p2] = mesh.triangle(prim as usize).map(|v| inst.transform.transform_point3(v));
        let n = (p1 - p0).cross(p2 - p0).normalize_or_zero();
        TriangleRecord {
            p: [p0, p1, p2],
            n: if n.is_finite() { n } else { Vec3::ZERO },
            scale: p0.abs().max(p1.abs()).max(p2.abs()).max_element(),
            material: scene.material_of(instance, prim),
        }
    }
}

/// The inverse transpose of a transform's linear part (the identity when singular).
fn normal_transform(t: &filtrace_core::Affine3A) -> Mat3A {
    let inv = t.matrix3.inverse();
    if inv.is_finite() {
        inv.transpose()
    } else {
        Mat3A::IDENTITY
    }
}

/// 32-bit words per [`TriangleRecord`]: `p` at 0..9, `n` at 9..12, `scale` at 12, the
/// material's bits at 13.
pub(crate) const TRI_FLOATS: usize = 14;
const _: () = assert!(std::mem::size_of::<TriangleRecord>() == TRI_FLOATS * 4);

impl SceneGeometry {
    pub fn new(scene: &Scene) -> Self {
        let constant_bsdfs = scene
            .materials
            .iter()
            .map(|m| {
                let constant = match &m.bsdf {
                    Bsdf::Diffuse { reflectance: t } | Bsdf::Plastic { diffuse: t, .. } => {
                        matches!(t, Texturable::Constant(_))
                    }
                    Bsdf::Conductor { .. } => true,
                };
                constant.then(|| SurfaceBsdf::from_material(&m.bsdf, &scene.textures, Vec2::ZERO))
            })
            .collect();
        let mut g = SceneGeometry {
            instances: Vec::with_capacity(scene.instances.len()),
            tris: Vec::with_capacity(scene.triangle_count()),
            constant_bsdfs,
        };
        for (ii, inst) in scene.instances.iter().enumerate() {
            let mesh = &scene.meshes[inst.mesh as usize];
            g.instances.push(InstanceRecord {
                normal_xf: normal_transform(&inst.transform),
                first_tri: g.tris.len() as u32,
                has_normals: !mesh.normals.is_empty() && mesh.normals.len() == mesh.positions.len(),
                has_uvs: !mesh.uvs.is_empty() && mesh.uvs.len() == mesh.positions.len(),
            });
            g.tris
                .extend((0..mesh.triangle_count() as u32).map(|p| TriangleRecord::new(scene, ii as u32, p)));
        }
        g
    }

    /// Rewrites the records of instance `i` after its transform changed (a moved object in
    /// a per-frame update): its triangles' world corners, normals and offset scales and
    /// its normal transform, the values a fresh [`SceneGeometry::new`] would compute.
    /// Costs one record per triangle of `i`; other instances are untouched. The scene's
    /// meshes and instance list must be those it was built from.
    pub fn update_instance(&mut self, scene: &Scene, i: u32) {
        let inst = &scene.instances[i as usize];
        let rec = &mut self.instances[i as usize];
        rec.normal_xf = normal_transform(&inst.transform);
        let first = rec.first_tri as usize;
        let count = scene.meshes[inst.mesh as usize].triangle_count();
        for (p, t) in self.tris[first..first + count].iter_mut().enumerate() {
            *t = TriangleRecord::new(scene, i, p as u32);
        }
    }

    #[inline]
    fn record(&self, instance: u32, prim: u32) -> &TriangleRecord {
        &self.tris[(self.instances[instance as usize].first_tri + prim) as usize]
    }

    /// Row of the record of triangle `prim` of instance `instance` in [`Self::tri_words`]
    /// (the lockstep integrator's vector `from_hit`) and whether the instance's mesh has
    /// vertex normals or uvs ([`Self::vertex_attributes`]).
    #[inline]
    pub(crate) fn row(&self, instance: u32, prim: u32) -> (usize, bool) {
        let inst = &self.instances[instance as usize];
        ((inst.first_tri + prim) as usize, inst.has_normals || inst.has_uvs)
    }

    /// What [`SurfaceInteraction::from_hit`] reads to interpolate the vertex attributes of
    /// a hit on instance `instance` of `scene`: its mesh, normal transform, and whether the
    /// mesh has vertex normals and uvs.
    #[inline]
    pub(crate) fn vertex_attributes<'s>(&'s self, scene: &'s Scene, instance: u32) -> VertexAttributes<'s> {
        let inst = &self.instances[instance as usize];
        VertexAttributes {
            mesh: &scene.meshes[scene.instances[instance as usize].mesh as usize],
            normal_xf: &inst.normal_xf,
            has_normals: inst.has_normals,
            has_uvs: inst.has_uvs,
        }
    }

    /// The triangle records as rows of [`TRI_FLOATS`] words (the material as its bits).
    #[inline]
    pub(crate) fn tri_words(&self) -> &[f32] {
        // SAFETY: `TriangleRecord` is `repr(C)` of 14 four-byte fields (`f32` and `u32`;
        // the size assertion above), so the buffer holds `len * TRI_FLOATS` initialised
        // words aligned for `f32`; every bit pattern is a valid `f32`.
        unsafe { std::slice::from_raw_parts(self.tris.as_ptr() as *const f32, self.tris.len() * TRI_FLOATS) }
    }

    /// World-space corners of triangle `prim` of instance `instance`.
    #[inline]
    pub fn triangle(&self, instance: u32, prim: u32) -> &[Vec3; 3] {
        &self.record(instance, prim).p
    }

    /// Unit winding normal of triangle `prim` of instance `instance` (zero when degenerate)
    /// and the largest absolute coordinate of its corners.
    #[inline]
    pub fn normal_and_scale(&self, instance: u32, prim: u32) -> (Vec3, f32) {
        let r = self.record(instance, prim);
        (r.n, r.scale)
    }

    /// The BSDF of `material` at texture coordinate `uv`: the stored one for materials
    /// without textures, else evaluated ([`SurfaceBsdf::from_material`]; same values).
    #[inline]
    pub fn bsdf(&self, scene: &Scene, material: MaterialId, uv: Vec2) -> SurfaceBsdf {
        match self.constant_bsdfs.get(material as usize) {
            Some(Some(b)) => *b,
            _ => SurfaceBsdf::from_material(&scene.materials[material as usize].bsdf, &scene.textures, uv),
        }
    }

    /// The reflectance of `material` when its BSDF is an untextured Lambert (the stored
    /// [`SurfaceBsdf::Diffuse`], so the same value `bsdf` gives).
    #[inline]
    pub(crate) fn constant_diffuse(&self, material: MaterialId) -> Option<filtrace_core::Rgb> {
        match self.constant_bsdfs.get(material as usize) {
            Some(Some(SurfaceBsdf::Diffuse(d))) => Some(d.reflectance),
            _ => None,
        }
    }

    /// Material of triangle `prim` of instance `instance` (overrides applied).
    #[inline]
    pub fn material(&self, instance: u32, prim: u32) -> MaterialId {
        self.record(instance, prim).material
    }
}

/// Everything the integrator needs to know about a hit.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceInteraction {
    /// World-space position recomputed from the barycentrics.
    pub p: Vec3,
    /// Per-component absolute error bound of `p`.
    pub p_error: Vec3,
    /// Unit geometric normal, on the side of `wo`.
    pub n_g: Vec3,
    /// Unit shading normal, in the hemisphere of `n_g`.
    pub n_s: Vec3,
    /// Geometric normal from the winding, not flipped (for `pdf_area` and one-sided emission).
    pub n_winding: Vec3,
    /// True when the ray arrived at the front face of the winding.
    pub front_face: bool,
    /// Unit direction towards where the ray came from.
    pub wo: Vec3,
    pub uv: Vec2,
    pub material: MaterialId,
    pub instance: u32,
    pub prim: u32,
    /// Distance along the (unit-direction) ray.
    pub t: f32,
}

impl SurfaceInteraction {
    /// The surface at `hit` of `ray` (`ray.dir` need not be unit; `t` is rescaled to a
    /// distance). Returns `None` for hits on degenerate triangles (zero normal).
    #[inline]
    pub fn from_hit(scene: &Scene, geom: &SceneGeometry, ray: &Ray, hit: &Hit) -> Option<Self> {
        let inst = &geom.instances[hit.instance as usize];
        let tri = &geom.tris[(inst.first_tri + hit.prim) as usize];
        let [p0, p1, p2] = tri.p;
        let (b1, b2) = (hit.u, hit.v);
        let b0 = 1.0 - b1 - b2;
        let p = b0 * p0 + b1 * p1 + b2 * p2;
        // Scale-aware bound: the BVH's watertight test works in a frame sheared towards the
        // ray, so its rounding error scales with the largest coordinate of the triangle, not
        // per component (a wall at x = 0 with y, z ~ 500 self-intersected with a
        // per-component bound: rays from it hit it again at t ~ 1e-5; the Cornell image was
        // 2% dark).
        // Per triangle, precomputed: the winding normal and max |coordinate|.
        let n_winding = tri.n;
        if n_winding == Vec3::ZERO {
            return None;
        }
        let p_error = Vec3::splat(tri.scale * (gamma(7) * OFFSET_SAFETY) + OFFSET_FLOOR);

        let dir_len = ray.dir.length();
        let wo = ray.dir * (-1.0 / dir_len);
        let front_face = n_winding.dot(wo) > 0.0;

        // Vertex attributes (shading normals, uvs) come from the mesh, when it has them.
        let mut n_s = n_winding;
        let mut uv = Vec2::new(b1, b2);
        if inst.has_normals || inst.has_uvs {
            let mesh = &scene.meshes[scene.instances[hit.instance as usize].mesh as usize];
            let [i0, i1, i2] = mesh.indices[hit.prim as usize].map(|i| i as usize);
            if inst.has_normals {
                let n = b0 * mesh.normals[i0] + b1 * mesh.normals[i1] + b2 * mesh.normals[i2];
                let n = (inst.normal_xf * n).normalize_or_zero();
                if n.is_finite() && n != Vec3::ZERO {
                    n_s = n;
                }
            }
            if inst.has_uvs {
                uv = b0 * mesh.uvs[i0] + b1 * mesh.uvs[i1] + b2 * mesh.uvs[i2];
            }
        }
        // The shading normal lives in the geometric normal's hemisphere.
        if n_s.dot(n_winding) < 0.0 {
            n_s = -n_s;
        }
        let mut si = SurfaceInteraction {
            p,
            p_error,
            n_g: n_winding,
            n_s,
            n_winding,
            front_face,
            wo,
            uv,
            material: tri.material,
            instance: hit.instance,
            prim: hit.prim,
            t: hit.t * dir_len,
        };
        si.facing();
        Some(si)
    }

    /// Flips `n_g` and `n_s` together to the side of `wo` (two-sided shading).
    #[inline]
    pub fn facing(&mut self) {
        if self.n_g.dot(self.wo) < 0.0 {
            self.n_g = -self.n_g;
            self.n_s = -self.n_s;
        }
    }

    /// The ray origin for leaving the surface in direction `w`: `p` pushed along `n_g` to the
    /// side of `w` by the error bound projected on the normal.
    #[inline]
    pub fn offset_origin(&self, w: Vec3) -> Vec3 {
        let d = self.n_g.abs().dot(self.p_error);
        let offset = if w.dot(self.n_g) < 0.0 { -d * self.n_g } else { d * self.n_g };
        self.p + offset
    }

    /// A ray leaving the surface in unit direction `w`.
    #[inline]
    pub fn spawn_ray(&self, w: Vec3) -> Ray {
        Ray::new(self.offset_origin(w), w)
    }

    /// A shadow ray towards the light point at distance `dist` in unit direction `w`
    /// (`dist = inf` for distant lights).
    #[inline]
    pub fn spawn_shadow_ray(&self, w: Vec3, dist: f32) -> Ray {
        let t_max = if dist.is_finite() { dist * (1.0 - SHADOW_END_FRACTION) } else { f32::INFINITY };
        Ray::segment(self.offset_origin(w), w, 0.0, t_max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use filtrace_accel::SceneAccel;
    use filtrace_core::Affine3A;
    use filtrace_scene::{Instance, Material, Mesh};

    fn quad_scene(transform: Affine3A) -> Scene {
        let mut s = Scene::default();
        let m = s.add_material(Material::default_grey());
        s.meshes.push(Mesh {
            name: "quad".into(),
            positions: vec![
                Vec3::new(-1.0, 0.0, -1.0),
                Vec3::new(-1.0, 0.0, 1.0),
                Vec3::new(1.0, 0.0, 1.0),
                Vec3::new(1.0, 0.0, -1.0),
            ],
            normals: vec![],
            uvs: vec![],
            indices: vec![[0, 1, 2], [0, 2, 3]],
            material_ids: vec![m, m],
        });
        s.instances.push(Instance { mesh: 0, transform, material_override: None });
        s
    }

    #[test]
    fn hit_point_normals_and_facing() {
        let s = quad_scene(Affine3A::IDENTITY);
        let geom = SceneGeometry::new(&s);
        let accel = SceneAccel::build(&s);
        // Winding (p1-p0)x(p2-p0) = (0,0,2)x(2,0,2) = +y: front face up.
        for (origin, dir, front) in [
            (Vec3::new(0.2, 5.0, 0.3), Vec3::new(0.0, -2.0, 0.0), true),
            (Vec3::new(0.2, -5.0, 0.3), Vec3::new(0.0, 1.0, 0.0), false),
        ] {
            let ray = Ray::new(origin, dir);
            let hit = accel.intersect(&ray).unwrap();
            let si = SurfaceInteraction::from_hit(&s, &geom, &ray, &hit).unwrap();
            assert!((si.p - Vec3::new(0.2, 0.0, 0.3)).length() < 1e-6);
            assert!((si.t - 5.0).abs() < 1e-5, "t is a distance: {}", si.t);
            assert_eq!(si.front_face, front);
            assert_eq!(si.n_winding, Vec3::Y);
            assert!(si.n_g.dot(si.wo) > 0.0 && si.n_s.dot(si.n_g) > 0.0);
            // Spawned rays leave without hitting the surface again, on both sides.
            let up = si.spawn_ray(si.n_g);
            assert!(accel.intersect(&up).is_none());
            assert!(up.origin.y * si.n_g.y > 0.0);
        }
    }

    /// The Cornell box's walls lie in planes like x = 0 with the other coordinates ~500: a
    /// per-component error bound offsets by ~1e-6 there, and the watertight test of the BVH
    /// found the wall again at t ~ 1e-5 (the image was 2% dark). Spawned rays must never
    /// hit their own (planar) wall again.
    #[test]
    fn cornell_walls_do_not_self_intersect() {
        let s = filtrace_scene::builtin("cornell").unwrap();
        let geom = SceneGeometry::new(&s);
        let accel = SceneAccel::build(&s);
        let cam = crate::camera::PinholeCamera::new(s.camera.as_ref().unwrap(), 128, 128);
        let mut sampler = filtrace_core::sampler::Sampler::new(0, 0, 0, 3);
        let mut tested = 0;
        for i in 0..128 * 128u32 {
            let ray = cam.generate_ray(i % 128, i / 128, Vec2::splat(0.5));
            let Some(hit) = accel.intersect(&ray) else { continue };
            let si = SurfaceInteraction::from_hit(&s, &geom, &ray, &hit).unwrap();
            sampler.set_slot(i);
            let frame = filtrace_core::sampling::Frame::from_z(si.n_g);
            let w = frame.to_world(filtrace_core::sampling::sample_uniform_hemisphere(sampler.next_2d()));
            if let Some(h2) = accel.intersect(&si.spawn_ray(w)) {
                let n2 = SurfaceInteraction::from_hit(&s, &geom, &si.spawn_ray(w), &h2).unwrap();
                let same_plane =
                    n2.n_winding.dot(si.n_winding) > 0.9999 && (n2.p - si.p).dot(si.n_winding).abs() < 1e-2;
                assert!(!same_plane, "self-hit at {} towards {w} (t = {})", si.p, h2.t);
            }
            tested += 1;
        }
        assert!(tested > 10000);
    }

    /// The stored BSDFs of untextured materials equal the per-hit evaluation, and textured
    /// ones are still evaluated at `uv`.
    #[test]
    fn stored_bsdfs_equal_evaluated_ones() {
        let mut s = quad_scene(Affine3A::IDENTITY);
        s.textures.push(filtrace_scene::Texture {
            name: "t".into(),
            width: 2,
            height: 1,
            texels: vec![filtrace_core::Rgb::X, filtrace_core::Rgb::Y],
        });
        let mut textured = Material::default_grey();
        textured.bsdf = filtrace_scene::Bsdf::Plastic {
            diffuse: filtrace_scene::Texturable::Texture { texture: 0, factor: filtrace_core::Rgb::ONE },
            roughness: 0.3,
            ior: 1.5,
        };
        s.add_material(textured);
        let mut metal = Material::default_grey();
        metal.bsdf = filtrace_scene::Bsdf::Conductor {
            eta: filtrace_core::Rgb::splat(0.2),
            k: filtrace_core::Rgb::splat(3.0),
            roughness: 0.1,
        };
        s.add_material(metal);
        let cornell = filtrace_scene::builtin("cornell").unwrap();
        for scene in [&s, &cornell] {
            let geom = SceneGeometry::new(scene);
            for m in 0..scene.materials.len() as MaterialId {
                for uv in [Vec2::ZERO, Vec2::new(0.25, 0.5), Vec2::new(0.75, 0.1)] {
                    let want = crate::bsdf::SurfaceBsdf::from_material(
                        &scene.materials[m as usize].bsdf,
                        &scene.textures,
                        uv,
                    );
                    assert_eq!(geom.bsdf(scene, m, uv), want, "material {m} at {uv}");
                }
            }
        }
        // The textured material really varies with uv (it is not stored).
        let geom = SceneGeometry::new(&s);
        assert_ne!(geom.bsdf(&s, 1, Vec2::new(0.25, 0.5)), geom.bsdf(&s, 1, Vec2::new(0.75, 0.5)));
    }

    #[test]
    fn spawned_rays_escape_far_from_origin() {
        // A large translation makes the rounding error of p large; grazing rays still escape.
        let s = quad_scene(Affine3A::from_translation(Vec3::new(1e5, 2e4, -3e4)));
        let geom = SceneGeometry::new(&s);
        let accel = SceneAccel::build(&s);
        let mut escaped = 0;
        for i in 0..200 {
            let x = -0.9 + 1.8 * (i as f32 / 200.0);
            let target = Vec3::new(1e5 + x, 2e4, -3e4 + 0.37 * x);
            let origin = target + Vec3::new(3.0, 7.0, -1.0);
            let ray = Ray::new(origin, target - origin);
            let Some(hit) = accel.intersect(&ray) else { continue };
            let si = SurfaceInteraction::from_hit(&s, &geom, &ray, &hit).unwrap();
            let w = Vec3::new(1.0, 0.02, 0.3).normalize(); // grazing, above the surface
            assert!(accel.intersect(&si.spawn_ray(w)).is_none(), "self-hit at {x}");
            escaped += 1;
        }
        assert!(escaped > 150);
    }
}
