//! The per-record He–Owen optimisation on synthetic problems with a known optimum: one
//! record, one shading point next to it (weight 1), so the record's problem is the
//! pixel's. The optimum is found by brute force: a grid over the mixture simplex with
//! the control-variate weights solved in closed form at each grid point.

// Index loops over the small matrices read as the formulas they implement.
#![allow(clippy::needless_range_loop)]

use super::super::*;
use super::{ToyScene, TOY_DIAGONAL};
use filtrace_core::rng::SplitMix64;
use filtrace_core::{luminance, Vec3};

const VPLS: usize = 48;

/// A single-record problem: `P_k(j)`, `Q_k(j)` per enabled technique and `f(j)`.
struct Problem {
    cache: ImportanceCache,
    techniques: Vec<Technique>,
    p: Vec<Vec<f64>>,
    q: Vec<Vec<f64>>,
    f: Vec<f64>,
    x: CachePoint,
}

impl Problem {
    fn new(seed: u64, f_of: impl Fn(&ToyScene, usize, Vec3, Vec3) -> f64) -> Self {
        let scene = ToyScene::new(VPLS, seed);
        let config =
            CacheParams { neighbours: 1, distributions: DistributionSet::thesis(), ..CacheParams::default() };
        let record = CachePoint { position: Vec3::new(2.0, 0.0, 2.0), normal: Vec3::Y, pixel: 0 };
        let cache = ImportanceCache::build(&scene, vec![record], TOY_DIAGONAL, &config, None).unwrap();
        let x = CachePoint { position: Vec3::new(2.3, 0.0, 1.8), ..record };
        let techniques: Vec<Technique> = config.distributions.techniques().collect();
        let r = &cache.records()[0];
        let p = techniques.iter().map(|&t| (0..VPLS).map(|j| r.pmf(t, j) as f64).collect()).collect();
        let q = techniques
            .iter()
            .map(|&t| (0..VPLS).map(|j| (r.pmf(t, j) * r.luminance_total(t)) as f64).collect())
            .collect();
        let f = (0..VPLS).map(|j| f_of(&scene, j, x.position, x.normal)).collect();
        Problem { cache, techniques, p, q, f, x }
    }

    /// `G(α, β) = Σ_j (f − β·Q)² / (α·P)` for a normalised α.
    fn objective(&self, alpha: &[f64], beta: &[f64]) -> f64 {
        (0..VPLS)
            .map(|j| {
                let s: f64 = (0..alpha.len()).map(|k| alpha[k] * self.p[k][j]).sum();
                let r = self.f[j] - (0..beta.len()).map(|k| beta[k] * self.q[k][j]).sum::<f64>();
                r * r / s
            })
            .sum()
    }

    /// G at the record's current parameters (α normalised).
    fn current(&self) -> (f64, Vec<f64>) {
        let params = self.cache.params()[0];
        let mix = params.mixture();
        let alpha: Vec<f64> = self.techniques.iter().map(|&t| mix[t as usize] as f64).collect();
        let beta: Vec<f64> = self.techniques.iter().map(|&t| params.beta[t as usize] as f64).collect();
        (self.objective(&alpha, &beta), alpha)
    }

    /// Brute-force optimum over α ≥ ε on the simplex (grid step `h`), β in closed form.
    fn brute_force(&self, h: f64) -> (f64, Vec<f64>) {
        let eps: Vec<f64> = self
            .techniques
            .iter()
            .map(|&t| self.cache.config().optimizer.min_alpha[t as usize] as f64)
            .collect();
        let steps = (1.0 / h).round() as usize;
        let mut best = (f64::INFINITY, vec![]);
        for a in 0..=steps {
            for b in 0..=steps - a {
                let alpha = [a as f64 * h, b as f64 * h, 1.0 - (a + b) as f64 * h];
                if alpha.iter().zip(&eps).any(|(x, e)| x < e) {
                    continue;
                }
                let beta = self.best_beta(&alpha);
                let g = self.objective(&alpha, &beta);
                if g < best.0 {
                    best = (g, alpha.to_vec());
                }
            }
        }
        best
    }

    /// `β*(α)`: the normal equations `(Σ Q Qᵀ / s) β = Σ f Q / s` (3 × 3, Cramer).
    fn best_beta(&self, alpha: &[f64]) -> Vec<f64> {
        let mut a = [[0.0f64; 3]; 3];
        let mut b = [0.0f64; 3];
        for j in 0..VPLS {
            let s: f64 = (0..3).map(|k| alpha[k] * self.p[k][j]).sum();
            for k in 0..3 {
                b[k] += self.f[j] * self.q[k][j] / s;
                for m in 0..3 {
                    a[k][m] += self.q[k][j] * self.q[m][j] / s;
                }
            }
        }
        let det = |m: &[[f64; 3]; 3]| {
            m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
        };
        let d = det(&a);
        (0..3)
            .map(|c| {
                let mut m = a;
                for r in 0..3 {
                    m[r][c] = b[r];
                }
                det(&m) / d
            })
            .collect()
    }

