//! Eight-ray packet queries ([`SceneAccel::intersect_packet`],
//! [`SceneAccel::occluded_packet`]) for integrators that trace eight paths in lockstep.
//!
//! Rays are stored as structure of arrays ([`RayPacket`]); an `active` bit mask selects
//! the lanes to trace. Per lane, the results are bit-identical to the single-ray queries
//! ([`SceneAccel::intersect`], [`SceneAccel::occluded`]): same hit distance, barycentrics
//! and ids, and the same answer for invalid rays (NaN or infinite components, zero
//! direction: no hit, not occluded).

#[cfg(target_arch = "x86_64")]
use crate::{avx2_packet, Simd};
use crate::{object_ray, Blas, Hit, SceneAccel, MERGED};
use filtrace_core::{Ray, Vec3};
use std::borrow::Cow;

/// Number of rays in a packet.
pub const LANES: usize = 8;

/// Fewest active lanes for which the closest-hit packet kernel beats one single-ray query
/// per lane. `cargo run --release -p filtrace-accel --example packet_lanes` (Cornell box,
/// AVX2, CPU time per ray, single / packet): 4 lanes 1.81x (camera tiles) and 1.16x
/// (incoherent), 3 lanes 1.37x and 0.88x, 2 lanes 0.94x and 0.60x.
const MIN_LANES_CLOSEST: u32 = 4;

/// The same for any-hit queries: 5 lanes 1.14x (shadow rays) and 1.27x (incoherent),
/// 4 lanes 0.91x and 1.09x.
const MIN_LANES_ANY: u32 = 5;

/// 8 rays, structure of arrays. Lane i is the ray (`origin[*][i]`, `dir[*][i]`, `t_min[i]`, `t_max[i]`).
#[derive(Clone, Copy, Debug, Default)]
pub struct RayPacket {
    pub origin: [[f32; LANES]; 3],
    pub dir: [[f32; LANES]; 3],
    pub t_min: [f32; LANES],
    pub t_max: [f32; LANES],
}

/// Closest hits of a packet: lane `i` is valid when bit `i` of `mask` is set.
#[derive(Clone, Copy, Debug, Default)]
pub struct HitPacket {
    pub mask: u8,
    pub t: [f32; LANES],
    pub u: [f32; LANES],
    pub v: [f32; LANES],
    pub instance: [u32; LANES],
    pub prim: [u32; LANES],
}

impl RayPacket {
    /// Lane `i` as a [`Ray`].
    #[inline]
    pub fn lane(&self, i: usize) -> Ray {
        Ray {
            origin: Vec3::new(self.origin[0][i], self.origin[1][i], self.origin[2][i]),
            dir: Vec3::new(self.dir[0][i], self.dir[1][i], self.dir[2][i]),
            t_min: self.t_min[i],
            t_max: self.t_max[i],
        }
    }

    /// Stores `ray` in lane `i`.
    #[inline]
    pub fn set_lane(&mut self, i: usize, ray: &Ray) {
        for k in 0..3 {
            self.origin[k][i] = ray.origin[k];
            self.dir[k][i] = ray.dir[k];
        }
        self.t_min[i] = ray.t_min;
        self.t_max[i] = ray.t_max;
    }

    /// A packet of up to eight rays (lanes past `rays.len()` stay default) and the mask of
    /// the lanes filled.
    pub fn from_rays(rays: &[Ray]) -> (Self, u8) {
        let mut p = Self::default();
        let n = rays.len().min(LANES);
        for (i, r) in rays[..n].iter().enumerate() {
            p.set_lane(i, r);
        }
        (p, ((1u32 << n) - 1) as u8)
    }
}

impl HitPacket {
    /// Lane `i` as an optional [`Hit`].
    #[inline]
    pub fn lane(&self, i: usize) -> Option<Hit> {
        (self.mask & (1 << i) != 0).then(|| Hit {
            t: self.t[i],
            u: self.u[i],
            v: self.v[i],
            instance: self.instance[i],
            prim: self.prim[i],
        })
    }

    /// Stores `hit` in lane `i` (clears the lane's bit for `None`).
    #[inline]
    pub fn set_lane(&mut self, i: usize, hit: Option<Hit>) {
        match hit {
            Some(h) => {
                self.mask |= 1 << i;
                self.t[i] = h.t;
                self.u[i] = h.u;
                self.v[i] = h.v;
                self.instance[i] = h.instance;
                self.prim[i] = h.prim;
            }
            None => self.mask &= !(1 << i),
        }
    }
}

