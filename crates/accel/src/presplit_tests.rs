use super::*;
use crate::testmesh::{self, SplitMix64};

fn random_point(rng: &mut SplitMix64, b: &Aabb) -> Vec3 {
    b.min + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * b.extent()
}

/// A point of `tri` from uniform barycentrics (vertices and edges included now and then).
fn point_on(rng: &mut SplitMix64, tri: &[Vec3; 3]) -> Vec3 {
    let (mut u, mut v) = (rng.next_f32(), rng.next_f32());
    if u + v > 1.0 {
        (u, v) = (1.0 - u, 1.0 - v);
    }
    match rng.next_f32() {
        x if x < 0.05 => tri[(8.0 * x) as usize % 3],
        x if x < 0.1 => tri[0] + (tri[1] - tri[0]) * u,
        _ => tri[0] + (tri[1] - tri[0]) * u + (tri[2] - tri[0]) * v,
    }
}

fn inside(p: Vec3, b: &Aabb) -> bool {
    p.cmpge(b.min).all() && p.cmple(b.max).all()
}

fn grown(b: &Aabb, by: f32) -> Aabb {
    Aabb { min: b.min - by, max: b.max + by }
}

fn blade_triangles(count: usize, seed: u64) -> Vec<[Vec3; 3]> {
    let mesh = testmesh::thin_blades(count, seed);
    (0..mesh.triangle_count()).map(|i| mesh.triangle(i)).collect()
}

/// The clipped polygon against the naive reference, sampled: every point of the triangle
/// inside the region lies in the polygon's box, the box lies in the triangle's box and the
/// region (to rounding), and a part found empty has no sampled point inside the region.
#[test]
fn clipped_box_bounds_exactly_the_part_inside_the_region() {
    let mut rng = SplitMix64(5);
    let (mut empty, mut cut) = (0, 0);
    for _ in 0..3000 {
        let tri = [0; 3].map(|_| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - 2.0);
        let tri_box = Aabb::from_points(tri);
        // Regions inside the triangle's box and regions reaching past it.
        let wide = grown(&tri_box, 0.5);
        let region = Aabb::from_points([random_point(&mut rng, &wide), random_point(&mut rng, &wide)]);
        let tol = 4.0 * f32::EPSILON * 2.5;
        let samples: Vec<Vec3> = (0..200).map(|_| point_on(&mut rng, &tri)).collect();
        match clip_triangle(&tri, &region) {
            None => {
                empty += 1;
                let shrunk = grown(&region, -tol);
                assert!(samples.iter().all(|&p| !inside(p, &shrunk)), "{tri:?} {region:?} found empty");
            }
            Some(poly) => {
                cut += 1;
                assert!(!poly.overflow, "{tri:?} {region:?}: {poly:?}");
                let b = Aabb::from_points(poly.vertices().iter().copied());
                let limit =
                    grown(&Aabb { min: region.min.max(tri_box.min), max: region.max.min(tri_box.max) }, tol);
                assert!(inside(b.min, &limit) && inside(b.max, &limit), "box {b:?} outside {limit:?}");
                for &p in samples.iter().filter(|&&p| inside(p, &region)) {
                    assert!(inside(p, &grown(&b, tol)), "{p} of {tri:?} in {region:?} outside the box {b:?}");
                }
            }
        }
    }
    assert!(empty > 300 && cut > 1000, "{empty} empty, {cut} cut");
}

/// Every point of every triangle lies in a piece box of that triangle (no slack needed:
/// the pieces are grown), every piece box lies in its triangle's box, and the splits use
/// the budget without exceeding it.
#[test]
fn pieces_cover_their_triangles_within_the_budget() {
    let tris = blade_triangles(300, 3);
    let boxes: Vec<Aabb> = tris.iter().map(|&t| Aabb::from_points(t)).collect();
    for budget in [0.1, 0.3, 1.0, 4.0] {
        let refs = presplit(&boxes, |i| tris[i], budget);
        let n = tris.len();
        assert!(refs.tri.len() <= n + (budget * n as f32) as usize, "{budget}: {} refs", refs.tri.len());
        assert!(
            refs.tri.len() as f32 >= n as f32 * (1.0 + 0.8 * budget),
            "{budget}: {} refs",
            refs.tri.len()
        );
        assert!(refs.tri.windows(2).all(|w| w[0] <= w[1]), "references in triangle order");
        let mut rng = SplitMix64(11);
        for (i, tri) in tris.iter().enumerate() {
            let pieces: Vec<Aabb> =
                refs.tri.iter().zip(&refs.boxes).filter(|(&t, _)| t as usize == i).map(|(_, &b)| b).collect();
            assert!(pieces.iter().all(|p| inside(p.min, &boxes[i]) && inside(p.max, &boxes[i])));
            for _ in 0..100 {
                let p = point_on(&mut rng, tri);
                assert!(
                    pieces.iter().any(|b| inside(p, b)),
                    "{budget}: {p} of triangle {i} in no piece {pieces:?}"
                );
            }
        }
    }
}

