//! Monte Carlo sampling routines: warps from the unit square to disks, hemispheres,
//! spheres, cones and triangles (each with its density), an orthonormal shading frame,
//! the MIS power heuristic, and a piecewise-constant 1D distribution.
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
use std::f32::consts::{FRAC_1_PI, FRAC_PI_2, FRAC_PI_4, PI};

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
    let (r, theta) = if o.x.abs() > o.y.abs() {
        (o.x, FRAC_PI_4 * (o.y / o.x))
    } else {
        (o.y, FRAC_PI_2 - FRAC_PI_4 * (o.x / o.y))
    };
    let (s, c) = theta.sin_cos();
    r * Vec2::new(c, s)
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

/// A piecewise-constant distribution over `n` cells of `[0, 1)` built from non-negative
/// weights (pbrt-v4 `PiecewiseConstant1D`). Used to pick lights by power and sky bands by
/// luminance.
///
/// Bad weights are handled, never propagated: a NaN, infinite or negative weight counts
/// as 0. If every weight is 0 (or the list is empty) the distribution is *degenerate*:
/// [`Distribution1D::is_degenerate`] is true, `total()` is 0, and sampling falls back to
/// uniform over the cells (so callers still get a valid index when `n > 0`). With `n = 0`
/// `sample_discrete` returns `(0, 0.0, u)`: a pmf of 0 tells the caller there is nothing.
#[derive(Clone, Debug, Default)]
pub struct Distribution1D {
    /// Sanitised weights (the step function's heights).
    func: Vec<f32>,
    /// `cdf[i]` = probability of cells `< i`; `cdf[n] = 1`. Length `n + 1`.
    cdf: Vec<f32>,
    /// Sum of the sanitised weights (the integral times `n`).
    total: f32,
}

impl Distribution1D {
    /// Builds the distribution from `weights` (see the type docs for bad weights).
    pub fn new(weights: &[f32]) -> Self {
        let func: Vec<f32> =
            weights.iter().map(|&w| if w.is_finite() && w > 0.0 { w } else { 0.0 }).collect();
        let n = func.len();
        // Accumulate in f64: thousands of lights with a wide power range lose precision in f32.
        let total64: f64 = func.iter().map(|&w| w as f64).sum();
        let mut cdf = Vec::with_capacity(n + 1);
        cdf.push(0.0f32);
        if total64 > 0.0 && total64.is_finite() {
            let mut acc = 0.0f64;
            for &w in &func {
                acc += w as f64;
                cdf.push((acc / total64) as f32);
            }
        } else {
            for i in 1..=n {
                cdf.push(i as f32 / n as f32);
            }
        }
        if n > 0 {
            cdf[n] = 1.0;
        }
        let total = if total64.is_finite() { total64 as f32 } else { 0.0 };
        Distribution1D { func, cdf, total }
    }

    /// Number of cells.
    #[inline]
    pub fn count(&self) -> usize {
        self.func.len()
    }

    /// Sum of the (sanitised) weights; 0 for a degenerate distribution.
    #[inline]
    pub fn total(&self) -> f32 {
        self.total
    }

    /// True when no weight was positive: sampling is uniform over the cells.
    #[inline]
    pub fn is_degenerate(&self) -> bool {
        self.total <= 0.0
    }

