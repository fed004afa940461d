//! The 8-ray packet queries against the single-ray queries, lane by lane and bit for bit
//! (`t`, `u`, `v` bits, instance and primitive, occlusion), on coherent (camera tiles,
//! shadow rays towards a small quad) and incoherent rays, random active masks, invalid
//! lanes, Cornell box vertices and edges, packets of every direction spread and from
//! surfaces (the hybrid traversal); both kernels; flat, BVH and two-level scenes.

#[path = "support/rays.rs"]
mod rays;

use filtrace_accel::testmesh::{self, SplitMix64};
use filtrace_accel::{BuildParams, HitPacket, RayPacket, SceneAccel, LANES};
use filtrace_core::{Affine3A, Quat, Ray, Vec3};
use filtrace_scene::{Instance, Mesh, Scene};
use rays::{bits, kernels};

fn single(mesh: Mesh, transform: Affine3A) -> Scene {
    let mut s = Scene::default();
    s.meshes.push(mesh);
    s.instances.push(Instance { mesh: 0, transform, material_override: None });
    s
}

/// Scenes of every path: the Cornell box (merged identity instances, flat), a flat
/// mesh alone, a transformed flat mesh, BVH meshes, a two-level scene, an empty scene.
fn scenes() -> Vec<(&'static str, Scene)> {
    let moved = Affine3A::from_scale_rotation_translation(
        Vec3::new(1.5, 0.5, 2.0),
        Quat::from_euler(glam::EulerRot::XYZ, 0.3, 1.1, -0.4),
        Vec3::new(0.5, -1.0, 0.25),
    );
    let mut two_level = single(testmesh::icosphere(2), moved);
    two_level.meshes.push(testmesh::subdivided_cube(2));
    two_level.instances.push(Instance { mesh: 1, transform: Affine3A::IDENTITY, material_override: None });
    two_level.instances.push(Instance {
        mesh: 1,
        transform: Affine3A::from_translation(Vec3::new(2.5, 0.0, 0.0)),
        material_override: None,
    });
    vec![
        ("cornell", filtrace_scene::builtin("cornell").expect("built-in cornell")),
        ("cube flat", single(testmesh::subdivided_cube(1), Affine3A::IDENTITY)),
        ("cube flat moved", single(testmesh::subdivided_cube(1), moved)),
        ("displaced sphere", single(testmesh::displaced_sphere(12, 0.2), Affine3A::IDENTITY)),
        ("icosphere moved", single(testmesh::icosphere(3), moved)),
        ("two levels", two_level),
        ("empty", Scene::default()),
    ]
}

/// Every build of `scene`: both kernels, and for small scenes also without the flat path.
fn accels(scene: &Scene) -> Vec<SceneAccel> {
    let mut params = vec![BuildParams::default()];
    if scene.triangle_count() <= BuildParams::default().max_flat_triangles {
        params.push(BuildParams { max_flat_triangles: 0, ..BuildParams::default() });
    }
    params
        .iter()
        .flat_map(|p| kernels().into_iter().map(move |k| SceneAccel::build_simd(scene, p, k)))
        .collect()
}

/// Packet queries (and the hybrid closest-hit traversal, not the default) equal the
/// single-ray queries in every lane (inactive lanes: no hit).
fn check_packet(accel: &SceneAccel, rays: &RayPacket, active: u8) -> (u32, u32) {
    let hits: HitPacket = accel.intersect_packet(rays, active);
    let hybrid = accel.intersect_packet_hybrid(rays, active);
    let occ = accel.occluded_packet(rays, active);
    for i in 0..LANES {
        let ray = rays.lane(i);
        let on = active & (1 << i) != 0;
        let want = if on { accel.intersect(&ray) } else { None };
        assert_eq!(
            bits(hits.lane(i)),
            bits(want),
            "{:?} lane {i} of {active:#010b}: packet {:?} single {want:?} ray {ray:?}",
            accel.simd(),
            hits.lane(i)
        );
        assert_eq!(bits(hybrid.lane(i)), bits(want), "{:?} hybrid lane {i} of {active:#010b}", accel.simd());
        let want_occ = on && accel.occluded(&ray);
        assert_eq!(occ & (1 << i) != 0, want_occ, "{:?} occluded lane {i}: ray {ray:?}", accel.simd());
    }
    assert_eq!(hits.mask & !active, 0);
    (hits.mask.count_ones(), occ.count_ones())
}

