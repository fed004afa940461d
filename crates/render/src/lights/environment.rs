//! Environment light: radiance arriving from infinitely far away in every direction.
//!
//! Supports the scene's [`Environment::Constant`] and [`Environment::Sky`]; several
//! environment entries add up. The sky model (our definition, the scene format leaves it
//! open): world `+y` is up; for `y ≥ 0` the radiance blends linearly in `y = cos θ` from
//! `horizon` (y = 0) to `zenith` (y = 1); below the horizon it is `ground`.
//!
//! Sampling: the radiance depends on `y` only, and `y` is uniform for uniform directions
//! on the sphere (Archimedes), so we importance-sample a piecewise-constant distribution
//! over [`Z_BINS`] bands of `y` (weight = the band's maximum luminance, so every direction
//! with radiance has density) and pick `φ` uniformly. Density in solid angle:
//! `pdf(ω) = p_y(y) / (2π)` (pbrt-v4 section 12.5 does the same with a 2D image
//! distribution). A constant environment gives exactly the uniform sphere density.
//!
//! Power for light selection: `π R² lum(E)` with `E = π · mean radiance` (irradiance a
//! plane would receive from a uniform hemisphere) and `R` the scene bounding radius.

use filtrace_core::sampling::{Distribution1D, INV_4PI};
use filtrace_core::{luminance, Rgb, Vec2, Vec3};
use filtrace_scene::Environment;
use std::f32::consts::PI;

/// Number of `y` bands of the sampling distribution (even, so the horizon is a band edge).
pub const Z_BINS: usize = 64;

#[derive(Clone, Debug)]
pub struct EnvironmentLight {
    /// Sum of constant environments.
    pub constant: Rgb,
    /// Summed sky colours `(zenith, horizon, ground)`, zero without a sky.
    pub zenith: Rgb,
    pub horizon: Rgb,
    pub ground: Rgb,
    distribution: Distribution1D,
    mean_luminance: f32,
}

impl EnvironmentLight {
    /// Combines the environments (sum); non-finite or negative colours become 0.
    pub fn new(envs: &[&Environment]) -> Self {
        let fix = |c: Rgb| if c.is_finite() { c.max(Rgb::ZERO) } else { Rgb::ZERO };
        let (mut constant, mut zenith, mut horizon, mut ground) =
            (Rgb::ZERO, Rgb::ZERO, Rgb::ZERO, Rgb::ZERO);
        for e in envs {
            match e {
                Environment::Constant { radiance } => constant += fix(*radiance),
                Environment::Sky { zenith: z, horizon: h, ground: g } => {
                    zenith += fix(*z);
                    horizon += fix(*h);
                    ground += fix(*g);
                }
            }
        }
        let mut light = EnvironmentLight {
            constant,
            zenith,
            horizon,
            ground,
            distribution: Distribution1D::default(),
            mean_luminance: 0.0,
        };
        let mut weights = [0.0f32; Z_BINS];
        let mut mean = 0.0f64;
        for (i, w) in weights.iter_mut().enumerate() {
            let y0 = -1.0 + 2.0 * i as f32 / Z_BINS as f32;
            let y1 = -1.0 + 2.0 * (i + 1) as f32 / Z_BINS as f32;
            // Band maximum: radiance is linear in y inside each band (the horizon is an edge),
            // so it is attained at an end; step just inside so the ground/sky choice is right.
            let lo = luminance(light.radiance_y(y0 + 1e-6 * (y1 - y0)));
            let hi = luminance(light.radiance_y(y1 - 1e-6 * (y1 - y0)));
            *w = lo.max(hi);
            mean += 0.5 * (lo + hi) as f64 / Z_BINS as f64;
        }
        light.distribution = Distribution1D::new(&weights);
        light.mean_luminance = mean as f32;
        light
    }

    /// Radiance as a function of the up component `y`.
    #[inline]
    fn radiance_y(&self, y: f32) -> Rgb {
        let sky =
            if y >= 0.0 { self.horizon + (self.zenith - self.horizon) * y.min(1.0) } else { self.ground };
        self.constant + sky
    }

    /// Radiance arriving from direction `dir` (unit, pointing away from the scene).
    #[inline]
    pub fn radiance(&self, dir: Vec3) -> Rgb {
        self.radiance_y(dir.y)
    }

    pub fn power(&self, scene_radius: f32) -> f32 {
        PI * scene_radius * scene_radius * PI * self.mean_luminance
    }

    /// Samples a direction; returns `(dir, pdf)` with solid-angle pdf, `None` for a black
    /// environment.
    #[inline]
    pub fn sample(&self, u: Vec2) -> Option<(Vec3, f32)> {
        let (x, px, _) = self.distribution.sample_continuous(u.x);
        if !(px > 0.0) || self.distribution.is_degenerate() {
            return None;
        }
        let y = (2.0 * x - 1.0).clamp(-1.0, 1.0);
        let r = (1.0 - y * y).max(0.0).sqrt();
        let (s, c) = (2.0 * PI * u.y).sin_cos();
        // p_y = px / 2 over y ∈ [-1, 1]; dω = dy dφ, φ uniform: pdf = px / (4π).
        Some((Vec3::new(r * c, y, r * s), px * INV_4PI))
    }

    /// Solid-angle density of [`Self::sample`] producing `dir`.
    #[inline]
    pub fn pdf(&self, dir: Vec3) -> f32 {
        if self.distribution.is_degenerate() {
            return 0.0;
        }
        let x = (0.5 * (dir.y + 1.0)).clamp(0.0, filtrace_core::sampling::ONE_MINUS_EPSILON);
        self.distribution.pdf_continuous(x) * INV_4PI
    }
}
