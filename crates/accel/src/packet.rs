//! Eight-ray packet queries ([`SceneAccel::intersect_packet`],
//! [`SceneAccel::occluded_packet`]) for integrators that trace eight paths in lockstep.
//!
//! Rays are stored as structure of arrays ([`RayPacket`]); an `active` bit mask selects
//! the lanes to trace. Per lane, the results are bit-identical to the single-ray queries
//! ([`SceneAccel::intersect`], [`SceneAccel::occluded`]): same hit distance, barycentrics
//! and ids, and the same answer for invalid rays (NaN or infinite components, zero
//! direction: no hit, not occluded).

use crate::blas::Blas;
use crate::ray_packet::{HitPacket, RayPacket, LANES};
#[cfg(target_arch = "x86_64")]
use crate::{avx2_packet, Simd};
#[cfg(target_arch = "x86_64")]
use crate::{blas::WideBvh, flat_blas::FlatBlas};
use crate::{object_ray, SceneAccel, MERGED};
use filtrace_core::Ray;

/// Fewest active lanes for which the closest-hit packet kernel beats one single-ray query
/// per lane on a flat mesh. `cargo run --release -p filtrace-accel --example packet_lanes`
/// (Cornell box, AVX2, group boxes on both paths, CPU time per ray, single / packet): 3 lanes 1.82x
/// (camera tiles) and 1.30x (incoherent), 2 lanes 1.22x and 1.10x, 1 lane 0.74x and 0.64x.
/// Cornell render (`throughput 16 1`, 3 interleaved runs, with [`MIN_LANES_ANY`]): 4 and 5
/// lanes 2.02-2.03 M samples per CPU-s, 2 and 3 lanes 2.08-2.12, 1 and 1 2.05-2.12.
pub(crate) const MIN_LANES_CLOSEST: u32 = 2;

/// The same for any-hit queries: 4 lanes 1.17x (shadow rays) and 1.12x (incoherent),
/// 3 lanes 0.95x and 0.97x, 2 lanes 0.73x and 0.78x; the render (above) is as fast or
/// faster with 3 as with 4.
pub(crate) const MIN_LANES_ANY: u32 = 3;

/// The thresholds of the packet traversal of BVH meshes (camera tiles on the bunny, single
/// / packet: 4 lanes 1.05x, 3 lanes 0.93x; docs/perf-accel.md, third pass).
const MIN_LANES_CLOSEST_BVH: u32 = 4;
const MIN_LANES_ANY_BVH: u32 = 5;

/// Fewest active lanes for which scenes of several objects take the packet through the
/// top level (`packet_two_level.rs`) rather than one single-ray query per lane. The
/// gates of `intersect_packet`/`occluded_packet` (2 and 3 lanes) apply first; with them
/// the renders of bunny-room, engine and classroom cost fewer instructions in the ray
/// queries than per lane (docs/perf-accel.md, "Packets through the top level"; higher
/// thresholds not yet measured).
const MIN_LANES_TWO_LEVEL: u32 = 2;

impl SceneAccel {
    /// Closest hits of the lanes whose bit is set in `active`; bit i of the result's `mask`
    /// is set iff lane i is active and hit; per lane identical to `intersect`.
    pub fn intersect_packet(&self, rays: &RayPacket, active: u8) -> HitPacket {
        #[cfg(target_arch = "x86_64")]
        if self.simd == Simd::Avx2 && active.count_ones() >= MIN_LANES_CLOSEST {
            if let Some((object, transformed)) = self.single_object() {
                let mut local = None;
                let (rays, active) = self.object_rays(object, transformed, rays, active, &mut local);
                // SAFETY: `build_simd` keeps `Simd::Avx2` only where the CPU has AVX2 and FMA.
                unsafe {
                    match self.object_blas(object) {
                        // Returned as it is (an `Option` around it was a 164-byte copy).
                        Blas::Flat(flat) => return self.intersect_flat_avx2(object, flat, rays, active),
                        Blas::Bvh8(bvh) if active.count_ones() >= MIN_LANES_CLOSEST_BVH => {
                            if let Some(hits) = self.intersect_bvh_avx2(object, bvh, rays, active) {
                                return hits;
                            }
                        }
                        _ => {}
                    }
                }
            } else if active.count_ones() >= MIN_LANES_TWO_LEVEL {
                // SAFETY: as above.
                return unsafe { self.intersect_two_level(rays, active) };
            }
        }
        // (The lane loops check each active lane's validity, as the single-ray queries do.)
        self.intersect_packet_lanes(rays, active)
    }

