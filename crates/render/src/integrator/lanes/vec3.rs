//! Eight 3-vectors ([`V8`]) mirroring glam's `Vec3` term by term.

use super::{select, F8, LANES, M8};
use filtrace_core::Vec3;
use std::ops::{Add, Div, Mul, Neg, Sub};

/// Eight 3-vectors, structure of arrays.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct V8<const A: bool> {
    pub x: F8<A>,
    pub y: F8<A>,
    pub z: F8<A>,
}

impl<const A: bool> V8<A> {
    #[inline(always)]
    pub fn new(x: F8<A>, y: F8<A>, z: F8<A>) -> V8<A> {
        V8 { x, y, z }
    }
    #[inline(always)]
    pub fn splat(v: Vec3) -> V8<A> {
        V8 { x: F8::splat(v.x), y: F8::splat(v.y), z: F8::splat(v.z) }
    }
    /// From three coordinate arrays.
    #[inline(always)]
    pub fn from_arrays(a: &[[f32; LANES]; 3]) -> V8<A> {
        V8::new(F8::from_array(a[0]), F8::from_array(a[1]), F8::from_array(a[2]))
    }
    /// The three coordinate arrays.
    #[inline(always)]
    pub fn to_arrays(self) -> [[f32; LANES]; 3] {
        [self.x.to_array(), self.y.to_array(), self.z.to_array()]
    }
    /// Lane `i` as a `Vec3`.
    #[inline(always)]
    pub fn lane(&self, i: usize) -> Vec3 {
        Vec3::new(self.x.lane(i), self.y.lane(i), self.z.lane(i))
    }
    /// Stores `v` in lane `i` (through memory: for per-lane fallbacks only).
    #[inline(always)]
    pub fn set_lane(&mut self, i: usize, v: Vec3) {
        self.x.set_lane(i, v.x);
        self.y.set_lane(i, v.y);
        self.z.set_lane(i, v.z);
    }
    /// glam's `dot`: `(x x' + y y') + z z'`.
    #[inline(always)]
    pub fn dot(self, o: V8<A>) -> F8<A> {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// glam's `length`.
    #[inline(always)]
    pub fn length(self) -> F8<A> {
        self.dot(self).sqrt()
    }
    /// glam's `normalize`: `v * (1 / length)`.
    #[inline(always)]
    pub fn normalize(self) -> V8<A> {
        let r = F8::splat(1.0) / self.length();
        self * r
    }
    #[inline(always)]
    pub fn abs(self) -> V8<A> {
        V8::new(self.x.abs(), self.y.abs(), self.z.abs())
    }
    /// glam's `max_element`: `max(x, max(y, z))`.
    #[inline(always)]
    pub fn max_element(self) -> F8<A> {
        self.x.max(self.y.max(self.z))
    }
    /// Lane-wise `self == 0` (all three components).
    #[inline(always)]
    pub fn is_zero(self) -> M8<A> {
        let z = F8::splat(0.0);
        (self.x.eq(z) & self.y.eq(z)) & self.z.eq(z)
    }
    /// Lane-wise glam `is_finite`.
    #[inline(always)]
    pub fn is_finite(self) -> M8<A> {
        self.x.is_finite() & self.y.is_finite() & self.z.is_finite()
    }
    /// Per-lane select.
    #[inline(always)]
    pub fn select(m: M8<A>, a: V8<A>, b: V8<A>) -> V8<A> {
        V8::new(select(m, a.x, b.x), select(m, a.y, b.y), select(m, a.z, b.z))
    }
}

impl<const A: bool> Add for V8<A> {
    type Output = V8<A>;
    #[inline(always)]
    fn add(self, o: V8<A>) -> V8<A> {
        V8::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}
impl<const A: bool> Sub for V8<A> {
    type Output = V8<A>;
    #[inline(always)]
    fn sub(self, o: V8<A>) -> V8<A> {
        V8::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}
/// Component-wise product (glam `Vec3 * Vec3`).
impl<const A: bool> Mul for V8<A> {
    type Output = V8<A>;
    #[inline(always)]
    fn mul(self, o: V8<A>) -> V8<A> {
        V8::new(self.x * o.x, self.y * o.y, self.z * o.z)
    }
}
/// Per-lane scale (glam `Vec3 * f32`; the product commutes exactly, so also `f32 * Vec3`).
impl<const A: bool> Mul<F8<A>> for V8<A> {
    type Output = V8<A>;
    #[inline(always)]
    fn mul(self, s: F8<A>) -> V8<A> {
        V8::new(self.x * s, self.y * s, self.z * s)
    }
}
/// Per-lane division (glam `Vec3 / f32`).
impl<const A: bool> Div<F8<A>> for V8<A> {
    type Output = V8<A>;
    #[inline(always)]
    fn div(self, s: F8<A>) -> V8<A> {
        V8::new(self.x / s, self.y / s, self.z / s)
    }
}
impl<const A: bool> Neg for V8<A> {
    type Output = V8<A>;
    #[inline(always)]
    fn neg(self) -> V8<A> {
        V8::new(-self.x, -self.y, -self.z)
    }
}
