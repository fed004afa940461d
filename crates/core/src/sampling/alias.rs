//! Walker's alias table: O(1) sampling of a discrete distribution.

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
///
/// [`Distribution1D`]: super::Distribution1D
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::ONE_MINUS_EPSILON;

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
}
