//! The packet's box tests, 8 rays x 1 box, lane for lane the fused slab test of
//! `avx2::box8` (`avx2::RayBoxes8::new`'s constants, [`slab`]): [`Boxes8`] for lanes of
//! one direction octant (coherent packets), [`LaneBoxes`] for any (the hybrid traversal,
//! flat meshes); and the direction spread that decides whether a packet is coherent.

use super::lanes::{lane_mask, ld};
use crate::ray_packet::RayPacket;
use crate::wide::{Node8, CULL_SCALE, FAR_SCALE};
use std::arch::x86_64::*;

/// One axis of the conservative slab test, lane for lane as `avx2::RayBoxes8::new`:
/// `(inv, o inv + e, o inv - e)` with `inv = 1 / d` (components of `d` below 1e-30 in
/// magnitude replaced by +-1e-30) and `e` the rounding slack of `o inv`.
#[inline(always)]
pub(super) unsafe fn slab(o: __m256, d: __m256) -> (__m256, __m256, __m256) {
    let sign = _mm256_castsi256_ps(_mm256_set1_epi32(i32::MIN));
    let abs = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
    let tiny = _mm256_set1_ps(1e-30);
    let small = _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_and_ps(d, abs), tiny);
    let d = _mm256_blendv_ps(d, _mm256_or_ps(_mm256_and_ps(d, sign), tiny), small);
    let inv = _mm256_div_ps(_mm256_set1_ps(1.0), d);
    let c = _mm256_mul_ps(o, inv);
    let e =
        _mm256_add_ps(_mm256_mul_ps(_mm256_and_ps(c, abs), _mm256_set1_ps(1.0 / (1u32 << 21) as f32)), tiny);
    (inv, _mm256_add_ps(c, e), _mm256_sub_ps(c, e))
}

/// The slab constants of the eight lanes, [`slab`] per axis.
#[derive(Clone, Copy)]
pub(super) struct Slabs {
    inv: [__m256; 3],
    oinv_near: [__m256; 3],
    oinv_far: [__m256; 3],
}

impl Slabs {
    #[inline(always)]
    unsafe fn new(rays: &RayPacket) -> Self {
        let zero = _mm256_setzero_ps();
        let mut s = Self { inv: [zero; 3], oinv_near: [zero; 3], oinv_far: [zero; 3] };
        for k in 0..3 {
            (s.inv[k], s.oinv_near[k], s.oinv_far[k]) = slab(ld(&rays.origin[k]), ld(&rays.dir[k]));
        }
        s
    }

    /// Lanes of `lanes` whose rays touch the box with near planes `bn` and far planes `bf`
    /// (per axis and lane) with `t` in `[t_min, t_cull]`, and their entry distances: the
    /// fused slab distances, then `avx2::box8`'s min/max order and far widening.
    #[inline(always)]
    unsafe fn touch(
        &self,
        bn: [__m256; 3],
        bf: [__m256; 3],
        t_min: __m256,
        t_cull: __m256,
        lanes: __m256,
    ) -> (u32, __m256) {
        let nx = _mm256_fmsub_ps(bn[0], self.inv[0], self.oinv_near[0]);
        let fx = _mm256_fmsub_ps(bf[0], self.inv[0], self.oinv_far[0]);
        let ny = _mm256_fmsub_ps(bn[1], self.inv[1], self.oinv_near[1]);
        let fy = _mm256_fmsub_ps(bf[1], self.inv[1], self.oinv_far[1]);
        let nz = _mm256_fmsub_ps(bn[2], self.inv[2], self.oinv_near[2]);
        let fz = _mm256_fmsub_ps(bf[2], self.inv[2], self.oinv_far[2]);
        let t_near = _mm256_max_ps(nz, _mm256_max_ps(ny, _mm256_max_ps(nx, t_min)));
        let t_far = _mm256_min_ps(fz, _mm256_min_ps(fy, _mm256_min_ps(fx, t_cull)));
        let t_far = _mm256_mul_ps(t_far, _mm256_set1_ps(FAR_SCALE));
        let hit = _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t_near, t_far), lanes);
        (_mm256_movemask_ps(hit) as u32, t_near)
    }
}

