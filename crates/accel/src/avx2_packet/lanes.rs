//! The rays of a packet in registers: their validity and watertight constants, lane for
//! lane those of the single-ray query ([`setup`]), and the running closest hits ([`Best8`]).

use crate::ray_packet::{RayPacket, LANES};
use crate::triangle::{intersect_watertight, Tri, WatertightRay};
use std::arch::x86_64::*;

/// Eight lanes, 32-byte aligned (for aligned vector loads and stores).
#[repr(C, align(32))]
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct F8(pub [f32; LANES]);

#[repr(C, align(32))]
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct I8(pub [i32; LANES]);

/// Id of "no hit yet" in [`Closest8::id`] (primitive ids are below `2^31`).
pub(crate) const NO_HIT: i32 = i32::MAX;

/// Per-lane results of [`closest_flat`]: lane `i` hit primitive `prim_ids` value `id[i]`
/// (`NO_HIT`: no hit) at `t[i]` with barycentrics `u[i], v[i]`.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Closest8 {
    pub t: F8,
    pub u: F8,
    pub v: F8,
    pub id: I8,
}

/// The running closest hits of a packet, in registers: what [`Closest8`] holds.
#[derive(Clone, Copy)]
pub(super) struct Best8 {
    pub t: __m256,
    pub u: __m256,
    pub v: __m256,
    pub id: __m256i,
}

impl Best8 {
    /// No hits yet, lanes searching up to `t_max`.
    #[inline(always)]
    pub(super) unsafe fn new(t_max: __m256) -> Self {
        Best8 { t: t_max, u: _mm256_setzero_ps(), v: _mm256_setzero_ps(), id: _mm256_set1_epi32(NO_HIT) }
    }

    #[inline(always)]
    pub(super) unsafe fn store(&self, out: &mut Closest8) {
        // SAFETY: `F8`/`I8` are 32-byte aligned.
        _mm256_store_ps(out.t.0.as_mut_ptr(), self.t);
        _mm256_store_ps(out.u.0.as_mut_ptr(), self.u);
        _mm256_store_ps(out.v.0.as_mut_ptr(), self.v);
        _mm256_store_si256(out.id.0.as_mut_ptr() as *mut __m256i, self.id);
    }

    #[inline(always)]
    pub(super) unsafe fn load(out: &Closest8) -> Self {
        // SAFETY: as in `store`.
        Best8 {
            t: _mm256_load_ps(out.t.0.as_ptr()),
            u: _mm256_load_ps(out.u.0.as_ptr()),
            v: _mm256_load_ps(out.v.0.as_ptr()),
            id: _mm256_load_si256(out.id.0.as_ptr() as *const __m256i),
        }
    }

    /// Takes the hits `(t, u, v)` of triangle `id` in the lanes not rejected and in
    /// `[t_min_act, self.t]` (`t_min_act`: NaN in the lanes not to update): closer means
    /// `t < self.t`, or `t == self.t` and a smaller id.
    #[inline(always)]
    pub(super) unsafe fn update(
        &mut self,
        t: __m256,
        u: __m256,
        v: __m256,
        reject: __m256,
        t_min_act: __m256,
        id: u32,
    ) {
        let in_range =
            _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(t, t_min_act), _mm256_cmp_ps::<_CMP_LE_OQ>(t, self.t));
        let hit = _mm256_andnot_ps(reject, in_range);
        let idv = _mm256_set1_epi32(id as i32);
        let smaller_id = _mm256_castsi256_ps(_mm256_cmpgt_epi32(self.id, idv));
        let closer = _mm256_and_ps(hit, _mm256_or_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(t, self.t), smaller_id));
        self.t = _mm256_blendv_ps(self.t, t, closer);
        self.u = _mm256_blendv_ps(self.u, u, closer);
        self.v = _mm256_blendv_ps(self.v, v, closer);
        self.id = _mm256_castps_si256(_mm256_blendv_ps(
            _mm256_castsi256_ps(self.id),
            _mm256_castsi256_ps(idv),
            closer,
        ));
    }

    /// Rare: some lane lies exactly on an edge of `tri`; the scalar test for the lanes `active`.
    #[inline(always)]
    pub(super) unsafe fn update_scalar(
        &mut self,
        rays: &RayPacket,
        active: u32,
        out: &mut Closest8,
        tri: &Tri,
        id: u32,
    ) {
        self.store(out);
        closest_scalar(rays, active, out, tri, id as i32);
        *self = Best8::load(out);
    }
}