    /// Bit i set iff lane i is active and occluded; per lane identical to `occluded`.
    pub fn occluded_packet(&self, rays: &RayPacket, active: u8) -> u8 {
        #[cfg(target_arch = "x86_64")]
        if self.simd == Simd::Avx2 && active.count_ones() >= MIN_LANES_ANY {
            if let Some((object, transformed)) = self.single_object() {
                let mut local = None;
                let (rays, active) = self.object_rays(object, transformed, rays, active, &mut local);
                // SAFETY: as in `intersect_packet`.
                let occluded = unsafe {
                    match self.object_blas(object) {
                        Blas::Flat(flat) if avx512() => {
                            Some(avx2_packet::occluded_flat_avx512(flat, rays, active))
                        }
                        Blas::Flat(flat) => Some(avx2_packet::occluded_flat(flat, rays, active)),
                        Blas::Bvh8(bvh) if active.count_ones() >= MIN_LANES_ANY_BVH => {
                            // Coherent packets (camera tiles) take the packet traversal,
                            // any other the hybrid one (docs/perf-accel.md, stop 16).
                            let (nodes, tris) = (&bvh.nodes, &bvh.tris);
                            avx2_packet::occluded_bvh(nodes, tris, rays, active).or_else(|| {
                                let min = avx2_packet::MIN_PACKET_LANES;
                                Some(avx2_packet::occluded_hybrid(nodes, tris, rays, active, min))
                            })
                        }
                        _ => None,
                    }
                };
                if let Some(o) = occluded {
                    return o;
                }
            } else if active.count_ones() >= MIN_LANES_TWO_LEVEL {
                // SAFETY: as in `intersect_packet`.
                return unsafe { self.occluded_two_level(rays, active) };
            }
        }
        self.occluded_packet_lanes(rays, active)
    }

    /// [`SceneAccel::intersect_packet`] by the hybrid packet / single-ray traversal
    /// (`avx2_packet::hybrid`) wherever the scene is a single 8-wide BVH and the CPU has
    /// AVX2, else as `intersect_packet`. Not the default: on BVH meshes it lost to one
    /// single-ray query per lane for incoherent and wide packets and to the coherent
    /// kernel for camera tiles (docs/perf-accel.md, "Stop 16"); kept for the benchmarks.
    pub fn intersect_packet_hybrid(&self, rays: &RayPacket, active: u8) -> HitPacket {
        #[cfg(target_arch = "x86_64")]
        if self.simd == Simd::Avx2 {
            if let Some((object, transformed)) = self.single_object() {
                let mut local = None;
                let (rays, active) = self.object_rays(object, transformed, rays, active, &mut local);
                if let Blas::Bvh8(bvh) = self.object_blas(object) {
                    // SAFETY: as in `intersect_packet`.
                    return unsafe { self.intersect_hybrid_avx2(object, bvh, rays, active) };
                }
            }
        }
        self.intersect_packet(rays, active)
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
        let mut left = active;
        while left != 0 {
            let i = left.trailing_zeros() as usize;
            left &= left - 1;
            let ray = rays.lane(i);
            if ray.is_valid() {
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
        let mut left = active;
        while left != 0 {
            let i = left.trailing_zeros() as usize;
            left &= left - 1;
            let ray = rays.lane(i);
            if ray.is_valid() && self.occluded_with::<true>(&ray) {
                out |= 1 << i;
            }
        }
        out
    }

    /// When the scene is a single object (no top level): that object, and whether rays
    /// must be moved into its object space ([`Self::object_space_rays`]; not for the merged
    /// meshes and untransformed instances, whose rays are used as they are, without a copy).
    #[inline]
    fn single_object(&self) -> Option<(u32, bool)> {
        let object = self.single?;
        Some((object, object != MERGED && !self.instances[object as usize].identity))
    }

    /// The single object's rays and lanes to trace: `rays` as they are, or (`transformed`)
    /// moved into its object space, in `local`.
    #[inline(always)]
    fn object_rays<'a>(
        &self,
        object: u32,
        transformed: bool,
        rays: &'a RayPacket,
        active: u8,
        local: &'a mut Option<(RayPacket, u8)>,
    ) -> (&'a RayPacket, u8) {
        if !transformed {
            return (rays, active);
        }
        let (local_rays, ok) = local.insert(self.object_space_rays(object, rays, active));
        (local_rays, *ok)
    }

    /// The rays of instance `object`'s object space, and the lanes to trace there: lanes
    /// whose rays are invalid or cannot be moved into object space are dropped, as in the
    /// single-ray query (the kernels drop invalid rays themselves).
    fn object_space_rays(&self, object: u32, rays: &RayPacket, active: u8) -> (RayPacket, u8) {
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
        (local, ok)
    }

    pub(crate) fn object_blas(&self, object: u32) -> &Blas {
        if object == MERGED {
            &self.merged
        } else {
            &self.blas[self.instances[object as usize].mesh as usize]
        }
    }

    /// The closest-hit packet query on a single flat object with AVX2 (the AVX-512VL
    /// build where the CPU has it).
    ///
    /// Safety: the CPU has AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn intersect_flat_avx2(&self, object: u32, flat: &FlatBlas, rays: &RayPacket, active: u8) -> HitPacket {
        // SAFETY: this function runs with AVX2 and FMA.
        let c = unsafe {
            if avx512() {
                avx2_packet::closest_flat_avx512(flat, rays, active)
            } else {
                avx2_packet::closest_flat(flat, rays, active)
            }
        };
        self.hit_packet(object, &c)
    }

