//! The BVH against the brute-force reference: same hits on random rays for every build
//! preset, watertightness on closed meshes, degenerate input, instancing and updates.

#[path = "support/rays.rs"]
mod rays;

use filtrace_accel::testmesh::{self, SplitMix64};
use filtrace_accel::{BruteForce, BuildParams, Hit, SceneAccel, Simd};
use filtrace_core::shared_data::shared_path;
use filtrace_core::{Affine3A, Quat, Ray, Vec3};
use filtrace_scene::{Instance, Mesh, Scene};
use rays::{kernels, random_rays};

fn single(mesh: Mesh) -> Scene {
    let mut s = Scene::default();
    s.add_mesh(mesh);
    s
}

/// Three meshes, five instances with rotations, non-uniform scales and translations;
/// one instance shares its mesh with another.
fn instanced_scene() -> Scene {
    let mut s = Scene::default();
    s.meshes.push(testmesh::displaced_sphere(10, 0.15));
    s.meshes.push(testmesh::icosphere(2));
    s.meshes.push(testmesh::subdivided_cube(3));
    let place = |mesh: u32, scale: Vec3, rot: Quat, t: Vec3| Instance {
        mesh,
        transform: Affine3A::from_scale_rotation_translation(scale, rot, t),
        material_override: None,
    };
    s.instances = vec![
        place(0, Vec3::ONE, Quat::IDENTITY, Vec3::ZERO),
        place(1, Vec3::new(0.5, 2.0, 1.0), Quat::from_rotation_z(0.7), Vec3::new(2.5, 0.0, 0.0)),
        place(
            2,
            Vec3::new(3.0, 0.2, 1.5),
            Quat::from_euler(glam::EulerRot::XYZ, 0.3, 1.1, -0.4),
            Vec3::new(0.0, -2.0, 0.5),
        ),
        place(0, Vec3::new(0.3, 0.6, 0.9), Quat::from_rotation_y(2.0), Vec3::new(-2.0, 1.0, 1.0)),
        place(1, Vec3::splat(0.4), Quat::from_rotation_x(-1.0), Vec3::new(0.5, 0.5, -1.5)),
    ];
    s
}

/// Checks one ray: the BVH gives exactly the brute-force hit (same bits of `t`, `u`, `v`:
/// both use the same watertight arithmetic; the same triangle: both keep the smallest
/// `(instance, prim)` among hits at equal `t`), and agrees on occlusion.
fn check_ray(accel: &SceneAccel, brute: &BruteForce, ray: &Ray) -> Result<(), String> {
    let a = accel.intersect(ray);
    let b = brute.intersect(ray);
    let bits = |h: Option<Hit>| h.map(|h| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits(), h.instance, h.prim));
    if bits(a) != bits(b) {
        let all = brute.all_hits(ray);
        return Err(format!("bvh {a:?} brute {b:?} ray {ray:?}; all hits {all:?}"));
    }
    if let Some(a) = a {
        check_hit_in_range(&a, ray)?;
    }
    let occ = accel.occluded(ray);
    if occ != b.is_some() || occ != brute.occluded(ray) {
        return Err(format!("occluded {occ} but closest hit {b:?}, ray {ray:?}"));
    }
    Ok(())
}

fn check_hit_in_range(h: &Hit, ray: &Ray) -> Result<(), String> {
    let ok = h.t >= ray.t_min && h.t <= ray.t_max && h.u >= -1e-6 && h.v >= -1e-6 && h.u + h.v <= 1.0 + 1e-5;
    ok.then_some(()).ok_or_else(|| format!("hit out of range {h:?} for {ray:?}"))
}

/// Builds `scene` for every kernel; small scenes also without the flat path (a BVH over
/// their few triangles), so that both bottom-level kinds are tested on them.
fn accels(scene: &Scene, params: &BuildParams) -> Vec<SceneAccel> {
    let mut variants = vec![params.clone()];
    if scene.triangle_count() <= params.max_flat_triangles {
        variants.push(BuildParams { max_flat_triangles: 0, ..params.clone() });
    }
    let mut out = Vec::new();
    for p in &variants {
        for simd in kernels() {
            let a = SceneAccel::build_simd(scene, p, simd);
            assert_eq!(a.simd(), simd);
            out.push(a);
        }
    }
    out
}

