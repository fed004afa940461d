//! The `motion` AOV: for each pixel's visible surface, where it was in the previous frame.
//!
//! Definition. The visible surface of a pixel is the primary hit of the ray through its
//! centre (the same ray as sample 0, which gives the G-buffer, see [`crate::camera`]).
//! Its object-space point (barycentrics on the mesh's own triangle) is placed with the
//! instance's previous transform and projected with the previous camera
//! ([`crate::frame`]: the state before the last update). Per pixel:
//! - `motion` (X, Y): previous raster position minus current raster position of the
//!   point, in pixels, x to the right and y down (the image's row order); the previous
//!   position is `(x + 0.5, y + 0.5) + motion`, up to rounding. Exactly zero when neither
//!   the camera nor the instance moved.
//! - `prev_depth`: the point's distance from the previous eye (the `depth` AOV's
//!   convention), and `prev_normal`: its shading normal in the previous frame, facing the
//!   previous eye (the `normal` AOV's convention). A consumer compares them with its
//!   history to detect disocclusion.
//!
//! Pixels without a previous position get `prev_depth = 0` and `prev_normal = 0` (the
//! G-buffer's "no surface"): background pixels, whose `motion` is that of the point at
//! infinity in their direction (camera rotation only) or zero when that direction was
//! behind the previous camera, and surface points that were behind the previous eye,
//! whose `motion` is zero.

use crate::renderer::Renderer;
use crate::surface::SurfaceInteraction;
use filtrace_accel::Hit;
use filtrace_core::{Affine3A, Image, Ray, Vec2, Vec3};
use rayon::prelude::*;

/// The motion layers of a frame (see the module docs).
#[derive(Clone, Debug)]
pub struct MotionAov {
    /// Two channels: offset to the previous raster position, in pixels.
    pub motion: Image,
    /// One channel: distance from the previous eye (0: no previous position).
    pub prev_depth: Image,
    /// Three channels: previous shading normal facing the previous eye.
    pub prev_normal: Image,
}

impl MotionAov {
    /// The EXR layers `motion.X/Y`, `prev_depth.Z`, `prev_normal.X/Y/Z`, as
    /// `(name, channel names, image)`.
    pub fn layers(&self) -> [(&'static str, &'static [&'static str], &Image); 3] {
        [
            ("motion", &["X", "Y"], &self.motion),
            ("prev_depth", &["Z"], &self.prev_depth),
            ("prev_normal", &["X", "Y", "Z"], &self.prev_normal),
        ]
    }
}

/// One pixel of [`MotionAov`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MotionSample {
    pub motion: Vec2,
    pub prev_depth: f32,
    pub prev_normal: Vec3,
}

impl Renderer {
    /// The motion AOV of the current frame (one primary ray per pixel, in parallel).
    pub fn motion_aov(&self) -> MotionAov {
        let (w, h) = (self.settings.width as usize, self.settings.height as usize);
        let rows: Vec<Vec<MotionSample>> = (0..h)
            .into_par_iter()
            .map(|y| (0..w).map(|x| self.motion_at(x as u32, y as u32)).collect())
            .collect();
        let pixels = rows.iter().flatten();
        let image = |c: usize, f: &dyn Fn(&MotionSample) -> Vec<f32>| {
            Image::from_vec(w, h, c, pixels.clone().flat_map(f).collect()).expect("size matches")
        };
        MotionAov {
            motion: image(2, &|s| s.motion.to_array().to_vec()),
            prev_depth: image(1, &|s| vec![s.prev_depth]),
            prev_normal: image(3, &|s| s.prev_normal.to_array().to_vec()),
        }
    }

    /// The motion of the surface seen through the centre of pixel `(x, y)`.
    pub fn motion_at(&self, x: u32, y: u32) -> MotionSample {
        let ray = self.camera.generate_ray(x, y, Vec2::splat(0.5));
        // As `PathContext::intersect`, keeping the hit's barycentrics.
        let hit = self.accel.intersect(&ray);
        let surface =
            hit.and_then(|h| Some((h, SurfaceInteraction::from_hit(&self.scene, &self.geometry, &ray, &h)?)));
        let Some((hit, si)) = surface else { return self.background_motion(&ray) };
        let (t1, t0) =
            (self.scene.instances[si.instance as usize].transform, self.previous_transform(si.instance));
        let (p, mut n_g, mut n_s) = if t1 == t0 {
            (si.p, si.n_g, si.n_s)
        } else {
            let p = t0.transform_point3(self.object_point(&hit));
            (p, carry_normal(&t1, &t0, si.n_g), carry_normal(&t1, &t0, si.n_s))
        };
        let prev = &self.frame.prev_camera;
        let (Some(before), Some(now)) = (prev.raster_of(p), self.camera.raster_of(si.p)) else {
            return MotionSample::default();
        };
        if n_g.dot(prev.eye - p) < 0.0 {
            (n_g, n_s) = (-n_g, -n_s);
        }
        debug_assert!(n_g.is_finite());
        MotionSample { motion: before - now, prev_depth: (p - prev.eye).length(), prev_normal: n_s }
    }

    /// A miss: the point at infinity moves with the camera's rotation only.
    fn background_motion(&self, ray: &Ray) -> MotionSample {
        let before = self.frame.prev_camera.raster_of_direction(ray.dir);
        let now = self.camera.raster_of_direction(ray.dir);
        match (before, now) {
            (Some(b), Some(n)) => MotionSample { motion: b - n, ..MotionSample::default() },
            _ => MotionSample::default(),
        }
    }

    /// Instance `i`'s transform in the previous frame.
    fn previous_transform(&self, i: u32) -> Affine3A {
        self.frame.prev_transforms[i as usize]
    }

    /// The hit point in its mesh's object space, from the barycentrics on the mesh's own
    /// triangle (no round trip through the inverse transform).
    fn object_point(&self, hit: &Hit) -> Vec3 {
        let mesh = &self.scene.meshes[self.scene.instances[hit.instance as usize].mesh as usize];
        let [p0, p1, p2] = mesh.triangle(hit.prim as usize);
        (1.0 - hit.u - hit.v) * p0 + hit.u * p1 + hit.v * p2
    }
}

/// A world normal under transform `from` carried to where transform `to` puts the same
/// surface: back to object space (`Mᵀ n`, the inverse of the inverse transpose), then out
/// with `to`'s inverse transpose. Unit length; zero when a transform is singular.
fn carry_normal(from: &Affine3A, to: &Affine3A, n: Vec3) -> Vec3 {
    let object = from.matrix3.transpose() * filtrace_core::Vec3A::from(n);
    let out = to.matrix3.inverse().transpose() * object;
    let out = Vec3::from(out).normalize_or_zero();
    if out.is_finite() {
        out
    } else {
        Vec3::ZERO
    }
}
