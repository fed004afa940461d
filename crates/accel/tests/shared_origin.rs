//! Segment fans (eight shadow segments from one origin, `SceneAccel::occluded_fan`): lane
//! by lane equal to the single-ray `occluded` and to brute force, on the Cornell box (flat
//! bottom level, and an 8-wide BVH), the Stanford bunny (../shared) and a scene of
//! instances (two levels); origins on surfaces (exactly on a triangle and offset from
//! it), segments towards points on other triangles as the VPL cache traces them, fans of
//! one class (the packet kernels' case) and of mixed classes, partial masks; both kernels.

use filtrace_accel::testmesh::{self, SplitMix64};
use filtrace_accel::{fan_class, BruteForce, BuildParams, SceneAccel, SegmentFan, Simd, FAN_CLASSES, LANES};
use filtrace_core::shared_data::shared_path;
use filtrace_core::{Affine3A, Quat, Vec3};
use filtrace_scene::{Instance, Scene};

fn kernels() -> Vec<Simd> {
    if Simd::Avx2.available() {
        vec![Simd::Sse, Simd::Avx2]
    } else {
        println!("SKIPPED: the AVX2 kernels (no AVX2 on this CPU)");
        vec![Simd::Sse]
    }
}

/// Random points on the scene's triangles (world space) with their geometric normals.
fn surface_points(scene: &Scene, n: usize, rng: &mut SplitMix64) -> Vec<(Vec3, Vec3)> {
    let tris: Vec<[Vec3; 3]> = scene
        .instances
        .iter()
        .flat_map(|inst| {
            let mesh = &scene.meshes[inst.mesh as usize];
            (0..mesh.triangle_count())
                .map(move |t| mesh.triangle(t).map(|p| inst.transform.transform_point3(p)))
        })
        .collect();
    (0..n)
        .map(|_| {
            let [a, b, c] = tris[(rng.next_u64() % tris.len() as u64) as usize];
            let (u, v) = (rng.next_f32(), rng.next_f32());
            let (u, v) = if u + v > 1.0 { (1.0 - u, 1.0 - v) } else { (u, v) };
            let n = (b - a).cross(c - a).normalize_or_zero();
            (a + u * (b - a) + v * (c - a), n)
        })
        .collect()
}

/// The fans of one origin towards `targets`: by class (as the VPL cache queues them),
/// then the same segments in arrival order (mixed classes), each with its mask.
fn fans(origin: Vec3, targets: &[Vec3], rng: &mut SplitMix64) -> Vec<(SegmentFan, u8)> {
    let mut by_class: Vec<Vec<(Vec3, f32)>> = vec![Vec::new(); FAN_CLASSES];
    let mut in_order = Vec::new();
    for &t in targets {
        let d = t - origin;
        let dist = d.length();
        if dist.is_nan() || dist <= 0.0 {
            continue;
        }
        let segment = (d / dist, dist * 0.999);
        by_class[fan_class(segment.0)].push(segment);
        in_order.push(segment);
    }
    let mut out = Vec::new();
    for group in by_class.iter().chain([&in_order]) {
        for chunk in group.chunks(LANES) {
            let mut fan = SegmentFan::new(origin, 0.0);
            for (i, &(dir, t_max)) in chunk.iter().enumerate() {
                fan.set_lane(i, dir, t_max);
            }
            let full = ((1u32 << chunk.len()) - 1) as u8;
            let mask = if rng.next_u64().is_multiple_of(4) { full & rng.next_u64() as u8 } else { full };
            out.push((fan, mask));
        }
    }
    out
}

