//! Emission sampling: a ray leaving a light with its emitted quantity and densities
//! (pbrt-v4 `Light::SampleLe`, section 12; Veach 1997, section 10.2 for light tracing).
//! Light tracing and instant radiosity (Keller 1997) start their paths here.
//!
//! Per light type, with `u_pos`, `u_dir` uniform in `[0, 1)²`:
//! - area (triangle): point uniform on the triangle (`pdf_pos = 1/A`), direction
//!   cosine-weighted around the emitting normal (`pdf_dir = cos θ / π`); a two-sided emitter
//!   picks its face with `u_dir.x` first (`pdf_dir = cos θ / 2π`); `le` = radiance;
//! - point: the light's position (`pdf_pos = 1`, delta), uniform direction on the sphere
//!   (`pdf_dir = 1/4π`), `le` = intensity;
//! - spot: position (delta), uniform direction inside the cone of total width
//!   (`pdf_dir = 1/(2π(1 − cos θ_w))`), `le` = intensity × falloff;
//! - directional: a point uniform on the disk of radius `R` (the scene's bounding sphere)
//!   facing the light, outside the scene (`pdf_pos = 1/πR²`), direction delta (`pdf_dir =
//!   1`), `le` = irradiance;
//! - environment: a direction from the environment's own distribution, then a point on
//!   the disk of radius `R` facing it (`pdf_pos = 1/πR²`), `le` = radiance.
//!
//! The flux one sample carries is [`LeSample::flux`]: `le |cos θ| / (p_sel pdf_pos
//! pdf_dir)`, its expectation the light's emitted power per channel (tested).

use super::{AreaLight, DirectionalLight, EnvironmentLight, PointLight, SpotLight};
use filtrace_core::sampling::{
    sample_concentric_disk, sample_cosine_hemisphere, sample_uniform_cone, sample_uniform_sphere,
    sample_uniform_triangle, uniform_cone_pdf, Frame, INV_4PI,
};
use filtrace_core::{Rgb, Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

/// Which kind of light emitted a [`LeSample`] (VPL generation treats them differently).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EmitterKind {
    Area,
    Point,
    Spot,
    Directional,
    Environment,
}

impl EmitterKind {
    /// The position is a delta (point and spot lights).
    pub fn delta_position(self) -> bool {
        matches!(self, EmitterKind::Point | EmitterKind::Spot)
    }
    /// The direction is a delta (directional light).
    pub fn delta_direction(self) -> bool {
        matches!(self, EmitterKind::Directional)
    }
}

/// A ray leaving a light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeSample {
    /// Ray origin (outside the scene's bounding sphere for distant lights).
    pub p: Vec3,
    /// Unit emitting normal at `p` on the side of `dir` (area lights), `dir` itself for the
    /// disk of a distant light, zero for point and spot lights.
    pub n: Vec3,
    /// Unit direction of emission.
    pub dir: Vec3,
    /// Radiance (area, environment), intensity (point, spot) or irradiance (directional).
    pub le: Rgb,
    /// Area density of `p` (1 for a delta position).
    pub pdf_pos: f32,
    /// Solid-angle density of `dir` (1 for a delta direction).
    pub pdf_dir: f32,
    /// Probability of having selected this light (1 from a light's own `sample_le`).
    pub pmf: f32,
    pub kind: EmitterKind,
}

impl LeSample {
    /// `|n · dir|`, or 1 where `n` is zero (point and spot lights).
    #[inline]
    pub fn cos_emit(&self) -> f32 {
        if self.n == Vec3::ZERO {
            1.0
        } else {
            self.n.dot(self.dir).abs()
        }
    }

    /// Flux carried by the ray, `le |cos| / (pmf pdf_pos pdf_dir)`: the initial path
    /// throughput of light tracing (its mean is the power).
    #[inline]
    pub fn flux(&self) -> Rgb {
        self.le * (self.cos_emit() / (self.pmf * self.pdf_pos * self.pdf_dir))
    }
}

/// `Some(s)` when its densities are positive and finite and it carries light.
#[inline]
fn usable(s: LeSample) -> Option<LeSample> {
    let ok = s.pdf_pos > 0.0 && s.pdf_pos.is_finite() && s.pdf_dir > 0.0 && s.pdf_dir.is_finite();
    (ok && s.le.max_element() > 0.0 && s.le.is_finite() && s.dir.is_finite()).then_some(s)
}

