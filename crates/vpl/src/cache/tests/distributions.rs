//! Chi-square tests: each record's CDF sampling against its pmf, and the one-sample
//! mixture sampler against the pdf it reports.

use super::super::*;
use super::{toy_cache, ToyScene};
use filtrace_core::rng::SplitMix64;
use filtrace_core::stats::{chi2_sf, chi2_statistic, sidak};

const VPLS: usize = 64;
const DRAWS: usize = 40_000;

/// Pearson's test of `counts` against `expected` (both per VPL); true when it passes at
/// the Šidák-corrected level of a family of `tests`.
fn chi2_passes(counts: &[f64], expected: &[f64], tests: usize) -> Result<f64, String> {
    let (stat, dof) = chi2_statistic(counts, expected, 5.0)?;
    let p = chi2_sf(stat, dof as f64);
    if p > sidak(0.01, tests) {
        Ok(p)
    } else {
        Err(format!("chi2 {stat:.1}, dof {dof}, p {p:.2e}"))
    }
}

#[test]
fn each_distribution_samples_its_pmf() {
    let scene = ToyScene::new(VPLS, 21);
    let cache = toy_cache(&scene, 8, &CacheParams::default());
    let tests = cache.records().len() * TECHNIQUES;
    let mut rng = SplitMix64::new(77);
    for (i, record) in cache.records().iter().enumerate() {
        for t in Technique::ALL {
            let pmf_sum: f64 = (0..VPLS).map(|j| record.pmf(t, j) as f64).sum();
            assert!((pmf_sum - 1.0).abs() < 1e-5, "record {i} {}: pmf sums to {pmf_sum}", t.name());
            let mut counts = vec![0.0f64; VPLS];
            for _ in 0..DRAWS {
                counts[record.sample(t, rng.next_f32())] += 1.0;
            }
            let expected: Vec<f64> = (0..VPLS).map(|j| record.pmf(t, j) as f64 * DRAWS as f64).collect();
            if let Err(e) = chi2_passes(&counts, &expected, tests) {
                panic!("record {i}, distribution {}: {e}", t.name());
            }
        }
    }
}

/// The three non-uniform tables are the toy scene's values: E¹ = E² · V (E² for the
/// faint VPLs, taken as visible) and E³ ≥ E² (the relaxed geometry term bounds the exact
/// one at the record itself, for VPLs farther than twice the radius: closer ones meet the
/// bound's clamp); with and without a faint share.
#[test]
fn distributions_hold_the_scene_values() {
    let scene = ToyScene::new(VPLS, 22);
    for faint_share in [0.0, 0.02, 0.2] {
        check_scene_values(&scene, faint_share);
    }
}

fn check_scene_values(scene: &ToyScene, faint_share: f32) {
    let cache = toy_cache(scene, 6, &CacheParams { faint_share, ..CacheParams::default() });
    for r in cache.records() {
        let (x, n) = (r.point.position, r.point.normal);
        let full = r.distribution(Technique::Full).unwrap();
        let unocc = r.distribution(Technique::Unoccluded).unwrap();
        let bounded = r.distribution(Technique::Bounded).unwrap();
        let lums: Vec<f32> =
            (0..VPLS).map(|j| filtrace_core::luminance(scene.unoccluded_at(j, x, n))).collect();
        let cut = FaintCut::new(&lums, faint_share);
        for (j, &e2) in lums.iter().enumerate() {
            let visible = cut.is_faint(e2) || scene.visible_at(j, x);
            let e1 = if visible { e2 } else { 0.0 };
            let share = |d: &VplCdf, v: f32| d.pmf(j) * d.total() - v;
            assert!(share(full, e1).abs() <= 1e-4 * full.total(), "E1 of VPL {j}, faint share {faint_share}");
            assert!(share(unocc, e2).abs() <= 1e-4 * unocc.total(), "E2 of VPL {j}");
            if (scene.vpls[j].position - x).length() > 2.0 * r.radius {
                assert!(
                    bounded.pmf(j) * bounded.total() >= e2 - 1e-4 * bounded.total(),
                    "E3 >= E2 for VPL {j}"
                );
            }
        }
    }
}

/// The one-sample sampler draws VPL j with the probability q(j) it reports, for the fixed
/// and the optimised mixtures, and q(j) is Σ_l w_l Σ_k α_lk p_lk(j).
#[test]
fn mixture_sampler_draws_its_reported_pdf() {
    let scene = ToyScene::new(VPLS, 23);
    let config = CacheParams { neighbours: 3, ..CacheParams::default() };
    let mut cache = toy_cache(&scene, 16, &config);
    // Non-uniform optimised parameters, so the records' mixtures differ.
    let mut params = cache.params().to_vec();
    for (i, p) in params.iter_mut().enumerate() {
        p.alpha = [0.1 + 0.05 * (i % 5) as f32, 0.3, 0.1, 0.1];
    }
    cache.set_params(params).unwrap();
    let x = super::surface_points(1, 99)[0];
    let nb = cache.neighbours(x.position, x.normal);
    assert_eq!(nb.len(), 3);
    let mut rng = SplitMix64::new(5);
    for kind in [SamplerKind::Balance, SamplerKind::Optimized] {
        let mixture = |l: usize| {
            if kind == SamplerKind::Optimized {
                cache.params()[l].mixture()
            } else {
                config.prior_mixture()
            }
        };
        let q: Vec<f64> = (0..VPLS)
            .map(|j| {
                nb.iter()
                    .map(|(l, w)| {
                        let a = mixture(l);
                        Technique::ALL
                            .iter()
                            .map(|&t| (w * a[t as usize] * cache.records()[l].pmf(t, j)) as f64)
                            .sum::<f64>()
                    })
                    .sum()
            })
            .collect();
        let mut counts = vec![0.0f64; VPLS];
        for _ in 0..DRAWS {
            let plan = cache.sample(kind, &nb, &mut || rng.next_f32());
            let d = plan.draws()[0];
            assert!((d.pdf as f64 - q[d.vpl as usize]).abs() <= 1e-5 * q[d.vpl as usize], "reported pdf");
            counts[d.vpl as usize] += 1.0;
        }
        let expected: Vec<f64> = q.iter().map(|p| p * DRAWS as f64).collect();
        chi2_passes(&counts, &expected, 2).unwrap_or_else(|e| panic!("{}: {e}", kind.name()));
    }
}
