//! Per-record optimal mixture and control-variate weights (He and Owen 2014, "Optimal
//! mixture weights in multiple importance sampling"; thesis 3.5 and 5.2.2).
//!
//! Record `i` owns mixture weights `α'` (the optimiser's variables; sampling uses
//! `α = α' / Σ α'`) and control-variate weights `β` (dimensionless: `β_k = 1` means "the
//! record's distribution k, scaled by its total, predicts f"). For the record's problem we
//! let its parameters act on the interpolated distributions of each sample's pixel:
//! `s(j) = Σ_k α'_k P_k(j)` and residual `r(j) = f(j) − Σ_k β_k Q_k(j)` (luminance), and
//! minimise He and Owen's objective
//!
//! `G(α', β) = E_q0[ r(j)² / (s(j) q0(j)) ] = Σ_j r(j)² / s(j)`,
//!
//! the second moment of the one-sample estimator with all J distributions as control
//! variates; it is jointly convex, and its minimum over β equals the minimal variance
//! (He and Owen, section 3), so minimising it minimises the variance. The frame's own
//! samples `j ~ q0` (the mixture actually used) estimate G, its gradient and Hessian, each
//! sample weighted by the record's interpolation weight `w_i` and normalised by `Σ w_i`
//! (thesis 5.2.2). Constraints `α'_k > ε_k`, `Σ α'_k < 1` enter as the log barrier
//!
//! `f'(α', β) = G − ρ Σ_k log(α'_k − ε_k) − ρ log(1 − Σ_k α'_k)`, `ρ = barrier · G`,
//!
//! (ρ relative to G keeps the barrier's pull independent of the scene's brightness).
//!
//! The samples are those a record has accumulated over the frame's passes
//! ([`SampleHistory`]), each with its own `1/q0`, so G and its derivatives are estimated at
//! the *current* parameters from every sample so far. One damped Newton step per record
//! per pass (the thesis: per frame):
//! - no step before the record's samples reach an effective count `(Σ w)² / Σ w²` of
//!   [`OptimizerParams::min_samples`] (a Newton step fitted to about as many samples as
//!   there are variables follows their noise: the previous one-pass version, stepping on
//!   ~8 samples per record, doubled the relMSE of `balance-cv`);
//! - the Newton direction is cut to a trust region (no α' moves more than
//!   `max_alpha_step`, no β more than `max_beta_step` per step);
//! - backtracking (t = 1, 1/2, ..., 1/512 of the largest step that stays 99 % inside the
//!   domain) on the samples' estimate of f' until the Armijo condition holds (Boyd and
//!   Vandenberghe 9.5) *and* the estimated G does not grow; no step if none does. So a
//!   step never raises the estimated objective.

// Index loops over the small matrices read as the formulas they implement.
#![allow(clippy::needless_range_loop)]

mod sums;

use super::feedback::SampleFeedback;
use super::history::{SampleHistory, StoredSample};
use super::{CacheParams, DistributionSet, ImportanceCache, TECHNIQUES};
use filtrace_core::cpu::isa;
use rayon::prelude::*;
use sums::{moments, objectives, MAX_VARS};

/// Step sizes tried by the backtracking line search, as fractions of the largest step
/// that keeps 1 % of the way to the barrier's boundary.
const STEPS: [f64; 10] =
    [1.0, 0.5, 0.25, 0.125, 0.0625, 0.03125, 0.015625, 0.0078125, 0.00390625, 0.001953125];
/// Fraction of the distance to the domain's boundary a step may cover.
const TO_BOUNDARY: f64 = 0.99;
/// Armijo sufficient-decrease constant.
const ARMIJO: f64 = 0.25;

