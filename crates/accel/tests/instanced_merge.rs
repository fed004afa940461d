//! Static instances merged into world space (`merge.rs`): the merged BVH against brute
//! force in object space (the reference for the transforms: rotations, uniform,
//! non-uniform and mirroring scales) within a tolerance, the memory budget, and animated
//! scenes, whose moving instances are told at build time and stay apart.

#[path = "support/rays.rs"]
mod rays;

use filtrace_accel::testmesh;
use filtrace_accel::{BruteForce, BuildParams, Hit, SceneAccel, Simd, TopLevelUpdate, MERGE_FLOOR_TRIANGLES};
use filtrace_core::{Affine3A, Quat, Ray, Vec3};
use filtrace_scene::{Instance, Scene};
use rays::{bits, kernels, random_rays};

/// Four meshes (two BVH, two flat), eight instances: rotated, uniformly and non-uniformly
/// scaled, mirrored in one axis and in all three, sheared, and one identity; meshes shared.
fn transformed_scene() -> Scene {
    let mut s = Scene::default();
    s.meshes.push(testmesh::displaced_sphere(10, 0.15));
    s.meshes.push(testmesh::icosphere(2));
    s.meshes.push(testmesh::subdivided_cube(1));
    s.meshes.push(testmesh::subdivided_cube(2));
    let srt = |scale: Vec3, rot: Quat, t: Vec3| Affine3A::from_scale_rotation_translation(scale, rot, t);
    let shear = Affine3A::from_cols(
        Vec3::new(1.0, 0.0, 0.0).into(),
        Vec3::new(0.6, 1.0, 0.0).into(),
        Vec3::new(0.0, -0.4, 0.8).into(),
        Vec3::new(-2.5, -2.0, 2.0).into(),
    );
    let transforms = [
        (0, Affine3A::IDENTITY),
        (1, srt(Vec3::splat(0.7), Quat::from_rotation_z(0.7), Vec3::new(2.5, 0.0, 0.0))),
        (
            3,
            srt(
                Vec3::new(3.0, 0.2, 1.5),
                Quat::from_euler(glam::EulerRot::XYZ, 0.3, 1.1, -0.4),
                -2.0 * Vec3::Y,
            ),
        ),
        (0, srt(Vec3::new(-0.5, 0.6, 0.9), Quat::from_rotation_y(2.0), Vec3::new(-2.0, 1.0, 1.0))),
        (1, srt(Vec3::splat(-0.4), Quat::from_rotation_x(-1.0), Vec3::new(0.5, 0.5, -1.5))),
        (2, srt(Vec3::new(0.3, 1.2, 0.5), Quat::from_rotation_y(0.4), Vec3::new(1.5, 1.5, 1.5))),
        (2, srt(Vec3::new(1.0, -1.0, 0.25), Quat::IDENTITY, Vec3::new(-1.0, -1.0, -2.5))),
        (3, shear),
    ];
    for (mesh, transform) in transforms {
        s.instances.push(Instance { mesh, transform, material_override: None });
    }
    s
}

/// Distance of barycentrics `(u, v)` from the triangle's boundary.
fn edge_distance(h: &Hit) -> f32 {
    h.u.min(h.v).min(1.0 - h.u - h.v)
}

/// The merged BVH's hit `a` against the object-space reference `b`: the same triangle
/// with `t`, `u`, `v` within `TOL`, or another triangle that the reference also hits at
/// about the same `t` (shared edges, coincident faces), or a miss on one side only where
/// the other's hit grazes an edge (world-space rounding moves edges by ulps).
fn agrees(a: Option<Hit>, b: Option<Hit>, brute: &BruteForce, ray: &Ray) -> Result<(), String> {
    const TOL: f32 = 2e-4;
    let close = |x: f32, y: f32| (x - y).abs() <= TOL * x.abs().max(y.abs()).max(1.0);
    match (a, b) {
        (None, None) => Ok(()),
        (Some(a), Some(b)) if (a.instance, a.prim) == (b.instance, b.prim) => {
            (close(a.t, b.t) && (a.u - b.u).abs() <= TOL && (a.v - b.v).abs() <= TOL)
                .then_some(())
                .ok_or_else(|| format!("same triangle, far apart: {a:?} {b:?} {ray:?}"))
        }
        (Some(a), Some(b)) => {
            let also =
                brute.all_hits(ray).iter().any(|&(t, i, p)| (i, p) == (a.instance, a.prim) && close(t, a.t));
            let near = also || edge_distance(&a) < TOL || edge_distance(&b) < TOL;
            (near && close(a.t, b.t) || also)
                .then_some(())
                .ok_or_else(|| format!("other triangle: {a:?} {b:?} {ray:?}"))
        }
        (Some(h), None) | (None, Some(h)) => (edge_distance(&h) < TOL)
            .then_some(())
            .ok_or_else(|| format!("hit {h:?} only on one side, far from an edge: {ray:?}")),
    }
}

/// Every static instance is merged; hits agree with object-space brute force within the
/// tolerance, exactly with the world-space reference, and occlusion with the closest hit.
#[test]
fn merged_transformed_instances_match_object_space_brute_force() {
    let scene = transformed_scene();
    let object_space = BruteForce::build(&scene);
    for simd in kernels() {
        for flat in [0, 40] {
            let params = BuildParams { max_flat_triangles: flat, ..BuildParams::default() };
            let accel = SceneAccel::build_simd(&scene, &params, simd);
            assert!((0..8).all(|i| accel.is_merged(i)), "a static scene merges whole");
            accel.validate().unwrap();
            let world = BruteForce::build_like(&scene, &accel);
            let (mut hits, mut instances) = (0, [0; 8]);
            let rays = random_rays(&scene, 3000, 5);
            for ray in &rays {
                let a = accel.intersect(ray);
                assert_eq!(bits(a), bits(world.intersect(ray)), "{simd:?}: world-space brute force, {ray:?}");
                assert_eq!(accel.occluded(ray), a.is_some(), "{simd:?}: occlusion of {ray:?}");
                agrees(a, object_space.intersect(ray), &object_space, ray)
                    .unwrap_or_else(|e| panic!("{simd:?} flat {flat}: {e}"));
                if let Some(h) = a {
                    hits += 1;
                    instances[h.instance as usize] += 1;
                }
            }
            assert!(hits > 600 && hits < 2700, "{hits} of {} rays hit", rays.len());
            assert!(instances.iter().all(|&n| n > 0), "every instance is hit: {instances:?}");
        }
    }
}

