//! The samplers' fast paths against the straightforward code they replaced: the same
//! draws, weights and offsets bit for bit for the same uniform numbers.

use super::super::*;
use super::{surface_points, toy_cache, ToyScene};
use filtrace_core::rng::SplitMix64;
use filtrace_core::Rgb;

/// α-max as first written: every draw reads all M × m pmfs, then `alpha_max_owner`.
/// Also whether a VPL was drawn twice (the fast path reads its pmfs once).
fn alpha_max_reference(
    cache: &ImportanceCache,
    nb: &Neighbours,
    next: &mut impl FnMut() -> f32,
) -> (Vec<(u32, u32)>, bool) {
    let config = cache.config();
    let techniques: Vec<Technique> = config.distributions.techniques().collect();
    let confidences: Vec<f32> = techniques.iter().map(|&t| config.confidences[t as usize]).collect();
    let (mut draws, mut drawn) = (Vec::new(), Vec::new());
    for (own, &t) in techniques.iter().enumerate() {
        let (u, mut acc, mut l) = (next(), 0.0f32, nb.iter().next().map_or(0, |(l, _)| l));
        for (slot, w) in nb.iter() {
            l = slot;
            acc += w;
            if u < acc {
                break;
            }
        }
        let j = cache.records()[l].sample(t, next());
        drawn.push(j);
        let pmfs: Vec<f32> = techniques
            .iter()
            .map(|&ti| nb.iter().map(|(l, w)| w * cache.records()[l].pmf(ti, j)).sum())
            .collect();
        if alpha_max_owner(&pmfs, &confidences) == own && pmfs[own] > 0.0 {
            draws.push((j as u32, (1.0 / pmfs[own]).to_bits()));
        }
    }
    let twice = (1..drawn.len()).any(|k| drawn[..k].contains(&drawn[k]));
    (draws, twice)
}

/// The cache with every third record rebuilt over only its first `n` VPLs (a uniform
/// pmf that is not the same at every VPL: a neighbour's `P_4(j)` falls to 0 above `n`).
fn with_short_records(mut cache: ImportanceCache, scene: &ToyScene, n: usize) -> ImportanceCache {
    for (i, r) in cache.records.iter_mut().enumerate().filter(|(i, _)| i % 3 == 0) {
        let region = Region { radius: r.radius, normal_cone: r.normal_cone };
        let mut values = RecordValues::default();
        scene.evaluate_record(&r.point, &region, cache.config.faint_share, &mut values);
        for list in [&mut values.full, &mut values.unoccluded, &mut values.bounded] {
            list.truncate(n);
        }
        *r = CacheRecord::new(r.point, r.radius, r.normal_cone, &values);
        assert_eq!(r.vpl_count(), n, "record {i}");
    }
    cache
}

fn bits(draws: &[VplDraw]) -> Vec<(u32, u32)> {
    draws.iter().map(|d| (d.vpl, d.weight.to_bits())).collect()
}

/// The one-pass α-max (all draws, then one pmf table per distinct VPL) keeps exactly
/// the draws and weights of the full evaluation one draw at a time, for every set of
/// distributions, M and confidences that make owners change often, with VPLs drawn
/// twice and with records that cover fewer VPLs than their neighbours.
#[test]
fn alpha_max_matches_the_full_pmf_evaluation() {
    let scene = ToyScene::new(96, 5);
    let configs = [
        CacheParams::default(),
        CacheParams { neighbours: 4, confidences: [0.9, 1.0, 0.7, 1.0], ..CacheParams::default() },
        CacheParams { neighbours: 1, distributions: DistributionSet::thesis(), ..CacheParams::default() },
        CacheParams { neighbours: 3, distributions: DistributionSet::first(2), ..CacheParams::default() },
        CacheParams { neighbours: 3, ..CacheParams::default() },
    ];
    let (mut kept, mut twice) = (0, 0);
    for (c, config) in configs.iter().enumerate() {
        let cache = toy_cache(&scene, 30, config);
        let cache = if c == 4 { with_short_records(cache, &scene, 70) } else { cache };
        let mut rng = SplitMix64::new(c as u64);
        for x in surface_points(300, 11 + c as u64) {
            let nb = cache.neighbours(x.position, x.normal);
            let us: Vec<f32> = (0..2 * TECHNIQUES).map(|_| rng.next_f32()).collect();
            let (mut a, mut b) = (us.iter().copied(), us.iter().copied());
            let plan = cache.sample(SamplerKind::AlphaMax, &nb, &mut || a.next().unwrap_or(0.5));
            let (reference, drawn_twice) = alpha_max_reference(&cache, &nb, &mut || b.next().unwrap_or(0.5));
            assert_eq!(bits(plan.draws()), reference, "config {c}, point {x:?}");
            kept += reference.len();
            twice += drawn_twice as usize;
        }
    }
    assert!(kept > 300 && twice > 30, "draws were kept ({kept}), VPLs drawn twice ({twice})");
}

