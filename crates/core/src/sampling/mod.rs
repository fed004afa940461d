//! Monte Carlo sampling routines: warps from the unit square to disks, hemispheres,
//! spheres, cones and triangles (each with its density), an orthonormal shading frame,
//! the MIS power heuristic; discrete distributions: a piecewise-constant 1D distribution
//! ([`Distribution1D`]) and Walker's alias table ([`AliasTable`]).
//!
//! Conventions: every `sample_*` takes uniform numbers in `[0, 1)`; every `*_pdf` is a
//! density with respect to the measure the warp produces (solid angle for directions,
//! area for points). Directions on the hemisphere are around `+z`.
//!
//! References: pbrt-v4, chapter A.5 ("Sampling multidimensional functions", concentric
//! disk, cosine hemisphere, cone, uniform triangle) and chapter
//! 13.4 (Veach 1997, chapter 9: multiple importance sampling, power heuristic β = 2);
//! Duff et al. 2017, "Building an orthonormal basis, revisited" (JCGT 6(1)) for [`Frame`];
//! Heitz 2019, "A low-distortion map between triangle and square" (the variant pbrt-v4
//! uses in `SampleUniformTriangle`).

use crate::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, FRAC_PI_4, PI};

mod alias;
mod distribution;

pub use alias::AliasTable;
pub use distribution::{normalized_cdf, Distribution1D};

/// `1 / (4π)`, the uniform sphere density.
pub const INV_4PI: f32 = 0.25 * FRAC_1_PI;
/// `1 / (2π)`, the uniform hemisphere density.
pub const INV_2PI: f32 = 0.5 * FRAC_1_PI;

/// An orthonormal basis `(x, y, z)`; `z` is the shading normal of a local shading frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub x: Vec3,
    pub y: Vec3,
    pub z: Vec3,
}

impl Frame {
    /// Builds a right-handed frame around the unit vector `n` without branches
    /// (Duff et al. 2017, listing 3). `n` must be normalised.
    #[inline]
    pub fn from_z(n: Vec3) -> Frame {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let x = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let y = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Frame { x, y, z: n }
    }

    /// World direction `v` expressed in this frame (z = component along the normal).
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.x), v.dot(self.y), v.dot(self.z))
    }

    /// Local direction `v` expressed in world coordinates.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.x * v.x + self.y * v.y + self.z * v.z
    }
}

/// Uniform point on the unit disk, Shirley–Chiu concentric mapping (pbrt-v4 A.5.1):
/// low distortion, so stratified `u` stays stratified.
#[inline]
pub fn sample_concentric_disk(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    // theta = phi in the first case and pi/2 - phi in the second, with |phi| <= pi/4, so
    // (cos theta, sin theta) is (cos phi, sin phi) or (sin phi, cos phi): a short
    // polynomial on [-pi/4, pi/4] instead of libm's sincosf (2% of the Cornell profile).
    if o.x.abs() > o.y.abs() {
        let (s, c) = sin_cos_quarter_pi(FRAC_PI_4 * (o.y / o.x));
        o.x * Vec2::new(c, s)
    } else {
        let (s, c) = sin_cos_quarter_pi(FRAC_PI_4 * (o.x / o.y));
        o.y * Vec2::new(s, c)
    }
}

/// `(sin x, cos x)` for `|x| <= pi/4` by Taylor polynomials of degree 9 and 10 (Horner,
/// in `x^2`): truncation error below `|x|^11 / 11! < 2e-9` and `|x|^12 / 12! < 1e-10` on
/// the interval, so the result is within a few ulp of the rounded value (tested against
/// `f64` in `sin_cos_quarter_pi_is_accurate`). Outside the interval the error grows fast.
#[inline]
pub fn sin_cos_quarter_pi(x: f32) -> (f32, f32) {
    let x2 = x * x;
    let s =
        x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362_880.0)))));
    let c = 1.0
        + x2 * (-0.5
            + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40_320.0 + x2 * (-1.0 / 3_628_800.0)))));
    (s, c)
}

/// Cosine-weighted direction on the `+z` hemisphere (Malley's method: project the
/// concentric disk up). Density [`cosine_hemisphere_pdf`].
#[inline]
pub fn sample_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = sample_concentric_disk(u);
    let z = (1.0 - d.x * d.x - d.y * d.y).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

