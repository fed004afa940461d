//! The VPL samplers: given a shading point's neighbouring records, which VPLs to
//! evaluate and how to combine them. Every sampler returns a [`SamplePlan`] and the
//! integrator forms `L ≈ offset + Σ_i weight_i · f(vpl_i)` with `f` the VPL's full
//! contribution (BSDF, geometry term and visibility; a draw of weight 0 needs no ray).
//!
//! Notation (thesis 5.2.2): records `l` with weights `w_l` (Σ = 1), techniques `k` with
//! per-record pmfs `p_lk(j)`, mixture weights `α_lk` (Σ_k = 1), control-variate weights
//! `β_lk` and RGB totals `T_lk`.
//! - one-sample balance heuristic: `(l, k) ~ w_l α_lk`, `j ~ p_lk`,
//!   `q(j) = Σ_l w_l Σ_k α_lk p_lk(j)`, estimate `f(j) / q(j)`;
//! - with control variates `h(j) = Σ_l w_l Σ_k β_lk p_lk(j) T_lk` whose sum over the VPLs
//!   is `C = Σ_l w_l Σ_k β_lk T_lk`: estimate `(f(j) − h(j)) / q(j) + C` (He and Owen
//!   2014; the control variate subtracted before importance sampling, thesis eq. 6).
//!   Unbiased for any fixed α, β since `Σ_j p_lk(j) = 1`;
//! - α-max: per enabled technique `k` one draw `j_k ~ P_k = Σ_l w_l p_lk` (the records'
//!   distributions combined by the balance heuristic with the record weights, as
//!   Georgiev interpolates), weight `w_k^α-max(j_k) / P_k(j_k)`.

use super::alpha_max::AlphaMaxSet;
use super::feedback::SampleFeedback;
use super::search::Neighbours;
use super::{CacheParams, ImportanceCache, SamplerKind, Technique, MAX_NEIGHBOURS, TECHNIQUES};
use filtrace_core::Rgb;

/// Most draws in one plan (α-max: one per distribution).
pub const MAX_DRAWS: usize = TECHNIQUES;

/// What the one-sample samplers read of the configuration at every shading point,
/// gathered once per cache (the same values as computed per point).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SamplerSetup {
    /// The enabled techniques, in order.
    techniques: [Technique; TECHNIQUES],
    count: usize,
    /// `balance` and `balance-cv`'s α and β of every record.
    prior_alpha: [f32; TECHNIQUES],
    prior_beta: [f32; TECHNIQUES],
}

impl SamplerSetup {
    pub(crate) fn new(config: &CacheParams) -> Self {
        let mut techniques = [Technique::Uniform; TECHNIQUES];
        let mut count = 0;
        for t in config.distributions.techniques() {
            techniques[count] = t;
            count += 1;
        }
        SamplerSetup {
            techniques,
            count,
            prior_alpha: config.prior_mixture(),
            prior_beta: super::optimize::prior_beta(&config.distributions),
        }
    }

    #[inline]
    fn techniques(&self) -> &[Technique] {
        &self.techniques[..self.count]
    }
}

/// One VPL to evaluate and its weight in the estimate.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VplDraw {
    pub vpl: u32,
    /// Multiplies the VPL's contribution `f(vpl)`.
    pub weight: f32,
    /// Mixture pmf `q(j)` (one-sample samplers; 0 for α-max).
    pub pdf: f32,
    /// `P_k(j) = Σ_l w_l p_lk(j)` per technique (0 for disabled ones; `optimized` and
    /// α-max only).
    pub interpolated_pmf: [f32; TECHNIQUES],
    /// `Q_k(j) = Σ_l w_l L_lk p_lk(j)`, the luminance control variates at β = 1
    /// (`optimized` only).
    pub interpolated_cv: [f32; TECHNIQUES],
}

/// What a sampler asks the integrator to do at one shading point (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SamplePlan {
    /// Added to the weighted contributions: `C − h(j)/q(j)` for the control-variate
    /// samplers, 0 otherwise.
    pub offset: Rgb,
    draws: [VplDraw; MAX_DRAWS],
    len: u8,
    neighbours: Neighbours,
    learns: bool,
}

impl SamplePlan {
    /// The VPLs to evaluate.
    pub fn draws(&self) -> &[VplDraw] {
        &self.draws[..self.len as usize]
    }

    /// The estimate given each draw's full contribution (with visibility).
    pub fn estimate(&self, mut contribution: impl FnMut(usize) -> Rgb) -> Rgb {
        self.draws().iter().fold(self.offset, |acc, d| {
            if d.weight > 0.0 {
                acc + d.weight * contribution(d.vpl as usize)
            } else {
                acc
            }
        })
    }