    /// Probability of choosing cell `i` (0 outside `0..count()`).
    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        if i < self.func.len() {
            self.cdf[i + 1] - self.cdf[i]
        } else {
            0.0
        }
    }

    /// Picks a cell with probability `pmf(index)`. Returns `(index, pmf, u_remapped)`
    /// where `u_remapped` is `u`'s position inside the chosen cell's CDF interval,
    /// uniform in `[0, 1)` again, so it can be reused for a further decision.
    #[inline]
    pub fn sample_discrete(&self, u: f32) -> (usize, f32, f32) {
        let n = self.func.len();
        if n == 0 {
            return (0, 0.0, u);
        }
        let i = self.find_interval(u);
        let lo = self.cdf[i];
        let pmf = self.cdf[i + 1] - lo;
        let u_remapped = if pmf > 0.0 { ((u - lo) / pmf).clamp(0.0, ONE_MINUS_EPSILON) } else { 0.0 };
        (i, pmf, u_remapped)
    }

    /// Samples a continuous position `x ∈ [0, 1)` with density `pdf` (relative to
    /// Lebesgue measure on `[0, 1)`); returns `(x, pdf, cell)`. The pdf is 0 only for an
    /// empty distribution.
    #[inline]
    pub fn sample_continuous(&self, u: f32) -> (f32, f32, usize) {
        let n = self.func.len();
        if n == 0 {
            return (u, 0.0, 0);
        }
        let (i, pmf, du) = self.sample_discrete(u);
        let x = ((i as f32 + du) / n as f32).min(ONE_MINUS_EPSILON);
        (x, pmf * n as f32, i)
    }

    /// Density of [`Distribution1D::sample_continuous`] at `x ∈ [0, 1)`.
    #[inline]
    pub fn pdf_continuous(&self, x: f32) -> f32 {
        let n = self.func.len();
        if n == 0 || !(0.0..1.0).contains(&x) {
            return 0.0;
        }
        let i = ((x * n as f32) as usize).min(n - 1);
        self.pmf(i) * n as f32
    }

    /// Largest `i` with `cdf[i] <= u`, skipping zero-width cells (binary search).
    #[inline]
    fn find_interval(&self, u: f32) -> usize {
        let n = self.func.len();
        // partition_point over cdf[1..=n]: number of cells whose upper CDF bound is <= u.
        let i = self.cdf[1..].partition_point(|&c| c <= u);
        let mut i = i.min(n - 1);
        // Zero-pmf cells can only be reached at exact boundaries; step back to a live cell.
        while i > 0 && self.cdf[i + 1] - self.cdf[i] <= 0.0 {
            i -= 1;
        }
        while i + 1 < n && self.cdf[i + 1] - self.cdf[i] <= 0.0 {
            i += 1;
        }
        i
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

    #[test]
    fn distribution_matches_weights() {
        let w = [1.0, 0.0, 3.0, 4.0];
        let d = Distribution1D::new(&w);
        assert_eq!(d.count(), 4);
        assert!(!d.is_degenerate());
        assert!((d.total() - 8.0).abs() < 1e-6);
        let n = 80_000;
        let mut counts = [0usize; 4];
        for k in 0..n {
            let u = (k as f32 + 0.5) / n as f32;
            let (i, pmf, ur) = d.sample_discrete(u);
            assert!((pmf - w[i] / 8.0).abs() < 1e-6 && pmf > 0.0);
            assert!((0.0..1.0).contains(&ur));
            counts[i] += 1;
        }
        for i in 0..4 {
            assert!((counts[i] as f32 / n as f32 - w[i] / 8.0).abs() < 1e-3);
            assert!((d.pmf(i) - w[i] / 8.0).abs() < 1e-6);
        }
        assert_eq!(d.pmf(4), 0.0);
        // Continuous sampling: the density integrates to 1 and matches pdf_continuous.
        for k in 0..100 {
            let (x, pdf, i) = d.sample_continuous((k as f32 + 0.5) / 100.0);
            assert_eq!(pdf, d.pdf_continuous(x));
            assert_eq!(i, (x * 4.0) as usize);
        }
        assert_eq!(d.sample_discrete(0.0).0, 0);
        assert_eq!(d.sample_discrete(ONE_MINUS_EPSILON).0, 3);
        // u right at the boundary of the zero-weight cell never selects it.
        assert_ne!(d.sample_discrete(0.125).0, 1);
    }

    /// Binary-search sampling equals a linear scan of the CDF (the naive version) for
    /// random weights with many zeros, at random and at boundary `u`.
    #[test]
    fn distribution_binary_search_matches_linear_scan() {
        let mut state = 0x1234_5678_9abc_def0u64;
        let mut next = || {
            state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for n in [1usize, 2, 3, 7, 64, 1000] {
            let w: Vec<f32> = (0..n).map(|_| if next() < 0.4 { 0.0 } else { next() * 10.0 }).collect();
            let d = Distribution1D::new(&w);
            if d.is_degenerate() {
                continue;
            }
            let naive = |u: f32| -> usize {
                // First cell with positive weight whose CDF interval contains u.
                (0..n)
                    .find(|&i| d.pmf(i) > 0.0 && u < d.cdf[i + 1])
                    .unwrap_or_else(|| (0..n).rev().find(|&i| d.pmf(i) > 0.0).unwrap())
            };
            let mut us: Vec<f32> = (0..2000).map(|_| next()).collect();
            us.extend(d.cdf.iter().copied().filter(|&c| c < 1.0));
            for u in us {
                let (i, pmf, _) = d.sample_discrete(u);
                assert_eq!(i, naive(u), "n {n}, u {u}");
                assert!(pmf > 0.0 && w[i] > 0.0);
            }
        }
    }

    #[test]
    fn distribution_handles_bad_weights() {
        let d = Distribution1D::new(&[f32::NAN, -1.0, 2.0, f32::INFINITY]);
        assert!(!d.is_degenerate());
        for k in 0..100 {
            let (i, pmf, _) = d.sample_discrete(k as f32 / 100.0);
            assert_eq!((i, pmf), (2, 1.0));
        }
        let z = Distribution1D::new(&[0.0, f32::NAN, 0.0]);
        assert!(z.is_degenerate());
        assert_eq!(z.total(), 0.0);
        let (i, pmf, _) = z.sample_discrete(0.9);
        assert_eq!(i, 2);
        assert!((pmf - 1.0 / 3.0).abs() < 1e-6);
        let e = Distribution1D::new(&[]);
        assert_eq!(e.sample_discrete(0.3), (0, 0.0, 0.3));
        assert_eq!(e.pmf(0), 0.0);
        assert_eq!(e.sample_continuous(0.3).1, 0.0);
    }
}