    /// Feedback of the exhaustive sum: every VPL once, importance weight 1.
    fn exact_feedback(&self) -> Vec<SampleFeedback> {
        (0..VPLS)
            .map(|j| {
                let mut pmf = [0.0f32; TECHNIQUES];
                let mut cv = [0.0f32; TECHNIQUES];
                for (k, &t) in self.techniques.iter().enumerate() {
                    pmf[t as usize] = self.p[k][j] as f32;
                    cv[t as usize] = self.q[k][j] as f32;
                }
                SampleFeedback::for_records(&[(0, 1.0)], pmf, cv, 1.0, self.f[j] as f32)
            })
            .collect()
    }

    fn assert_feasible(&self) {
        let p = self.cache.params()[0];
        let eps = self.cache.config().optimizer.min_alpha;
        let sum: f32 = p.alpha.iter().sum();
        assert!(sum < 1.0, "Σ α' = {sum}");
        for &t in &self.techniques {
            assert!(
                p.alpha[t as usize] > eps[t as usize],
                "α' of {} = {} <= ε",
                t.name(),
                p.alpha[t as usize]
            );
        }
    }
}

/// The scene's luminance of f at the shading point: the realistic integrand.
fn scene_f(scene: &ToyScene, j: usize, x: Vec3, n: Vec3) -> f64 {
    luminance(scene.contribution(j, x, n)) as f64
}

#[test]
fn newton_steps_on_the_exact_objective_reach_the_optimum() {
    for seed in [1u64, 2, 3] {
        let mut problem = Problem::new(seed, scene_f);
        let (optimum, alpha_opt) = problem.brute_force(0.002);
        let feedback = problem.exact_feedback();
        let (g_prior, _) = problem.current();
        let mut last = g_prior;
        for frame in 0..40 {
            let stats = problem.cache.optimize(&feedback);
            problem.assert_feasible();
            let (g, _) = problem.current();
            if frame == 0 {
                assert_eq!(stats.stepped, 1, "seed {seed}: the first step is taken");
                assert!(g < g_prior, "seed {seed}: the first step lowers E[F²]: {g} vs {g_prior}");
            }
            // The barrier objective decreases; G itself may rise by the barrier's share.
            assert!(g <= last * (1.0 + 1e-2), "seed {seed} frame {frame}: G rose from {last} to {g}");
            last = g;
        }
        let (g, alpha) = problem.current();
        // Log-barrier duality gap: at most (J + 1) ρ = 4e-3 G above the constrained optimum.
        assert!(g <= optimum * (1.0 + 5e-3), "seed {seed}: G {g} vs brute-force optimum {optimum}");
        let gap: f64 = alpha.iter().zip(&alpha_opt).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(gap < 0.03, "seed {seed}: α {alpha:?} vs brute force {alpha_opt:?}");
        assert!(g < 0.9 * g_prior, "seed {seed}: the optimum is worth it ({g} vs prior {g_prior})");
    }
}

/// An integrand the full distribution misses entirely: the light blocked at the shading
/// point (f = E² where the record's E¹ is mostly 0). The optimum puts α_full on its lower
/// bound ε; the iterates approach it from inside and never cross it.
#[test]
fn newton_steps_respect_the_lower_bounds() {
    let mut problem = Problem::new(5, |scene, j, x, n| {
        if scene.visible_at(j, x) {
            0.0
        } else {
            luminance(scene.unoccluded_at(j, x, n)) as f64
        }
    });
    let eps = problem.cache.config().optimizer.min_alpha[0] as f64;
    let (optimum, alpha_opt) = problem.brute_force(0.002);
    assert!(alpha_opt[0] <= eps + 0.002, "the constructed optimum lies on the bound: {alpha_opt:?}");
    let feedback = problem.exact_feedback();
    for _ in 0..60 {
        problem.cache.optimize(&feedback);
        problem.assert_feasible();
    }
    let (g, alpha) = problem.current();
    assert!(g <= optimum * (1.0 + 5e-3), "G {g} vs {optimum}");
    assert!(alpha[0] < eps + 0.01, "α_full {} near its bound {eps}", alpha[0]);
    assert!((alpha[1] - alpha_opt[1]).abs() < 0.03, "α {alpha:?} vs {alpha_opt:?}");
}