/// Splitting shrinks what the builder sees: the pieces' total box area is well below the
/// triangles' (the blades are diagonal, so each cut trims much of the box).
#[test]
fn pieces_of_thin_blades_have_far_less_box_area() {
    let tris = blade_triangles(500, 4);
    let boxes: Vec<Aabb> = tris.iter().map(|&t| Aabb::from_points(t)).collect();
    let area = |bs: &[Aabb]| bs.iter().map(|b| f64::from(b.surface_area())).sum::<f64>();
    let refs = presplit(&boxes, |i| tris[i], 0.5);
    assert!(area(&refs.boxes) < 0.8 * area(&boxes), "{} vs {}", area(&refs.boxes), area(&boxes));
}

#[test]
fn no_budget_means_one_reference_per_triangle_in_order() {
    let tris = blade_triangles(20, 1);
    let boxes: Vec<Aabb> = tris.iter().map(|&t| Aabb::from_points(t)).collect();
    for budget in [0.0, -1.0, f32::NAN, 1e-6] {
        let refs = presplit(&boxes, |i| tris[i], budget);
        assert_eq!(refs.tri, (0..tris.len() as u32).collect::<Vec<_>>(), "{budget}");
        assert_eq!(refs.boxes, boxes, "{budget}");
    }
}

/// Degenerate triangles (a point, a segment, axis-aligned slivers) split without
/// panicking and stay covered.
#[test]
fn degenerate_triangles_split_safely() {
    let p = Vec3::new(0.3, -0.2, 0.7);
    let tris = [
        [p, p, p],
        [p, p + Vec3::new(1.0, 1.0, 1.0), p + Vec3::new(2.0, 2.0, 2.0)],
        [p, p + Vec3::X, p + Vec3::new(0.5, 1e-7, 0.0)],
        [Vec3::ZERO, Vec3::new(1e30, 1e30, 0.0), Vec3::new(0.0, 1e30, 1e30)],
    ];
    let boxes: Vec<Aabb> = tris.iter().map(|&t| Aabb::from_points(t)).collect();
    let refs = presplit(&boxes, |i| tris[i], 3.0);
    for (i, tri) in tris.iter().enumerate() {
        let pieces: Vec<Aabb> =
            refs.tri.iter().zip(&refs.boxes).filter(|(&t, _)| t as usize == i).map(|(_, &b)| b).collect();
        assert!(!pieces.is_empty());
        assert!(tri.iter().all(|&v| pieces.iter().any(|b| inside(v, b))), "triangle {i}: {pieces:?}");
    }
}

/// The coarsest plane found with bit tricks against trying every level in turn.
#[test]
fn coarsest_plane_matches_a_search_over_levels() {
    let grid = Grid::new(Aabb { min: Vec3::new(-3.0, 0.0, 1.0), max: Vec3::new(5.0, 0.5, 1.25) });
    let naive = |b: &Aabb, axis: usize| -> Option<(u32, f32)> {
        let (o, e) = (grid.bounds.min[axis], grid.bounds.max[axis] - grid.bounds.min[axis]);
        (1..=MAX_LEVEL).find_map(|level| {
            let cells = (1u64 << level) as f64;
            let k = ((f64::from(b.min[axis]) - f64::from(o)) / f64::from(e) * cells).floor() + 1.0;
            let pos = (f64::from(o) + k / cells * f64::from(e)) as f32;
            (k < cells && pos > b.min[axis] && pos < b.max[axis]).then_some((level, pos))
        })
    };
    let mut rng = SplitMix64(2);
    let mut found = 0;
    for i in 0..20000 {
        let scale = 0.5f32.powi(i % 20);
        let a = random_point(&mut rng, &grid.bounds);
        let b = Aabb::from_points([a, a + (random_point(&mut rng, &grid.bounds) - grid.bounds.min) * scale]);
        let b = Aabb { min: b.min, max: b.max.min(grid.bounds.max) };
        for axis in 0..3 {
            let fast = grid.plane_on(&b, axis);
            found += fast.is_some() as usize;
            assert_eq!(fast, naive(&b, axis), "{b:?} axis {axis}");
        }
    }
    assert!(found > 20000, "{found} planes found");
}

/// A budget beyond what the per-triangle limit can use neither allocates for it nor
/// exceeds the limit.
#[test]
fn huge_budgets_stop_at_the_per_triangle_limit() {
    let tris = blade_triangles(20, 1);
    let boxes: Vec<Aabb> = tris.iter().map(|&t| Aabb::from_points(t)).collect();
    for budget in [1e9, f32::INFINITY] {
        let refs = presplit(&boxes, |i| tris[i], budget);
        assert!(refs.tri.len() <= tris.len() * (MAX_SPLITS_PER_TRIANGLE + 1), "{budget}: {}", refs.tri.len());
        assert!(refs.tri.len() > 10 * tris.len(), "{budget}: {}", refs.tri.len());
    }
}
