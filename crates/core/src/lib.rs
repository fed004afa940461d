//! # filtrace-core
//!
//! The foundation every other filtrace crate stands on: math types (re-exported from
//! `glam`), rays and bounding boxes, Monte Carlo sampling routines, the deterministic
//! low-discrepancy sampler, and plain image buffers. No I/O lives here, except
//! [`shared_data`]: where every crate's tests find the data kept outside the repository.

pub mod aabb;
pub mod cpu;
pub mod image;
pub mod ray;
pub mod rng;
pub mod sampler;
pub mod sampling;
pub mod shared_data;
pub mod stats;

pub use aabb::Aabb;
pub use glam::{Affine3A, Mat3, Mat3A, Mat4, Quat, UVec2, Vec2, Vec3, Vec3A, Vec4};
pub use image::Image;
pub use ray::Ray;

/// Linear RGB radiance / reflectance triple. filtrace renders in linear sRGB primaries.
pub type Rgb = Vec3;

/// Relative luminance of linear sRGB (Rec. 709 weights).
#[inline]
pub fn luminance(c: Rgb) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}