impl SceneAccel {
    /// Closest hits of the lanes whose bit is set in `active`; bit i of the result's `mask`
    /// is set iff lane i is active and hit; per lane identical to `intersect`.
    pub fn intersect_packet(&self, rays: &RayPacket, active: u8) -> HitPacket {
        #[cfg(target_arch = "x86_64")]
        if self.simd == Simd::Avx2 && active.count_ones() >= MIN_LANES_CLOSEST {
            if let Some((object, rays, active)) = self.single_object(rays, active) {
                // SAFETY: `build_simd` keeps `Simd::Avx2` only where the CPU has AVX2 and FMA.
                if let Some(hits) = unsafe { self.intersect_packet_avx2(object, &rays, active) } {
                    return hits;
                }
            }
        }
        let active = active & valid_lanes(rays);
        if active == 0 {
            return HitPacket::default();
        }
        self.intersect_packet_lanes(rays, active)
    }

    /// Bit i set iff lane i is active and occluded; per lane identical to `occluded`.
    pub fn occluded_packet(&self, rays: &RayPacket, active: u8) -> u8 {
        #[cfg(target_arch = "x86_64")]
        if self.simd == Simd::Avx2 && active.count_ones() >= MIN_LANES_ANY {
            if let Some((object, rays, active)) = self.single_object(rays, active) {
                let blas = self.object_blas(object);
                // SAFETY: as in `intersect_packet`.
                let occluded = unsafe {
                    if blas.flat {
                        Some(avx2_packet::occluded_flat(blas, &rays, active))
                    } else {
                        avx2_packet::occluded_bvh(blas, &rays, active)
                    }
                };
                if let Some(o) = occluded {
                    return o;
                }
            }
        }
        let active = active & valid_lanes(rays);
        if active == 0 {
            return 0;
        }
        self.occluded_packet_lanes(rays, active)
    }

    /// [`SceneAccel::intersect_packet`] as one single-ray query per active lane (the
    /// reference of the tests, and the path of scenes without a packet kernel).
    pub fn intersect_packet_lanes(&self, rays: &RayPacket, active: u8) -> HitPacket {
        #[cfg(target_arch = "x86_64")]
        if self.simd == Simd::Avx2 {
            // SAFETY: as in `intersect_packet`.
            return unsafe { self.intersect_lanes_avx2(rays, active) };
        }
        let mut out = HitPacket::default();
        for i in (0..LANES).filter(|i| active & (1 << i) != 0) {
            out.set_lane(i, self.intersect(&rays.lane(i)));
        }
        out
    }

    /// [`SceneAccel::occluded_packet`] as one single-ray query per active lane (the
    /// reference of the tests, and the path of scenes without a packet kernel).
    pub fn occluded_packet_lanes(&self, rays: &RayPacket, active: u8) -> u8 {
        #[cfg(target_arch = "x86_64")]
        if self.simd == Simd::Avx2 {
            // SAFETY: as in `intersect_packet`.
            return unsafe { self.occluded_lanes_avx2(rays, active) };
        }
        (0..LANES)
            .filter(|&i| active & (1 << i) != 0 && self.occluded(&rays.lane(i)))
            .fold(0, |m, i| m | (1 << i))
    }

