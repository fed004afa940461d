//! Rays and hit comparisons shared by the accel tests (included with `#[path]`; not every
//! file uses every helper).
#![allow(dead_code)]

use filtrace_accel::testmesh::SplitMix64;
use filtrace_accel::{Hit, Simd};
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

/// The kernels this CPU runs: SSE always, AVX2 where available (said when skipped).
pub fn kernels() -> Vec<Simd> {
    if Simd::Avx2.available() {
        vec![Simd::Sse, Simd::Avx2]
    } else {
        println!("SKIPPED: the AVX2 kernels (no AVX2 on this CPU)");
        vec![Simd::Sse]
    }
}
