//! Which VPLs a record may take as visible without a shadow ray.
//!
//! The full distribution E¹ is only an importance function: every estimator divides by
//! the pmf it sampled with, and the uniform distribution (or, for `balance-cv`, a control
//! variate whose integral is its own total, Σ_j p(j) T = T) keeps them unbiased whatever
//! E¹ holds. So a record need not pay a visibility ray for a VPL whose unoccluded
//! contribution is a vanishing part of its light: taking it as visible moves E¹ by at most
//! that part and biases nothing. On mesh scenes these rays are most of the cache stage
//! (docs/many-light-cache.md, "Faint VPLs without a ray").
//!
//! The faint VPLs are those of the faintest binary orders of magnitude (relative to the
//! record's total) that together carry at most `share` of the total: a histogram of 64
//! power-of-two buckets, no sort.

/// Power-of-two buckets of `contribution / total`; the last also holds everything fainter.
const BUCKETS: usize = 64;

/// The record's cut between VPLs that get a visibility ray and faint ones that do not.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaintCut {
    /// `1 / total` of the record's unoccluded luminances.
    inv_total: f32,
    /// Buckets from this one on are faint; `BUCKETS` or more: none is.
    first_faint: usize,
}

impl FaintCut {
    /// No VPL is faint: every one with a contribution gets its ray.
    pub const NONE: FaintCut = FaintCut { inv_total: 0.0, first_faint: BUCKETS };

    /// The cut for a record's unoccluded luminances (as `RecordValues::unoccluded` keeps
    /// them: ≥ 0): the faintest buckets whose luminances sum to at most `share` of the
    /// total. `share` ≤ 0 (or a record without light) gives [`FaintCut::NONE`].
    pub fn new(unoccluded: &[f32], share: f32) -> Self {
        let total: f64 = unoccluded.iter().map(|&l| l as f64).sum();
        if !(share > 0.0 && total > 0.0 && total.is_finite()) {
            return FaintCut::NONE;
        }
        let inv_total = (1.0 / total) as f32;
        let mut mass = [0.0f64; BUCKETS];
        for &l in unoccluded {
            mass[bucket(l * inv_total)] += l as f64;
        }
        let allowed = share as f64 * total;
        let mut faint = 0.0;
        let mut first_faint = BUCKETS;
        while first_faint > 0 && faint + mass[first_faint - 1] <= allowed {
            first_faint -= 1;
            faint += mass[first_faint];
        }
        FaintCut { inv_total, first_faint }
    }

    /// Whether a VPL with this unoccluded luminance is taken as visible without a ray
    /// (only VPLs with a positive contribution have a ray to skip).
    #[inline]
    pub fn is_faint(&self, unoccluded: f32) -> bool {
        unoccluded > 0.0 && bucket(unoccluded * self.inv_total) >= self.first_faint
    }
}

/// `−⌊log2 x⌋` clamped to the buckets, from the exponent bits (`x ≤ 1` up to rounding;
/// subnormals and zero land in the last bucket).
#[inline]
fn bucket(x: f32) -> usize {
    let exponent = ((x.to_bits() >> 23) & 0xff) as i32 - 127;
    (-exponent).clamp(0, BUCKETS as i32 - 1) as usize
}

#[cfg(test)]
mod tests {
    use super::*;
    use filtrace_core::rng::SplitMix64;

    /// Luminances spread over many orders of magnitude, some zero.
    fn skewed(rng: &mut SplitMix64, n: usize) -> Vec<f32> {
        (0..n)
            .map(|i| if i % 17 == 0 { 0.0 } else { 10f32.powf(rng.range(-9.0, 2.0)) * rng.range(0.5, 1.0) })
            .collect()
    }

    /// The faint VPLs carry at most the share, and the cut is the largest of whole
    /// buckets: one more bucket would exceed it.
    #[test]
    fn faint_vpls_carry_at_most_the_share_and_the_cut_is_maximal() {
        let mut rng = SplitMix64::new(9);
        for case in 0..400 {
            let lums = skewed(&mut rng, 1 + case * 5);
            let share = [0.001, 0.01, 0.02, 0.1, 0.5][case % 5];
            let cut = FaintCut::new(&lums, share);
            let total: f64 = lums.iter().map(|&l| l as f64).sum();
            let faint: f64 = lums.iter().filter(|&&l| cut.is_faint(l)).map(|&l| l as f64).sum();
            assert!(faint <= share as f64 * total, "case {case}: faint {faint} of {total}, share {share}");
            if total > 0.0 && cut.first_faint > 0 {
                let widened = FaintCut { first_faint: cut.first_faint - 1, ..cut };
                let more: f64 = lums.iter().filter(|&&l| widened.is_faint(l)).map(|&l| l as f64).sum();
                assert!(more > share as f64 * total, "case {case}: the cut could go one bucket further");
            }
        }
    }

    /// Faintness is monotone in the contribution (faint exactly below a threshold), and
    /// zero is never faint (it has no ray to skip).
    #[test]
    fn faintness_is_monotone_and_zero_is_never_faint() {
        let mut rng = SplitMix64::new(2);
        let lums = skewed(&mut rng, 2048);
        let cut = FaintCut::new(&lums, 0.05);
        let mut sorted: Vec<f32> = lums.iter().copied().filter(|&l| l > 0.0).collect();
        sorted.sort_by(f32::total_cmp);
        let flags: Vec<bool> = sorted.iter().map(|&l| cut.is_faint(l)).collect();
        let first_bright = flags.iter().position(|&f| !f).unwrap_or(flags.len());
        assert!(flags[first_bright..].iter().all(|&f| !f), "faint only below a threshold");
        assert!(first_bright > 100, "the skewed list has faint VPLs ({first_bright})");
        assert!(!cut.is_faint(0.0));
    }

    /// A share of 0, an all-zero record and non-finite totals skip no ray.
    #[test]
    fn no_share_or_no_light_skips_nothing() {
        let lums = [1.0, 1e-6, 1e-9];
        assert_eq!(FaintCut::new(&lums, 0.0), FaintCut::NONE);
        assert_eq!(FaintCut::new(&[0.0; 8], 0.5), FaintCut::NONE);
        assert!(FaintCut::new(&[f32::MAX, f32::MAX, 1.0], 0.5).is_faint(1.0));
        assert!(!FaintCut::NONE.is_faint(1e-30));
        assert!(FaintCut::new(&lums, 0.01).is_faint(1e-9));
    }
}
