//! The group boxes of flat bottom levels only cull: on the Cornell box (one flat mesh of
//! 36 triangles) the hits equal brute force bit for bit also for the rays where a box
//! test and the watertight test's rounding disagree most easily: origins on the walls'
//! planes and a few ulps to a thousandth of a unit off them (as a renderer spawns its
//! rays, `t_min = 0`), grazing directions, and shadow segments that end just short of the
//! light. Single rays, 8-ray packets with every lane count, both kernels, the flat bottom
//! level and a BVH over the same triangles.

#[path = "support/rays.rs"]
mod rays;

use filtrace_accel::testmesh::SplitMix64;
use filtrace_accel::{BruteForce, BuildParams, RayPacket, SceneAccel, Simd, LANES};
use filtrace_core::{Ray, Vec3};
use rays::bits;

/// Rays from points of the Cornell box's triangles pushed off their planes by `offsets`
/// along the normal, in random and in grazing directions, plus shadow segments from
/// those points towards the light quad ending `1e-4` of the distance short of it.
fn wall_rays(scene: &filtrace_scene::Scene, n: usize) -> Vec<Ray> {
    let tris: Vec<[Vec3; 3]> = scene
        .instances
        .iter()
        .flat_map(|i| {
            let m = &scene.meshes[i.mesh as usize];
            (0..m.triangle_count()).map(move |p| m.triangle(p))
        })
        .collect();
    let offsets = [0.0f32, 1e-6, -1e-6, 1e-5, -1e-5, 1e-4, -1e-4, 5e-4, -5e-4, 1e-3, 1e-2];
    let mut rng = SplitMix64(0x5eed_f1a7);
    let mut rays = Vec::with_capacity(n);
    while rays.len() < n {
        let t = tris[(rng.next_f32() * tris.len() as f32) as usize % tris.len()];
        let (a, b) = (rng.next_f32(), rng.next_f32());
        let (a, b) = if a + b > 1.0 { (1.0 - a, 1.0 - b) } else { (a, b) };
        let normal = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
        let mut p = t[0] + a * (t[1] - t[0]) + b * (t[2] - t[0]);
        // Axis-aligned planes: the point exactly in the plane before the offset.
        let n = normal.abs();
        let axis = if n.x >= n.y && n.x >= n.z {
            0
        } else if n.y >= n.z {
            1
        } else {
            2
        };
        if normal.abs()[axis] == 1.0 {
            p[axis] = t[0][axis];
        }
        let o = p + normal * offsets[rays.len() % offsets.len()];
        let d = match rays.len() % 4 {
            0 => rng.unit_vector(),
            // Grazing: almost in the plane.
            1 => {
                let v = rng.unit_vector();
                (v - normal * v.dot(normal) + normal * (1e-3 * (rng.next_f32() - 0.5))).normalize()
            }
            2 => {
                let v = rng.unit_vector();
                if v.dot(normal) < 0.0 {
                    -v
                } else {
                    v
                }
            }
            _ => {
                let target = Vec3::new(213.0 + 130.0 * rng.next_f32(), 548.7, 227.0 + 105.0 * rng.next_f32());
                let dist = (target - o).length();
                rays.push(Ray::segment(o, (target - o) / dist, 0.0, dist * (1.0 - 1e-4)));
                continue;
            }
        };
        if d.is_finite() && d != Vec3::ZERO {
            rays.push(Ray::new(o, d));
        }
    }
    rays
}

#[test]
fn cornell_wall_rays_hit_as_brute_force() {
    let scene = filtrace_scene::builtin("cornell").expect("cornell");
    let brute = BruteForce::build(&scene);
    let rays = wall_rays(&scene, 40_000);
    let kernels: Vec<Simd> = [Simd::Sse, Simd::Avx2].into_iter().filter(|k| k.available()).collect();
    let mut rng = SplitMix64(17);
    let (mut hits, mut occluded) = (0, 0);
    // The flat bottom level, and a BVH over the same 36 triangles (its node boxes must
    // be as conservative as the group boxes).
    let flat = BuildParams::default();
    let bvh = BuildParams { max_flat_triangles: 0, ..BuildParams::default() };
    for (k, params) in kernels.iter().flat_map(|&k| [(k, &flat), (k, &bvh)]) {
        let accel = SceneAccel::build_simd(&scene, params, k);
        let expect: Vec<_> = rays.iter().map(|r| (bits(brute.intersect(r)), brute.occluded(r))).collect();
        for (r, e) in rays.iter().zip(&expect) {
            assert_eq!(bits(accel.intersect(r)), e.0, "{k:?} {r:?}");
            assert_eq!(accel.occluded(r), e.1, "{k:?} {r:?}");
            hits += e.0.is_some() as usize;
            occluded += e.1 as usize;
        }
        for (chunk, e) in rays.chunks(LANES).zip(expect.chunks(LANES)) {
            let (p, all) = RayPacket::from_rays(chunk);
            // Every lane count, the lanes chosen at random.
            let active = all & (rng.next_f32() * 256.0) as u8 | (1 << (chunk.len() - 1));
            let h = accel.intersect_packet(&p, active);
            let o = accel.occluded_packet(&p, active);
            for i in 0..chunk.len() {
                let on = active & (1 << i) != 0;
                assert_eq!(bits(h.lane(i)), if on { e[i].0 } else { None }, "{k:?} lane {i} {:?}", chunk[i]);
                assert_eq!(o & (1 << i) != 0, on && e[i].1, "{k:?} lane {i} {:?}", chunk[i]);
            }
        }
    }
    // The rays mean something: most hit, and some shadow segments are blocked.
    assert!(hits > rays.len() / 2 && occluded > rays.len() / 2, "{hits} hits, {occluded} occluded");
}

/// A flat bottom level of 2k triangles (`max_flat_triangles` raised: groups are runs of
/// triangles then) answers as brute force.
#[test]
fn large_flat_mesh_hits_as_brute_force() {
    let mut scene = filtrace_scene::Scene::default();
    scene.add_mesh(filtrace_accel::testmesh::displaced_sphere(18, 0.1));
    assert!(scene.triangle_count() > 1000);
    let brute = BruteForce::build(&scene);
    let params = BuildParams { max_flat_triangles: usize::MAX, ..BuildParams::default() };
    let accel = SceneAccel::build_with(&scene, &params);
    let mut rng = SplitMix64(3);
    let rays: Vec<Ray> = (0..2000)
        .map(|_| {
            Ray::new(Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 3.0 - 1.5, rng.unit_vector())
        })
        .collect();
    for chunk in rays.chunks(LANES) {
        let (p, all) = RayPacket::from_rays(chunk);
        let (h, o) = (accel.intersect_packet(&p, all), accel.occluded_packet(&p, all));
        for (i, r) in chunk.iter().enumerate() {
            let e = bits(brute.intersect(r));
            assert_eq!(bits(accel.intersect(r)), e, "{r:?}");
            assert_eq!(bits(h.lane(i)), e, "{r:?}");
            assert_eq!(o & (1 << i) != 0, brute.occluded(r), "{r:?}");
        }
    }
}