/// The real loop: samples drawn by the `optimized` sampler at the shading point, one
/// Newton step per frame from those samples only.
#[test]
fn sampled_newton_steps_approach_the_optimum() {
    let mut problem = Problem::new(2, scene_f);
    let (optimum, _) = problem.brute_force(0.005);
    let (g_prior, _) = problem.current();
    let mut rng = SplitMix64::new(12);
    let scene = ToyScene::new(VPLS, 2);
    let x = problem.x;
    for _ in 0..30 {
        let nb = problem.cache.neighbours(x.position, x.normal);
        let mut feedback = Vec::new();
        for _ in 0..2000 {
            let plan = problem.cache.sample(SamplerKind::Optimized, &nb, &mut || rng.next_f32());
            let d = plan.draws()[0];
            feedback.extend(plan.feedback(0, scene.contribution(d.vpl as usize, x.position, x.normal)));
        }
        problem.cache.optimize(&feedback);
        problem.assert_feasible();
    }
    let (g, _) = problem.current();
    assert!(g < g_prior, "G {g} vs prior {g_prior}");
    assert!(g <= optimum * 1.02, "G {g} vs optimum {optimum} (prior {g_prior})");
}

/// No samples, too few, or an all-zero integrand: parameters stay.
#[test]
fn records_without_evidence_keep_their_parameters() {
    let mut problem = Problem::new(1, |_, _, _, _| 0.0);
    let before = problem.cache.params()[0];
    let stats = problem.cache.optimize(&[]);
    assert_eq!((stats.stepped, stats.kept), (0, 1));
    let few: Vec<SampleFeedback> = problem.exact_feedback().into_iter().take(2).collect();
    problem.cache.optimize(&few);
    assert_eq!(problem.cache.params()[0], before);
    // f = 0 but β_full = 1: G > 0 until the CV weight goes to 0, so steps are taken.
    let feedback = problem.exact_feedback();
    problem.cache.optimize(&feedback);
    problem.assert_feasible();
}

/// Parameters of a rebuilt cache are interpolated from the previous one's.
#[test]
fn parameters_carry_over_to_a_rebuilt_cache() {
    let scene = ToyScene::new(VPLS, 9);
    let config = CacheParams::default();
    let points = super::surface_points(12, 3);
    let mut cache = ImportanceCache::build(&scene, points.clone(), TOY_DIAGONAL, &config, None).unwrap();
    let mut params = cache.params().to_vec();
    for (i, p) in params.iter_mut().enumerate() {
        p.beta[1] = i as f32;
    }
    cache.set_params(params.clone()).unwrap();
    // Same points: each record finds itself at distance 0 and keeps its parameters.
    let rebuilt = ImportanceCache::build(&scene, points, TOY_DIAGONAL, &config, Some(&cache)).unwrap();
    for (a, b) in rebuilt.params().iter().zip(&params) {
        assert!((a.beta[1] - b.beta[1]).abs() < 1e-6 && a.alpha == b.alpha, "{a:?} vs {b:?}");
    }
    // New points: convex combinations of the old parameters (feasible).
    let moved =
        ImportanceCache::build(&scene, super::surface_points(20, 4), TOY_DIAGONAL, &config, Some(&cache))
            .unwrap();
    for p in moved.params() {
        assert!(p.alpha.iter().sum::<f32>() < 1.0 && (0.0..=11.0).contains(&p.beta[1]), "{p:?}");
    }
}

/// Progressive passes as the renderer runs them: each pass draws samples with the
/// record's current parameters, adds them to the record's history, and takes one step on
/// every sample so far. No step before the history holds `min_samples` samples; every
/// step lowers the estimated G on the samples it was taken on; the carried parameters
/// stay feasible and converge to the optimum of the exact objective (80 passes of 32).
#[test]
fn accumulated_passes_never_raise_the_estimated_objective_and_converge() {
    for seed in [2u64, 3] {
        let mut problem = Problem::new(seed, scene_f);
        let (optimum, _) = problem.brute_force(0.005);
        let (g_prior, _) = problem.current();
        let opt = problem.cache.config().optimizer.clone();
        // A history large enough to hold every sample: convergence to the exact optimum
        // needs the estimate to become exact (the renderer's 256 bound the memory).
        let mut history = SampleHistory::new(1, 4096);
        let mut rng = SplitMix64::new(seed * 7);
        let scene = ToyScene::new(VPLS, seed);
        let x = problem.x;
        let mut steps = 0;
        for pass in 0..80 {
            let nb = problem.cache.neighbours(x.position, x.normal);
            let mut feedback = Vec::new();
            for _ in 0..32 {
                let plan = problem.cache.sample(SamplerKind::Optimized, &nb, &mut || rng.next_f32());
                let d = plan.draws()[0];
                feedback.extend(plan.feedback(0, scene.contribution(d.vpl as usize, x.position, x.normal)));
            }
            history.add(&feedback);
            let before = problem.cache.params()[0];
            let stats = problem.cache.optimize_history(&history);
            if (history.seen(0) as f32) < opt.min_samples {
                assert_eq!(
                    problem.cache.params()[0],
                    before,
                    "seed {seed} pass {pass}: stepped on too few samples"
                );
            }
            if stats.stepped == 1 {
                steps += 1;
                assert!(
                    stats.objective_after <= stats.objective_before,
                    "seed {seed} pass {pass}: estimated G rose from {} to {}",
                    stats.objective_before,
                    stats.objective_after
                );
            }
            problem.assert_feasible();
        }
        assert_eq!(history.seen(0), 80 * 32);
        let (g, _) = problem.current();
        assert!(steps >= 20, "seed {seed}: {steps} steps");
        assert!(
            g < g_prior && g <= optimum * 1.03,
            "seed {seed}: G {g} vs optimum {optimum} (prior {g_prior})"
        );
    }
}