/// The packet's box test of one child (8 rays x 1 box): [`Boxes8`] for lanes of one
/// direction octant, [`LaneBoxes`] for any.
pub(super) trait ChildBoxes {
    /// Lanes of `lanes` whose rays touch child `i` of `n` (the test of `avx2::box8`, lane
    /// for lane) and their entry distances.
    unsafe fn child(
        &self,
        n: &Node8,
        i: usize,
        t_min: __m256,
        t_cull: __m256,
        lanes: __m256,
    ) -> (u32, __m256);
}

/// [`Slabs`] for lanes that share their direction signs: the near and far bound rows of
/// each axis are the same for all of them.
pub(super) struct Boxes8 {
    slabs: Slabs,
    near: [usize; 3],
    far: [usize; 3],
}

impl Boxes8 {
    /// `None` when the lanes `active` differ in direction sign on some axis (lanes with
    /// NaN directions count as differing).
    #[inline(always)]
    pub(super) unsafe fn new(rays: &RayPacket, active: u32) -> Option<Self> {
        // Sign bits first (incoherent packets stop here, before any division).
        for d in &rays.dir {
            let neg = _mm256_movemask_ps(ld(d)) as u32 & active;
            if neg != 0 && neg != active {
                return None;
            }
        }
        let slabs = Slabs::new(rays);
        let (mut near, mut far) = ([0; 3], [0; 3]);
        for k in 0..3 {
            let pos = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(slabs.inv[k], _mm256_setzero_ps()))
                as u32
                & active;
            (near[k], far[k]) = if pos == active {
                (k, k + 3)
            } else if pos == 0 {
                (k + 3, k)
            } else {
                return None;
            };
        }
        Some(Self { slabs, near, far })
    }
}

impl ChildBoxes for Boxes8 {
    #[inline(always)]
    unsafe fn child(
        &self,
        n: &Node8,
        i: usize,
        t_min: __m256,
        t_cull: __m256,
        lanes: __m256,
    ) -> (u32, __m256) {
        let b = &n.bounds;
        let (mut bn, mut bf) = ([_mm256_setzero_ps(); 3], [_mm256_setzero_ps(); 3]);
        for k in 0..3 {
            (bn[k], bf[k]) = (_mm256_set1_ps(b[self.near[k]][i]), _mm256_set1_ps(b[self.far[k]][i]));
        }
        self.slabs.touch(bn, bf, t_min, t_cull, lanes)
    }
}

/// [`Slabs`] for lanes of any direction signs: per axis, the lanes whose near plane is the
/// box's upper one.
pub(super) struct LaneBoxes {
    slabs: Slabs,
    /// All ones in lanes with `1 / d < 0` on the axis (`avx2::RayBoxes8`'s row choice).
    neg: [__m256; 3],
}

impl LaneBoxes {
    #[inline(always)]
    pub(super) unsafe fn new(rays: &RayPacket) -> Self {
        let slabs = Slabs::new(rays);
        let mut neg = [_mm256_setzero_ps(); 3];
        for (n, inv) in neg.iter_mut().zip(slabs.inv) {
            *n = _mm256_cmp_ps::<_CMP_LT_OQ>(inv, _mm256_setzero_ps());
        }
        Self { slabs, neg }
    }

