//! Rays with a parametric validity interval `[t_min, t_max]`.

use glam::Vec3;

/// A ray `origin + t * dir`, valid for `t` in `[t_min, t_max]`.
///
/// `dir` need not be normalised; `t` is then measured in units of `|dir|`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    pub t_min: f32,
    pub t_max: f32,
}

impl Ray {
    /// A ray valid on `[0, inf)`.
    #[inline]
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self { origin, dir, t_min: 0.0, t_max: f32::INFINITY }
    }

    /// A ray valid on `[t_min, t_max]`.
    #[inline]
    pub fn segment(origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Self {
        Self { origin, dir, t_min, t_max }
    }

    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + t * self.dir
    }

    /// True when origin and direction are finite and the direction is non-zero.
    /// Queries on invalid rays report no hit instead of panicking.
    #[inline]
    pub fn is_valid(&self) -> bool {
        self.origin.is_finite()
            && self.dir.is_finite()
            && self.dir != Vec3::ZERO
            && !self.t_min.is_nan()
            && !self.t_max.is_nan()
    }
}
