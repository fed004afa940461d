//! Nearest-record search against brute force.

use super::super::*;
use filtrace_core::cpu::Isa;
use filtrace_core::rng::SplitMix64;
use filtrace_core::Vec3;

/// Point sets that stress the tree: uniform, clustered on two planes, with duplicates.
fn point_set(kind: usize, n: usize, rng: &mut SplitMix64) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut positions = Vec::with_capacity(n);
    let mut normals = Vec::with_capacity(n);
    for i in 0..n {
        let (p, nrm) = match kind {
            0 => (
                Vec3::new(rng.range(-5.0, 5.0), rng.range(-5.0, 5.0), rng.range(-5.0, 5.0)),
                rng.unit_vector(),
            ),
            1 if i % 2 == 0 => (Vec3::new(rng.range(0.0, 1.0), 0.0, rng.range(0.0, 1.0)), Vec3::Y),
            1 => (
                Vec3::new(rng.range(0.0, 1.0), rng.range(0.0, 1.0), 0.0),
                if i % 4 == 1 { Vec3::Z } else { -Vec3::Z },
            ),
            _ if i % 3 == 0 && i > 0 => (positions[i - 1], normals[i - 1]),
            _ => {
                (Vec3::new(rng.range(0.0, 2.0), rng.range(0.0, 0.01), rng.range(0.0, 2.0)), rng.unit_vector())
            }
        };
        positions.push(p);
        normals.push(nrm);
    }
    (positions, normals)
}

/// Exact: the same `(distance, index)` bits as brute force, with the baseline and the
/// AVX2 lane code, on uniform, clustered and duplicated points.
#[test]
fn kd_tree_matches_brute_force() {
    let mut rng = SplitMix64::new(0x5eed);
    for kind in 0..3 {
        for &n in &[1usize, 2, 7, 9, 64, 500] {
            for &lambda in &[0.0f32, 0.3, 5.0] {
                let (positions, normals) = point_set(kind, n, &mut rng);
                let tree = KdTree::new(&positions, &normals, lambda);
                for _ in 0..60 {
                    let q = Vec3::new(rng.range(-1.0, 3.0), rng.range(-1.0, 3.0), rng.range(-1.0, 3.0));
                    let qn = rng.unit_vector();
                    for k in 1..=MAX_NEIGHBOURS + 1 {
                        let slow = tree.nearest_brute_force(q, qn, k);
                        // Every lane-code level this CPU runs: the same bits.
                        for level in Isa::supported() {
                            let fast = tree.nearest_with(level, q, qn, k);
                            assert_eq!(
                                fast.as_slice(),
                                &slow[..],
                                "kind {kind}, n {n}, lambda {lambda}, k {k}, {level:?}"
                            );
                        }
                    }
                }
            }
        }
    }
}

/// The warm start (each thread's previous result seeds the next query) changes nothing:
/// coherent queries along a path, alternating between two trees over the same indices
/// (whose previous results must not leak into each other), and on two threads, all
/// equal brute force.
#[test]
fn warm_started_queries_match_brute_force() {
    let mut rng = SplitMix64::new(0xa11);
    let (pa, na) = point_set(0, 500, &mut rng);
    let (pb, nb) = point_set(2, 500, &mut rng);
    let trees = [KdTree::new(&pa, &na, 0.3), KdTree::new(&pb, &nb, 0.3)];
    let walk = |start: f32| {
        for s in 0..400 {
            let t = start + s as f32 * 0.01;
            let q = Vec3::new(t.sin() * 3.0, t * 0.5 - 1.0, t.cos() * 2.0);
            let qn = Vec3::new(t.cos(), 0.5, t.sin()).normalize();
            let tree = &trees[s % 2 + (s % 7 == 0) as usize * (1 - s % 2)];
            for k in [3, 5, 1] {
                let fast = tree.nearest(q, qn, k);
                assert_eq!(fast.as_slice(), &tree.nearest_brute_force(q, qn, k)[..], "step {s}, k {k}");
            }
        }
    };
    std::thread::scope(|scope| {
        scope.spawn(|| walk(0.0));
        scope.spawn(|| walk(1.7));
    });
}

#[test]
fn search_handles_empty_sets_and_bad_queries() {
    let tree = KdTree::new(&[], &[], 1.0);
    assert!(tree.nearest(Vec3::ZERO, Vec3::Y, 3).as_slice().is_empty());
    let tree = KdTree::new(&[Vec3::ONE], &[Vec3::ZERO], 1.0);
    assert!(tree.nearest(Vec3::splat(f32::NAN), Vec3::Y, 3).as_slice().is_empty());
    // A zero normal counts as +z, on both sides.
    let hit = tree.nearest(Vec3::ONE, Vec3::ZERO, 1);
    assert_eq!(hit.as_slice(), &[(0.0, 0)]);
}

#[test]
fn distance_is_georgievs_metric() {
    let d = cache_distance(Vec3::ZERO, Vec3::Y, Vec3::new(3.0, 4.0, 0.0), Vec3::X, 2.0);
    assert!((d - (5.0 + 2.0)).abs() < 1e-6);
    // Opposite normals: sqrt(2) λ.
    let d = cache_distance(Vec3::ZERO, Vec3::Y, Vec3::ZERO, -Vec3::Y, 1.0);
    assert!((d - 2f32.sqrt()).abs() < 1e-6);
}

#[test]
fn neighbour_weights_sum_to_one_and_fall_with_distance() {
    let mut rng = SplitMix64::new(11);
    let (positions, normals) = point_set(0, 200, &mut rng);
    let tree = KdTree::new(&positions, &normals, 1.0);
    for m in 1..=MAX_NEIGHBOURS {
        for _ in 0..50 {
            let nearest = tree.nearest(rng.unit_vector() * 3.0, rng.unit_vector(), m + 1);
            let nb = Neighbours::from_nearest(nearest.as_slice(), m);
            assert_eq!(nb.len(), m);
            let w: Vec<f32> = nb.iter().map(|(_, w)| w).collect();
            assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-5, "{w:?}");
            assert!(w.windows(2).all(|p| p[0] >= p[1]), "nearer records weigh more: {w:?}");
            assert_eq!(nb.closest_distance(), Some(nearest.as_slice()[0].0));
        }
    }
    // Ties with the (M+1)-th: equal weights rather than 0/0.
    let nb = Neighbours::from_nearest(&[(1.0, 4), (1.0, 5), (1.0, 6)], 2);
    assert_eq!(nb.iter().collect::<Vec<_>>(), vec![(4, 0.5), (5, 0.5)]);
}

/// The interpolation weight of a record goes to 0 as it leaves the M nearest (M >= 2):
/// the interpolated distributions change continuously along a path.
#[test]
fn weights_are_continuous_along_a_path() {
    let positions: Vec<Vec3> = (0..6).map(|i| Vec3::new(i as f32, 0.0, 0.0)).collect();
    let normals = vec![Vec3::Y; 6];
    let tree = KdTree::new(&positions, &normals, 1.0);
    let weights_at = |x: f32| {
        let nb = Neighbours::from_nearest(tree.nearest(Vec3::new(x, 0.0, 0.3), Vec3::Y, 3).as_slice(), 2);
        let mut w = [0.0f32; 6];
        nb.iter().for_each(|(l, v)| w[l] = v);
        w
    };
    let mut prev = weights_at(0.0);
    for step in 1..=5000 {
        let w = weights_at(step as f32 * 0.001);
        let jump = w.iter().zip(&prev).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
        assert!(jump < 0.01, "weights jump by {jump} at x = {}", step as f32 * 0.001);
        prev = w;
    }
}
