//! Watertight ray-triangle intersection (Woop, Benthin and Wald, "Watertight Ray/Triangle
//! Intersection", JCGT 2(1), 2013).
//!
//! The ray is turned into a ray along +z through the origin by a per-ray permutation
//! (`kx, ky, kz`, `kz` the dominant axis) and shear (`S_x, S_y, S_z`); a triangle is then
//! hit when the three 2D edge functions `U, V, W` of its sheared vertices share a sign.
//! Two triangles sharing an edge evaluate that edge's function on bit-identical inputs
//! (with opposite sign), so a ray through the edge hits at least one of them; when an
//! edge function is exactly zero it is recomputed in `f64`, as the paper recommends.

use filtrace_core::{Ray, Vec3};

/// Per-ray constants of the watertight test (Woop et al. 2013, section 3, fig. 4).
#[derive(Clone, Copy, Debug)]
pub struct WatertightRay {
    pub org: [f32; 3],
    /// Permutation: `kz` is the axis of largest `|dir|`; `kx, ky` keep the winding.
    pub kx: usize,
    pub ky: usize,
    pub kz: usize,
    /// Shear constants `S_x = d_kx / d_kz`, `S_y = d_ky / d_kz`, `S_z = 1 / d_kz`.
    pub sx: f32,
    pub sy: f32,
    pub sz: f32,
}

impl WatertightRay {
    /// Precomputes the permutation and shear. `dir` must be finite and non-zero.
    #[inline]
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        // Branch-free (bit operations and table lookups instead of `if`s): for incoherent
        // rays the dominant axis and its sign are random, and the mispredicted branches
        // cost as much as a triangle packet test on small scenes. Same result as
        // `kz = argmax |d|` (first axis on ties), `kx, ky` the next axes, swapped when
        // `d[kz] < 0`.
        // The components are read from an array: `Vec3`'s `Index` is a `match`, which
        // compiled to two data-dependent branches per lookup.
        let a = dir.abs();
        let d = dir.to_array();
        let x_max = (a.x >= a.y) & (a.x >= a.z);
        let z_over_y = a.y < a.z;
        let kz = (!x_max as usize) * (1 + z_over_y as usize);
        // `kx = [1, 2, 0][kz]`, `ky = [2, 0, 1][kz]` as two-bit fields of a constant (the
        // arrays were written to the stack on every ray).
        let (kx, ky) = ((0b00_10_01 >> (2 * kz)) & 3, (0b01_00_10 >> (2 * kz)) & 3);
        // Swap kx and ky to preserve the winding direction of triangles.
        let swap = 0usize.wrapping_sub((d[kz] < 0.0) as usize);
        let (kx, ky) = (kx ^ ((kx ^ ky) & swap), ky ^ ((kx ^ ky) & swap));
        let sz = 1.0 / d[kz];
        Self { org: origin.to_array(), kx, ky, kz, sx: d[kx] * sz, sy: d[ky] * sz, sz }
    }
}

/// A triangle stored as three corner positions (the layout the BVH leaves use).
pub type Tri = [[f32; 3]; 3];