/// Parameters of the per-record optimisation.
#[derive(Clone, Debug, PartialEq)]
pub struct OptimizerParams {
    /// Lower bounds ε_k of the mixture weights (full, unoccluded, bounded, uniform): no
    /// distribution is ever dismissed, the uniform one least of all (the defensive
    /// fallback that bounds the variance, thesis 3.5).
    pub min_alpha: [f32; TECHNIQUES],
    /// Barrier strength ρ relative to the objective G. The optimum sits about
    /// `barrier` from `Σ α' = 1` (relatively) and a comparable distance above each ε_k.
    pub barrier: f32,
    /// A record whose accumulated samples have a smaller effective count `(Σ w)² / Σ w²`
    /// keeps its parameters: a Newton step from a handful of samples is noise. 32: four
    /// samples per variable of the four-distribution problem (8 variables).
    pub min_samples: f32,
    /// Trust region: the largest change of any α' in one step.
    pub max_alpha_step: f32,
    /// Trust region: the largest change of any β in one step (β is dimensionless, ~1).
    pub max_beta_step: f32,
    /// Samples a record keeps over a frame's passes (a uniform reservoir beyond it):
    /// 256 × 44 bytes × 2048 records = 23 MB at most.
    pub history: usize,
}

impl Default for OptimizerParams {
    fn default() -> Self {
        OptimizerParams {
            min_alpha: [0.02, 0.02, 0.02, 0.05],
            barrier: 1e-3,
            min_samples: 32.0,
            max_alpha_step: 0.1,
            max_beta_step: 0.25,
            history: 256,
        }
    }
}

impl OptimizerParams {
    /// Checks the parameters for the enabled distributions.
    pub fn validate(&self, set: &DistributionSet) -> Result<(), String> {
        let sum: f32 = set.techniques().map(|t| self.min_alpha[t as usize]).sum();
        if self.min_alpha.iter().any(|&e| !(e.is_finite() && e >= 0.0)) || sum >= 0.9 {
            return Err(format!(
                "optimizer mixture lower bounds {:?} (expected >= 0, summing below 0.9)",
                self.min_alpha
            ));
        }
        if !(self.barrier.is_finite() && self.barrier > 0.0) {
            return Err(format!("optimizer barrier {} (expected > 0)", self.barrier));
        }
        if !(self.min_samples.is_finite() && self.min_samples >= 0.0) {
            return Err(format!("optimizer minimum effective samples {} (expected >= 0)", self.min_samples));
        }
        for (name, v) in [("alpha", self.max_alpha_step), ("beta", self.max_beta_step)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("optimizer largest {name} step {v} (expected > 0)"));
            }
        }
        if self.history == 0 {
            return Err("optimizer history of 0 samples per record (expected >= 1)".into());
        }
        Ok(())
    }
}

/// The `optimized` sampler's parameters of one record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RecordParams {
    /// α', the unnormalised mixture weights (`Σ < 1`, `α'_k > ε_k`; 0 for disabled
    /// distributions).
    pub alpha: [f32; TECHNIQUES],
    /// β, the control-variate weights (0 for disabled distributions).
    pub beta: [f32; TECHNIQUES],
}

/// A priori β: the full distribution at its own total, the interpolated full
/// contribution as the first guess of the pixel (thesis 5.2.1); 0 without it.
pub(crate) fn prior_beta(set: &DistributionSet) -> [f32; TECHNIQUES] {
    [if set.full { 1.0 } else { 0.0 }, 0.0, 0.0, 0.0]
}

impl RecordParams {
    /// The a priori start: `α' = 0.95 · prior mixture` where that clears every bound ε_k
    /// (then `optimized` samples exactly as `balance-cv` until its first step), else
    /// `α' = ε + 0.95 (1 − Σ ε) · prior mixture`; β from `prior_beta`.
    pub fn prior(config: &CacheParams) -> Self {
        let eps = config.optimizer.min_alpha;
        let set = config.distributions;
        let mix = config.prior_mixture();
        let mut alpha = [0.0; TECHNIQUES];
        if set.techniques().all(|t| 0.95 * mix[t as usize] > eps[t as usize]) {
            set.techniques().for_each(|t| alpha[t as usize] = 0.95 * mix[t as usize]);
        } else {
            let free = 1.0 - set.techniques().map(|t| eps[t as usize]).sum::<f32>();
            set.techniques()
                .for_each(|t| alpha[t as usize] = eps[t as usize] + 0.95 * free * mix[t as usize]);
        }
        RecordParams { alpha, beta: prior_beta(&set) }
    }

    /// The normalised mixture `α' / Σ α'` the sampler uses.
    pub fn mixture(&self) -> [f32; TECHNIQUES] {
        let sum: f32 = self.alpha.iter().sum();
        self.alpha.map(|a| a / sum)
    }