impl AreaLight {
    /// Point uniform on the triangle, direction cosine-weighted on the emitting side (a
    /// two-sided light picks its side with `u_dir.x`).
    #[inline]
    pub fn sample_le(&self, u_pos: Vec2, u_dir: Vec2) -> Option<LeSample> {
        let [_, b1, b2] = sample_uniform_triangle(u_pos);
        let p = self.p0 + self.e1 * b1 + self.e2 * b2;
        let (n, u, side_pmf) = if !self.two_sided {
            (self.n, u_dir, 1.0)
        } else if u_dir.x < 0.5 {
            (self.n, Vec2::new(2.0 * u_dir.x, u_dir.y), 0.5)
        } else {
            (-self.n, Vec2::new((2.0 * u_dir.x - 1.0).min(1.0 - f32::EPSILON), u_dir.y), 0.5)
        };
        let local = sample_cosine_hemisphere(u);
        let dir = Frame::from_z(n).to_world(local);
        let pdf_dir = side_pmf * local.z * FRAC_1_PI;
        let (pdf_pos, pmf, kind) = (1.0 / self.area, 1.0, EmitterKind::Area);
        usable(LeSample { p, n, dir, le: self.le, pdf_pos, pdf_dir, pmf, kind })
    }
}

impl PointLight {
    /// The light's position, direction uniform on the sphere.
    #[inline]
    pub fn sample_le(&self, u_dir: Vec2) -> Option<LeSample> {
        let dir = sample_uniform_sphere(u_dir);
        let (n, pdf_pos, pdf_dir, pmf) = (Vec3::ZERO, 1.0, INV_4PI, 1.0);
        usable(LeSample {
            p: self.position,
            n,
            dir,
            le: self.intensity,
            pdf_pos,
            pdf_dir,
            pmf,
            kind: EmitterKind::Point,
        })
    }
}

impl SpotLight {
    /// The light's position, direction uniform in the cone of total width.
    #[inline]
    pub fn sample_le(&self, u_dir: Vec2) -> Option<LeSample> {
        let local = sample_uniform_cone(u_dir, self.cos_total_width);
        let dir = Frame::from_z(self.axis).to_world(local);
        let le = self.intensity * self.falloff(local.z);
        let pdf_dir = uniform_cone_pdf(self.cos_total_width);
        let (n, pdf_pos, pmf) = (Vec3::ZERO, 1.0, 1.0);
        usable(LeSample { p: self.position, n, dir, le, pdf_pos, pdf_dir, pmf, kind: EmitterKind::Spot })
    }
}

/// A point uniform on the disk of radius `radius` facing `-dir`, pushed `radius` back
/// from `center` against `dir`, so the ray `(p, dir)` crosses the whole bounding sphere.
#[inline]
fn disk_origin(center: Vec3, radius: f32, dir: Vec3, u: Vec2) -> Vec3 {
    let d = sample_concentric_disk(u);
    let f = Frame::from_z(dir);
    center + radius * (f.x * d.x + f.y * d.y - dir)
}

impl DirectionalLight {
    /// Parallel rays towards the scene from a disk covering its bounding sphere
    /// (`center`, `radius`).
    #[inline]
    pub fn sample_le(&self, u_pos: Vec2, center: Vec3, radius: f32) -> Option<LeSample> {
        let dir = -self.to_light;
        let p = disk_origin(center, radius, dir, u_pos);
        let pdf_pos = 1.0 / (PI * radius * radius);
        let (le, pdf_dir, pmf) = (self.irradiance, 1.0, 1.0);
        usable(LeSample { p, n: dir, dir, le, pdf_pos, pdf_dir, pmf, kind: EmitterKind::Directional })
    }
}

impl EnvironmentLight {
    /// A direction from the environment's distribution (`u_dir`), then a point on the disk
    /// facing it (`u_pos`) covering the bounding sphere (`center`, `radius`).
    #[inline]
    pub fn sample_le(&self, u_pos: Vec2, u_dir: Vec2, center: Vec3, radius: f32) -> Option<LeSample> {
        let (wi, pdf_dir) = self.sample(u_dir)?;
        let dir = -wi;
        let p = disk_origin(center, radius, dir, u_pos);
        let pdf_pos = 1.0 / (PI * radius * radius);
        let (le, pmf) = (self.radiance(wi), 1.0);
        usable(LeSample { p, n: dir, dir, le, pdf_pos, pdf_dir, pmf, kind: EmitterKind::Environment })
    }
}

#[cfg(test)]
#[path = "emission_tests.rs"]
mod tests;