/// The one-sample balance heuristic as first written: `(draw, weight, offset)` bits.
fn one_sample_reference(
    cache: &ImportanceCache,
    nb: &Neighbours,
    optimized: bool,
    cv: bool,
    next: &mut impl FnMut() -> f32,
) -> (u32, u32, [u32; 3]) {
    let config = cache.config();
    let prior = (config.prior_mixture(), super::super::optimize::prior_beta(&config.distributions));
    let weights = |l: usize| {
        if optimized {
            (cache.params()[l].mixture(), cache.params()[l].beta)
        } else {
            prior
        }
    };
    let u = next();
    let (mut acc, mut chosen) = (0.0f32, None);
    'pick: for (l, w) in nb.iter() {
        for t in config.distributions.techniques() {
            let pk = w * weights(l).0[t as usize];
            if pk > 0.0 {
                chosen = Some((l, t));
                acc += pk;
                if u < acc {
                    break 'pick;
                }
            }
        }
    }
    let (l, t) = chosen.expect("a positive mixture");
    let j = cache.records()[l].sample(t, next());
    let (mut pdf, mut h, mut c) = (0.0f32, Rgb::ZERO, Rgb::ZERO);
    for (l, w) in nb.iter() {
        let (r, (alpha, beta)) = (&cache.records()[l], weights(l));
        for t in config.distributions.techniques() {
            let (k, p) = (t as usize, r.pmf(t, j));
            pdf += w * alpha[k] * p;
            if cv {
                h += (w * beta[k] * p) * r.total(t);
                c += (w * beta[k]) * r.total(t);
            }
        }
    }
    let weight = 1.0 / pdf;
    (j as u32, weight.to_bits(), (c - h * weight).to_array().map(f32::to_bits))
}

/// `balance`, `balance-cv` and `optimized` draw the same VPL with the same weight and
/// offset as the straightforward code, bit for bit (optimised parameters included).
#[test]
fn one_sample_samplers_match_the_straightforward_code() {
    let scene = ToyScene::new(96, 6);
    let config = CacheParams { neighbours: 3, ..CacheParams::default() };
    let mut cache = toy_cache(&scene, 30, &config);
    // Parameters away from the prior: blend each record's with a skewed mixture.
    let params: Vec<RecordParams> = cache
        .params()
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let mut q = *p;
            q.alpha[i % TECHNIQUES] *= 3.0;
            q.beta = [0.7, 0.2 * (i % 3) as f32, -0.1, 0.05];
            q
        })
        .collect();
    cache.set_params(params).expect("one per record");
    let mut rng = SplitMix64::new(17);
    for (kind, optimized, cv) in [
        (SamplerKind::Balance, false, false),
        (SamplerKind::BalanceCv, false, true),
        (SamplerKind::Optimized, true, true),
    ] {
        for x in surface_points(300, 23) {
            let nb = cache.neighbours(x.position, x.normal);
            let us = [rng.next_f32(), rng.next_f32()];
            let (mut a, mut b) = (us.iter().copied(), us.iter().copied());
            let plan = cache.sample(kind, &nb, &mut || a.next().unwrap_or(0.5));
            let reference = one_sample_reference(&cache, &nb, optimized, cv, &mut || b.next().unwrap_or(0.5));
            let d = plan.draws()[0];
            let got = (d.vpl, d.weight.to_bits(), plan.offset.to_array().map(f32::to_bits));
            assert_eq!(got, reference, "{kind:?} at {x:?}");
        }
    }
}
