//! A piecewise-constant 1D distribution over `[0, 1)` and the CDF it is built from.

use super::ONE_MINUS_EPSILON;

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

#[cfg(test)]
mod tests {
    use super::*;

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