/// Brute force over the triangles the BVH of `scene` tests: merged instances in world
/// space (which instances merge depends on the scene only, not on the build parameters).
fn brute_like(scene: &Scene) -> BruteForce {
    BruteForce::build_like(scene, &SceneAccel::build(scene))
}

fn check_scene(scene: &Scene, n: usize, seed: u64) {
    let brute = brute_like(scene);
    for (preset, params) in BuildParams::presets() {
        for accel in accels(scene, &params) {
            let name = format!("{preset} {:?} ({} nodes)", accel.simd(), accel.stats().nodes);
            accel.validate().unwrap_or_else(|e| panic!("{name}: {e}"));
            let rays = random_rays(scene, n, seed);
            let mut hits = 0;
            for ray in &rays {
                check_ray(&accel, &brute, ray).unwrap_or_else(|e| panic!("preset {name}: {e}"));
                hits += brute.intersect(ray).is_some() as usize;
            }
            // The test only means something when both outcomes occur often.
            assert!(hits > n / 10 && hits < n * 9 / 10, "{name}: {hits} of {n} rays hit");
        }
    }
}

#[test]
fn single_mesh_matches_brute_force_for_every_preset() {
    check_scene(&single(testmesh::displaced_sphere(14, 0.2)), 3000, 1);
}

#[test]
fn instanced_scene_matches_brute_force_for_every_preset() {
    check_scene(&instanced_scene(), 3000, 2);
}

#[test]
fn bunny_matches_brute_force() {
    let Some(path) = shared_path("scenes/bunny/bunny_lowres.obj") else { return };
    let mesh = testmesh::read_obj(&path).unwrap_or_else(|e| panic!("{e}"));
    assert!(mesh.triangle_count() > 3000);
    check_scene(&single(mesh), 3000, 3);
}

/// Rays from inside closed meshes aimed exactly at every vertex and edge midpoint (and in
/// random directions) must all hit: a ray through a shared edge or vertex may not slip
/// between the triangles (Woop et al. 2013).
#[test]
fn closed_meshes_are_watertight_from_inside() {
    for mesh in [testmesh::subdivided_cube(6), testmesh::icosphere(3), testmesh::displaced_sphere(9, 0.1)] {
        let scene = single(mesh.clone());
        let brute = BruteForce::build(&scene);
        for accel in accels(&scene, &BuildParams::default()) {
            let mut targets: Vec<Vec3> = mesh.positions.clone();
            for [a, b, c] in &mesh.indices {
                let (a, b, c) =
                    (mesh.positions[*a as usize], mesh.positions[*b as usize], mesh.positions[*c as usize]);
                targets.extend([0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a)]);
            }
            let mut rng = SplitMix64(9);
            targets.extend((0..2000).map(|_| rng.unit_vector()));
            for origin in [Vec3::ZERO, Vec3::new(0.1, -0.2, 0.3), Vec3::new(1.0 / 3.0, 0.25, -0.125)] {
                for &t in &targets {
                    let ray = Ray::new(origin, t - origin);
                    assert!(accel.intersect(&ray).is_some(), "{}: ray {ray:?} escaped", mesh.name);
                    assert!(accel.occluded(&ray), "{}: shadow ray {ray:?} escaped", mesh.name);
                    assert!(
                        brute.intersect(&ray).is_some(),
                        "{}: brute-force ray {ray:?} escaped",
                        mesh.name
                    );
                }
            }
        }
    }
}

#[test]
fn axis_aligned_rays_with_zero_direction_components() {
    let scene = single(testmesh::subdivided_cube(4));
    for accel in accels(&scene, &BuildParams::default()) {
        for (o, d) in [
            (Vec3::new(0.3, 0.2, -5.0), Vec3::Z),
            (Vec3::new(0.3, 0.2, 5.0), -Vec3::Z),
            (Vec3::new(-5.0, 0.5, 0.5), Vec3::X),
            (Vec3::new(0.5, 5.0, -0.5), -Vec3::Y * 3.0),
            // On the slab boundary itself: origin exactly in the plane x = 1 of a face.
            (Vec3::new(1.0, 0.2, -5.0), Vec3::Z),
            (Vec3::new(-0.0, 0.0, -5.0), Vec3::new(-0.0, 0.0, 1.0)),
        ] {
            let h = accel.intersect(&Ray::new(o, d)).unwrap_or_else(|| panic!("missed from {o} along {d}"));
            let p = o + h.t * d;
            assert!((p.abs().max_element() - 1.0).abs() < 1e-5, "hit point {p} not on the cube");
        }
        assert!(accel.intersect(&Ray::new(Vec3::new(2.0, 0.0, -5.0), Vec3::Z)).is_none());
    }
}

