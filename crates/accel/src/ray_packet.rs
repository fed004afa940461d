//! Eight rays and their hits as structure of arrays: what integrators that trace eight
//! paths in lockstep hand to [`crate::SceneAccel::intersect_packet`] and
//! [`crate::SceneAccel::occluded_packet`].

use crate::Hit;
use filtrace_core::{Ray, Vec3};

/// Number of rays in a packet.
pub const LANES: usize = 8;

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
