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
//!   share a class and their directions lie within the packet kernel's spread bound
//!   (`avx2_packet::MAX_SPREAD`, that of rays from a camera tile; whether fans, which
//!   visit the same nodes around their origin, pay at a wider bound is not measured);
//! - several objects: the packet walk of the top level (`packet_two_level.rs`);
//! - otherwise, and without AVX2: one single-ray query per lane.
//!
//! The shared origin only makes a fan coherent; no kernel relies on it for its answer
//! (each lane keeps its own origin), so a fan whose lanes leave different points is
//! answered as correctly, only not faster.

use crate::ray_packet::{RayPacket, LANES};
use crate::SceneAccel;
use filtrace_core::{Ray, Vec3};

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
    /// to [`SceneAccel::occluded`]. A fan is a packet: the class sorting makes it one the
    /// packet kernels take (see the module docs).
    pub fn occluded_fan(&self, fan: &SegmentFan, active: u8) -> u8 {
        self.occluded_packet(&fan.rays, active)
    }
}