/// The history keeps every sample up to its capacity, then a uniform subset, the same
/// for the same feedback order, also after a reset.
#[test]
fn history_reservoir_is_bounded_and_deterministic() {
    let fb = |i: usize| SampleFeedback::for_records(&[(i % 3, 0.5)], [0.1; 4], [0.0; 4], 1.0, i as f32);
    let all: Vec<SampleFeedback> = (0..3000).map(fb).collect();
    let (mut a, mut b, mut c) =
        (SampleHistory::new(3, 100), SampleHistory::new(3, 100), SampleHistory::new(3, 100));
    a.add(&all);
    for chunk in all.chunks(7) {
        b.add(chunk);
    }
    c.add_parts(&all.chunks(11).collect::<Vec<_>>());
    // A history reset after another frame (other records, another capacity) is new.
    let mut d = SampleHistory::new(5, 7);
    d.add(&all[..200]);
    d.reset(3, 100);
    d.add_parts(&all.chunks(13).collect::<Vec<_>>());
    for l in 0..3 {
        assert_eq!((d.samples(l), d.seen(l)), (a.samples(l), a.seen(l)), "record {l}: reset");
        assert_eq!((a.samples(l).len(), a.seen(l)), (100, 1000));
        assert_eq!(a.samples(l), b.samples(l), "record {l}: pass boundaries change nothing");
        assert_eq!(a.samples(l), c.samples(l), "record {l}: feedback in parts changes nothing");
        // A uniform subset of 0..3000 with i % 3 == l: its mean index near 1500.
        let mean = a.samples(l).iter().map(|s| s.value as f64).sum::<f64>() / 100.0;
        assert!((mean - 1500.0).abs() < 4.0 * 866.0 / 10.0, "record {l}: mean index {mean}");
    }
}

/// `optimize_pass` (which skips records whose samples and parameters are those of their
/// last kept step) gives the parameters of `optimize_history` bit for bit, pass after
/// pass, while records keep, step and get no new samples.
#[test]
fn optimize_pass_equals_optimize_history() {
    let mut problem = Problem::new(4, scene_f);
    let scene = ToyScene::new(VPLS, 4);
    let x = problem.x;
    let mut reference = problem.cache.clone();
    let (mut fast, mut slow) = (SampleHistory::new(1, 256), SampleHistory::new(1, 256));
    let mut rng = SplitMix64::new(17);
    let (mut stepped, mut kept) = (0, 0);
    for pass in 0..40 {
        let nb = problem.cache.neighbours(x.position, x.normal);
        let mut feedback = Vec::new();
        // Every third pass brings no samples: a kept record is then skipped.
        for _ in 0..if pass % 3 == 2 { 0 } else { 12 } {
            let plan = problem.cache.sample(SamplerKind::Optimized, &nb, &mut || rng.next_f32());
            let d = plan.draws()[0];
            feedback.extend(plan.feedback(0, scene.contribution(d.vpl as usize, x.position, x.normal)));
        }
        fast.add(&feedback);
        slow.add(&feedback);
        let a = problem.cache.optimize_pass(&mut fast);
        let b = reference.optimize_history(&slow);
        assert_eq!(problem.cache.params(), reference.params(), "pass {pass}");
        assert_eq!((a.stepped, a.kept), (b.stepped, b.kept), "pass {pass}");
        (stepped, kept) = (stepped + a.stepped, kept + a.kept);
    }
    assert!(stepped >= 5 && kept >= 5, "{stepped} steps, {kept} kept: both cases occur");
}
