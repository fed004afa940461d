//! Isotropic point light of radiant intensity `I` (W/sr per channel): radiance arriving
//! at distance `d` is the delta `I / d²` (pbrt-v4 section 12.1, `PointLight`).
//! Power `4π lum(I)`.

use filtrace_core::{luminance, Rgb, Vec3};
use std::f32::consts::PI;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointLight {
    pub position: Vec3,
    pub intensity: Rgb,
}

impl PointLight {
    pub fn power(&self) -> f32 {
        4.0 * PI * luminance(self.intensity)
    }

    /// `(wi, I / d², d)` from `p`; `None` at the light's own position.
    #[inline]
    pub fn sample(&self, p: Vec3) -> Option<(Vec3, Rgb, f32)> {
        let d = self.position - p;
        let dist2 = d.length_squared();
        if !(dist2 > 0.0) {
            return None;
        }
        let dist = dist2.sqrt();
        Some((d / dist, self.intensity / dist2, dist))
    }
}