/// Packets of four kinds: camera tiles (4x2 pixels), incoherent rays from inside,
/// shadow segments towards a small quad, and a mix of both with invalid lanes.
fn packets(scene: &Scene, n: usize, seed: u64) -> Vec<(RayPacket, u8)> {
    let b = scene.bounds();
    let (b_min, ext) = if b.is_empty() { (Vec3::splat(-1.0), Vec3::splat(2.0)) } else { (b.min, b.extent()) };
    let c = b_min + 0.5 * ext;
    let r = 0.5 * ext.length();
    let mut rng = SplitMix64(seed);
    let mut out = Vec::new();
    let eye = c + Vec3::new(0.3, 0.4, 1.0).normalize() * 2.5 * r;
    let light = c + Vec3::new(0.1 * ext.x, 0.45 * ext.y, -0.05 * ext.z);
    for k in 0..n {
        let mut p = RayPacket::default();
        let inside =
            |rng: &mut SplitMix64| b_min + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * ext;
        match k % 4 {
            0 => {
                // A 4x2 pixel tile of a 256x256 camera looking at the centre.
                let (tx, ty) = ((rng.next_u64() % 64) as f32 * 4.0, (rng.next_u64() % 128) as f32 * 2.0);
                let fwd = (c - eye).normalize();
                let right = fwd.cross(Vec3::Y).normalize();
                let up = right.cross(fwd);
                for i in 0..LANES {
                    let (px, py) = (tx + (i % 4) as f32, ty + (i / 4) as f32);
                    let d = fwd + (px / 128.0 - 1.0) * 0.45 * right + (py / 128.0 - 1.0) * 0.45 * up;
                    p.set_lane(i, &Ray::new(eye, d));
                }
            }
            1 => {
                for i in 0..LANES {
                    let t_min = if i % 3 == 0 { 0.2 * r * rng.next_f32() } else { 0.0 };
                    p.set_lane(i, &Ray::segment(inside(&mut rng), rng.unit_vector(), t_min, f32::INFINITY));
                }
            }
            2 => {
                // Shadow rays: from points in the scene to points on a small quad.
                for i in 0..LANES {
                    let o = inside(&mut rng);
                    let q = light + Vec3::new(rng.next_f32() - 0.5, 0.0, rng.next_f32() - 0.5) * 0.2 * ext;
                    p.set_lane(i, &Ray::segment(o, q - o, 1e-4, 1.0 - 1e-4));
                }
            }
            _ => {
                for i in 0..LANES {
                    let o = inside(&mut rng);
                    let ray = match rng.next_u64() % 6 {
                        0 => Ray::new(o, Vec3::ZERO),
                        1 => Ray::new(Vec3::new(f32::NAN, o.y, o.z), Vec3::X),
                        2 => Ray::new(o, Vec3::new(1.0, f32::INFINITY, 0.0)),
                        3 => Ray::segment(o, rng.unit_vector(), 0.0, f32::NAN),
                        _ => Ray::new(o, rng.unit_vector() * 3.0),
                    };
                    p.set_lane(i, &ray);
                }
            }
        }
        let active = if k % 3 == 0 { 0xff } else { rng.next_u64() as u8 };
        out.push((p, active));
    }
    out
}

#[test]
fn packets_equal_single_rays_in_every_lane() {
    for (name, scene) in scenes() {
        for accel in accels(&scene) {
            let (mut hits, mut occluded) = (0, 0);
            for (p, active) in packets(&scene, 1200, 5) {
                let (h, o) = check_packet(&accel, &p, active);
                hits += h;
                occluded += o;
            }
            if name != "empty" {
                // Enough hits and misses for the comparison to mean something.
                assert!(
                    hits > 1000 && occluded > 500,
                    "{name} {:?}: {hits} hits, {occluded} occluded",
                    accel.simd()
                );
            }
        }
    }
}