    /// What the `optimized` sampler learns from draw `i` whose full contribution was
    /// `contribution`; `None` for the other samplers. The integrator collects these in a
    /// fixed order (e.g. by pixel) and hands them to [`ImportanceCache::optimize`].
    pub fn feedback(&self, i: usize, contribution: Rgb) -> Option<SampleFeedback> {
        let d = self.draws().get(i)?;
        (self.learns && d.pdf > 0.0).then(|| {
            SampleFeedback::new(
                &self.neighbours,
                d.interpolated_pmf,
                d.interpolated_cv,
                1.0 / d.pdf,
                contribution,
            )
        })
    }

    fn push(&mut self, d: VplDraw) {
        self.draws[self.len as usize] = d;
        self.len += 1;
    }
}

/// The record of the neighbour slot `u ∈ [0, 1)` falls in, slot `l` with probability
/// `w_l` (the last one where rounding leaves `u` above the weights' sum).
#[inline]
fn pick_record(nb: &Neighbours, u: f32) -> usize {
    let (mut acc, mut l) = (0.0f32, nb.iter().next().map_or(0, |(l, _)| l));
    for (slot, w) in nb.iter() {
        l = slot;
        acc += w;
        if u < acc {
            break;
        }
    }
    l
}

/// `k` uniform on `0..n` from `u ∈ [0, 1)`, pmf 1/n (Keller's one random VPL).
pub fn sample_uniform_vpl(n: usize, u: f32) -> VplDraw {
    if n == 0 {
        return VplDraw::default();
    }
    let j = ((u * n as f32) as usize).min(n - 1);
    VplDraw { vpl: j as u32, weight: n as f32, pdf: 1.0 / n as f32, ..VplDraw::default() }
}

impl ImportanceCache {
    /// Draws VPLs for a shading point with neighbours `nb` (from
    /// [`ImportanceCache::neighbours`]); `next` yields uniform numbers in `[0, 1)` (two
    /// per draw; α-max uses two per distribution). Falls back to `uniform` when `nb` is
    /// empty. An empty VPL set gives an empty plan (estimate 0).
    pub fn sample(&self, kind: SamplerKind, nb: &Neighbours, next: &mut impl FnMut() -> f32) -> SamplePlan {
        let mut plan = SamplePlan { neighbours: *nb, ..SamplePlan::default() };
        if self.vpl_count() == 0 {
            return plan;
        }
        if kind == SamplerKind::Uniform || nb.is_empty() {
            plan.push(sample_uniform_vpl(self.vpl_count(), next()));
            return plan;
        }
        match kind {
            SamplerKind::AlphaMax => self.sample_alpha_max(&mut plan, next),
            SamplerKind::Balance => self.sample_one(&mut plan, false, false, next),
            SamplerKind::BalanceCv => self.sample_one(&mut plan, false, true, next),
            _ => self.sample_one(&mut plan, true, true, next),
        }
        plan
    }

    /// `α_l` and `β_l` of each neighbour slot: fixed a priori or the record's optimised.
    #[inline]
    fn slot_weights(
        &self,
        nb: &Neighbours,
        optimized: bool,
    ) -> ([[f32; TECHNIQUES]; MAX_NEIGHBOURS], [[f32; TECHNIQUES]; MAX_NEIGHBOURS]) {
        let setup = &self.setup;
        let (mut alpha, mut beta) = ([setup.prior_alpha; MAX_NEIGHBOURS], [setup.prior_beta; MAX_NEIGHBOURS]);
        if optimized {
            for (s, (l, _)) in nb.iter().enumerate() {
                (alpha[s], beta[s]) = (self.params[l].mixture(), self.params[l].beta);
            }
        }
        (alpha, beta)
    }