/// One triangle against the lanes `active` with the scalar test, updating `out`.
#[inline(never)]
pub(super) fn closest_scalar(rays: &RayPacket, active: u32, out: &mut Closest8, tri: &Tri, id: i32) {
    for i in (0..LANES).filter(|i| active & (1 << i) != 0) {
        let ray = rays.lane(i);
        let wr = WatertightRay::new(ray.origin, ray.dir);
        if let Some((t, u, v)) = intersect_watertight(&wr, tri, ray.t_min, out.t.0[i]) {
            if t < out.t.0[i] || id < out.id.0[i] {
                (out.t.0[i], out.u.0[i], out.v.0[i], out.id.0[i]) = (t, u, v, id);
            }
        }
    }
}

/// The rays of a packet prepared for the watertight test, in object space, in registers.
#[derive(Clone, Copy)]
pub(super) struct Regs<'a> {
    /// The rays (for the scalar edge fallback).
    pub rays: &'a RayPacket,
    /// Lanes to trace: active and valid.
    pub active: u32,
    /// `org[kx], org[ky], org[kz]` and `S_x, S_y, S_z` per lane.
    pub o: [__m256; 3],
    pub s: [__m256; 3],
    pub t_min: __m256,
    pub t_max: __m256,
    /// All ones in active lanes.
    pub act: __m256,
    /// `t_min` in active lanes, NaN in the others (no `t` compares `>=` to it).
    pub t_min_act: __m256,
    /// `kx, ky, kz` per lane (shuffle indices).
    pub kidx: [__m256i; 3],
    /// All active lanes share this permutation.
    pub uniform: Option<[usize; 3]>,
}

/// True lanes where `x` is finite.
#[inline(always)]
pub(super) unsafe fn finite(x: __m256) -> __m256 {
    let abs = _mm256_and_ps(x, _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff)));
    _mm256_cmp_ps::<_CMP_LT_OQ>(abs, _mm256_set1_ps(f32::INFINITY))
}

/// Per lane, `x`, `y` or `z` where the lane's axis is 0, 1 (`is1`) or 2 (`is2`).
#[inline(always)]
pub(super) unsafe fn pick(x: __m256, y: __m256, z: __m256, is1: __m256, is2: __m256) -> __m256 {
    _mm256_blendv_ps(_mm256_blendv_ps(x, y, is1), z, is2)
}

/// Loads eight unaligned floats.
#[inline(always)]
pub(super) unsafe fn ld(x: &[f32; LANES]) -> __m256 {
    // SAFETY: reads the 32 bytes of `x`.
    unsafe { _mm256_loadu_ps(x.as_ptr()) }
}

