//! Batch schedule: scan, sample-to-pixel map, every sample once, race-free accumulation.

use filtrace_adaptive::{
    exclusive_scan, exclusive_scan_parallel, AdaptiveError, BatchSchedule, SampleCounts, Slot,
};
use proptest::prelude::*;

/// All (pixel, sample) pairs in order, by the obvious nested loop.
fn naive_slots(counts: &[u32]) -> Vec<Slot> {
    let mut v = Vec::new();
    for (p, &c) in counts.iter().enumerate() {
        for s in 0..c {
            v.push(Slot { pixel: p as u32, sample: s });
        }
    }
    v
}

fn check_schedule(counts: &[u32], batch: usize) {
    let sched = BatchSchedule::from_counts(counts, batch).unwrap();
    let expected = naive_slots(counts);
    assert_eq!(sched.total_samples(), expected.len() as u64);
    let mut via_iter = Vec::new();
    let mut via_fill = Vec::new();
    let mut buf = vec![Slot::default(); batch];
    let mut sums = vec![0u64; counts.len()];
    for b in sched.batches() {
        assert!(b.len() <= batch && !b.is_empty());
        via_iter.extend(b.slots());
        b.fill_sample_to_pixel(&mut buf);
        via_fill.extend_from_slice(&buf[..b.len()]);
        // Accumulate the value 1 per sample: sums must end equal to the counts.
        let ones = vec![1u64; b.len()];
        b.accumulate(&ones, &mut sums);
    }
    assert_eq!(via_iter, expected, "iterator visits every sample once, in order");
    assert_eq!(via_fill, expected, "parallel fill equals the iterator");
    let want: Vec<u64> = counts.iter().map(|&c| c as u64).collect();
    assert_eq!(sums, want);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]
    #[test]
    fn every_sample_is_visited_once(
        counts in prop::collection::vec(prop_oneof![Just(0u32), 0u32..20], 0..200),
        batch in 1usize..64,
    ) {
        check_schedule(&counts, batch);
    }
}

#[test]
fn resolution_sized_batches_on_an_adaptive_frame() {
    let counts: Vec<u32> = (0..5000u32).map(|i| 1 + (i * 7919 % 13 == 0) as u32 * 30).collect();
    let c = SampleCounts::from_vec(100, 50, counts.clone()).unwrap();
    check_schedule(&counts, filtrace_adaptive::schedule::resolution_batch(&c));
    // A pixel holding more samples than a whole batch spans several batches.
    check_schedule(&[0, 100, 0, 3], 7);
}

#[test]
fn parallel_scan_equals_sequential() {
    let counts: Vec<u32> = (0..300_001u32).map(|i| i.wrapping_mul(2654435761) % 17).collect();
    assert_eq!(exclusive_scan_parallel(&counts), exclusive_scan(&counts));
    assert_eq!(exclusive_scan_parallel(&[]), vec![0]);
    assert_eq!(exclusive_scan(&[3, 0, 2]), vec![0, 3, 3, 5]);
}

#[test]
fn float_accumulation_per_pixel_matches_sequential_sum() {
    let counts = [2u32, 0, 5, 1, 9];
    let sched = BatchSchedule::from_counts(&counts, 4).unwrap();
    let mut sums = vec![0.0f64; 5];
    for b in sched.batches() {
        let vals: Vec<f64> = b.slots().map(|s| (s.pixel * 100 + s.sample) as f64).collect();
        b.accumulate(&vals, &mut sums);
    }
    for (p, &c) in counts.iter().enumerate() {
        let want: f64 = (0..c).map(|s| (p as u32 * 100 + s) as f64).sum();
        assert_eq!(sums[p], want);
    }
}

#[test]
fn zero_batch_size_and_empty_frames() {
    assert!(matches!(
        BatchSchedule::from_counts(&[1, 2], 0),
        Err(AdaptiveError::InvalidParameter { name: "batch_size", .. })
    ));
    let s = BatchSchedule::from_counts(&[0, 0, 0], 4).unwrap();
    assert_eq!((s.total_samples(), s.num_batches()), (0, 0));
}
