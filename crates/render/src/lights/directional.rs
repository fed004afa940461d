//! Directional (distant) light: irradiance `E` on a surface facing it, arriving along
//! `-direction` (`direction` points towards the light). A delta light in direction
//! (pbrt-v4 section 12.4, `DistantLight`). Power for light selection `π R² lum(E)` with
//! `R` the scene's bounding-sphere radius (the light crosses the scene's disk).

use filtrace_core::{luminance, Rgb, Vec3};
use std::f32::consts::PI;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirectionalLight {
    /// Unit direction towards the light.
    pub to_light: Vec3,
    pub irradiance: Rgb,
}

impl DirectionalLight {
    /// `None` for a zero or non-finite direction.
    pub fn new(direction: Vec3, irradiance: Rgb) -> Option<Self> {
        Some(DirectionalLight { to_light: direction.try_normalize()?, irradiance })
    }

    pub fn power(&self, scene_radius: f32) -> f32 {
        PI * scene_radius * scene_radius * luminance(self.irradiance)
    }
}
