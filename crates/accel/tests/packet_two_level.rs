//! Eight-ray packets through the top level (scenes of many instances): lane by lane and
//! bit for bit equal to the single-ray queries, and to brute force, on scenes of random
//! instances (flat and BVH meshes, shared meshes, merged static instances, moving
//! instances after `update_instances`), for coherent packets (camera tiles), incoherent
//! ones and shadow segments, with random partial masks; both kernels. Brute force is
//! [`BruteForce::build_like`]: merged instances tested in world space, as the BVH does.

#[path = "support/rays.rs"]
mod rays;

use filtrace_accel::testmesh::{self, SplitMix64};
use filtrace_accel::{BruteForce, BuildParams, RayPacket, SceneAccel, TopLevelUpdate, LANES};
use filtrace_core::{Affine3A, Quat, Ray, Vec3};
use filtrace_scene::{Instance, Scene};
use rays::{bits, kernels};

/// A random rigid-plus-scale transform inside a cube of side `spread`.
fn random_transform(rng: &mut SplitMix64, spread: f32) -> Affine3A {
    let scale = Vec3::new(0.3 + rng.next_f32(), 0.3 + rng.next_f32(), 0.3 + rng.next_f32());
    let rot = Quat::from_euler(
        glam::EulerRot::XYZ,
        6.0 * rng.next_f32(),
        6.0 * rng.next_f32(),
        6.0 * rng.next_f32(),
    );
    let at = (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5) * spread;
    Affine3A::from_scale_rotation_translation(scale, rot, at)
}

/// `n` instances of four meshes (two flat: a cube of 12 triangles and one of 48; two with
/// a BVH), randomly placed, every fifth one with the identity transform.
fn random_scene(n: usize, seed: u64) -> Scene {
    let mut rng = SplitMix64(seed);
    let mut s = Scene::default();
    s.add_mesh(testmesh::subdivided_cube(1));
    s.add_mesh(testmesh::subdivided_cube(2));
    s.add_mesh(testmesh::icosphere(2));
    s.add_mesh(testmesh::displaced_sphere(10, 0.2));
    s.instances.clear();
    for i in 0..n {
        let transform = if i % 5 == 0 { Affine3A::IDENTITY } else { random_transform(&mut rng, 8.0) };
        let mesh = (rng.next_u64() % 4) as u32;
        s.instances.push(Instance { mesh, transform, material_override: None });
    }
    s
}

/// Packets of three kinds: camera tiles (4x2 pixels of a 256x256 camera; coherent),
/// rays in random directions from inside the scene (incoherent), shadow segments towards
/// a small quad; a third of them with a random partial mask.
fn packets(scene: &Scene, n: usize, seed: u64) -> Vec<(RayPacket, u8)> {
    let b = scene.bounds();
    let (b_min, ext) = (b.min, b.extent());
    let c = b_min + 0.5 * ext;
    let r = 0.5 * ext.length();
    let mut rng = SplitMix64(seed);
    let eye = c + Vec3::new(0.3, 0.4, 1.0).normalize() * 1.5 * r;
    let light = c + Vec3::new(0.1 * ext.x, 0.45 * ext.y, -0.05 * ext.z);
    let fwd = (c - eye).normalize();
    let right = fwd.cross(Vec3::Y).normalize();
    let up = right.cross(fwd);
    let mut out = Vec::new();
    for k in 0..n {
        let mut p = RayPacket::default();
        let inside =
            |rng: &mut SplitMix64| b_min + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * ext;
        for i in 0..LANES {
            let ray = match k % 3 {
                0 => {
                    let (tx, ty) = ((k / 3 % 64) as f32 * 4.0, (k / 192 % 128) as f32 * 2.0);
                    let (px, py) = (tx + (i % 4) as f32, ty + (i / 4) as f32);
                    Ray::new(eye, fwd + (px / 128.0 - 1.0) * 0.6 * right + (py / 128.0 - 1.0) * 0.6 * up)
                }
                1 => Ray::segment(inside(&mut rng), rng.unit_vector(), 0.0, f32::INFINITY),
                _ => {
                    let o = inside(&mut rng);
                    let q = light + Vec3::new(rng.next_f32() - 0.5, 0.0, rng.next_f32() - 0.5) * 0.2 * ext;
                    Ray::segment(o, q - o, 1e-4, 1.0 - 1e-4)
                }
            };
            p.set_lane(i, &ray);
        }
        let active = if k % 3 == 1 { rng.next_u64() as u8 } else { 0xff };
        out.push((p, active));
    }
    out
}

