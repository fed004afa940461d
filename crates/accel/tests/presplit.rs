//! Pre-split bottom levels (`BuildParams::split_budget`) against brute force: a mesh of
//! long thin slanted blades, whose triangles are split over several leaves, gives the
//! same closest hits (bits of `t`, `u`, `v`, the triangle) and any hits, single rays and
//! 8-ray packets, alone and instanced, for every preset, budget and kernel; and its tree
//! is not worse by the surface area heuristic than the one built without splitting.

#[path = "support/blades.rs"]
mod blades;
#[path = "support/rays.rs"]
mod rays;

use blades::{check_rays, instanced_blades, rays_at_corners_and_edges};
use filtrace_accel::testmesh;
use filtrace_accel::{BruteForce, BuildParams, SceneAccel};
use filtrace_scene::Scene;
use rays::{kernels, random_rays};

fn blades(count: usize, seed: u64) -> Scene {
    let mut s = Scene::default();
    s.add_mesh(testmesh::thin_blades(count, seed));
    s
}

fn check_scene(scene: &Scene, n: usize, seed: u64) {
    // Camera rays too: eight neighbours of a row make a coherent packet, which takes the
    // AVX2 packet traversal of a single BVH mesh rather than one query per lane.
    let mut rays = random_rays(scene, n, seed);
    rays.extend(filtrace_accel::bench::primary_rays(scene, 32, 16));
    let n = rays.len();
    for (preset, params) in BuildParams::presets() {
        for budget in [0.3, 1.0, 4.0] {
            let params = BuildParams { split_budget: budget, ..params.clone() };
            for simd in kernels() {
                let accel = SceneAccel::build_simd(scene, &params, simd);
                let stats = accel.stats();
                let name = format!("{preset} budget {budget} {simd:?} ({stats:?})");
                accel.validate().unwrap_or_else(|e| panic!("{name}: {e}"));
                // Static instances are merged into world space: the reference tests them there.
                let brute = BruteForce::build_like(scene, &accel);
                assert!(stats.references > stats.triangles, "{name}: nothing split");
                let hits = check_rays(&accel, &brute, &rays, &name);
                assert!(hits > n / 10 && hits < n * 9 / 10, "{name}: {hits} of {n} rays hit");
            }
        }
    }
}

#[test]
fn split_thin_blades_match_brute_force() {
    check_scene(&blades(800, 7), 1500, 1);
}

#[test]
fn split_instanced_blades_match_brute_force() {
    check_scene(&instanced_blades(), 1500, 2);
}

/// Rays along the blades' split planes' neighbourhood: aimed at vertices and edge
/// midpoints of every blade triangle (split pieces meet there), from above.
#[test]
fn rays_at_blade_vertices_and_edges_match_brute_force() {
    let scene = blades(200, 9);
    let brute = BruteForce::build(&scene);
    let rays = rays_at_corners_and_edges(&scene);
    for simd in kernels() {
        let params = BuildParams { split_budget: 1.0, ..BuildParams::default() };
        let accel = SceneAccel::build_simd(&scene, &params, simd);
        check_rays(&accel, &brute, &rays, &format!("{simd:?}"));
    }
}

/// Splitting lowers the expected cost of a random ray on thin diagonal triangles, the
/// more the larger the budget.
#[test]
fn splitting_lowers_the_sah_cost_of_thin_blades() {
    let scene = blades(3000, 5);
    for simd in kernels() {
        let cost = |budget: f32| {
            let params = BuildParams { split_budget: budget, ..BuildParams::default() };
            SceneAccel::build_simd(&scene, &params, simd).stats().sah_cost
        };
        let (plain, some, more) = (cost(0.0), cost(0.3), cost(1.0));
        println!("{simd:?}: SAH cost {plain:.2} without splitting, {some:.2} at budget 0.3, {more:.2} at 1");
        assert!(more < some && some < plain, "{simd:?}: SAH cost {plain} {some} {more} at budgets 0, 0.3, 1");
    }
}

/// The presets leave pre-splitting off: it did not pay on the suite's meshes (`sah.rs`).
/// (Their spatial splits, which also add references, are `spatial_splits.rs`'s.)
#[test]
fn presets_do_not_split() {
    for (name, params) in BuildParams::presets() {
        assert_eq!(params.split_budget, 0.0, "{name}");
        let params = BuildParams { spatial_split_budget: 0.0, ..params };
        let accel = SceneAccel::build_with(&blades(100, 3), &params);
        assert_eq!(accel.stats().references, accel.stats().triangles, "{name}");
    }
}