#[test]
fn degenerate_inputs_give_no_hit_and_no_panic() {
    for simd in kernels() {
        for flat in [0, 64] {
            degenerate_inputs_with(simd, &BuildParams { max_flat_triangles: flat, ..BuildParams::default() });
        }
    }
}

fn degenerate_inputs_with(simd: Simd, params: &BuildParams) {
    let build = |s: &Scene| SceneAccel::build_simd(s, params, simd);
    let empty = build(&Scene::default());
    let ray = Ray::new(Vec3::ZERO, Vec3::X);
    assert!(empty.intersect(&ray).is_none() && !empty.occluded(&ray));
    assert_eq!(empty.triangle_count(), 0);

    // Zero-triangle mesh, instance of a missing mesh, singular and NaN transforms.
    let mut s = single(Mesh::default());
    s.meshes.push(testmesh::subdivided_cube(2));
    s.instances.push(Instance {
        mesh: 1,
        transform: Affine3A::from_scale(Vec3::new(1.0, 0.0, 1.0)),
        material_override: None,
    });
    s.instances.push(Instance {
        mesh: 1,
        transform: Affine3A::from_translation(Vec3::NAN),
        material_override: None,
    });
    s.instances.push(Instance { mesh: 7, transform: Affine3A::IDENTITY, material_override: None });
    s.instances.push(Instance {
        mesh: 1,
        transform: Affine3A::from_translation(Vec3::X * 10.0),
        material_override: None,
    });
    let accel = build(&s);
    accel.validate().unwrap();
    let h = accel.intersect(&Ray::new(Vec3::new(10.0, 0.0, -5.0), Vec3::Z)).expect("live instance");
    assert_eq!(h.instance, 4);

    // Invalid rays.
    let cube = build(&single(testmesh::subdivided_cube(2)));
    for bad in [
        Ray::new(Vec3::new(f32::NAN, 0.0, -5.0), Vec3::Z),
        Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::new(0.0, f32::NAN, 1.0)),
        Ray::new(Vec3::new(f32::INFINITY, 0.0, -5.0), Vec3::Z),
        Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::new(0.0, 0.0, f32::INFINITY)),
        Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::ZERO),
        Ray::segment(Vec3::new(0.0, 0.0, -5.0), Vec3::Z, f32::NAN, 10.0),
        Ray::segment(Vec3::new(0.0, 0.0, -5.0), Vec3::Z, 0.0, f32::NAN),
        Ray::segment(Vec3::new(0.0, 0.0, -5.0), Vec3::Z, 7.0, 3.0),
    ] {
        assert!(cube.intersect(&bad).is_none() && !cube.occluded(&bad), "{bad:?}");
    }

    // A triangle with a NaN corner is skipped, the rest of the mesh still works.
    let mut m = testmesh::subdivided_cube(2);
    m.positions[0] = Vec3::NAN;
    let accel = build(&single(m));
    assert!(accel.intersect(&Ray::new(Vec3::new(0.5, 0.5, -5.0), Vec3::Z)).is_some());
}

#[test]
fn triangle_count_counts_instanced_triangles() {
    let s = instanced_scene();
    assert_eq!(SceneAccel::build(&s).triangle_count(), s.triangle_count());
}

