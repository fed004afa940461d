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
use std::f32::consts::{FRAC_1_PI, FRAC_PI_4, PI};

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

/// The CDF of sanitised (finite, non-negative) weights `func` and their sum: `cdf[i]` =
/// probability of cells `< i`, `cdf[n] = 1`, length `n + 1`; uniform when the sum is 0 or
/// not finite (a sum that is not finite is returned as 0). Accumulated in f64:
/// thousands of lights with a wide power range lose precision in f32. Shared by
/// [`Distribution1D`] and the VPL renderer's cached distributions, so both give the same
/// values bit for bit.
pub fn normalized_cdf(func: &[f32]) -> (Vec<f32>, f32) {
    let n = func.len();
    let total64: f64 = func.iter().map(|&w| w as f64).sum();
    let mut cdf = Vec::with_capacity(n + 1);
    cdf.push(0.0f32);
    if total64 > 0.0 && total64.is_finite() {
        let mut acc = 0.0f64;
        for &w in func {
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
    (cdf, total)
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
        let (cdf, total) = normalized_cdf(&func);
        Distribution1D { func, cdf, total }
    }

    /// Number of cells.
    #[inline]
    pub fn count(&self) -> usize {
        self.func.len()
    }

    /// The CDF: `cdf()[i]` = probability of the cells `< i`, `cdf()[count()] = 1` (for
    /// vectorised copies of the sampling routines).
    #[inline]
    pub fn cdf(&self) -> &[f32] {
        &self.cdf
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

/// One cell of an [`AliasTable`]: keep the cell with probability `q`, else take `alias`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct AliasBin {
    q: f32,
    alias: u32,
}

/// Walker's alias method with Vose's O(n) construction (Walker 1977; Vose 1991, "A linear
/// algorithm for generating random numbers with a given distribution"; pbrt-v4
/// `AliasTable`): picks one of `n` cells with probability proportional to its weight in
/// O(1), one multiply, one table read and one comparison, where [`Distribution1D`]
/// binary-searches its CDF. Used to pick lights by power.
///
/// Sampling: `u n = i + f` selects bin `i`, then `f < q_i` keeps `i`, otherwise the bin's
/// `alias`. Bad weights as in [`Distribution1D`]: NaN, infinite or negative weights count
/// as 0; if no weight is positive the table is *degenerate* and uniform over the cells; an
/// empty table samples `(0, 0.0)`.
#[derive(Clone, Debug, Default)]
pub struct AliasTable {
    bins: Vec<AliasBin>,
    /// Probability of each cell (`weight / total`, or `1 / n` when degenerate).
    pmf: Vec<f32>,
    /// Sum of the sanitised weights; 0 when degenerate.
    total: f32,
}

impl AliasTable {
    /// Builds the table from `weights` (see the type docs for bad weights).
    pub fn new(weights: &[f32]) -> Self {
        let n = weights.len();
        let w: Vec<f64> =
            weights.iter().map(|&w| if w.is_finite() && w > 0.0 { w as f64 } else { 0.0 }).collect();
        let total64: f64 = w.iter().sum();
        let degenerate = !(total64 > 0.0 && total64.is_finite());
        let p: Vec<f64> =
            if degenerate { vec![1.0 / n as f64; n] } else { w.iter().map(|&x| x / total64).collect() };
        let pmf = p.iter().map(|&x| x as f32).collect();

        // Vose: split the cells scaled to mean 1 into "small" (< 1) and "large" (>= 1);
        // each small cell is topped up by a large one, which becomes its alias.
        let mut bins = vec![AliasBin::default(); n];
        let mut scaled: Vec<f64> = p.iter().map(|&x| x * n as f64).collect();
        let (mut small, mut large): (Vec<usize>, Vec<usize>) = (0..n).partition(|&i| scaled[i] < 1.0);
        while let (Some(&s), Some(&l)) = (small.last(), large.last()) {
            small.pop();
            large.pop();
            bins[s] = AliasBin { q: scaled[s] as f32, alias: l as u32 };
            scaled[l] -= 1.0 - scaled[s];
            if scaled[l] < 1.0 {
                small.push(l);
            } else {
                large.push(l);
            }
        }
        // What is left is 1 up to rounding: keep the cell (alias unused).
        for i in large.into_iter().chain(small) {
            bins[i] = AliasBin { q: 1.0, alias: i as u32 };
        }
        // A zero-probability cell can be left over only through rounding; never return it.
        if let Some(live) = p.iter().position(|&x| x > 0.0) {
            for (i, b) in bins.iter_mut().enumerate() {
                if p[i] == 0.0 {
                    *b = AliasBin {
                        q: 0.0,
                        alias: if p[b.alias as usize] > 0.0 { b.alias } else { live as u32 },
                    };
                }
            }
        }
        let total = if degenerate { 0.0 } else { total64 as f32 };
        AliasTable { bins, pmf, total }
    }

    /// Number of cells.
    #[inline]
    pub fn count(&self) -> usize {
        self.bins.len()
    }

    /// Sum of the (sanitised) weights; 0 for a degenerate table.
    #[inline]
    pub fn total(&self) -> f32 {
        self.total
    }

    /// True when no weight was positive: sampling is uniform over the cells.
    #[inline]
    pub fn is_degenerate(&self) -> bool {
        self.total <= 0.0
    }

    /// Bin `i` as `(q, alias)` (`None` outside `0..count()`): [`AliasTable::sample`] keeps
    /// cell `i` when the fraction of `u * count()` is below `q`, else returns `alias` (for
    /// vectorised copies of `sample`).
    #[inline]
    pub fn bin(&self, i: usize) -> Option<(f32, u32)> {
        self.bins.get(i).map(|b| (b.q, b.alias))
    }

    /// Probability of choosing cell `i` (0 outside `0..count()`).
    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        self.pmf.get(i).copied().unwrap_or(0.0)
    }

    /// Picks a cell with probability `pmf(index)` for `u` in `[0, 1)`; returns
    /// `(index, pmf)`. `(0, 0.0)` for an empty table.
    #[inline]
    pub fn sample(&self, u: f32) -> (usize, f32) {
        let n = self.bins.len();
        if n <= 1 {
            return (0, self.pmf(0));
        }
        let x = u * n as f32;
        let i = (x as usize).min(n - 1);
        let f = x - i as f32;
        let b = self.bins[i];
        let k = if f < b.q { i } else { b.alias as usize };
        (k, self.pmf[k])
    }

    /// The exact probability with which [`AliasTable::sample`] returns each cell for `u`
    /// uniform in `[0, 1)` (read from the bins: `(q_i + sum over bins j aliased to i of
    /// (1 - q_j)) / n`), to check the construction against `pmf`.
    pub fn implied_pmf(&self) -> Vec<f64> {
        let n = self.bins.len();
        let mut p = vec![0.0f64; n];
        for (i, b) in self.bins.iter().enumerate() {
            p[i] += b.q as f64 / n as f64;
            p[b.alias as usize] += (1.0 - b.q as f64) / n as f64;
        }
        p
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

    /// The bins of the alias table give every cell exactly its pmf (the exact check of
    /// the construction), for random weights with many zeros and bad values.
    #[test]
    fn alias_table_bins_reproduce_the_pmf() {
        let mut rng = crate::rng::SplitMix64::new(17);
        for n in [1usize, 2, 3, 5, 7, 64, 1000] {
            for _ in 0..20 {
                let w: Vec<f32> = (0..n)
                    .map(|_| match rng.next_f32() {
                        x if x < 0.3 => 0.0,
                        x if x < 0.32 => f32::NAN,
                        x if x < 0.34 => -1.0,
                        x if x < 0.4 => x * 1e-6,
                        _ => rng.next_f32() * 10.0,
                    })
                    .collect();
                let t = AliasTable::new(&w);
                let total: f64 =
                    w.iter().map(|&x| if x.is_finite() && x > 0.0 { x as f64 } else { 0.0 }).sum();
                let implied = t.implied_pmf();
                for i in 0..n {
                    let want = if total > 0.0 {
                        if w[i].is_finite() && w[i] > 0.0 {
                            w[i] as f64 / total
                        } else {
                            0.0
                        }
                    } else {
                        1.0 / n as f64
                    };
                    assert!((implied[i] - want).abs() < 1e-6, "n {n} cell {i}: {} vs {want}", implied[i]);
                    assert!((t.pmf(i) as f64 - want).abs() < 1e-6);
                    if want == 0.0 {
                        assert_eq!(implied[i], 0.0, "zero-weight cell {i} reachable");
                    }
                }
                // Every sample has the claimed pmf and positive weight.
                for k in 0..4 * n {
                    let (i, pmf) = t.sample((k as f32 + 0.5) / (4 * n) as f32);
                    assert_eq!(pmf, t.pmf(i));
                    assert!(pmf > 0.0);
                }
            }
        }
    }

    /// Chi-square of alias-table sampling with uniform random `u` against the weights.
    #[test]
    fn alias_table_chi_square() {
        let w = [1.0f32, 0.0, 3.0, 4.0, 0.5, 0.25, 7.0];
        let t = AliasTable::new(&w);
        let total: f64 = w.iter().map(|&x| x as f64).sum();
        let n = 200_000;
        let mut rng = crate::rng::SplitMix64::new(5);
        let mut obs = vec![0.0f64; w.len()];
        for _ in 0..n {
            obs[t.sample(rng.next_f32()).0] += 1.0;
        }
        let exp: Vec<f64> = w.iter().map(|&x| x as f64 / total * n as f64).collect();
        let (chi2, dof) = crate::stats::chi2_statistic(&obs, &exp, 5.0).unwrap();
        let p = 1.0 - crate::stats::regularized_gamma_p(dof as f64 / 2.0, chi2 / 2.0);
        assert!(p > 1e-3, "chi2 {chi2} dof {dof} p {p}");
    }

    #[test]
    fn alias_table_edge_cases() {
        let e = AliasTable::new(&[]);
        assert_eq!(e.sample(0.3), (0, 0.0));
        assert_eq!(e.pmf(0), 0.0);
        let one = AliasTable::new(&[2.0]);
        assert_eq!(one.sample(0.7), (0, 1.0));
        let z = AliasTable::new(&[0.0, f32::NAN, 0.0]);
        assert!(z.is_degenerate() && z.total() == 0.0);
        assert!((z.sample(0.9).1 - 1.0 / 3.0).abs() < 1e-6);
        assert_eq!(z.sample(0.9).0, 2);
        let t = AliasTable::new(&[1.0, 3.0]);
        assert_eq!(t.sample(ONE_MINUS_EPSILON).0, 1);
        assert_eq!(t.pmf(2), 0.0);
        assert!((t.total() - 4.0).abs() < 1e-6);
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