/// A mesh with so many copies that its world-space triangles exceed the budget keeps its
/// instances in the top level; the other static instances are still merged, and the two
/// together answer as brute force does.
#[test]
fn instances_beyond_the_memory_budget_stay_instanced() {
    let mut s = Scene::default();
    s.meshes.push(testmesh::icosphere(5)); // 20,480 triangles
    s.meshes.push(testmesh::subdivided_cube(2));
    let copies = MERGE_FLOOR_TRIANGLES / 20_480 + 2;
    for k in 0..copies {
        let at = Vec3::new((k % 8) as f32, (k / 8) as f32, 0.0) * 2.5;
        let transform =
            Affine3A::from_scale_rotation_translation(Vec3::ONE, Quat::from_rotation_y(k as f32), at);
        s.instances.push(Instance { mesh: 0, transform, material_override: None });
    }
    for at in [Vec3::new(-3.0, 0.0, 0.0), Vec3::new(-3.0, 3.0, 1.0)] {
        s.instances.push(Instance {
            mesh: 1,
            transform: Affine3A::from_translation(at),
            material_override: None,
        });
    }
    assert!(s.triangle_count() > MERGE_FLOOR_TRIANGLES);
    let accel = SceneAccel::build(&s);
    assert!((0..copies as u32).all(|i| !accel.is_merged(i)), "the many copies stay instanced");
    assert!(accel.is_merged(copies as u32) && accel.is_merged(copies as u32 + 1), "the cubes merge");
    let brute = BruteForce::build_like(&s, &accel);
    let mut hits = 0;
    for ray in random_rays(&s, 30, 9) {
        let a = accel.intersect(&ray);
        assert_eq!(bits(a), bits(brute.intersect(&ray)), "{ray:?}");
        hits += a.is_some() as usize;
    }
    assert!(hits > 3, "{hits} hits");
}

/// The classroom: the instances its animation moves (the teacher's chair) are told at
/// build time and stay apart, every desk and chair is merged; every frame of the
/// animation is a top-level update (never a full rebuild) with the hits of brute force.
/// A merged instance moved anyway is not silently wrong: the update reports a full
/// rebuild, after which it is apart and hits are right.
#[test]
fn classroom_animation_moves_only_its_own_instances() {
    let mut scene = filtrace_scene::builtin("classroom").expect("built-in classroom");
    let anim = scene.animation.clone().expect("animated");
    let moving: Vec<u32> = anim.instances.iter().map(|&(i, _, _)| i).collect();
    assert!(!moving.is_empty());
    let mut accel = SceneAccel::build_with_moving(&scene, &BuildParams::default(), Simd::best(), &moving);
    for i in 0..scene.instances.len() as u32 {
        assert_eq!(accel.is_merged(i), !moving.contains(&i), "instance {i}");
    }
    for frame in [0, 7, 20, 33, 48] {
        let pose = scene.pose_at_frame(frame).unwrap();
        for &(i, t) in &pose.instances {
            scene.instances[i as usize].transform = t;
        }
        let moved: Vec<u32> = pose.instances.iter().map(|&(i, _)| i).collect();
        let update = accel.update_instances(&scene, &moved);
        assert_ne!(update, TopLevelUpdate::Full, "frame {frame}");
        check_against_brute(&accel, &scene, &format!("frame {frame}"));
    }
    let desk = (0..scene.instances.len() as u32).find(|&i| accel.is_merged(i)).unwrap();
    let t = &mut scene.instances[desk as usize].transform;
    *t = Affine3A::from_translation(Vec3::new(0.3, 0.0, 0.2)) * *t;
    assert_eq!(accel.update_instances(&scene, &[desk]), TopLevelUpdate::Full);
    assert!(!accel.is_merged(desk));
    check_against_brute(&accel, &scene, "after a merged desk moved");
    // `update_transforms` (no list of what moved) finds merged instances that moved too.
    let other = (0..scene.instances.len() as u32).find(|&i| accel.is_merged(i)).unwrap();
    let t = &mut scene.instances[other as usize].transform;
    *t = Affine3A::from_translation(Vec3::new(0.0, 0.5, 0.0)) * *t;
    accel.update_transforms(&scene);
    assert!(!accel.is_merged(other));
    check_against_brute(&accel, &scene, "after update_transforms");
}

fn check_against_brute(accel: &SceneAccel, scene: &Scene, what: &str) {
    accel.validate().unwrap_or_else(|e| panic!("{what}: {e}"));
    let brute = BruteForce::build_like(scene, accel);
    let mut hits = 0;
    for ray in random_rays(scene, 150, 3) {
        let a = accel.intersect(&ray);
        assert_eq!(bits(a), bits(brute.intersect(&ray)), "{what}: {ray:?}");
        assert_eq!(accel.occluded(&ray), a.is_some(), "{what}: occlusion of {ray:?}");
        hits += a.is_some() as usize;
    }
    assert!(hits > 50, "{what}: {hits} hits");
}