/// Packet results equal the single-ray ones (and brute force where given) in every lane;
/// returns (lanes hit, lanes occluded).
fn check(accel: &SceneAccel, brute: Option<&BruteForce>, rays: &RayPacket, active: u8) -> (u32, u32) {
    let hits = accel.intersect_packet(rays, active);
    let occ = accel.occluded_packet(rays, active);
    assert_eq!(hits.mask & !active, 0);
    assert_eq!(occ & !active, 0);
    for i in (0..LANES).filter(|i| active & (1 << i) != 0) {
        let ray = rays.lane(i);
        let want = accel.intersect(&ray);
        assert_eq!(
            bits(hits.lane(i)),
            bits(want),
            "{:?} lane {i} of {active:#010b}: ray {ray:?}",
            accel.simd()
        );
        assert_eq!(
            occ & (1 << i) != 0,
            accel.occluded(&ray),
            "{:?} occluded lane {i}: {ray:?}",
            accel.simd()
        );
        if let Some(brute) = brute {
            assert_eq!(bits(want), bits(brute.intersect(&ray)), "brute force, ray {ray:?}");
        }
    }
    (hits.mask.count_ones(), occ.count_ones())
}

/// The transformed instances of `scene`: told to move, they keep their own top-level
/// entries (the identity ones are merged), so that packets walk the top level.
fn transformed(scene: &Scene) -> Vec<u32> {
    (0..scene.instances.len() as u32)
        .filter(|&i| scene.instances[i as usize].transform != Affine3A::IDENTITY)
        .collect()
}

fn check_all(accel: &SceneAccel, scene: &Scene, n: usize, seed: u64) {
    let brute = BruteForce::build_like(scene, accel);
    let (mut hit, mut occluded) = (0, 0);
    for (k, (p, active)) in packets(scene, n, seed).iter().enumerate() {
        let (h, o) = check(accel, (k % 4 == 0).then_some(&brute), p, *active);
        hit += h;
        occluded += o;
    }
    assert!(hit > n as u32 && occluded > n as u32 / 4, "{hit} hits, {occluded} occluded of {n} packets");
}

#[test]
fn many_instances_packets_equal_single_rays_and_brute_force() {
    for (n, seed) in [(3, 1), (12, 2), (60, 3)] {
        let scene = random_scene(n, seed);
        for simd in kernels() {
            // Static: every instance merged into one world-space bottom level; moving: the
            // transformed ones walked through the top level.
            for moving in [vec![], transformed(&scene)] {
                let accel = SceneAccel::build_with_moving(&scene, &BuildParams::default(), simd, &moving);
                check_all(&accel, &scene, 900, seed);
            }
        }
    }
}

/// Instances moving between frames (kept apart from the merged bottom level, so moves are
/// top-level refits or rebuilds): after every `update_instances` the packets still equal the
/// single-ray queries and brute force on the moved scene.
#[test]
fn moving_instances_packets_equal_single_rays_after_updates() {
    let mut scene = random_scene(24, 9);
    let moving: Vec<u32> = (0..scene.instances.len() as u32).filter(|i| i % 3 != 1).collect();
    let mut rng = SplitMix64(77);
    for simd in kernels() {
        let mut accel = SceneAccel::build_with_moving(&scene, &BuildParams::default(), simd, &moving);
        let mut updates = Vec::new();
        for frame in 0..4 {
            let moved: Vec<u32> = moving.iter().copied().filter(|_| rng.next_u64() & 1 == 0).collect();
            for &i in &moved {
                let small = Affine3A::from_rotation_translation(
                    Quat::from_rotation_y(0.3 * rng.next_f32()),
                    (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5) * (frame as f32 + 1.0),
                );
                scene.instances[i as usize].transform = small * scene.instances[i as usize].transform;
            }
            updates.push(accel.update_instances(&scene, &moved));
            check_all(&accel, &scene, 300, frame);
        }
        assert!(updates.iter().all(|u| *u != TopLevelUpdate::Full), "{updates:?}");
    }
}

/// Packets where some lanes hit the same instance and others miss everything or are
/// invalid, and where every lane but one or two is masked off (the per-lane fallbacks).
#[test]
fn sparse_masks_and_invalid_lanes_through_the_top_level() {
    let scene = random_scene(16, 5);
    for simd in kernels() {
        let accel =
            SceneAccel::build_with_moving(&scene, &BuildParams::default(), simd, &transformed(&scene));
        let mut rng = SplitMix64(3);
        for (mut p, _) in packets(&scene, 600, 11) {
            p.dir[1][2] = f32::NAN;
            p.origin[0][5] = f32::INFINITY;
            p.t_max[6] = f32::NAN;
            for active in [0u8, 1, 0b1000_0100, rng.next_u64() as u8, 0b0110_0000, 0xff] {
                check(&accel, None, &p, active);
            }
        }
    }
}