    /// The lane loop compiled with AVX2, so that the single-ray queries inline into it
    /// (calling `intersect` per lane cost ~10 % on the bunny).
    ///
    /// Safety: the CPU has AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn intersect_lanes_avx2(&self, rays: &RayPacket, active: u8) -> HitPacket {
        let mut out = HitPacket::default();
        for i in 0..LANES {
            let ray = rays.lane(i);
            if active & (1 << i) != 0 && ray.is_valid() {
                out.set_lane(i, self.intersect_with::<true>(&ray));
            }
        }
        out
    }

    /// As [`SceneAccel::intersect_lanes_avx2`].
    ///
    /// Safety: the CPU has AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn occluded_lanes_avx2(&self, rays: &RayPacket, active: u8) -> u8 {
        let mut out = 0;
        for i in 0..LANES {
            let ray = rays.lane(i);
            if active & (1 << i) != 0 && ray.is_valid() && self.occluded_with::<true>(&ray) {
                out |= 1 << i;
            }
        }
        out
    }

    /// When the scene is a single object (no top level): that object, the rays in its
    /// object space, and the lanes to trace there (the kernels drop invalid rays; for a
    /// transformed instance, lanes whose rays are invalid or cannot be moved into object
    /// space are dropped here, as in the single-ray query).
    fn single_object<'a>(&self, rays: &'a RayPacket, active: u8) -> Option<(u32, Cow<'a, RayPacket>, u8)> {
        let object = self.single?;
        if object == MERGED || self.instances[object as usize].identity {
            return Some((object, Cow::Borrowed(rays), active));
        }
        let rec = &self.instances[object as usize];
        let active = active & valid_lanes(rays);
        let mut local = *rays;
        let mut ok = 0u8;
        for i in (0..LANES).filter(|i| active & (1 << i) != 0) {
            let ray = rays.lane(i);
            if let Some((o, d)) = object_ray(&rec.world_to_object, rec.identity, &ray) {
                local.set_lane(i, &Ray { origin: o, dir: d, ..ray });
                ok |= 1 << i;
            }
        }
        Some((object, Cow::Owned(local), ok))
    }

    fn object_blas(&self, object: u32) -> &Blas {
        if object == MERGED {
            &self.merged
        } else {
            &self.blas[self.instances[object as usize].mesh as usize]
        }
    }

    /// The closest-hit packet query on a single object with AVX2: the flat kernel, or
    /// the packet traversal of a BVH (`None` for packets it does not take: lanes with
    /// different direction signs or permutations).
    ///
    /// Safety: the CPU has AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn intersect_packet_avx2(&self, object: u32, rays: &RayPacket, active: u8) -> Option<HitPacket> {
        let mut out = HitPacket::default();
        let blas = self.object_blas(object);
        // SAFETY: this function runs with AVX2 and FMA.
        let c = unsafe {
            if blas.flat {
                avx2_packet::closest_flat(blas, rays, active)
            } else {
                avx2_packet::closest_bvh(blas, rays, active)?
            }
        };
        for i in 0..LANES {
            let id = c.id.0[i];
            if id == avx2_packet::NO_HIT {
                continue;
            }
            let (instance, prim) =
                if object == MERGED { self.merged_refs[id as usize] } else { (object, id as u32) };
            out.mask |= 1 << i;
            (out.t[i], out.u[i], out.v[i]) = (c.t.0[i], c.u.0[i], c.v.0[i]);
            (out.instance[i], out.prim[i]) = (instance, prim);
        }
        Some(out)
    }
}

/// Lanes whose rays are valid ([`Ray::is_valid`]: finite, non-zero direction, no NaN
/// bounds); the others never hit, as in the single-ray queries.
#[inline]
fn valid_lanes(rays: &RayPacket) -> u8 {
    (0..LANES).filter(|&i| rays.lane(i).is_valid()).fold(0, |m, i| m | (1 << i))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh;
    use filtrace_scene::Scene;

    #[test]
    fn lanes_round_trip() {
        let mut p = RayPacket::default();
        let r = Ray::segment(Vec3::new(1.0, 2.0, 3.0), Vec3::new(-1.0, 0.5, 0.25), 0.1, 7.0);
        p.set_lane(5, &r);
        assert_eq!(p.lane(5), r);
        let (q, m) = RayPacket::from_rays(&[r, r, r]);
        assert_eq!(m, 0b111);
        assert_eq!(q.lane(2), r);
    }

    #[test]
    fn packet_equals_single_rays_on_a_cube() {
        let mut scene = Scene::default();
        scene.add_mesh(testmesh::subdivided_cube(4));
        let accel = SceneAccel::build(&scene);
        let mut p = RayPacket::default();
        for i in 0..LANES {
            let o = Vec3::new(-0.9 + 0.25 * i as f32, 0.3, -5.0);
            p.set_lane(i, &Ray::new(o, Vec3::Z));
        }
        p.dir[2][3] = f32::NAN;
        let h = accel.intersect_packet(&p, 0b1011_1101);
        let occ = accel.occluded_packet(&p, 0b1011_1101);
        for i in 0..LANES {
            let active = 0b1011_1101 & (1 << i) != 0;
            let single = if active { accel.intersect(&p.lane(i)) } else { None };
            assert_eq!(h.lane(i), single);
            assert_eq!(occ & (1 << i) != 0, active && accel.occluded(&p.lane(i)));
        }
        assert_ne!(h.mask, 0);
    }
}