/// Rays from two points inside the Cornell box through every vertex and edge midpoint,
/// as full packets and with segments ending just before and after the target.
#[test]
fn cornell_vertices_and_edges_in_packets() {
    let scene = filtrace_scene::builtin("cornell").expect("built-in cornell");
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
    let mut rays = Vec::new();
    for o in origins {
        for &t in &targets {
            rays.push(Ray::new(o, t - o));
            rays.push(Ray::segment(o, t - o, 0.0, 0.999));
            rays.push(Ray::segment(o, t - o, 0.0, 1.001));
        }
    }
    for accel in accels(&scene) {
        for chunk in rays.chunks(LANES) {
            let (p, active) = RayPacket::from_rays(chunk);
            check_packet(&accel, &p, active);
            // The same rays in another lane order.
            let mut rev: Vec<Ray> = chunk.to_vec();
            rev.reverse();
            let (p, active) = RayPacket::from_rays(&rev);
            check_packet(&accel, &p, active);
        }
    }
}

/// A packet of eight rays whose directions lie within `spread` of `axis` (per component of
/// the unit direction, as the kernels measure it) from origins `origin(lane)`.
fn cone_packet(
    rng: &mut SplitMix64,
    axis: Vec3,
    spread: f32,
    mut origin: impl FnMut(&mut SplitMix64) -> (Vec3, f32),
    t_max: f32,
) -> RayPacket {
    let mut p = RayPacket::default();
    for i in 0..LANES {
        let jitter = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5;
        let (o, t_min) = origin(rng);
        p.set_lane(i, &Ray::segment(o, axis + jitter * spread, t_min, t_max));
    }
    p
}

/// The hybrid packet traversal's entry (packets of every direction spread, from one
/// point, from nearby points and from points on the surfaces, with `t_min` zero or
/// not, closest hits and segments, random masks) equals the single-ray queries lane for
/// lane.
#[test]
fn packets_of_every_spread_equal_single_rays() {
    let spreads = [0.0, 0.005, 0.02, 0.04, 0.1, 0.3, 1.0, 4.0];
    for (name, scene) in scenes() {
        let b = scene.bounds();
        if b.is_empty() {
            continue;
        }
        let (c, r, ext) = (b.center(), b.bounding_radius(), b.extent());
        for accel in accels(&scene) {
            let mut rng = SplitMix64(17);
            // Points on the surfaces: hits of random rays from inside.
            let surface: Vec<Vec3> = rays::random_rays(&scene, 400, 3)
                .iter()
                .filter_map(|ray| accel.intersect(ray).map(|h| ray.origin + h.t * ray.dir))
                .collect();
            assert!(surface.len() > 50, "{name}: {} surface points", surface.len());
            let (mut hits, mut occluded) = (0, 0);
            for (k, &spread) in spreads.iter().cycle().take(8 * 150).enumerate() {
                let axis = rng.unit_vector();
                let near = c + (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5) * ext;
                let p = match k % 3 {
                    0 => cone_packet(&mut rng, axis, spread, |_| (c - axis * 2.0 * r, 0.0), f32::INFINITY),
                    1 => cone_packet(
                        &mut rng,
                        axis,
                        spread,
                        |rng| (near + (rng.unit_vector() * 0.02 * r), 0.0),
                        if k % 2 == 0 { f32::INFINITY } else { 0.5 * r },
                    ),
                    _ => {
                        let i = rng.next_u64() as usize % surface.len();
                        let t_min = if k % 2 == 0 { 0.0 } else { 1e-4 * r };
                        cone_packet(
                            &mut rng,
                            axis,
                            spread,
                            |rng| {
                                let j = (i + (rng.next_u64() % 8) as usize) % surface.len();
                                (if spread < 0.05 { surface[i] } else { surface[j] }, t_min)
                            },
                            f32::INFINITY,
                        )
                    }
                };
                let active = if k % 4 == 0 { 0xff } else { rng.next_u64() as u8 | 0x0f };
                let (h, o) = check_packet(&accel, &p, active);
                hits += h;
                occluded += o;
            }
            assert!(
                hits > 1000 && occluded > 1000,
                "{name} {:?}: {hits} hits, {occluded} occluded",
                accel.simd()
            );
        }
    }
}
