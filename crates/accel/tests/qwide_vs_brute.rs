//! The BVH with compressed 8-wide nodes (`BuildParams::min_quantized_triangles`) against
//! brute force and against the uncompressed 8-wide BVH: the same hits bit for bit (the
//! leaves and their tests are the same; compressed boxes only contain more), for every
//! build preset, on the four ray kinds of `support/rays.rs` and on rays leaving surfaces.

#[path = "support/rays.rs"]
mod rays;

use filtrace_accel::testmesh::{self, SplitMix64};
use filtrace_accel::{BruteForce, BuildParams, SceneAccel, Simd};
use filtrace_core::shared_data::shared_path;
use filtrace_core::{Ray, Vec3};
use filtrace_scene::{Mesh, Scene};
use rays::{bits, check_rays, random_rays};

fn single(mesh: Mesh) -> Scene {
    let mut s = Scene::default();
    s.add_mesh(mesh);
    s
}

/// `params` with every AVX2 BVH compressed.
fn compress_all(params: &BuildParams) -> BuildParams {
    BuildParams { min_quantized_triangles: 0, ..params.clone() }
}

/// The AVX2 BVH of `scene` with compressed nodes, checked to have them; `None` (with a
/// message) on CPUs without AVX2, where the layout is never built.
fn compressed(scene: &Scene, params: &BuildParams) -> Option<SceneAccel> {
    if !Simd::Avx2.available() {
        println!("SKIPPED: compressed nodes are built for the AVX2 kernels only (no AVX2 on this CPU)");
        return None;
    }
    let accel = SceneAccel::build_simd(scene, &compress_all(params), Simd::Avx2);
    let st = accel.stats();
    assert!(st.nodes > 0 && st.compressed_nodes == st.nodes, "{st:?}");
    accel.validate().unwrap_or_else(|e| panic!("{e}"));
    Some(accel)
}

/// The four kinds of `random_rays` plus, from the brute-force hits of the first kind,
/// rays leaving the hit points (origins on surfaces: `t_min = 0` and a small `t_min`).
fn rays_with_surface_origins(scene: &Scene, brute: &BruteForce, n: usize, seed: u64) -> Vec<Ray> {
    let mut rays = random_rays(scene, n, seed);
    let mut rng = SplitMix64(seed ^ 0x5eed);
    let spawned: Vec<Ray> = rays
        .iter()
        .filter_map(|r| brute.intersect(r).map(|h| r.origin + r.dir * h.t))
        .enumerate()
        .map(|(i, p)| {
            let t_min = if i % 2 == 0 { 0.0 } else { 1e-4 };
            Ray::segment(p, rng.unit_vector(), t_min, f32::INFINITY)
        })
        .collect();
    rays.extend(spawned);
    rays
}

fn check_scene(scene: &Scene, n: usize, seed: u64) {
    let brute = BruteForce::build_like(scene, &SceneAccel::build(scene));
    let rays = rays_with_surface_origins(scene, &brute, n, seed);
    for (preset, params) in BuildParams::presets() {
        let Some(accel) = compressed(scene, &params) else { return };
        let hits = check_rays(&accel, &brute, &rays, preset);
        // Only meaningful when both outcomes occur often.
        assert!(
            hits > rays.len() / 10 && hits < rays.len() * 9 / 10,
            "{preset}: {hits} of {} hit",
            rays.len()
        );
    }
}

#[test]
fn displaced_sphere_matches_brute_force() {
    check_scene(&single(testmesh::displaced_sphere(14, 0.2)), 3000, 11);
}

/// Thin diagonal triangles (a grass patch): boxes much larger than their triangles, and
/// grid steps much larger than a blade's width.
#[test]
fn grass_patch_matches_brute_force() {
    check_scene(&single(testmesh::thin_blades(1500, 4)), 3000, 12);
}

#[test]
fn bunny_matches_brute_force() {
    let Some(path) = shared_path("scenes/bunny/bunny_lowres.obj") else { return };
    let mesh = testmesh::read_obj(&path).unwrap_or_else(|e| panic!("{e}"));
    check_scene(&single(mesh), 3000, 13);
}

/// Instances (their own bottom levels, some compressed) and a merged bottom level.
#[test]
fn instances_match_brute_force() {
    let mut s = Scene::default();
    s.meshes.push(testmesh::displaced_sphere(10, 0.15));
    s.meshes.push(testmesh::thin_blades(200, 7));
    let at = |mesh: u32, t: Vec3| filtrace_scene::Instance {
        mesh,
        transform: filtrace_core::Affine3A::from_scale_rotation_translation(
            Vec3::new(1.0, 0.5, 2.0),
            filtrace_core::Quat::from_rotation_y(0.3 * t.x),
            t,
        ),
        material_override: None,
    };
    s.instances = vec![at(0, Vec3::ZERO), at(1, Vec3::new(2.0, 0.0, 0.0)), at(0, Vec3::new(-2.0, 1.0, 0.0))];
    let moving = [1u32];
    let brute = BruteForce::build_like(
        &s,
        &SceneAccel::build_with_moving(&s, &BuildParams::default(), Simd::best(), &moving),
    );
    if !Simd::Avx2.available() {
        println!("SKIPPED: no AVX2 on this CPU");
        return;
    }
    let accel =
        SceneAccel::build_with_moving(&s, &compress_all(&BuildParams::default()), Simd::Avx2, &moving);
    assert!(accel.stats().compressed_nodes > 0);
    let rays = rays_with_surface_origins(&s, &brute, 3000, 14);
    check_rays(&accel, &brute, &rays, "instances");
}

/// The compressed and uncompressed 8-wide BVHs of a 1M-triangle mesh give the same hits on
/// many rays (bit for bit), and brute force agrees on a few. (The presets leave a mesh
/// of this size uncompressed: `MIN_QUANTIZED_TRIANGLES`.)
#[test]
#[ignore = "slow: builds a 1M-triangle mesh twice and shoots brute-force rays at it"]
fn million_triangles_match_the_uncompressed_bvh() {
    let scene = single(testmesh::displaced_sphere(290, 0.1));
    assert!(scene.triangle_count() > 1_000_000);
    assert!(scene.triangle_count() < filtrace_accel::sah::MIN_QUANTIZED_TRIANGLES);
    let Some(accel) = compressed(&scene, &BuildParams::default()) else { return };
    let plain = SceneAccel::build_simd(&scene, &BuildParams::default(), Simd::Avx2);
    assert_eq!(plain.stats().compressed_nodes, 0, "the presets compress from 2 M triangles");
    for ray in random_rays(&scene, 40_000, 15) {
        assert_eq!(bits(accel.intersect(&ray)), bits(plain.intersect(&ray)), "ray {ray:?}");
        assert_eq!(accel.occluded(&ray), plain.occluded(&ray), "ray {ray:?}");
    }
    let brute = BruteForce::build(&scene);
    let rays = rays_with_surface_origins(&scene, &brute, 200, 16);
    check_rays(&accel, &brute, &rays, "1M triangles");
}