    /// The closest-hit packet traversal of a single object's BVH with AVX2 (`None` for
    /// packets it does not take: lanes with different direction signs or permutations).
    ///
    /// Safety: the CPU has AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn intersect_bvh_avx2(
        &self,
        object: u32,
        bvh: &WideBvh<8>,
        rays: &RayPacket,
        active: u8,
    ) -> Option<HitPacket> {
        // SAFETY: this function runs with AVX2 and FMA.
        let c = unsafe { avx2_packet::closest_bvh(&bvh.nodes, &bvh.tris, rays, active)? };
        Some(self.hit_packet(object, &c))
    }

    /// The closest-hit hybrid traversal of a single object's BVH with AVX2.
    ///
    /// Safety: the CPU has AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn intersect_hybrid_avx2(
        &self,
        object: u32,
        bvh: &WideBvh<8>,
        rays: &RayPacket,
        active: u8,
    ) -> HitPacket {
        let min = avx2_packet::MIN_PACKET_LANES;
        // SAFETY: this function runs with AVX2 and FMA.
        let c = unsafe { avx2_packet::closest_hybrid(&bvh.nodes, &bvh.tris, rays, active, min) };
        self.hit_packet(object, &c)
    }

    /// The kernels' closest hits `c` on `object` as a [`HitPacket`], with vector selects
    /// instead of a branch per lane (whether a lane hit is a coin flip on some packets);
    /// lanes without a hit keep zeros, as `HitPacket::default`.
    ///
    /// Safety: the CPU has AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn hit_packet(&self, object: u32, c: &avx2_packet::Closest8) -> HitPacket {
        use std::arch::x86_64::*;
        let mut out = HitPacket::default();
        let mut refs = [[0u32; LANES]; 2];
        // SAFETY: unaligned loads and stores of 8 lanes within the arrays named.
        unsafe {
            let id = _mm256_loadu_si256(c.id.0.as_ptr() as *const __m256i);
            let miss = _mm256_cmpeq_epi32(id, _mm256_set1_epi32(avx2_packet::NO_HIT));
            let keep = |x: __m256i| _mm256_andnot_si256(miss, x);
            let ps = |x: &[f32; LANES]| _mm256_castps_si256(_mm256_loadu_ps(x.as_ptr()));
            let store = |dst: *mut __m256i, x: __m256i| _mm256_storeu_si256(dst, keep(x));
            out.mask = !(_mm256_movemask_ps(_mm256_castsi256_ps(miss)) as u8);
            store(out.t.as_mut_ptr() as *mut __m256i, ps(&c.t.0));
            store(out.u.as_mut_ptr() as *mut __m256i, ps(&c.u.0));
            store(out.v.as_mut_ptr() as *mut __m256i, ps(&c.v.0));
            if object == MERGED {
                let mut k = [0u32; LANES];
                _mm256_storeu_si256(k.as_mut_ptr() as *mut __m256i, keep(id));
                for i in 0..LANES {
                    (refs[0][i], refs[1][i]) = self.merged_refs[k[i] as usize];
                }
            } else {
                refs[0] = [object; LANES];
                _mm256_storeu_si256(refs[1].as_mut_ptr() as *mut __m256i, id);
            }
            store(
                out.instance.as_mut_ptr() as *mut __m256i,
                _mm256_loadu_si256(refs[0].as_ptr() as *const __m256i),
            );
            store(
                out.prim.as_mut_ptr() as *mut __m256i,
                _mm256_loadu_si256(refs[1].as_ptr() as *const __m256i),
            );
        }
        out
    }
}