/// Solid-angle density `cos θ / π` of [`sample_cosine_hemisphere`] (0 below the horizon).
#[inline]
pub fn cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    cos_theta.max(0.0) * FRAC_1_PI
}

/// Uniform direction on the `+z` hemisphere; density [`INV_2PI`].
#[inline]
pub fn sample_uniform_hemisphere(u: Vec2) -> Vec3 {
    let z = u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * u.y).sin_cos();
    Vec3::new(r * c, r * s, z)
}

/// Density of [`sample_uniform_hemisphere`].
#[inline]
pub fn uniform_hemisphere_pdf() -> f32 {
    INV_2PI
}

/// Uniform direction on the unit sphere (Archimedes: `z` uniform in `[-1, 1]`).
#[inline]
pub fn sample_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * u.y).sin_cos();
    Vec3::new(r * c, r * s, z)
}

/// Density of [`sample_uniform_sphere`].
#[inline]
pub fn uniform_sphere_pdf() -> f32 {
    INV_4PI
}

/// Uniform direction inside the cone of half-angle `acos(cos_theta_max)` around `+z`.
#[inline]
pub fn sample_uniform_cone(u: Vec2, cos_theta_max: f32) -> Vec3 {
    let cos_theta = (1.0 - u.x) + u.x * cos_theta_max;
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * u.y).sin_cos();
    Vec3::new(sin_theta * c, sin_theta * s, cos_theta)
}

/// Density `1 / (2π (1 - cos θ_max))` of [`sample_uniform_cone`]; infinite for a
/// degenerate cone (`cos_theta_max == 1`).
#[inline]
pub fn uniform_cone_pdf(cos_theta_max: f32) -> f32 {
    1.0 / (2.0 * PI * (1.0 - cos_theta_max))
}

/// Uniform barycentrics `(b0, b1, b2)` over a triangle, Heitz's low-distortion map
/// (pbrt-v4 `SampleUniformTriangle`). The point is `b0 p0 + b1 p1 + b2 p2`; its area
/// density is `1 / area`.
#[inline]
pub fn sample_uniform_triangle(u: Vec2) -> [f32; 3] {
    // pbrt halves the smaller of u.x, u.y and subtracts that half from the other, in two
    // branches; `u - u/2 = u/2` exactly in floating point, so subtracting `m` from both is
    // the same bits without the (unpredictable) branch: 6% of `sample_one_light`.
    let m = 0.5 * u.x.min(u.y);
    let (b0, b1) = (u.x - m, u.y - m);
    [b0, b1, 1.0 - b0 - b1]
}

/// [`sample_uniform_triangle`] as pbrt-v4 writes it (two branches), the reference the
/// branch-free form is tested against.
pub fn sample_uniform_triangle_naive(u: Vec2) -> [f32; 3] {
    let (b0, b1) = if u.x < u.y {
        let b0 = u.x * 0.5;
        (b0, u.y - b0)
    } else {
        let b1 = u.y * 0.5;
        (u.x - b1, b1)
    };
    [b0, b1, 1.0 - b0 - b1]
}

/// Veach's power heuristic (β = 2) weight for strategy `f` taking `nf` samples of density
/// `f_pdf` against strategy `g` with `ng` samples of density `g_pdf` (Veach 1997, eq. 9.13).
/// Returns 0 when both densities are 0, and 1 when `f`'s term overflows.
#[inline]
pub fn power_heuristic(nf: f32, f_pdf: f32, ng: f32, g_pdf: f32) -> f32 {
    let f = nf * f_pdf;
    let g = ng * g_pdf;
    let f2 = f * f;
    if f2.is_infinite() {
        return 1.0;
    }
    let denom = f2 + g * g;
    if denom > 0.0 {
        f2 / denom
    } else {
        0.0
    }
}

