//! Shadow segments that leave one point ("fans"): the importance cache of the many-light
//! renderer traces, per record, a segment from the record's point to every VPL.
//!
//! [`SegmentFan`] holds up to eight segments from one origin; [`SceneAccel::occluded_fan`]
//! answers them together, per lane bit-identical to [`SceneAccel::occluded`].
//! [`fan_class`] sorts directions into the 24 classes (octant x axis of the largest
//! component) within which the packet kernels' preconditions hold: equal direction signs
//! (the 8-wide box test shares its near and far planes) and one watertight permutation
//! (triangle corners broadcast to all lanes, not shuffled per lane).
//!
//! What the query does with a fan:
//! - a single flat object (the Cornell box): the flat 8 rays x 1 triangle kernel, as for any
//!   packet ([`SceneAccel::occluded_packet`]);
//! - a single object with an 8-wide BVH: one traversal for the whole fan when its lanes
//!   share a class and their directions lie within [`FAN_MAX_SPREAD`]; segments from
//!   one point visit the same nodes around it, so the bound can be wider than that of
//!   rays from a camera tile (`avx2_packet::MAX_SPREAD`);
//! - several objects: the packet walk of the top level (`packet_two_level.rs`);
//! - otherwise, and without AVX2: one single-ray query per lane.
//!
//! The shared origin only makes a fan coherent; no kernel relies on it for its answer
//! (each lane keeps its own origin), so a fan whose lanes leave different points is
//! answered as correctly, only not faster.

use crate::ray_packet::{RayPacket, LANES};
use crate::SceneAccel;
use filtrace_core::{Ray, Vec3};

/// Widest direction spread (`avx2_packet::direction_spread`, the largest per-axis range
/// of the normalised directions) for which a fan on a BVH is traversed as one packet.
pub const FAN_MAX_SPREAD: f32 = 0.03;

/// Up to eight segments `origin + t dir_i`, `t ∈ [t_min, t_max_i]`, from one origin.
#[derive(Clone, Copy, Debug)]
pub struct SegmentFan {
    rays: RayPacket,
}

impl SegmentFan {
    /// A fan from `origin` whose segments start at `t_min`; no lane set yet.
    pub fn new(origin: Vec3, t_min: f32) -> Self {
        let mut rays = RayPacket::default();
        for k in 0..3 {
            rays.origin[k] = [origin[k]; LANES];
        }
        rays.t_min = [t_min; LANES];
        SegmentFan { rays }
    }

    /// The fan's origin.
    #[inline]
    pub fn origin(&self) -> Vec3 {
        Vec3::new(self.rays.origin[0][0], self.rays.origin[1][0], self.rays.origin[2][0])
    }

    /// Lane `i` becomes the segment along `dir` up to `t_max`.
    #[inline]
    pub fn set_lane(&mut self, i: usize, dir: Vec3, t_max: f32) {
        for k in 0..3 {
            self.rays.dir[k][i] = dir[k];
        }
        self.rays.t_max[i] = t_max;
    }

    /// Lane `i` as a [`Ray`].
    #[inline]
    pub fn lane(&self, i: usize) -> Ray {
        self.rays.lane(i)
    }

    /// The fan as a ray packet (every lane with the fan's origin).
    #[inline]
    pub fn rays(&self) -> &RayPacket {
        &self.rays
    }
}

/// The class of a direction, `0..24`: bits 0-2 its octant (sign bits of x, y, z), times
/// 8 the axis of its largest component (`WatertightRay::new`'s `kz`: first on ties).
/// Directions of one class share the signs and the watertight permutation.
#[inline]
pub fn fan_class(dir: Vec3) -> usize {
    let octant = dir.x.is_sign_negative() as usize
        | (dir.y.is_sign_negative() as usize) << 1
        | (dir.z.is_sign_negative() as usize) << 2;
    let a = dir.abs();
    let x_max = (a.x >= a.y) & (a.x >= a.z);
    let kz = (!x_max as usize) * (1 + (a.y < a.z) as usize);
    octant | kz << 3
}

/// Number of [`fan_class`] values.
pub const FAN_CLASSES: usize = 24;

impl SceneAccel {
    /// Bit `i` set iff lane `i` is active and its segment is occluded; per lane identical
    /// to [`SceneAccel::occluded`] (see the module docs for how the fan is traced).
    pub fn occluded_fan(&self, fan: &SegmentFan, active: u8) -> u8 {
        #[cfg(target_arch = "x86_64")]
        if let Some(occluded) = self.occluded_fan_bvh(fan, active) {
            return occluded;
        }
        self.occluded_packet(&fan.rays, active)
    }

    /// The fan on a single object's 8-wide BVH: one traversal for the packet, or one
    /// query per lane where the kernel refuses it (lanes of different classes, too wide a
    /// spread: `occluded_packet` would refuse it too, as [`FAN_MAX_SPREAD`] is at least
    /// its bound); `None` for scenes of another shape and too few lanes.
    #[cfg(target_arch = "x86_64")]
    fn occluded_fan_bvh(&self, fan: &SegmentFan, active: u8) -> Option<u8> {
        use crate::blas::Blas;
        if self.simd != crate::Simd::Avx2 || active.count_ones() < crate::packet::MIN_LANES_ANY_BVH {
            return None;
        }
        let (object, transformed) = self.single_object()?;
        let Blas::Bvh8(bvh) = self.object_blas(object) else { return None };
        let mut local = None;
        let (rays, lanes) = self.object_rays(object, transformed, &fan.rays, active, &mut local);
        // SAFETY: `build_simd` keeps `Simd::Avx2` only where the CPU has AVX2 and FMA.
        let packet = unsafe {
            crate::avx2_packet::occluded_bvh_within(&bvh.nodes, &bvh.tris, rays, lanes, FAN_MAX_SPREAD)
        };
        Some(packet.unwrap_or_else(|| self.occluded_packet_lanes(&fan.rays, active)))
    }
}
