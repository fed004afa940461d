//! Rays, hit comparisons and the brute-force check shared by the accel tests (included
//! with `#[path]`; not every file uses every helper).
#![allow(dead_code)]

use filtrace_accel::testmesh::SplitMix64;
use filtrace_accel::{BruteForce, Hit, RayPacket, SceneAccel, Simd, LANES};
use filtrace_core::{Ray, Vec3};
use filtrace_scene::Scene;

/// Rays of every kind: from inside the bounds, from outside aimed at them, short
/// segments, and segments starting past `t_min > 0`.
pub fn random_rays(scene: &Scene, n: usize, seed: u64) -> Vec<Ray> {
    let b = scene.bounds();
    let (c, r) = (b.center(), b.bounding_radius());
    let mut rng = SplitMix64(seed);
    (0..n)
        .map(|i| {
            let inside = b.min + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * b.extent();
            match i % 4 {
                0 => Ray::new(inside, rng.unit_vector()),
                1 => {
                    let o = c + rng.unit_vector() * 2.0 * r;
                    Ray::new(o, (inside - o) * (0.1 + 3.0 * rng.next_f32()))
                }
                2 => Ray::segment(inside, rng.unit_vector(), 0.0, r * rng.next_f32()),
                _ => Ray::segment(inside, rng.unit_vector() * 2.0, 0.3 * r * rng.next_f32(), f32::INFINITY),
            }
        })
        .collect()
}

/// The bits of a hit (`t`, `u`, `v`, instance, primitive), for exact comparisons.
pub fn bits(h: Option<Hit>) -> Option<(u32, u32, u32, u32, u32)> {
    h.map(|h| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits(), h.instance, h.prim))
}

/// Every ray, singly and in packets of [`LANES`] consecutive rays: the closest hit equals
/// brute force's bit for bit and the occlusion equals whether brute force hits (each
/// packet lane against brute force too, not only against the single ray); returns how
/// many rays hit. A failure names `name`, the ray and every brute-force hit along it.
pub fn check_rays(accel: &SceneAccel, brute: &BruteForce, rays: &[Ray], name: &str) -> usize {
    let want: Vec<Option<Hit>> = rays.iter().map(|r| brute.intersect(r)).collect();
    for (ray, &want) in rays.iter().zip(&want) {
        assert_eq!(
            bits(accel.intersect(ray)),
            bits(want),
            "{name}: ray {ray:?}; all hits {:?}",
            brute.all_hits(ray)
        );
        assert_eq!(accel.occluded(ray), want.is_some(), "{name}: occlusion of {ray:?}");
    }
    for (chunk, want) in rays.chunks(LANES).zip(want.chunks(LANES)) {
        let (packet, active) = RayPacket::from_rays(chunk);
        let (closest, occluded) =
            (accel.intersect_packet(&packet, active), accel.occluded_packet(&packet, active));
        for (i, (ray, &want)) in chunk.iter().zip(want).enumerate() {
            assert_eq!(bits(closest.lane(i)), bits(want), "{name}: packet lane {i}, ray {ray:?}");
            assert_eq!(occluded & (1 << i) != 0, want.is_some(), "{name}: packet occlusion of {ray:?}");
        }
    }
    want.iter().filter(|w| w.is_some()).count()
}

/// The kernels this CPU runs: SSE always, AVX2 where available (said when skipped).
pub fn kernels() -> Vec<Simd> {
    if Simd::Avx2.available() {
        vec![Simd::Sse, Simd::Avx2]
    } else {
        println!("SKIPPED: the AVX2 kernels (no AVX2 on this CPU)");
        vec![Simd::Sse]
    }
}
