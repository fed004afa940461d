//! The α-max heuristic against its definition.

use super::super::*;
use filtrace_core::rng::SplitMix64;

const GEORGIEV: [f32; 4] = [1.0, 0.5, 0.5, 0.3];

#[test]
fn owner_matches_the_definition_on_constructed_pdfs() {
    // (pdfs, expected owner) worked out by hand from the definition.
    let cases: [([f32; 4], usize); 6] = [
        // Full beats every later one: it owns x.
        ([0.4, 0.5, 0.6, 0.1], 0),
        // Full too small against 0.5 · unoccluded; unoccluded beats the rest.
        ([0.2, 0.5, 0.6, 0.1], 1),
        // Unoccluded loses to 0.5 · bounded as well: bounded (beats 0.3 · uniform).
        ([0.2, 0.2, 0.6, 0.1], 2),
        // Everything zero but uniform.
        ([0.0, 0.0, 0.0, 0.1], 3),
        // Full exactly at the confidence-weighted max: ties go to the earlier one.
        ([0.3, 0.6, 0.2, 0.1], 0),
        // Full zero and everything else zero but uniform still lets nothing earlier win.
        ([0.0, 0.01, 0.0, 0.1], 3),
    ];
    for (p, owner) in cases {
        assert_eq!(alpha_max_owner(&p, &GEORGIEV), owner, "{p:?}");
        let w: Vec<f32> = (0..4).map(|s| alpha_max_weight(s, &p, &GEORGIEV)).collect();
        let mut expected = [0.0f32; 4];
        expected[owner] = 1.0;
        assert_eq!(w, expected, "{p:?}");
    }
}

#[test]
fn owner_matches_the_definition_on_random_pdfs_and_partitions() {
    let mut rng = SplitMix64::new(42);
    for m in 1..=4 {
        for _ in 0..5000 {
            let mut p: Vec<f32> =
                (0..m).map(|_| if rng.next_f32() < 0.3 { 0.0 } else { rng.next_f32() }).collect();
            p[m - 1] = 0.05 + rng.next_f32(); // the uniform fallback is positive
            let c: Vec<f32> = (0..m).map(|_| 0.05 + 0.95 * rng.next_f32()).collect();
            let owner = alpha_max_owner(&p, &c);
            let weights: Vec<f32> = (0..m).map(|s| alpha_max_weight(s, &p, &c)).collect();
            assert_eq!(weights.iter().sum::<f32>(), 1.0, "a partition of unity: {p:?} {c:?}");
            assert_eq!(weights[owner], 1.0, "{p:?} {c:?}");
            assert!(p[owner] > 0.0, "the owner can sample x: {p:?}");
        }
    }
}

/// All confidences 1: the max heuristic (earliest maximal pdf).
#[test]
fn unit_confidences_give_the_max_heuristic() {
    let mut rng = SplitMix64::new(4);
    for _ in 0..2000 {
        let p: Vec<f32> = (0..4).map(|_| (rng.next_f32() * 8.0).floor()).collect();
        let max = p.iter().cloned().fold(0.0, f32::max);
        let first_max = p.iter().position(|&v| v == max).unwrap();
        assert_eq!(alpha_max_owner(&p, &[1.0; 4]), first_max, "{p:?}");
    }
}