    /// One-sample balance heuristic over all (record, technique) pairs, optionally with
    /// the control variates.
    fn sample_one(&self, plan: &mut SamplePlan, optimized: bool, cv: bool, next: &mut impl FnMut() -> f32) {
        let nb = plan.neighbours;
        let (alpha, beta) = self.slot_weights(&nb, optimized);
        let techniques = self.setup.techniques();
        // Pick (l, k) with probability w_l α_lk, then j ~ p_lk.
        let u = next();
        let (mut acc, mut chosen) = (0.0f32, None);
        'pick: for (s, (l, w)) in nb.iter().enumerate() {
            for &t in techniques {
                let pk = w * alpha[s][t as usize];
                if pk > 0.0 {
                    chosen = Some((l, t));
                    acc += pk;
                    if u < acc {
                        break 'pick;
                    }
                }
            }
        }
        let Some((l, t)) = chosen else {
            plan.push(sample_uniform_vpl(self.vpl_count(), next()));
            return;
        };
        let j = self.records[l].sample(t, next());
        let mut d = VplDraw { vpl: j as u32, ..VplDraw::default() };
        let (mut h, mut c) = (Rgb::ZERO, Rgb::ZERO);
        let rows = self.neighbour_pmfs(&nb, j);
        for (s, (l, w)) in nb.iter().enumerate() {
            let r = &self.records[l];
            for &t in techniques {
                let (k, p) = (t as usize, rows[s][t as usize]);
                d.pdf += w * alpha[s][k] * p;
                // Only the learning sampler's feedback reads them.
                if optimized {
                    d.interpolated_pmf[k] += w * p;
                    d.interpolated_cv[k] += w * p * r.luminance_total(t);
                }
                if cv {
                    h += (w * beta[s][k] * p) * r.total(t);
                    c += (w * beta[s][k]) * r.total(t);
                }
            }
        }
        // q(j) >= w_l α_lk p_lk(j) > 0 for the pair that drew j.
        d.weight = 1.0 / d.pdf;
        plan.offset = c - h * d.weight;
        plan.learns = optimized;
        plan.push(d);
    }

    /// Every technique's pmf of VPL `j` at each neighbour slot.
    #[inline]
    fn neighbour_pmfs(&self, nb: &Neighbours, j: usize) -> [[f32; TECHNIQUES]; MAX_NEIGHBOURS] {
        let mut rows = [[0.0f32; TECHNIQUES]; MAX_NEIGHBOURS];
        for (row, (l, _)) in rows.iter_mut().zip(nb.iter()) {
            *row = self.records[l].pmfs(j);
        }
        rows
    }

    /// Georgiev's multi-sample estimator: one draw per enabled distribution, kept where
    /// α-max gives it the sample (draws of weight 0 are left out: no ray for them). All
    /// draws come first (the random numbers in the order of one draw at a time), then
    /// one table of `P_i(j)` per distinct drawn VPL, then the owners.
    fn sample_alpha_max(&self, plan: &mut SamplePlan, next: &mut impl FnMut() -> f32) {
        let nb = plan.neighbours;
        let set = AlphaMaxSet::new(&self.config);
        let mut drawn = [0usize; MAX_DRAWS];
        for (j, &t) in drawn.iter_mut().zip(set.techniques()) {
            let l = pick_record(&nb, next());
            *j = self.records[l].sample(t, next());
        }
        let drawn = &drawn[..set.techniques().len()];
        let table = self.interpolated_pmfs(&nb, drawn);
        for (own, (&j, row)) in drawn.iter().zip(&table).enumerate() {
            let pmfs = set.gather(row);
            if set.owner(&pmfs) == own && pmfs[own] > 0.0 {
                let mut d = VplDraw { vpl: j as u32, weight: 1.0 / pmfs[own], ..VplDraw::default() };
                for (&t, &p) in set.techniques().iter().zip(&pmfs) {
                    d.interpolated_pmf[t as usize] = p;
                }
                plan.push(d);
            }
        }
    }

    /// `P_t(j) = Σ_l w_l p_lt(j)` of every technique (by `Technique as usize`) at each
    /// drawn VPL, summed in neighbour order from −0 as `Iterator::sum` does (so with its
    /// bits). A VPL drawn twice is read once; the uniform term, the same at every VPL
    /// all neighbours cover, is summed once.
    fn interpolated_pmfs(&self, nb: &Neighbours, drawn: &[usize]) -> [[f32; TECHNIQUES]; MAX_DRAWS] {
        // `P_4(j)` is `P_4(0)` at every VPL below each neighbour's count.
        let covered = nb.iter().map(|(l, _)| self.records[l].vpl_count()).min().unwrap_or(0);
        let uniform = self.interpolated_uniform(nb, 0);
        let mut table = [[0.0f32; TECHNIQUES]; MAX_DRAWS];
        for (k, &j) in drawn.iter().enumerate() {
            if let Some(i) = drawn[..k].iter().position(|&i| i == j) {
                table[k] = table[i];
                continue;
            }
            let mut p = [-0.0f32; TECHNIQUES];
            for (l, w) in nb.iter() {
                let [full, unoccluded, bounded] = self.records[l].cdf_pmfs(j);
                p[0] += w * full;
                p[1] += w * unoccluded;
                p[2] += w * bounded;
            }
            p[3] = if j < covered { uniform } else { self.interpolated_uniform(nb, j) };
            table[k] = p;
        }
        table
    }

    /// `P_4(j) = Σ_l w_l p_l4(j)` of the uniform technique.
    fn interpolated_uniform(&self, nb: &Neighbours, j: usize) -> f32 {
        nb.iter().fold(-0.0, |acc, (l, w)| acc + w * self.records[l].pmf(Technique::Uniform, j))
    }
}