    /// `Σ w_l θ_l` for weights summing to 1: stays feasible (the constraints are convex).
    pub fn blend<'a>(items: impl Iterator<Item = (&'a RecordParams, f32)>) -> Self {
        let mut out = RecordParams { alpha: [0.0; TECHNIQUES], beta: [0.0; TECHNIQUES] };
        for (p, w) in items {
            for k in 0..TECHNIQUES {
                out.alpha[k] += w * p.alpha[k];
                out.beta[k] += w * p.beta[k];
            }
        }
        out
    }
}

/// Summary of one [`ImportanceCache::optimize`] call.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OptimizeStats {
    /// Records that took a step.
    pub stepped: usize,
    /// Records left unchanged (too few samples, no decrease, degenerate objective).
    pub kept: usize,
    /// Σ over stepped records of the estimated G before and after the step.
    pub objective_before: f64,
    pub objective_after: f64,
}

/// Result of one record's step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepOutcome {
    pub params: RecordParams,
    /// Whether a step was taken.
    pub stepped: bool,
    /// Estimated G at the old and new parameters (equal when no step; 0 when the record
    /// has too few samples to estimate it).
    pub objective_before: f64,
    pub objective_after: f64,
}

impl ImportanceCache {
    /// One damped Newton step per record from `feedback` alone (a history of one pass; see
    /// [`ImportanceCache::optimize_history`]). `feedback` must come in a fixed order (e.g.
    /// pixel order, draws in order): the result then does not depend on the thread count.
    pub fn optimize(&mut self, feedback: &[SampleFeedback]) -> OptimizeStats {
        let mut history = SampleHistory::new(self.records.len(), usize::MAX);
        history.add(feedback);
        self.optimize_history(&history)
    }

    /// One damped Newton step per record on every sample it has accumulated (see the
    /// module docs). A history of another cache's size changes nothing.
    pub fn optimize_history(&mut self, history: &SampleHistory) -> OptimizeStats {
        self.step_records(history, |_, _| false).0
    }

    /// [`ImportanceCache::optimize_history`] for a frame's passes, the same parameters
    /// bit for bit: a record whose samples and parameters are those its last step kept
    /// is skipped (the step is a function of the two, so it would keep them again), and
    /// `history` remembers which records this step kept.
    pub fn optimize_pass(&mut self, history: &mut SampleHistory) -> OptimizeStats {
        let (stats, outcomes) =
            self.step_records(history, |l, p| history.settled(l) == Some((p.alpha, p.beta)));
        for (l, o) in outcomes.iter().enumerate() {
            if !o.stepped {
                history.settle(l, (o.params.alpha, o.params.beta));
            }
        }
        stats
    }

    /// One step per record, `skip(record, parameters)` keeping a record without one; the
    /// summary and each record's outcome.
    fn step_records(
        &mut self,
        history: &SampleHistory,
        skip: impl Fn(usize, &RecordParams) -> bool + Sync,
    ) -> (OptimizeStats, Vec<StepOutcome>) {
        let n = self.records.len();
        if history.len() != n {
            return (OptimizeStats { kept: n, ..OptimizeStats::default() }, Vec::new());
        }
        let set = self.config.distributions;
        let opt = &self.config.optimizer;
        let outcomes: Vec<StepOutcome> = (0..n)
            .into_par_iter()
            .with_min_len(16)
            .map(|l| match &self.params[l] {
                p if skip(l, p) => {
                    StepOutcome { params: *p, stepped: false, objective_before: 0.0, objective_after: 0.0 }
                }
                p => newton_step(p, &set, opt, history.samples(l)),
            })
            .collect();
        let mut stats = OptimizeStats::default();
        for (l, o) in outcomes.iter().enumerate() {
            self.params[l] = o.params;
            if o.stepped {
                stats.stepped += 1;
                stats.objective_before += o.objective_before;
                stats.objective_after += o.objective_after;
            } else {
                stats.kept += 1;
            }
        }
        (stats, outcomes)
    }
}

