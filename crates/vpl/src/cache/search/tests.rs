//! The four-wide tree against brute force on the sets that shape it oddly: a handful of
//! points (nodes with two or three children), every point at one place or with one
//! normal, exact ties, and sets large enough for several levels.

use super::*;
use filtrace_core::rng::SplitMix64;

/// Positions and normals.
type PointSet = (Vec<Vec3>, Vec<Vec3>);

/// Every `k` and every lane-code level this CPU runs: the brute-force bits.
fn assert_exact(tree: &KdTree, q: Vec3, qn: Vec3, what: &str) {
    for k in 1..=MAX_NEIGHBOURS + 1 {
        let slow = tree.nearest_brute_force(q, qn, k);
        for level in Isa::supported() {
            let fast = tree.nearest_with(level, q, qn, k);
            assert_eq!(fast.as_slice(), &slow[..], "{what}, k {k}, {level:?}");
        }
    }
}

/// Every point in exactly one leaf, every child inside its box, unused slots empty.
fn assert_well_formed(tree: &KdTree) {
    let mut seen = vec![0u32; tree.len()];
    for leaf in &tree.leaves {
        let len = leaf.lanes.count_ones();
        assert!((1..=LEAF_SIZE as u32).contains(&len) && leaf.lanes == (1 << len) - 1);
        leaf.ids[..len as usize].iter().for_each(|&i| seen[i as usize] += 1);
    }
    assert!(seen.iter().all(|&s| s == 1), "each point in one leaf");
    for node in &tree.inner {
        let count = node.used.count_ones();
        assert!((2..=WIDTH as u32).contains(&count) && node.used == (1 << count) - 1);
        for c in count as usize..WIDTH {
            assert_eq!(node.children[c], EMPTY);
            assert!(node.lo.iter().all(|row| row[c] == f32::INFINITY));
        }
    }
}

#[test]
fn small_sets_give_nodes_of_two_to_four_children() {
    let mut rng = SplitMix64::new(0x4a1d);
    for n in 1..=40 {
        let positions: Vec<Vec3> = (0..n).map(|_| rng.unit_vector() * rng.range(0.0, 2.0)).collect();
        let normals: Vec<Vec3> = (0..n).map(|_| rng.unit_vector()).collect();
        let tree = KdTree::new(&positions, &normals, 0.7);
        assert_well_formed(&tree);
        for _ in 0..20 {
            assert_exact(&tree, rng.unit_vector() * 2.0, rng.unit_vector(), &format!("n {n}"));
        }
    }
}

#[test]
fn degenerate_sets_match_brute_force() {
    let mut rng = SplitMix64::new(0xd06e);
    let n = 100;
    let one_point = (vec![Vec3::new(0.5, -1.0, 2.0); n], (0..n).map(|_| rng.unit_vector()).collect());
    let one_normal = ((0..n).map(|_| rng.unit_vector() * 3.0).collect(), vec![Vec3::Y; n]);
    let everything_equal = (vec![Vec3::ONE; n], vec![Vec3::X; n]);
    let fewer_than_m = (vec![Vec3::ZERO, Vec3::X], vec![Vec3::Y, Vec3::Y]);
    let sets: [(&str, PointSet); 4] = [
        ("one point", one_point),
        ("one normal", one_normal),
        ("all equal", everything_equal),
        ("fewer than M", fewer_than_m),
    ];
    for (what, (positions, normals)) in sets {
        for lambda in [0.0, 0.4, 30.0] {
            let tree = KdTree::new(&positions, &normals, lambda);
            assert_well_formed(&tree);
            assert_exact(&tree, Vec3::ONE, Vec3::X, what);
            assert_exact(&tree, Vec3::new(0.5, -1.0, 2.0), Vec3::Y, what);
            for _ in 0..30 {
                assert_exact(&tree, rng.unit_vector() * 3.0, rng.unit_vector(), what);
            }
        }
    }
}

/// Points at exactly equal distances from the queries (a lattice around them, repeated
/// points): ties go by index, as in the sorted brute force.
#[test]
fn ties_go_by_index() {
    let mut positions = Vec::new();
    for x in -3..=3 {
        for z in -3..=3 {
            positions.push(Vec3::new(x as f32, 0.0, z as f32));
        }
    }
    positions.extend_from_within(..);
    let normals = vec![Vec3::Y; positions.len()];
    let tree = KdTree::new(&positions, &normals, 1.0);
    assert_well_formed(&tree);
    for x in -3..=3 {
        for z in -3..=3 {
            assert_exact(&tree, Vec3::new(x as f32, 0.0, z as f32), Vec3::Y, "on a point");
            assert_exact(&tree, Vec3::new(x as f32 + 0.5, 0.0, z as f32 + 0.5), Vec3::Y, "between four");
        }
    }
}

/// Thousands of points on the planes of a box, as records on a scene's walls: several
/// levels of four-wide nodes, queried along a path (warm starts) and at random.
#[test]
fn deep_trees_match_brute_force() {
    let mut rng = SplitMix64::new(0xdee9);
    let walls = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
    let point_on_wall = |w: usize, rng: &mut SplitMix64| {
        let n = walls[w];
        let p = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        (p - n * p.dot(n) - n, n)
    };
    let (positions, normals): (Vec<Vec3>, Vec<Vec3>) =
        (0..3000).map(|i| point_on_wall(i % 6, &mut rng)).unzip();
    let tree = KdTree::new(&positions, &normals, 0.5 * 12f32.sqrt());
    assert_well_formed(&tree);
    for s in 0..300 {
        let (q, qn) = if s % 3 == 0 {
            (rng.unit_vector() * 1.5, rng.unit_vector())
        } else {
            point_on_wall(s % 6, &mut rng)
        };
        assert_exact(&tree, q, qn, &format!("query {s}"));
    }
}