/// Largest f32 below 1.
pub const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize) -> impl Iterator<Item = Vec2> {
        (0..n).flat_map(move |i| {
            (0..n).map(move |j| Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32))
        })
    }

    #[test]
    fn frame_is_orthonormal_and_round_trips() {
        let dirs = [
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.3, -0.4, 0.866).normalize(),
            Vec3::new(1e-4, 2e-4, -1.0).normalize(),
            Vec3::new(-0.7, 0.7, 1e-7).normalize(),
        ];
        for n in dirs {
            let f = Frame::from_z(n);
            assert!((f.x.length() - 1.0).abs() < 1e-5 && (f.y.length() - 1.0).abs() < 1e-5);
            assert!(f.x.dot(f.y).abs() < 1e-5 && f.x.dot(f.z).abs() < 1e-5 && f.y.dot(f.z).abs() < 1e-5);
            assert!((f.x.cross(f.y) - f.z).length() < 1e-5, "right-handed for {n}");
            let v = Vec3::new(0.2, -0.5, 0.7);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
            assert!((f.to_local(n) - Vec3::Z).length() < 1e-5);
        }
    }

    proptest::proptest! {
        /// Frames from arbitrary (normalised) directions are orthonormal and right-handed.
        #[test]
        fn frame_orthonormal_for_any_normal(x in -1.0f32..1.0, y in -1.0f32..1.0, z in -1.0f32..1.0) {
            let v = Vec3::new(x, y, z);
            proptest::prop_assume!(v.length() > 1e-3);
            let n = v.normalize();
            let f = Frame::from_z(n);
            proptest::prop_assert!((f.x.length() - 1.0).abs() < 1e-4 && (f.y.length() - 1.0).abs() < 1e-4);
            proptest::prop_assert!(f.x.dot(f.y).abs() < 1e-4 && f.x.dot(n).abs() < 1e-4 && f.y.dot(n).abs() < 1e-4);
            proptest::prop_assert!((f.x.cross(f.y) - n).length() < 1e-4);
        }

        /// Every warp maps the closed unit square into its domain with a finite result.
        #[test]
        fn warps_stay_in_domain(u in 0.0f32..1.0, v in 0.0f32..1.0, c in -1.0f32..1.0) {
            let uv = Vec2::new(u, v);
            proptest::prop_assert!(sample_concentric_disk(uv).length() <= 1.0 + 1e-6);
            let h = sample_cosine_hemisphere(uv);
            proptest::prop_assert!(h.is_finite() && h.z >= 0.0 && (h.length() - 1.0).abs() < 1e-4);
            let k = sample_uniform_cone(uv, c);
            proptest::prop_assert!(k.z >= c - 1e-5 && (k.length() - 1.0).abs() < 1e-4);
            let b = sample_uniform_triangle(uv);
            proptest::prop_assert!(b.iter().all(|&x| (-1e-6..=1.0 + 1e-6).contains(&x)));
        }
    }

    #[test]
    fn disk_and_hemisphere_warps_land_in_their_domains() {
        for u in grid(64) {
            assert!(sample_concentric_disk(u).length() <= 1.0 + 1e-6);
            let c = sample_cosine_hemisphere(u);
            assert!((c.length() - 1.0).abs() < 1e-5 && c.z >= 0.0);
            let h = sample_uniform_hemisphere(u);
            assert!((h.length() - 1.0).abs() < 1e-5 && h.z >= 0.0);
            let s = sample_uniform_sphere(u);
            assert!((s.length() - 1.0).abs() < 1e-5);
            let k = sample_uniform_cone(u, 0.8);
            assert!((k.length() - 1.0).abs() < 1e-5 && k.z >= 0.8 - 1e-6);
            let b = sample_uniform_triangle(u);
            assert!(
                b.iter().all(|&x| (0.0..=1.0).contains(&x)) && (b.iter().sum::<f32>() - 1.0).abs() < 1e-6
            );
        }
        assert_eq!(sample_concentric_disk(Vec2::splat(0.5)), Vec2::ZERO);
    }

    /// Moments of the warps against their analytic values (stratified grid, so the
    /// quadrature error is small): E[z] for cosine = 2/3, for uniform hemisphere = 1/2,
    /// for the cone = (1 + cos)/2; disk E[r^2] = 1/2; triangle E[b] = 1/3.
    #[test]
    fn warps_have_analytic_moments() {
        let n = 256;
        let m = (n * n) as f64;
        let (mut cz, mut hz, mut kz, mut r2, mut b0, mut sz2) = (0.0f64, 0.0, 0.0, 0.0, 0.0, 0.0);
        for u in grid(n) {
            cz += sample_cosine_hemisphere(u).z as f64;
            hz += sample_uniform_hemisphere(u).z as f64;
            kz += sample_uniform_cone(u, 0.5).z as f64;
            r2 += sample_concentric_disk(u).length_squared() as f64;
            b0 += sample_uniform_triangle(u)[0] as f64;
            sz2 += (sample_uniform_sphere(u).z as f64).powi(2);
        }
        assert!((cz / m - 2.0 / 3.0).abs() < 1e-3, "cosine E[z] {}", cz / m);
        assert!((hz / m - 0.5).abs() < 1e-3);
        assert!((kz / m - 0.75).abs() < 1e-3);
        assert!((r2 / m - 0.5).abs() < 1e-3);
        assert!((b0 / m - 1.0 / 3.0).abs() < 1e-3);
        assert!((sz2 / m - 1.0 / 3.0).abs() < 1e-3);
    }

    #[test]
    fn pdfs_integrate_to_one() {
        // ∫ cos/π dω over the hemisphere = 1; ∫ cone pdf over the cone = 1.
        let n = 2000;
        let mut s = 0.0f64;
        for i in 0..n {
            let ct = (i as f32 + 0.5) / n as f32; // z = cos θ uniform grid, dω = dz dφ
            s += cosine_hemisphere_pdf(ct) as f64 * 2.0 * PI as f64 / n as f64;
        }
        assert!((s - 1.0).abs() < 1e-4);
        assert!((uniform_cone_pdf(0.5) * 2.0 * PI * 0.5 - 1.0).abs() < 1e-6);
        assert!((uniform_sphere_pdf() * 4.0 * PI - 1.0).abs() < 1e-6);
        assert!((uniform_hemisphere_pdf() * 2.0 * PI - 1.0).abs() < 1e-6);
    }

    #[test]
    fn power_heuristic_edge_cases() {
        assert_eq!(power_heuristic(1.0, 0.0, 1.0, 0.0), 0.0);
        assert_eq!(power_heuristic(1.0, f32::INFINITY, 1.0, 1.0), 1.0);
        assert!((power_heuristic(1.0, 1.0, 1.0, 1.0) - 0.5).abs() < 1e-6);
        let (a, b) = (0.3, 2.0);
        assert!((power_heuristic(1.0, a, 1.0, b) + power_heuristic(1.0, b, 1.0, a) - 1.0).abs() < 1e-6);
    }

    /// The polynomial sincos of the disk warp against `f64` on a fine grid of
    /// `[-pi/4, pi/4]`, and the warp against the libm formula it replaces.
    #[test]
    fn sin_cos_quarter_pi_is_accurate() {
        let n = 200_000;
        let mut worst = 0.0f64;
        for k in 0..=n {
            let x = (-1.0 + 2.0 * k as f64 / n as f64) * std::f64::consts::FRAC_PI_4;
            let (s, c) = sin_cos_quarter_pi(x as f32);
            let xf = x as f32 as f64;
            worst = worst.max((s as f64 - xf.sin()).abs()).max((c as f64 - xf.cos()).abs());
        }
        // A few ulp of values <= 1 (1 ulp of 1.0 is 1.2e-7).
        assert!(worst < 3e-7, "max abs error {worst}");
        for u in grid(300) {
            let o = 2.0 * u - Vec2::ONE;
            let (r, theta) = if o.x.abs() > o.y.abs() {
                (o.x as f64, std::f64::consts::FRAC_PI_4 * (o.y as f64 / o.x as f64))
            } else {
                (
                    o.y as f64,
                    std::f64::consts::FRAC_PI_2 - std::f64::consts::FRAC_PI_4 * (o.x as f64 / o.y as f64),
                )
            };
            let d = sample_concentric_disk(u);
            assert!(
                (d.x as f64 - r * theta.cos()).abs() < 5e-7 && (d.y as f64 - r * theta.sin()).abs() < 5e-7
            );
        }
    }

    /// The branch-free triangle warp gives the bits of pbrt's two-branch form.
    #[test]
    fn triangle_warp_matches_naive_bit_for_bit() {
        let mut rng = crate::rng::SplitMix64::new(9);
        let mut us: Vec<Vec2> = (0..100_000).map(|_| Vec2::new(rng.next_f32(), rng.next_f32())).collect();
        us.extend(grid(64));
        us.extend([Vec2::ZERO, Vec2::splat(0.5), Vec2::new(0.25, 0.25), Vec2::splat(ONE_MINUS_EPSILON)]);
        for u in us {
            let (a, b) = (sample_uniform_triangle(u), sample_uniform_triangle_naive(u));
            assert_eq!(a.map(f32::to_bits), b.map(f32::to_bits), "u {u}");
        }
    }
}