#[test]
fn update_transforms_matches_a_fresh_build() {
    let mut scene = instanced_scene();
    let mut accel = SceneAccel::build(&scene);
    for (k, inst) in scene.instances.iter_mut().enumerate() {
        inst.transform = Affine3A::from_rotation_translation(
            Quat::from_rotation_y(0.5 * k as f32),
            Vec3::new(0.0, k as f32, 0.0),
        ) * inst.transform;
    }
    accel.update_transforms(&scene);
    accel.validate().unwrap();
    let brute = BruteForce::build(&scene);
    for ray in random_rays(&scene, 2000, 5) {
        check_ray(&accel, &brute, &ray).unwrap();
    }
    // A structural change (new instance) falls back to a full rebuild.
    scene.instances.push(Instance {
        mesh: 2,
        transform: Affine3A::from_translation(Vec3::Z * 6.0),
        material_override: None,
    });
    accel.update_transforms(&scene);
    assert_eq!(accel.triangle_count(), scene.triangle_count());
    let h = accel.intersect(&Ray::new(Vec3::new(0.0, 0.0, 12.0), -Vec3::Z)).unwrap();
    assert_eq!(h.instance, 5);
}

#[test]
fn hit_distance_is_in_units_of_the_unnormalised_direction() {
    let mut s = single(testmesh::subdivided_cube(2));
    s.instances[0].transform = Affine3A::from_scale(Vec3::new(2.0, 1.0, 4.0));
    let accel = SceneAccel::build(&s);
    // Box [-2,2]x[-1,1]x[-4,4]; from z = -10 along 0.5 z the face z = -4 is at t = 12.
    let h = accel.intersect(&Ray::new(Vec3::new(0.3, 0.1, -10.0), Vec3::Z * 0.5)).unwrap();
    assert!((h.t - 12.0).abs() < 1e-4, "{h:?}");
    assert!(!accel.occluded(&Ray::segment(Vec3::new(0.3, 0.1, -10.0), Vec3::Z * 0.5, 0.0, 11.9)));
    assert!(accel.occluded(&Ray::segment(Vec3::new(0.3, 0.1, -10.0), Vec3::Z * 0.5, 0.0, 12.1)));
}

/// Several identity instances (merged into one bottom level, as loaders produce one
/// instance per object) next to transformed ones; then a merged instance moves.
#[test]
fn merged_identity_instances_match_brute_force_and_survive_moves() {
    let mut scene = instanced_scene();
    scene.meshes.push(testmesh::icosphere(1));
    let mut shifted = testmesh::subdivided_cube(2);
    shifted.positions.iter_mut().for_each(|p| *p = *p * 0.5 + Vec3::new(0.0, 2.5, 0.0));
    scene.meshes.push(shifted);
    for mesh in [3, 4] {
        scene.instances.push(Instance { mesh, transform: Affine3A::IDENTITY, material_override: None });
    }
    check_scene(&scene, 2000, 8);
    let mut accel = SceneAccel::build(&scene);
    scene.instances[5].transform = Affine3A::from_translation(Vec3::new(0.0, 0.0, 3.0));
    accel.update_transforms(&scene);
    assert!(!accel.is_merged(5) && accel.is_merged(6), "the moved instance is apart, the rest merged");
    let brute = BruteForce::build_like(&scene, &accel);
    for ray in random_rays(&scene, 2000, 9) {
        check_ray(&accel, &brute, &ray).unwrap();
    }
    let h = accel.intersect(&Ray::new(Vec3::new(0.0, 0.0, 10.0), -Vec3::Z)).unwrap();
    assert_eq!(h.instance, 5);
    assert!((h.t - 6.0).abs() < 1e-4, "{h:?}");
}

/// The instanced glTF engine (34 meshes, transformed instances) against brute force.
#[test]
#[ignore = "slow: brute force over 121k triangles"]
fn gltf_engine_matches_brute_force() {
    let Some(path) = shared_path("scenes/gltf/2CylinderEngine.glb") else { return };
    let scene = filtrace_scene::load(&path).expect("engine loads");
    let accel = SceneAccel::build(&scene);
    let brute = BruteForce::build_like(&scene, &accel);
    let mut hits = 0;
    let rays = random_rays(&scene, 1500, 12);
    for ray in &rays {
        check_ray(&accel, &brute, ray).unwrap();
        hits += accel.intersect(ray).is_some() as usize;
    }
    assert!(hits > 150 && hits < 1350, "{hits}");
}

