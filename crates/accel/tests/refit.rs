//! Per-frame updates of the top level ([`SceneAccel::update_instances`]): after every
//! refit or rebuild the BVH gives exactly the brute-force answers, over seeded random
//! moves of many instances.

#[path = "support/rays.rs"]
mod rays;

use filtrace_accel::testmesh::{self, SplitMix64};
use filtrace_accel::{BruteForce, BuildParams, SceneAccel, TopLevelUpdate};
use filtrace_core::{Affine3A, Quat, Ray, Vec3};
use filtrace_scene::{Instance, Scene};

const MOVERS: u32 = 6;

/// Two identity instances (merged) and [`MOVERS`] instances (indices 2..) that will move.
fn scene() -> Scene {
    let mut s = Scene::default();
    let mut ground = testmesh::subdivided_cube(3);
    ground.positions.iter_mut().for_each(|p| *p *= Vec3::new(8.0, 0.1, 8.0));
    s.meshes.push(ground);
    s.meshes.push(testmesh::displaced_sphere(8, 0.2));
    s.meshes.push(testmesh::icosphere(2));
    for mesh in [0, 2] {
        s.instances.push(Instance { mesh, transform: Affine3A::IDENTITY, material_override: None });
    }
    for k in 0..MOVERS {
        let transform = Affine3A::from_translation(Vec3::new(k as f32 - 2.5, 1.0, 0.0));
        s.instances.push(Instance { mesh: 1 + k % 2, transform, material_override: None });
    }
    s
}

fn random_transform(rng: &mut SplitMix64, reach: f32) -> Affine3A {
    let mut r = || rng.next_f32();
    let scale = Vec3::new(0.3 + r(), 0.3 + r(), 0.3 + r());
    let rotation = Quat::from_euler(glam::EulerRot::XYZ, 6.0 * r(), 6.0 * r(), 6.0 * r());
    let t = Vec3::new(r() - 0.5, r(), r() - 0.5) * reach;
    Affine3A::from_scale_rotation_translation(scale, rotation, t)
}

fn random_rays(rng: &mut SplitMix64, n: usize) -> Vec<Ray> {
    (0..n)
        .map(|i| {
            let o = Vec3::new(rng.next_f32() - 0.5, rng.next_f32(), rng.next_f32() - 0.5) * 16.0;
            let d = rng.unit_vector();
            if i % 3 == 0 {
                Ray::segment(o, d, 0.0, 4.0 * rng.next_f32())
            } else {
                Ray::new(o, d)
            }
        })
        .collect()
}

/// `accel` is valid and agrees with brute force on `rays` (single rays and packets:
/// `rays::check_rays`), with both outcomes common.
fn check(accel: &SceneAccel, scene: &Scene, rays: &[Ray], what: &str) {
    accel.validate().unwrap_or_else(|e| panic!("{what}: {e}"));
    let hits = rays::check_rays(accel, &BruteForce::build_like(scene, accel), rays, what);
    assert!(hits > rays.len() / 10 && hits < rays.len() * 9 / 10, "{what}: {hits} of {} hit", rays.len());
}

/// Random subsets of the movers take random transforms, frame after frame: small moves
/// refit, large ones degrade the tree until it is rebuilt; every frame agrees with brute
/// force, bit for bit, for both kernels.
#[test]
fn refits_and_rebuilds_agree_with_brute_force_over_random_moves() {
    for simd in rays::kernels() {
        let mut scene = scene();
        let movers: Vec<u32> = (2..2 + MOVERS).collect();
        let mut accel = SceneAccel::build_with_moving(&scene, &BuildParams::default(), simd, &movers);
        assert!(accel.is_merged(0) && accel.is_merged(1), "still identity instances are merged");
        assert!(movers.iter().all(|&i| !accel.is_merged(i)), "moving instances are kept apart");
        let mut rng = SplitMix64(7);
        let (mut refits, mut rebuilds) = (0, 0);
        for frame in 0..40 {
            // Frames 0..20 move a little around where the tree was built, later ones far.
            let reach = if frame < 20 { 6.0 } else { 14.0 };
            let moved: Vec<u32> = movers.iter().copied().filter(|_| rng.next_f32() < 0.5).collect();
            for &i in &moved {
                let jitter = random_transform(&mut rng, reach);
                scene.instances[i as usize].transform = jitter;
            }
            match accel.update_instances(&scene, &moved) {
                TopLevelUpdate::Refit => refits += 1,
                TopLevelUpdate::Rebuilt => rebuilds += 1,
                TopLevelUpdate::Unchanged => assert!(moved.is_empty()),
                TopLevelUpdate::Full => panic!("frame {frame}: a full rebuild for moved movers"),
            }
            check(&accel, &scene, &random_rays(&mut rng, 300), &format!("{simd:?} frame {frame}"));
        }
        assert!(refits > 5 && rebuilds > 0, "{simd:?}: {refits} refits, {rebuilds} rebuilds");
    }
}

/// A merged instance (built as static: identity or not) that moves costs a full rebuild,
/// after which it is apart and later moves are top-level only; an instance made singular
/// leaves the top level.
#[test]
fn merged_and_singular_instances_fall_back_to_rebuilds() {
    let mut scene = scene();
    let mut accel = SceneAccel::build(&scene);
    assert!((0..2 + MOVERS).all(|i| accel.is_merged(i)), "a static scene merges whole");
    let mut rng = SplitMix64(3);
    assert_eq!(accel.update_instances(&scene, &[]), TopLevelUpdate::Unchanged);
    scene.instances[1].transform = Affine3A::from_translation(Vec3::new(0.0, 3.0, 1.0));
    assert_eq!(accel.update_instances(&scene, &[1]), TopLevelUpdate::Full);
    assert!(!accel.is_merged(1));
    check(&accel, &scene, &random_rays(&mut rng, 300), "after the merged instance moved");
    scene.instances[1].transform = Affine3A::from_translation(Vec3::new(0.0, 3.1, 1.0));
    assert_eq!(accel.update_instances(&scene, &[1]), TopLevelUpdate::Refit);
    check(&accel, &scene, &random_rays(&mut rng, 300), "after it moved again");
    scene.instances[3].transform = Affine3A::from_scale(Vec3::ZERO);
    assert_eq!(accel.update_instances(&scene, &[3]), TopLevelUpdate::Full, "3 was merged");
    assert!(!accel.is_merged(3) && accel.is_merged(4));
    check(&accel, &scene, &random_rays(&mut rng, 300), "after an instance became singular");
    scene.instances[3].transform = Affine3A::IDENTITY;
    assert_eq!(accel.update_instances(&scene, &[3]), TopLevelUpdate::Rebuilt);
    assert_eq!(accel.update_instances(&scene, &[99]), TopLevelUpdate::Full, "bad index: rebuild, no panic");
    check(&accel, &scene, &random_rays(&mut rng, 300), "after a bad index");
}
