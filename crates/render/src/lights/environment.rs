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
//!
//! The lockstep tracer's eight-lane versions ([`EnvironmentLight::radiance8`],
//! [`EnvironmentLight::pdf8`], [`EnvironmentLight::sample8`]) perform the same operations
//! in the same order, so each lane has the scalar bits.

use crate::integrator::lanes::{gather, mask_words, select, trunc_below, F8, LANES, M8, U8, V8};
use filtrace_core::sampling::{Distribution1D, INV_4PI, ONE_MINUS_EPSILON};
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

    /// The distribution of `y` that [`Self::sample`] draws from.
    pub fn distribution(&self) -> &Distribution1D {
        &self.distribution
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

/// Eight samples of [`EnvironmentLight::sample8`].
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct EnvSample8<const A: bool> {
    /// The lanes with a sample (where the scalar code returns `Some`).
    pub(crate) ok: M8<A>,
    /// The lanes left to the scalar [`EnvironmentLight::sample`]: a CDF cell of zero
    /// width (`find_interval` steps off it; reached only at its boundary).
    pub(crate) scalar: M8<A>,
    pub(crate) wi: V8<A>,
    /// The radiance from `wi`.
    pub(crate) li: V8<A>,
    /// Solid-angle density, without light selection.
    pub(crate) pdf: F8<A>,
}

impl EnvironmentLight {
    /// [`Self::radiance`] in lanes, from the directions' up components `y`.
    #[inline(always)]
    pub(crate) fn radiance8<const A: bool>(&self, y: F8<A>) -> V8<A> {
        let blend = V8::splat(self.horizon) + V8::splat(self.zenith - self.horizon) * y.min(F8::splat(1.0));
        let sky = V8::select(y.ge(F8::splat(0.0)), blend, V8::splat(self.ground));
        V8::splat(self.constant) + sky
    }

    /// [`Self::pdf`] in lanes, from the directions' up components `y`.
    #[inline(always)]
    pub(crate) fn pdf8<const A: bool>(&self, y: F8<A>) -> F8<A> {
        let d = &self.distribution;
        let n = d.count();
        if d.is_degenerate() || n == 0 {
            return F8::splat(0.0);
        }
        let (zero, nf) = (F8::splat(0.0), F8::splat(n as f32));
        // `Distribution1D::pdf_continuous`.
        let x = (F8::splat(0.5) * (y + F8::splat(1.0))).clamp(zero, F8::splat(ONE_MINUS_EPSILON));
        let inside = x.ge(zero) & x.lt(F8::splat(1.0));
        let i = trunc_below(x * nf, n as u32);
        let cdf = d.cdf();
        let pmf = gather(cdf, i.wrapping_add(U8::splat(1))) - gather(cdf, i);
        select(inside, pmf * nf, zero) * F8::splat(INV_4PI)
    }

    /// [`Self::sample`] in the lanes `lanes` with `(ux, uy)`. The band is found by
    /// counting the CDF entries at or below `ux` (`find_interval`'s binary search, without
    /// its branches) and read by two gathers; the sine and cosine of `φ` are libm's, per
    /// lane, as in the scalar code.
    #[inline(always)]
    pub(crate) fn sample8<const A: bool>(&self, lanes: M8<A>, ux: F8<A>, uy: F8<A>) -> EnvSample8<A> {
        let d = &self.distribution;
        let n = d.count();
        if d.is_degenerate() || n == 0 {
            return EnvSample8::default();
        }
        let (zero, one, nf) = (F8::<A>::splat(0.0), F8::<A>::splat(1.0), F8::<A>::splat(n as f32));
        // `Distribution1D::sample_continuous`: the cell, its CDF interval, `u` within it.
        let cdf = d.cdf();
        let mut below = U8::<A>::splat(0);
        for &c in &cdf[1..] {
            below = below.wrapping_sub(mask_words(F8::splat(c).le(ux)));
        }
        let i = below.min(U8::splat(n as u32 - 1));
        let lo = gather(cdf, i);
        let pmf = gather(cdf, i.wrapping_add(U8::splat(1))) - lo;
        let live = pmf.gt(zero);
        let du = select(live, ((ux - lo) / pmf).clamp(zero, F8::splat(ONE_MINUS_EPSILON)), zero);
        let x = ((i.to_f32() + du) / nf).min(F8::splat(ONE_MINUS_EPSILON));
        let px = pmf * nf;
        // The direction: `y` from the band, `φ` uniform.
        let y = (F8::splat(2.0) * x - one).clamp(-one, one);
        let r = (one - y * y).max(zero).sqrt();
        let ok = lanes & live & px.gt(zero);
        let phi = (F8::<A>::splat(2.0 * PI) * uy).to_array();
        let (mut sin, mut cos) = ([0.0f32; LANES], [0.0f32; LANES]);
        for k in 0..LANES {
            if ok.get(k) {
                (sin[k], cos[k]) = phi[k].sin_cos();
            }
        }
        let (sin, cos) = (F8::from_array(sin), F8::from_array(cos));
        EnvSample8 {
            ok,
            scalar: lanes & !live,
            wi: V8::new(r * cos, y, r * sin),
            li: self.radiance8(y),
            pdf: px * F8::splat(INV_4PI),
        }
    }
}