/// The built-in Cornell box (36 triangles, eight identity instances merged: the small-scene
/// path) against brute force, on random rays and on rays aimed exactly at every vertex
/// and edge midpoint from inside the room.
#[test]
fn cornell_box_matches_brute_force_at_vertices_and_edges() {
    let scene = filtrace_scene::builtin("cornell").expect("built-in cornell");
    check_scene(&scene, 3000, 13);
    let brute = BruteForce::build(&scene);
    let mut targets = Vec::new();
    for inst in &scene.instances {
        let mesh = &scene.meshes[inst.mesh as usize];
        for [a, b, c] in &mesh.indices {
            let [a, b, c] = [a, b, c].map(|&i| inst.transform.transform_point3(mesh.positions[i as usize]));
            targets.extend([a, b, c, 0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a)]);
        }
    }
    let bounds = scene.bounds();
    let origins = [bounds.center(), bounds.min + bounds.extent() * Vec3::new(0.3, 0.7, 0.4)];
    for accel in accels(&scene, &BuildParams::default()) {
        for o in origins {
            for &t in &targets {
                // Rays through the corner, and segments ending just before and after it.
                let ray = Ray::new(o, t - o);
                check_ray(&accel, &brute, &ray).unwrap_or_else(|e| panic!("{:?}: {e}", accel.simd()));
                for t_max in [0.999, 1.001] {
                    let seg = Ray::segment(o, t - o, 0.0, t_max);
                    check_ray(&accel, &brute, &seg).unwrap_or_else(|e| panic!("{:?}: {e}", accel.simd()));
                }
            }
        }
    }
}

/// A mesh holding every triangle of `mesh` twice (the copies after the originals, in
/// reverse order, so that they land in other packets and leaves).
fn doubled(mesh: &Mesh) -> Mesh {
    let mut m = mesh.clone();
    m.indices.extend(mesh.indices.iter().rev());
    m.material_ids.extend(mesh.material_ids.iter().rev());
    m
}

/// Ties (hits at bit-identical `t`) go to the smallest `(instance, prim)` in every kernel,
/// for flat and BVH bottom levels, merged and transformed instances: coincident triangles
/// (a doubled mesh, and two instances of it) and rays through shared edges and vertices.
#[test]
fn ties_go_to_the_smallest_instance_and_prim() {
    let cube = testmesh::subdivided_cube(3); // 108 triangles: a BVH
    let tiny = testmesh::subdivided_cube(1); // 12 triangles: flat
    let mut edge_ties = 0;
    let moved = Affine3A::from_scale_rotation_translation(
        Vec3::new(1.0, 2.0, 0.5),
        Quat::from_rotation_y(0.3),
        Vec3::new(0.25, 0.0, 0.0),
    );
    for base in [cube, tiny] {
        let n = base.triangle_count() as u32;
        for transform in [Affine3A::IDENTITY, moved] {
            let mut scene = Scene::default();
            scene.meshes.push(doubled(&base));
            let inst = Instance { mesh: 0, transform, material_override: None };
            scene.instances = vec![inst.clone(), inst];
            let brute = brute_like(&scene);
            // Rays from inside through every vertex and edge midpoint, and random rays.
            let mut rays = random_rays(&scene, 400, 31);
            let c = transform.transform_point3(Vec3::new(0.1, -0.2, 0.3));
            for [a, b, _] in &base.indices {
                let [a, b] = [a, b].map(|&i| transform.transform_point3(base.positions[i as usize]));
                rays.extend([Ray::new(c, a - c), Ray::new(c, 0.5 * (a + b) - c)]);
            }
            for accel in accels(&scene, &BuildParams::default()) {
                let mut hits = 0;
                for ray in &rays {
                    check_ray(&accel, &brute, ray).unwrap_or_else(|e| panic!("{:?}: {e}", accel.simd()));
                    if let Some(h) = accel.intersect(ray) {
                        hits += 1;
                        assert_eq!(h.instance, 0, "{h:?}");
                        assert!(h.prim < n, "a copy won a tie: {h:?}");
                        let ties = brute.all_hits(ray).iter().filter(|a| a.0 == h.t).count();
                        assert!(ties >= 4, "every hit is shared by at least 4 triangles: {ties}");
                        edge_ties += (ties > 4) as usize;
                    }
                }
                assert!(hits > 250, "{hits} hits");
            }
        }
    }
    // Rays through edges with bit-identical `t` on both sides (ties of 8 triangles).
    assert!(edge_ties > 100, "{edge_ties}");
}