/// The enabled techniques as indices, and their count J (2J variables: α' then β).
fn enabled(set: &DistributionSet) -> ([usize; TECHNIQUES], usize) {
    let mut ts = [0usize; TECHNIQUES];
    let mut j = 0;
    for t in set.techniques() {
        ts[j] = t as usize;
        j += 1;
    }
    (ts, j)
}

/// The effective sample count `(Σ w)² / Σ w²` of a record's samples.
fn effective_count(samples: &[StoredSample]) -> f64 {
    let (sum, sum_sq) = samples.iter().fold((0.0f64, 0.0f64), |(a, b), fb| {
        let w = fb.weight as f64;
        (a + w, b + w * w)
    });
    if sum_sq > 0.0 {
        sum * sum / sum_sq
    } else {
        0.0
    }
}

/// The barrier `−ρ Σ log(α'_k − ε_k) − ρ log(1 − Σ α'_k)`; +∞ outside the domain.
fn barrier(x: &[f64], eps: &[f64], rho: f64) -> f64 {
    let mut b = 0.0;
    let mut sum = 0.0;
    for (k, &e) in eps.iter().enumerate() {
        let slack = x[k] - e;
        if !(slack > 0.0) {
            return f64::INFINITY;
        }
        b -= rho * slack.ln();
        sum += x[k];
    }
    if !(sum < 1.0) {
        return f64::INFINITY;
    }
    b - rho * (1.0 - sum).ln()
}

/// One damped Newton step of record parameters `params` on the weighted samples (see
/// the module docs). The samples are read twice (moments, then the line search).
pub fn newton_step(
    params: &RecordParams,
    set: &DistributionSet,
    opt: &OptimizerParams,
    samples: &[StoredSample],
) -> StepOutcome {
    let keep =
        |g: f64| StepOutcome { params: *params, stepped: false, objective_before: g, objective_after: g };
    let (ts, j) = enabled(set);
    let ts = &ts[..j];
    let dim = 2 * j;
    let mut x = [0.0f64; MAX_VARS];
    for (k, &t) in ts.iter().enumerate() {
        x[k] = params.alpha[t] as f64;
        x[j + k] = params.beta[t] as f64;
    }
    // Too few samples: no step, and G is not estimated (reported as 0).
    if effective_count(samples) < opt.min_samples as f64 {
        return keep(0.0);
    }
    let eps: Vec<f64> = ts.iter().map(|&t| opt.min_alpha[t] as f64).collect();
    let level = isa();
    let m = moments(level, &x, ts, samples);
    let g0 = m.objective;
    if !(g0 > 0.0 && g0.is_finite() && barrier(&x, &eps, 1.0).is_finite()) {
        return keep(g0);
    }
    let rho = opt.barrier as f64 * g0;
    let (mut grad, mut hess) = (m.gradient, m.hessian);
    add_barrier_derivatives(&x[..j], &eps, rho, &mut grad, &mut hess);
    let Some(mut dx) = solve_newton(&hess, &grad, dim) else { return keep(g0) };
    trust_region(&mut dx, j, opt);
    let decrement: f64 = -(0..dim).map(|i| grad[i] * dx[i]).sum::<f64>();
    if !(decrement > 0.0) {
        return keep(g0);
    }
    // Backtracking on the sampled f' at the trial points, all in one pass.
    let t_max = max_feasible_step(&x[..j], &dx[..j], &eps).min(1.0);
    let steps = STEPS.map(|t| t * t_max);
    let trials: Vec<[f64; MAX_VARS]> = steps
        .iter()
        .map(|&t| std::array::from_fn(|i| if i < dim { x[i] + t * dx[i] } else { 0.0 }))
        .collect();
    let f0 = g0 + barrier(&x, &eps, rho);
    // The full step usually passes near the optimum: try it and its half first, and
    // replay the samples for the shorter steps only when both fail.
    let mut values = objectives(level, &trials[..2], ts, samples);
    for (s, &t) in steps.iter().enumerate() {
        if s == values.len() {
            values.extend(objectives(level, &trials[s..], ts, samples));
        }
        let f = values[s] + barrier(&trials[s], &eps, rho);
        if f.is_finite() && f <= f0 - ARMIJO * t * decrement && values[s] <= g0 {
            let mut out = *params;
            for (k, &tk) in ts.iter().enumerate() {
                out.alpha[tk] = trials[s][k] as f32;
                out.beta[tk] = trials[s][j + k] as f32;
            }
            // Rounding to f32 must not leave the domain.
            let back: Vec<f64> = (0..j).map(|k| out.alpha[ts[k]] as f64).collect();
            if !barrier(&back, &eps, 1.0).is_finite() {
                return keep(g0);
            }
            return StepOutcome {
                params: out,
                stepped: true,
                objective_before: g0,
                objective_after: values[s],
            };
        }
    }
    keep(g0)
}

