//! Every sampler's estimator against the exhaustive VPL sum: a z-test per shading point
//! and colour channel over many independent estimates, tolerance from the sample
//! variance.

use super::super::*;
use super::{mean_and_error, surface_points, toy_cache, ToyScene};
use filtrace_core::rng::SplitMix64;
use filtrace_core::Rgb;

/// |mean − exact| may reach this many standard errors: 5 samplers × 4 settings × 6
/// points × 3 channels = 360 tests, Šidák at 1 % gives 4.3σ; 4.5σ leaves room for the
/// heavy tails of 1/q weights.
const Z_MAX: f64 = 4.5;

/// Runs `samples` estimates of `kind` at each shading point and z-tests them.
fn check_unbiased(scene: &ToyScene, cache: &ImportanceCache, kind: SamplerKind, samples: usize, seed: u64) {
    let mut rng = SplitMix64::new(seed);
    for (i, x) in surface_points(6, 1234).into_iter().enumerate() {
        let exact = scene.exact(x.position, x.normal);
        let nb = cache.neighbours(x.position, x.normal);
        let mut channels: [Vec<f64>; 3] = Default::default();
        for _ in 0..samples {
            let plan = cache.sample(kind, &nb, &mut || rng.next_f32());
            let e: Rgb = plan.estimate(|j| scene.contribution(j, x.position, x.normal));
            for (c, v) in channels.iter_mut().zip(e.to_array()) {
                c.push(v as f64);
            }
        }
        for (c, values) in channels.iter().enumerate() {
            let (mean, error) = mean_and_error(values);
            let z = (mean - exact[c]) / error.max(1e-12 * exact[c].abs().max(1e-30));
            assert!(
                z.abs() < Z_MAX || (mean - exact[c]).abs() <= 1e-5 * exact[c].abs(),
                "{} point {i} channel {c}: mean {mean:.6} vs exact {:.6} (z = {z:.2}, se {error:.2e})",
                kind.name(),
                exact[c]
            );
        }
    }
}

/// A few frames of the `optimized` loop so its parameters are far from the prior.
fn optimise(scene: &ToyScene, cache: &mut ImportanceCache, frames: usize) {
    let mut rng = SplitMix64::new(31);
    let points = surface_points(600, 77);
    for _ in 0..frames {
        let mut feedback = Vec::new();
        for x in &points {
            let nb = cache.neighbours(x.position, x.normal);
            let plan = cache.sample(SamplerKind::Optimized, &nb, &mut || rng.next_f32());
            for (i, d) in plan.draws().iter().enumerate() {
                feedback.extend(plan.feedback(i, scene.contribution(d.vpl as usize, x.position, x.normal)));
            }
        }
        cache.optimize(&feedback);
    }
}

/// Faint VPLs that are in fact occluded, over the cache's records: those whose E¹ the
/// faint share makes wrong.
fn occluded_faint_vpls(scene: &ToyScene, cache: &ImportanceCache, share: f32) -> usize {
    let mut wrong = 0;
    for r in cache.records() {
        let (x, n) = (r.point.position, r.point.normal);
        let lums: Vec<f32> =
            (0..scene.vpls.len()).map(|j| filtrace_core::luminance(scene.unoccluded_at(j, x, n))).collect();
        let cut = FaintCut::new(&lums, share);
        wrong += (0..lums.len()).filter(|&j| cut.is_faint(lums[j]) && !scene.visible_at(j, x)).count();
    }
    wrong
}

#[test]
fn every_sampler_is_unbiased() {
    let scene = ToyScene::new(64, 3);
    let settings = [
        CacheParams::default(),
        CacheParams { neighbours: 1, distributions: DistributionSet::thesis(), ..CacheParams::default() },
        CacheParams { neighbours: 3, distributions: DistributionSet::first(1), ..CacheParams::default() },
        // A tenth of each record's light from VPLs taken as visible without a ray.
        CacheParams { faint_share: 0.1, ..CacheParams::default() },
    ];
    for (s, config) in settings.iter().enumerate() {
        let mut cache = toy_cache(&scene, 24, config);
        if config.faint_share >= 0.1 {
            let wrong = occluded_faint_vpls(&scene, &cache, config.faint_share);
            assert!(wrong > 10, "setting {s}: {wrong} occluded VPLs taken as visible, the test has power");
        }
        optimise(&scene, &mut cache, 3);
        assert!(cache.params().iter().any(|p| *p != RecordParams::prior(config)), "the optimiser moved");
        for kind in SamplerKind::ALL {
            check_unbiased(&scene, &cache, kind, 20_000, 100 * s as u64 + kind as u64);
        }
    }
}

/// The control variates pay off where the cache predicts well: at a record itself
/// (interpolation weight 1), balance-cv's variance is below balance's.
#[test]
fn control_variates_reduce_variance_at_a_record() {
    let scene = ToyScene::new(64, 4);
    let config = CacheParams::default();
    let cache = toy_cache(&scene, 24, &config);
    let mut rng = SplitMix64::new(8);
    let (mut var_balance, mut var_cv) = (0.0, 0.0);
    for r in cache.records().iter().take(8) {
        let (x, n) = (r.point.position, r.point.normal);
        let nb = cache.neighbours(x, n);
        for (kind, var) in [(SamplerKind::Balance, &mut var_balance), (SamplerKind::BalanceCv, &mut var_cv)] {
            let values: Vec<f64> = (0..4000)
                .map(|_| {
                    let plan = cache.sample(kind, &nb, &mut || rng.next_f32());
                    filtrace_core::luminance(plan.estimate(|j| scene.contribution(j, x, n))) as f64
                })
                .collect();
            let (_, se) = mean_and_error(&values);
            *var += se * se * values.len() as f64;
        }
    }
    assert!(var_cv < var_balance, "balance-cv variance {var_cv:.3e} vs balance {var_balance:.3e}");
}
