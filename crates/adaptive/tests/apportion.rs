//! Budget apportionment: exact budget, minimum, monotonicity, fast vs naive, degenerate input.

use filtrace_adaptive::synthetic::grass_gbuffer;
use filtrace_adaptive::{
    apportion, apportion_naive, importance_map, plan_frame, AdaptiveError, AdaptiveParams, ImportanceParams,
    Mode,
};
use filtrace_core::Image;
use proptest::prelude::*;

fn image(v: Vec<f32>) -> Image {
    let n = v.len();
    Image::from_vec(n, 1, 1, v).unwrap()
}

/// Checks every documented invariant of one apportionment.
fn check(imp: &Image, budget: u64, min_spp: u32, mode: Mode) {
    let c = apportion(imp, budget, min_spp, mode).unwrap();
    let n = imp.pixel_count() as u64;
    let total: u64 = c.counts().iter().map(|&x| x as u64).sum();
    assert_eq!(total, c.total());
    match mode {
        Mode::Exact => assert_eq!(total, budget, "exact mode must use the whole budget"),
        Mode::Paper => {
            assert!(total <= budget, "paper mode exceeded the budget: {total} > {budget}");
            assert!(total + n > budget, "paper mode lost {} >= pixels samples", budget - total);
        }
    }
    assert!(c.counts().iter().all(|&x| x >= min_spp), "a pixel got fewer than min_spp");
    // Monotone: sort by importance, counts must not decrease where importance increases.
    let mut idx: Vec<usize> = (0..imp.pixel_count()).collect();
    idx.sort_by(|&a, &b| imp.data()[a].total_cmp(&imp.data()[b]));
    for w in idx.windows(2) {
        let (a, b) = (w[0], w[1]);
        if imp.data()[b] > imp.data()[a] {
            assert!(
                c.counts()[b] >= c.counts()[a],
                "importance {} > {} but {} < {} samples",
                imp.data()[b],
                imp.data()[a],
                c.counts()[b],
                c.counts()[a]
            );
        }
    }
    // The selection-based method equals the sort-based reference.
    assert_eq!(c, apportion_naive(imp, budget, min_spp, mode).unwrap());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]
    #[test]
    fn invariants_hold_for_random_importance(
        v in prop::collection::vec(prop_oneof![Just(0.0f32), Just(0.5f32), 0.0f32..1.0], 1..300),
        min_spp in 0u32..4,
        extra in 0u64..4000,
    ) {
        let n = v.len() as u64;
        let imp = image(v);
        for mode in [Mode::Exact, Mode::Paper] {
            check(&imp, min_spp as u64 * n + extra, min_spp, mode);
        }
    }
}

#[test]
fn invariants_hold_on_a_rendered_importance_map() {
    let (n, p) = grass_gbuffer(160, 120, 80, 11);
    for (_, params) in ImportanceParams::presets() {
        let imp = importance_map(&n, &p, &params).unwrap();
        for (budget_spp, min_spp) in [(4u64, 1u32), (4, 2), (16, 1), (1, 1), (2, 0)] {
            for mode in [Mode::Exact, Mode::Paper] {
                check(&imp, budget_spp * imp.pixel_count() as u64, min_spp, mode);
            }
        }
    }
}

#[test]
fn paper_example_numbers() {
    // s = 12 - 3 = 9, t = 1: quotas 0, 2.25, 6.75 -> floors 0, 2, 6 (8 of 9).
    let imp = image(vec![0.0, 0.25, 0.75]);
    assert_eq!(apportion(&imp, 12, 1, Mode::Paper).unwrap().counts(), &[1, 3, 7]);
    assert_eq!(apportion(&imp, 12, 1, Mode::Exact).unwrap().counts(), &[1, 3, 8]);
}

#[test]
fn budget_below_minimum_is_an_error_and_equal_gives_minimum() {
    let imp = image(vec![0.1, 0.9, 0.3, 0.0]);
    let e = apportion(&imp, 7, 2, Mode::Exact).unwrap_err();
    assert_eq!(e, AdaptiveError::BudgetBelowMinimum { budget: 7, min_spp: 2, pixels: 4 });
    assert!(e.to_string().contains("below the minimum"));
    assert_eq!(apportion(&imp, 8, 2, Mode::Exact).unwrap().counts(), &[2; 4]);
}

#[test]
fn all_equal_importance_is_uniform_and_spread() {
    for v in [0.0f32, 0.3, 1.0] {
        let imp = Image::filled(64, 64, 1, v);
        let budget = 4 * 4096 + 1000; // 1000 leftover samples
        let c = apportion(&imp, budget, 1, Mode::Exact).unwrap();
        assert_eq!(c.total(), budget);
        assert_eq!((c.min(), c.max()), (4, 5));
        // The 1000 extra samples are spread over the frame, not packed in the top rows:
        // each quarter of the rows gets 250 ± 60 of them.
        for q in 0..4 {
            let extra: u32 = c.counts()[q * 1024..(q + 1) * 1024].iter().map(|&x| x - 4).sum();
            assert!((190..=310).contains(&extra), "quarter {q} got {extra} of 1000");
        }
        let p = apportion(&imp, budget, 1, Mode::Paper).unwrap();
        assert_eq!(p.counts(), &[4; 4096][..]);
    }
}

#[test]
fn one_pixel_gets_the_whole_budget() {
    for v in [0.0, 0.7] {
        for mode in [Mode::Exact, Mode::Paper] {
            assert_eq!(apportion(&image(vec![v]), 13, 2, mode).unwrap().counts(), &[13]);
        }
    }
}

#[test]
fn invalid_importance_is_an_error() {
    for bad in [f32::NAN, f32::INFINITY, -0.1] {
        let e = apportion(&image(vec![0.5, bad, 0.1]), 30, 1, Mode::Exact).unwrap_err();
        assert!(matches!(e, AdaptiveError::InvalidImportance { pixel: 1, .. }), "{e}");
    }
    assert!(matches!(
        apportion(&Image::new(2, 2, 3), 30, 1, Mode::Exact),
        Err(AdaptiveError::Channels { .. })
    ));
    assert_eq!(apportion(&Image::new(0, 3, 1), 30, 1, Mode::Exact), Err(AdaptiveError::EmptyImage));
    assert_eq!(
        apportion(&image(vec![1.0]), u32::MAX as u64 + 10, 0, Mode::Exact),
        Err(AdaptiveError::Overflow)
    );
}

#[test]
fn deterministic_and_thread_count_independent() {
    let (n, p) = grass_gbuffer(128, 96, 50, 5);
    let params = AdaptiveParams::paper();
    let (imp_a, a) = plan_frame(&n, &p, &params).unwrap();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let (imp_b, b) = pool.install(|| plan_frame(&n, &p, &params).unwrap());
    assert_eq!(imp_a, imp_b);
    assert_eq!(a, b);
    assert_eq!(a.total(), 4 * 128 * 96);
}

/// Zero-normal background pixels get importance 0 and hence exactly `min_spp`
/// (documented: the pipeline may skip them).
#[test]
fn background_gets_the_minimum() {
    let (n, p) = grass_gbuffer(64, 64, 20, 2);
    let (_, c) = plan_frame(&n, &p, &AdaptiveParams::paper()).unwrap();
    let mut sky = 0;
    for y in 0..64 {
        for x in 0..64 {
            if n.rgb(x, y) == filtrace_core::Vec3::ZERO {
                sky += 1;
                assert_eq!(c.counts()[y * 64 + x], 1, "sky pixel ({x},{y})");
            }
        }
    }
    assert!(sky > 300, "only {sky} sky pixels");
}