/// Shortens the Newton direction (α' then β, J each) so that no α' moves more than
/// `max_alpha_step` and no β more than `max_beta_step`.
fn trust_region(dx: &mut [f64; MAX_VARS], j: usize, opt: &OptimizerParams) {
    let largest = |d: &[f64]| d.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let scale = (opt.max_alpha_step as f64 / largest(&dx[..j]))
        .min(opt.max_beta_step as f64 / largest(&dx[j..2 * j]))
        .min(1.0);
    dx.iter_mut().for_each(|d| *d *= scale);
}

/// The largest `t` (times [`TO_BOUNDARY`]) with `α' + t dα` inside `α'_k > ε_k`,
/// `Σ α'_k < 1`.
fn max_feasible_step(alpha: &[f64], d_alpha: &[f64], eps: &[f64]) -> f64 {
    let mut t = f64::INFINITY;
    for k in 0..alpha.len() {
        if d_alpha[k] < 0.0 {
            t = t.min((alpha[k] - eps[k]) / -d_alpha[k]);
        }
    }
    let d_sum: f64 = d_alpha.iter().sum();
    if d_sum > 0.0 {
        t = t.min((1.0 - alpha.iter().sum::<f64>()) / d_sum);
    }
    TO_BOUNDARY * t
}

/// Adds the barrier's gradient and Hessian (α' block only).
fn add_barrier_derivatives(
    alpha: &[f64],
    eps: &[f64],
    rho: f64,
    grad: &mut [f64; MAX_VARS],
    hess: &mut [[f64; MAX_VARS]; MAX_VARS],
) {
    let slack_sum = 1.0 - alpha.iter().sum::<f64>();
    for k in 0..alpha.len() {
        let slack = alpha[k] - eps[k];
        grad[k] += -rho / slack + rho / slack_sum;
        hess[k][k] += rho / (slack * slack);
        for n in 0..alpha.len() {
            hess[k][n] += rho / (slack_sum * slack_sum);
        }
    }
}

/// Solves `H dx = −g` for the symmetric positive semi-definite `H` by Cholesky, with a
/// tiny relative ridge (directions no sample constrains get no step). `None` if `H` is
/// not positive definite even so.
fn solve_newton(h: &[[f64; MAX_VARS]; MAX_VARS], g: &[f64; MAX_VARS], dim: usize) -> Option<[f64; MAX_VARS]> {
    let scale = (0..dim).map(|i| h[i][i].abs()).fold(0.0, f64::max);
    if !(scale > 0.0 && scale.is_finite()) {
        return None;
    }
    let mut l = [[0.0f64; MAX_VARS]; MAX_VARS];
    for i in 0..dim {
        for k in 0..=i {
            let mut s = h[i][k] + if i == k { 1e-9 * scale } else { 0.0 };
            for m in 0..k {
                s -= l[i][m] * l[k][m];
            }
            if i == k {
                if !(s > 0.0) {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][k] = s / l[k][k];
            }
        }
    }
    // Forward then back substitution.
    let mut y = [0.0f64; MAX_VARS];
    for i in 0..dim {
        y[i] = (-g[i] - (0..i).map(|m| l[i][m] * y[m]).sum::<f64>()) / l[i][i];
    }
    let mut dx = [0.0f64; MAX_VARS];
    for i in (0..dim).rev() {
        dx[i] = (y[i] - (i + 1..dim).map(|m| l[m][i] * dx[m]).sum::<f64>()) / l[i][i];
    }
    dx.iter().all(|v| v.is_finite()).then_some(dx)
}