/// Watertight test of triangle `tri` against a ray; returns `(t, u, v)` with `t` in
/// `[t_min, t_max]` and barycentrics `p = (1-u-v) p0 + u p1 + v p2`. Both faces hit.
#[inline(always)]
pub fn intersect_watertight(r: &WatertightRay, tri: &Tri, t_min: f32, t_max: f32) -> Option<(f32, f32, f32)> {
    let (kx, ky, kz) = (r.kx, r.ky, r.kz);
    // Vertices relative to the ray origin (step 1 of the paper).
    let a = sub(&tri[0], &r.org);
    let b = sub(&tri[1], &r.org);
    let c = sub(&tri[2], &r.org);
    // Shear and scale (step 2).
    let ax = a[kx] - r.sx * a[kz];
    let ay = a[ky] - r.sy * a[kz];
    let bx = b[kx] - r.sx * b[kz];
    let by = b[ky] - r.sy * b[kz];
    let cx = c[kx] - r.sx * c[kz];
    let cy = c[ky] - r.sy * c[kz];
    // Scaled barycentric coordinates: 2D edge functions (step 3).
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    if u == 0.0 || v == 0.0 || w == 0.0 {
        // Fall back to double precision on the edge (section 3.3).
        u = (cx as f64 * by as f64 - cy as f64 * bx as f64) as f32;
        v = (ax as f64 * cy as f64 - ay as f64 * cx as f64) as f32;
        w = (bx as f64 * ay as f64 - by as f64 * ax as f64) as f32;
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    // Scaled hit distance (step 4).
    let az = r.sz * a[kz];
    let bz = r.sz * b[kz];
    let cz = r.sz * c[kz];
    let t_scaled = u * az + v * bz + w * cz;
    let rcp = 1.0 / det;
    let t = t_scaled * rcp;
    // NaN (from non-finite vertices) fails both comparisons and is rejected here.
    if t >= t_min && t <= t_max {
        Some((t, v * rcp, w * rcp))
    } else {
        None
    }
}

#[inline(always)]
fn sub(p: &[f32; 3], o: &[f32; 3]) -> [f32; 3] {
    [p[0] - o[0], p[1] - o[1], p[2] - o[2]]
}

/// Möller-Trumbore test in `f64` ("Fast, minimum storage ray/triangle intersection",
/// 1997): an independent reference for tests, not used by the BVH.
pub fn intersect_moller_trumbore_f64(ray: &Ray, tri: &[Vec3; 3]) -> Option<(f64, f64, f64)> {
    let d = ray.dir.as_dvec3();
    let o = ray.origin.as_dvec3();
    let p0 = tri[0].as_dvec3();
    let e1 = tri[1].as_dvec3() - p0;
    let e2 = tri[2].as_dvec3() - p0;
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - p0;
    let u = s.dot(p) * inv;
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    if u < 0.0 || v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    (t >= ray.t_min as f64 && t <= ray.t_max as f64).then_some((t, u, v))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The branch-free permutation equals the `if` chain of the paper (Woop et al. 2013,
    /// fig. 4), including ties, zeros and signs.
    #[test]
    fn permutation_matches_the_reference_if_chain() {
        let reference = |d: Vec3| {
            let a = d.abs();
            let kz = if a.x >= a.y && a.x >= a.z {
                0
            } else if a.y >= a.z {
                1
            } else {
                2
            };
            let mut kx = if kz == 2 { 0 } else { kz + 1 };
            let mut ky = if kx == 2 { 0 } else { kx + 1 };
            if d[kz] < 0.0 {
                std::mem::swap(&mut kx, &mut ky);
            }
            (kx, ky, kz)
        };
        let vals = [-2.0f32, -1.0, -0.0, 0.0, 0.5, 1.0, 2.0];
        let mut n = 0;
        for &x in &vals {
            for &y in &vals {
                for &z in &vals {
                    let d = Vec3::new(x, y, z);
                    if d == Vec3::ZERO {
                        continue;
                    }
                    let r = WatertightRay::new(Vec3::ZERO, d);
                    assert_eq!((r.kx, r.ky, r.kz), reference(d), "{d}");
                    n += 1;
                }
            }
        }
        assert!(n > 300);
    }

    fn hit(o: Vec3, d: Vec3, tri: &[Vec3; 3]) -> Option<(f32, f32, f32)> {
        let t = tri.map(|p| p.to_array());
        intersect_watertight(&WatertightRay::new(o, d), &t, 0.0, f32::INFINITY)
    }

    #[test]
    fn barycentrics_reproduce_the_hit_point() {
        let tri = [Vec3::new(0.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 1.5), Vec3::new(0.0, 3.0, 2.0)];
        let o = Vec3::new(0.3, 0.4, -1.0);
        let target = 0.5 * tri[0] + 0.2 * tri[1] + 0.3 * tri[2];
        let d = (target - o) * 0.5; // unnormalised: t must come out as 2
        let (t, u, v) = hit(o, d, &tri).expect("hit");
        assert!((t - 2.0).abs() < 1e-5, "t = {t}");
        assert!((u - 0.2).abs() < 1e-5 && (v - 0.3).abs() < 1e-5, "u = {u}, v = {v}");
        let p = (1.0 - u - v) * tri[0] + u * tri[1] + v * tri[2];
        assert!((p - o - t * d).length() < 1e-5);
    }

    #[test]
    fn agrees_with_moller_trumbore_on_random_rays() {
        let mut s = 0x1234_5678_u64;
        let mut rnd = move || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        };
        let (mut hits, mut agree) = (0, 0);
        for _ in 0..20_000 {
            let tri = [0, 1, 2].map(|_| Vec3::new(rnd(), rnd(), rnd()));
            let o = Vec3::new(rnd(), rnd(), rnd()) * 2.0;
            // Aim near the triangle so that about half of the rays hit.
            let (a, b) = (0.7 * rnd() + 0.5, 0.7 * rnd() + 0.5);
            let d = (tri[0] + a * (tri[1] - tri[0]) + b * (tri[2] - tri[0]) - o) * (rnd() + 1.5);
            let a = hit(o, d, &tri);
            let b = intersect_moller_trumbore_f64(&Ray::new(o, d), &tri);
            hits += a.is_some() as usize;
            match (a, b) {
                (Some(a), Some(b)) => {
                    assert!((a.0 as f64 - b.0).abs() <= 1e-3 * b.0.abs().max(1.0));
                    agree += 1;
                }
                (None, None) => agree += 1,
                _ => {}
            }
        }
        assert!(hits > 5000 && hits < 15_000, "too few hits ({hits}) for the test to mean anything");
        // Disagreements only on rays grazing an edge within float rounding.
        assert!(agree >= 19_990, "agree = {agree}");
    }

    #[test]
    fn nan_vertex_never_hits() {
        let tri = [Vec3::new(f32::NAN, 0.0, 1.0), Vec3::new(1.0, 0.0, 1.0), Vec3::new(0.0, 1.0, 1.0)];
        assert!(hit(Vec3::new(0.2, 0.2, 0.0), Vec3::Z, &tri).is_none());
    }
}