/// Prepares the lanes of `rays` set in `active`, all eight at once, with the decisions of
/// the single-ray query, lane for lane: `Ray::is_valid` and the watertight permutation and
/// shear (`WatertightRay::new`, the same selection rules and roundings). No bounds check:
/// the callers test boxes (group boxes of flat meshes, BVH nodes), which only cull.
#[inline(always)]
pub(super) unsafe fn setup(rays: &RayPacket, active: u32) -> Regs<'_> {
    let [ox, oy, oz] = [ld(&rays.origin[0]), ld(&rays.origin[1]), ld(&rays.origin[2])];
    let [dx, dy, dz] = [ld(&rays.dir[0]), ld(&rays.dir[1]), ld(&rays.dir[2])];
    let (t_min, t_max) = (ld(&rays.t_min), ld(&rays.t_max));
    let zero = _mm256_setzero_ps();
    // `Ray::is_valid`: finite origin and direction, non-zero direction, no NaN bounds.
    let finite_o = _mm256_and_ps(_mm256_and_ps(finite(ox), finite(oy)), finite(oz));
    let finite_d = _mm256_and_ps(_mm256_and_ps(finite(dx), finite(dy)), finite(dz));
    let nonzero = _mm256_or_ps(
        _mm256_or_ps(_mm256_cmp_ps::<_CMP_NEQ_OQ>(dx, zero), _mm256_cmp_ps::<_CMP_NEQ_OQ>(dy, zero)),
        _mm256_cmp_ps::<_CMP_NEQ_OQ>(dz, zero),
    );
    let valid = _mm256_and_ps(
        _mm256_and_ps(finite_o, finite_d),
        _mm256_and_ps(nonzero, _mm256_cmp_ps::<_CMP_ORD_Q>(t_min, t_max)),
    );
    let one = _mm256_set1_ps(1.0);
    let act = _mm256_and_ps(valid, lane_mask(active));
    // `WatertightRay::new`: `kz` the axis of largest |d| (first on ties), `kx, ky` the
    // next ones, swapped when `d[kz] < 0`; `S_z = 1 / d[kz]`, `S_x = d[kx] S_z`, ...
    let abs = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
    let (ax, ay, az) = (_mm256_and_ps(dx, abs), _mm256_and_ps(dy, abs), _mm256_and_ps(dz, abs));
    let x_max = _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(ax, ay), _mm256_cmp_ps::<_CMP_GE_OQ>(ax, az));
    let z_over_y = _mm256_cmp_ps::<_CMP_LT_OQ>(ay, az);
    let kz0 = x_max;
    let kz2 = _mm256_andnot_ps(x_max, z_over_y);
    let kz1 = _mm256_andnot_ps(x_max, _mm256_andnot_ps(z_over_y, _mm256_castsi256_ps(_mm256_set1_epi32(-1))));
    let dkz = pick(dx, dy, dz, kz1, kz2);
    let swap = _mm256_cmp_ps::<_CMP_LT_OQ>(dkz, zero);
    let sel = [
        [_mm256_blendv_ps(kz0, kz2, swap), _mm256_blendv_ps(kz1, kz0, swap)],
        [_mm256_blendv_ps(kz2, kz0, swap), _mm256_blendv_ps(kz0, kz1, swap)],
        [kz1, kz2],
    ];
    let sz = _mm256_div_ps(one, dkz);
    let sx = _mm256_mul_ps(pick(dx, dy, dz, sel[0][0], sel[0][1]), sz);
    let sy = _mm256_mul_ps(pick(dx, dy, dz, sel[1][0], sel[1][1]), sz);
    let o = [
        pick(ox, oy, oz, sel[0][0], sel[0][1]),
        pick(ox, oy, oz, sel[1][0], sel[1][1]),
        pick(ox, oy, oz, sel[2][0], sel[2][1]),
    ];
    let active = _mm256_movemask_ps(act) as u32;
    // One permutation for all active lanes: each axis mask is all or nothing of them.
    let bits = [
        [_mm256_movemask_ps(sel[0][0]) as u32 & active, _mm256_movemask_ps(sel[0][1]) as u32 & active],
        [_mm256_movemask_ps(sel[1][0]) as u32 & active, _mm256_movemask_ps(sel[1][1]) as u32 & active],
        [_mm256_movemask_ps(sel[2][0]) as u32 & active, _mm256_movemask_ps(sel[2][1]) as u32 & active],
    ];
    let all_or_none = |m: u32| m == 0 || m == active;
    let uniform = bits.iter().flatten().all(|&m| all_or_none(m));
    let axis = |b: [u32; 2]| {
        if b[0] != 0 {
            1
        } else if b[1] != 0 {
            2
        } else {
            0
        }
    };
    let kidx = [
        _mm256_or_si256(
            _mm256_and_si256(_mm256_castps_si256(sel[0][0]), _mm256_set1_epi32(1)),
            _mm256_and_si256(_mm256_castps_si256(sel[0][1]), _mm256_set1_epi32(2)),
        ),
        _mm256_or_si256(
            _mm256_and_si256(_mm256_castps_si256(sel[1][0]), _mm256_set1_epi32(1)),
            _mm256_and_si256(_mm256_castps_si256(sel[1][1]), _mm256_set1_epi32(2)),
        ),
        _mm256_or_si256(
            _mm256_and_si256(_mm256_castps_si256(sel[2][0]), _mm256_set1_epi32(1)),
            _mm256_and_si256(_mm256_castps_si256(sel[2][1]), _mm256_set1_epi32(2)),
        ),
    ];
    Regs {
        rays,
        kidx,
        active,
        o,
        s: [sx, sy, sz],
        t_min,
        t_max,
        act,
        t_min_act: _mm256_blendv_ps(_mm256_set1_ps(f32::NAN), t_min, act),
        uniform: uniform.then(|| [axis(bits[0]), axis(bits[1]), axis(bits[2])]),
    }
}

/// All ones in the lanes whose bit is set in `m`.
#[inline(always)]
pub(super) unsafe fn lane_mask(m: u32) -> __m256 {
    let bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    let v = _mm256_and_si256(_mm256_set1_epi32(m as i32), bits);
    _mm256_castsi256_ps(_mm256_cmpeq_epi32(v, bits))
}