/// The CPU has AVX-512F and AVX-512VL (the flat kernels' builds for 32 registers).
#[cfg(target_arch = "x86_64")]
#[inline]
pub(crate) fn avx512() -> bool {
    filtrace_core::cpu::isa().has_avx512()
}

/// Lanes whose rays are valid ([`Ray::is_valid`]: finite, non-zero direction, no NaN
/// bounds); the others never hit, as in the single-ray queries.
#[inline]
pub(crate) fn valid_lanes(rays: &RayPacket) -> u8 {
    (0..LANES).filter(|&i| rays.lane(i).is_valid()).fold(0, |m, i| m | (1 << i))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh;
    use filtrace_core::Vec3;
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

    /// The hybrid traversal equals the single-ray queries at every lane threshold: 0 and
    /// 1 (a packet down to the leaves, leaves of mixed permutations lane by lane), the
    /// renderer's, and 9 (every lane alone from the root), on coherent and incoherent
    /// packets with random masks.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn hybrid_equals_single_rays_at_every_threshold() {
        if !Simd::Avx2.available() {
            println!("SKIPPED: no AVX2 on this CPU");
            return;
        }
        let mut scene = Scene::default();
        scene.add_mesh(testmesh::displaced_sphere(24, 0.3));
        let accel = SceneAccel::build_simd(&scene, &crate::BuildParams::default(), Simd::Avx2);
        let (object, transformed) = accel.single_object().expect("one object");
        let Blas::Bvh8(bvh) = accel.object_blas(object) else { panic!("not an 8-wide BVH") };
        assert!(!transformed);
        let mut rng = testmesh::SplitMix64(9);
        let (mut hits, mut occluded) = (0, 0);
        for k in 0..1500 {
            let spread = [0.001, 0.03, 0.2, 3.0][k % 4];
            let axis = rng.unit_vector();
            let o = -2.5 * axis;
            let mut p = RayPacket::default();
            for i in 0..LANES {
                let jitter = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5;
                let t_max = if k % 3 == 0 { 2.5 } else { f32::INFINITY };
                p.set_lane(i, &Ray::segment(o + 0.1 * jitter, axis + spread * jitter, 0.0, t_max));
            }
            let active = if k % 2 == 0 { 0xff } else { rng.next_u64() as u8 };
            for min_lanes in [0, 1, avx2_packet::MIN_PACKET_LANES, 9] {
                // SAFETY: AVX2 checked above.
                let (h, occ) = unsafe {
                    let c = avx2_packet::closest_hybrid(&bvh.nodes, &bvh.tris, &p, active, min_lanes);
                    (
                        accel.hit_packet(object, &c),
                        avx2_packet::occluded_hybrid(&bvh.nodes, &bvh.tris, &p, active, min_lanes),
                    )
                };
                for i in 0..LANES {
                    let on = active & (1 << i) != 0;
                    let want = if on { accel.intersect(&p.lane(i)) } else { None };
                    let bits = |h: Option<crate::Hit>| {
                        h.map(|h| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits(), h.prim))
                    };
                    assert_eq!(bits(h.lane(i)), bits(want), "case {k} min {min_lanes} lane {i}");
                    assert_eq!(
                        occ & (1 << i) != 0,
                        on && accel.occluded(&p.lane(i)),
                        "case {k} min {min_lanes} lane {i}"
                    );
                }
                hits += h.mask.count_ones();
                occluded += occ.count_ones();
            }
        }
        assert!(hits > 5000 && occluded > 5000, "{hits} {occluded}");
    }
}