    /// Lanes of `lanes` whose rays touch the box `lo..hi` with `t` in `[t_min, t_cull]`,
    /// and their entry distances.
    #[inline(always)]
    pub(super) unsafe fn touch(
        &self,
        lo: [f32; 3],
        hi: [f32; 3],
        t_min: __m256,
        t_cull: __m256,
        lanes: __m256,
    ) -> (u32, __m256) {
        let mut bn = [_mm256_setzero_ps(); 3];
        let mut bf = [_mm256_setzero_ps(); 3];
        for k in 0..3 {
            let (l, h) = (_mm256_set1_ps(lo[k]), _mm256_set1_ps(hi[k]));
            (bn[k], bf[k]) = (_mm256_blendv_ps(l, h, self.neg[k]), _mm256_blendv_ps(h, l, self.neg[k]));
        }
        self.slabs.touch(bn, bf, t_min, t_cull, lanes)
    }
}

impl ChildBoxes for LaneBoxes {
    #[inline(always)]
    unsafe fn child(
        &self,
        n: &Node8,
        i: usize,
        t_min: __m256,
        t_cull: __m256,
        lanes: __m256,
    ) -> (u32, __m256) {
        let b = &n.bounds;
        self.touch([b[0][i], b[1][i], b[2][i]], [b[3][i], b[4][i], b[5][i]], t_min, t_cull, lanes)
    }
}

/// Largest spread of the active lanes' directions: the maximum over the axes of
/// `max - min` of the normalised direction component. Only decides between the packet
/// traversal and per-lane queries (never the result).
#[inline(always)]
pub(super) unsafe fn direction_spread(rays: &RayPacket, active: u32) -> f32 {
    let [dx, dy, dz] = [ld(&rays.dir[0]), ld(&rays.dir[1]), ld(&rays.dir[2])];
    let len2 =
        _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)), _mm256_mul_ps(dz, dz));
    let inv = _mm256_rsqrt_ps(len2);
    let act = lane_mask(active);
    let (inf, neg_inf) = (_mm256_set1_ps(f32::INFINITY), _mm256_set1_ps(f32::NEG_INFINITY));
    // Per lane the largest spread is found after the horizontal min and max of each axis.
    let (mut lo, mut hi) = ([inf; 3], [neg_inf; 3]);
    for (k, d) in [dx, dy, dz].into_iter().enumerate() {
        let n = _mm256_mul_ps(d, inv);
        let (l, h) = (_mm256_blendv_ps(inf, n, act), _mm256_blendv_ps(neg_inf, n, act));
        let l = _mm256_min_ps(l, _mm256_permute2f128_ps::<1>(l, l));
        let h = _mm256_max_ps(h, _mm256_permute2f128_ps::<1>(h, h));
        let l = _mm256_min_ps(l, _mm256_permute_ps::<0b01_00_11_10>(l));
        let h = _mm256_max_ps(h, _mm256_permute_ps::<0b01_00_11_10>(h));
        lo[k] = _mm256_min_ps(l, _mm256_permute_ps::<0b10_11_00_01>(l));
        hi[k] = _mm256_max_ps(h, _mm256_permute_ps::<0b10_11_00_01>(h));
    }
    let spread = _mm256_max_ps(
        _mm256_sub_ps(hi[0], lo[0]),
        _mm256_max_ps(_mm256_sub_ps(hi[1], lo[1]), _mm256_sub_ps(hi[2], lo[2])),
    );
    _mm256_cvtss_f32(spread)
}

/// Widest direction spread ([`direction_spread`]) for which a packet is traversed as one.
/// `packet_lanes bunny.obj` (camera tiles of 4x2 pixels `s` pixels apart, 1024^2 image,
/// 45 degree fov, single / packet CPU time): s = 1: 2.17x, 2: 2.15x, 4: 1.84x,
/// 8: 1.35x (spread ~0.02), 16: 0.80x (~0.04), 32: 0.73x, 64: 0.63x.
pub(super) const MAX_SPREAD: f32 = 0.03;

/// `cull_bound` of every lane.
#[inline(always)]
pub(super) unsafe fn cull8(t_max: __m256) -> __m256 {
    _mm256_max_ps(_mm256_mul_ps(t_max, _mm256_set1_ps(CULL_SCALE)), t_max)
}