/// Every lane of every fan against `occluded` (all fans) and brute force (every
/// `brute_every`-th fan), with every instance static (merged into world space) and, when
/// `moving` is not empty, with those instances kept in the top level; returns (occluded,
/// visible) lanes seen.
fn check_scene(
    scene: &Scene,
    moving: &[u32],
    origins: usize,
    targets: usize,
    brute_every: usize,
    seed: u64,
) -> (usize, usize) {
    let mut rng = SplitMix64(seed);
    let points = surface_points(scene, origins + targets, &mut rng);
    let (origin_points, target_points) = points.split_at(origins);
    let targets: Vec<Vec3> = target_points.iter().map(|p| p.0 + 1e-3 * p.1).collect();
    let (mut occluded, mut visible) = (0, 0);
    let params = [BuildParams::default(), BuildParams { max_flat_triangles: 0, ..BuildParams::default() }];
    let layouts: Vec<&[u32]> = if moving.is_empty() { vec![&[]] } else { vec![&[], moving] };
    for (simd, moving) in kernels().into_iter().flat_map(|k| layouts.iter().map(move |m| (k, *m))) {
        for p in &params {
            let accel = SceneAccel::build_with_moving(scene, p, simd, moving);
            let brute = BruteForce::build_like(scene, &accel);
            for (k, &(p, n)) in origin_points.iter().enumerate() {
                // Exactly on the surface, and offset along the normal to both sides.
                for origin in [p, p + 1e-3 * n, p - 1e-3 * n] {
                    for (f, (fan, mask)) in fans(origin, &targets, &mut rng).into_iter().enumerate() {
                        let answer = accel.occluded_fan(&fan, mask);
                        for i in 0..LANES {
                            let ray = fan.lane(i);
                            let expected = mask & (1 << i) != 0 && accel.occluded(&ray);
                            let got = answer & (1 << i) != 0;
                            assert_eq!(got, expected, "{simd:?}, origin {k}, fan {f}, lane {i}: {ray:?}");
                            if mask & (1 << i) != 0 && (k + f) % brute_every == 0 {
                                assert_eq!(got, brute.occluded(&ray), "brute force, origin {k}, lane {i}");
                            }
                            if mask & (1 << i) != 0 {
                                (occluded, visible) = (occluded + got as usize, visible + !got as usize);
                            }
                        }
                    }
                }
            }
        }
    }
    (occluded, visible)
}

fn assert_power((occluded, visible): (usize, usize)) {
    assert!(
        occluded > 500 && visible > 500,
        "{occluded} occluded, {visible} visible lanes: the test has power"
    );
}

#[test]
fn cornell_fans_equal_single_rays_and_brute_force() {
    let scene = filtrace_scene::builtin("cornell").expect("built-in Cornell box");
    assert_power(check_scene(&scene, &[], 24, 256, 1, 1));
}

#[test]
fn bunny_fans_equal_single_rays_and_brute_force() {
    let Some(path) = shared_path("scenes/bunny/bunny.obj") else { return };
    let mesh = testmesh::read_obj(&path).unwrap_or_else(|e| panic!("{e}"));
    let mut scene = Scene::default();
    scene.add_mesh(mesh);
    assert_power(check_scene(&scene, &[], 12, 256, 16, 2));
}

/// Instances of a flat cube and of two BVH spheres, some moved, some with the identity
/// transform (merged into one bottom level): fans go through the top level.
#[test]
fn two_level_fans_equal_single_rays_and_brute_force() {
    let mut rng = SplitMix64(3);
    let mut scene = Scene::default();
    scene.add_mesh(testmesh::subdivided_cube(2));
    scene.add_mesh(testmesh::icosphere(2));
    scene.add_mesh(testmesh::displaced_sphere(10, 0.2));
    scene.instances.clear();
    for i in 0..24 {
        let transform = if i % 5 == 0 {
            Affine3A::IDENTITY
        } else {
            let rot = Quat::from_euler(glam::EulerRot::XYZ, 6.0 * rng.next_f32(), 6.0 * rng.next_f32(), 0.0);
            let at = (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5) * 8.0;
            Affine3A::from_scale_rotation_translation(Vec3::splat(0.5 + rng.next_f32()), rot, at)
        };
        scene.instances.push(Instance { mesh: (i % 3) as u32, transform, material_override: None });
    }
    let transformed: Vec<u32> = (0..24).filter(|i| i % 5 != 0).collect();
    assert_power(check_scene(&scene, &transformed, 16, 256, 2, 4));
}
