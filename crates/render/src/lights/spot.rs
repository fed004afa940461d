//! Spot light: a point light whose intensity is `I · smoothstep(cos θ)` around its axis:
//! full inside `cos_falloff_start`, zero outside `cos_total_width`, a smoothstep in
//! `cos θ` between (pbrt-v4 section 12.1.2, `SpotLight::I`). Power
//! `2π (1 − (cos_start + cos_width) / 2) lum(I)` (pbrt-v4 `SpotLight::Phi`).

use filtrace_core::{luminance, Rgb, Vec3};
use std::f32::consts::PI;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpotLight {
    pub position: Vec3,
    /// Unit axis, pointing from the light into the lit cone.
    pub axis: Vec3,
    pub intensity: Rgb,
    pub cos_falloff_start: f32,
    pub cos_total_width: f32,
}

/// `smoothstep(a, b, x)`: 0 below `a`, 1 above `b`, `3t² − 2t³` between; a step at `a`
/// when `a == b`.
#[inline]
pub fn smoothstep(a: f32, b: f32, x: f32) -> f32 {
    if a == b {
        return if x < a { 0.0 } else { 1.0 };
    }
    let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

impl SpotLight {
    /// `None` when the axis is zero or not finite. Cosines are clamped to `[-1, 1]` and
    /// the falloff start is kept inside the total width.
    pub fn new(
        position: Vec3,
        direction: Vec3,
        intensity: Rgb,
        cos_total_width: f32,
        cos_falloff_start: f32,
    ) -> Option<Self> {
        let axis = direction.try_normalize()?;
        let cw = if cos_total_width.is_finite() { cos_total_width.clamp(-1.0, 1.0) } else { return None };
        let cs = if cos_falloff_start.is_finite() { cos_falloff_start.clamp(cw, 1.0) } else { cw };
        Some(SpotLight { position, axis, intensity, cos_falloff_start: cs, cos_total_width: cw })
    }

    /// Angular falloff in `[0, 1]` for a direction at `cos θ` from the axis.
    #[inline]
    pub fn falloff(&self, cos_theta: f32) -> f32 {
        smoothstep(self.cos_total_width, self.cos_falloff_start, cos_theta)
    }

    pub fn power(&self) -> f32 {
        2.0 * PI * (1.0 - 0.5 * (self.cos_falloff_start + self.cos_total_width)) * luminance(self.intensity)
    }

    /// `(wi, I falloff / d², d)` from `p`; `None` outside the cone or at the light.
    #[inline]
    pub fn sample(&self, p: Vec3) -> Option<(Vec3, Rgb, f32)> {
        let d = self.position - p;
        let dist2 = d.length_squared();
        if !(dist2 > 0.0) {
            return None;
        }
        let dist = dist2.sqrt();
        let wi = d / dist;
        let fall = self.falloff(-wi.dot(self.axis));
        if fall <= 0.0 {
            return None;
        }
        Some((wi, self.intensity * (fall / dist2), dist))
    }
}
