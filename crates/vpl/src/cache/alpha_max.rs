//! Georgiev's α-max heuristic (Georgiev et al. 2012; thesis 4.2.5):
//!
//! `w_s(x) = 1` if `w_i(x) = 0` for all `i < s` and `p_s(x) ≥ max_{s<i≤m} α_i p_i(x)`,
//! else 0,
//!
//! with `α_i ∈ (0, 1]` the confidences. The domain is partitioned: each `x` belongs to the
//! earliest distribution whose pdf beats every later one's confidence-weighted pdf. With
//! the last distribution positive everywhere (uniform), every `x` has exactly one owner
//! and that owner's pdf is positive, so the multi-sample estimator
//! `Σ_s w_s(x_s) f(x_s) / p_s(x_s)` is unbiased.

use super::{CacheParams, Technique, TECHNIQUES};

/// The distribution that owns `x` (the `s` with `w_s(x) = 1`), given the pdfs `p[i]` of
/// the m distributions at `x` and their confidences `c[i]`, in order. Scans from the back
/// once: `O(m)`. Returns `p.len() - 1` when nothing else qualifies (the last distribution
/// always satisfies the condition: its max is over an empty set).
#[inline]
pub fn alpha_max_owner(p: &[f32], c: &[f32]) -> usize {
    debug_assert_eq!(p.len(), c.len());
    let m = p.len();
    // later[s] = max over i > s of c_i p_i, computed back to front.
    let mut later = [0.0f32; TECHNIQUES];
    let mut running = 0.0f32;
    for s in (0..m).rev() {
        later[s] = running;
        running = running.max(c[s] * p[s]);
    }
    (0..m).find(|&s| p[s] >= later[s]).unwrap_or(m.saturating_sub(1))
}

/// `w_s(x)` straight from the recursive definition (the reference the tests hold
/// [`alpha_max_owner`] to).
pub fn alpha_max_weight(s: usize, p: &[f32], c: &[f32]) -> f32 {
    let earlier_zero = (0..s).all(|i| alpha_max_weight(i, p, c) == 0.0);
    let beats_later = (s + 1..p.len()).all(|i| p[s] >= c[i] * p[i]);
    if earlier_zero && beats_later {
        1.0
    } else {
        0.0
    }
}

/// The enabled distributions in α-max order with their confidences `c_i`: what
/// [`alpha_max_owner`] needs at every shading point, gathered once per point.
#[derive(Clone, Copy, Debug)]
pub struct AlphaMaxSet {
    techniques: [Technique; TECHNIQUES],
    confidences: [f32; TECHNIQUES],
    count: usize,
}

impl AlphaMaxSet {
    #[inline]
    pub fn new(config: &CacheParams) -> Self {
        let mut set = AlphaMaxSet {
            techniques: [Technique::Uniform; TECHNIQUES],
            confidences: [0.0; TECHNIQUES],
            count: 0,
        };
        let d = config.distributions;
        for (t, on) in Technique::ALL.into_iter().zip([d.full, d.unoccluded, d.bounded, true]) {
            if on {
                set.techniques[set.count] = t;
                set.confidences[set.count] = config.confidences[t as usize];
                set.count += 1;
            }
        }
        set
    }

    /// The enabled techniques, in order.
    #[inline]
    pub fn techniques(&self) -> &[Technique] {
        &self.techniques[..self.count]
    }

    /// The pdfs `p_i` of the enabled techniques, in order, from a row indexed by
    /// `Technique as usize`.
    #[inline]
    pub fn gather(&self, row: &[f32; TECHNIQUES]) -> [f32; TECHNIQUES] {
        let mut p = [0.0; TECHNIQUES];
        for (p, &t) in p.iter_mut().zip(self.techniques()) {
            *p = row[t as usize];
        }
        p
    }

    /// [`alpha_max_owner`] of the enabled techniques' pdfs `p` (from [`AlphaMaxSet::gather`]).
    #[inline]
    pub fn owner(&self, p: &[f32; TECHNIQUES]) -> usize {
        alpha_max_owner(&p[..self.count], &self.confidences[..self.count])
    }
}
