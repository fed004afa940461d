//! Eight-ray packet kernels with AVX2 for flat bottom levels (meshes of at most
//! [`crate::BuildParams::max_flat_triangles`] triangles, the Cornell box): every triangle
//! is tested against all active rays at once, one ray per lane (8 rays x 1 triangle per
//! instruction), instead of one ray against two 4-triangle packets.
//!
//! Per lane the arithmetic is that of the single-ray kernels, operation for operation
//! (the watertight test of Woop et al. 2013 as in `avx2::test8v`, without fused
//! multiply-adds), so each lane's hit is bit-identical to [`crate::SceneAccel::intersect`]:
//! the rays' permutation `kx, ky, kz` may differ per lane, so each triangle corner is
//! broadcast and its permuted components picked per lane with two blends (skipped when all
//! active lanes share the permutation, the common case for camera and shadow rays); a lane
//! with an edge function exactly zero takes the scalar test with its `f64` fallback, as the
//! single-ray kernels do; ties in `t` go to the smallest primitive id.
//!
//! As in `avx2.rs`, the kernels are `#[target_feature(enable = "avx2,fma")]` functions that
//! callers reach only when [`crate::Simd::Avx2`] is available.

use crate::packet::{RayPacket, LANES};
use crate::tri4::Tri4;
use crate::triangle::{intersect_watertight, WatertightRay};
use crate::wide::ray_touches_box;
use crate::Blas;
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

/// The rays of a packet prepared for the watertight test, in object space.
pub(crate) struct Packet8 {
    /// Lanes to trace: active, valid, and touching the mesh bounds.
    active: u32,
    /// Scalar constants per lane (for the edge fallback; default in inactive lanes).
    wr: [WatertightRay; LANES],
    /// `org[kx], org[ky], org[kz]` and `S_x, S_y, S_z` per lane.
    o: [F8; 3],
    s: [F8; 3],
    t_min: F8,
    t_max: F8,
    /// `k[j][i]`: axis `kx` (j = 0), `ky` (1), `kz` (2) of lane `i`.
    k: [[u8; LANES]; 3],
    /// All active lanes share this permutation.
    uniform: Option<[usize; 3]>,
}

impl Packet8 {
    /// Lanes of `rays` set in `active`, culled by the bounds of `blas` exactly as the
    /// single-ray query culls them (`ray_touches_box`). Rays must be valid.
    pub fn new(rays: &RayPacket, active: u8, blas: &Blas) -> Self {
        let wr0 = WatertightRay { org: [0.0; 3], kx: 0, ky: 1, kz: 2, sx: 0.0, sy: 0.0, sz: 0.0 };
        let mut p = Self {
            active: 0,
            wr: [wr0; LANES],
            o: [F8::default(); 3],
            s: [F8::default(); 3],
            t_min: F8::default(),
            t_max: F8::default(),
            k: [[0; LANES]; 3],
            uniform: None,
        };
        let mut perm: Option<[usize; 3]> = None;
        let mut uniform = true;
        for i in (0..LANES).filter(|i| active & (1 << i) != 0) {
            let r = rays.lane(i);
            if !ray_touches_box(r.origin, r.dir, r.t_min, r.t_max, &blas.bounds) {
                continue;
            }
            let wr = WatertightRay::new(r.origin, r.dir);
            let k = [wr.kx, wr.ky, wr.kz];
            uniform &= perm.is_none_or(|q| q == k);
            perm = Some(k);
            for (j, &a) in k.iter().enumerate() {
                p.o[j].0[i] = wr.org[a];
                p.k[j][i] = a as u8;
            }
            p.s[0].0[i] = wr.sx;
            p.s[1].0[i] = wr.sy;
            p.s[2].0[i] = wr.sz;
            p.t_min.0[i] = r.t_min;
            p.t_max.0[i] = r.t_max;
            p.wr[i] = wr;
            p.active |= 1 << i;
        }
        p.uniform = if uniform { perm } else { None };
        p
    }

    /// Lanes left after the bounds check.
    pub fn active(&self) -> u32 {
        self.active
    }
}

/// Register form of a [`Packet8`].
#[derive(Clone, Copy)]
struct Regs {
    o: [__m256; 3],
    s: [__m256; 3],
    t_min: __m256,
    /// All ones in active lanes.
    act: __m256,
    /// Per permuted axis `j`: lanes whose axis is 1, lanes whose axis is 2.
    sel: [[__m256; 2]; 3],
}

impl Regs {
    #[inline(always)]
    unsafe fn new(p: &Packet8) -> Self {
        // SAFETY (all loads): `F8`/`I8` are 32-byte aligned.
        let ld = |x: &F8| unsafe { _mm256_load_ps(x.0.as_ptr()) };
        let bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
        let lanes = |m: u32| {
            let v = _mm256_and_si256(_mm256_set1_epi32(m as i32), bits);
            _mm256_castsi256_ps(_mm256_cmpeq_epi32(v, bits))
        };
        let axis_is =
            |j: usize, a: u8| lanes((0..LANES).filter(|&i| p.k[j][i] == a).fold(0, |m, i| m | (1 << i)));
        Self {
            o: [ld(&p.o[0]), ld(&p.o[1]), ld(&p.o[2])],
            s: [ld(&p.s[0]), ld(&p.s[1]), ld(&p.s[2])],
            t_min: ld(&p.t_min),
            act: lanes(p.active),
            sel: [0, 1, 2].map(|j| [axis_is(j, 1), axis_is(j, 2)]),
        }
    }
}

/// Corner `c` of triangle `l` of packet `tri`, permuted per lane: `(v[kx], v[ky], v[kz])`.
#[inline(always)]
unsafe fn corner<const UNIFORM: bool>(
    tri: &Tri4,
    c: usize,
    l: usize,
    r: &Regs,
    k: [usize; 3],
) -> [__m256; 3] {
    let v = &tri.v[c];
    if UNIFORM {
        return k.map(|a| _mm256_set1_ps(v[a][l]));
    }
    let (x, y, z) = (_mm256_set1_ps(v[0][l]), _mm256_set1_ps(v[1][l]), _mm256_set1_ps(v[2][l]));
    [0, 1, 2].map(|j| _mm256_blendv_ps(_mm256_blendv_ps(x, y, r.sel[j][0]), z, r.sel[j][1]))
}

/// The watertight test of one triangle against the eight lanes, as `avx2::test8v` per
/// lane: `(edge, reject, t, u, v)` where `edge` marks lanes with a zero edge function
/// (their other results are meaningless: the caller redoes them with the scalar test).
#[inline(always)]
unsafe fn test_tri<const UNIFORM: bool>(
    tri: &Tri4,
    l: usize,
    r: &Regs,
    k: [usize; 3],
) -> (__m256, __m256, __m256, __m256, __m256) {
    let [ox, oy, oz] = r.o;
    let [sx, sy, sz] = r.s;
    let [a0, a1, a2] = corner::<UNIFORM>(tri, 0, l, r, k);
    let [b0, b1, b2] = corner::<UNIFORM>(tri, 1, l, r, k);
    let [c0, c1, c2] = corner::<UNIFORM>(tri, 2, l, r, k);
    // Translate, shear and scale each corner (Woop et al. 2013, steps 1-2).
    let (az, bz, cz) = (_mm256_sub_ps(a2, oz), _mm256_sub_ps(b2, oz), _mm256_sub_ps(c2, oz));
    let ax = _mm256_sub_ps(_mm256_sub_ps(a0, ox), _mm256_mul_ps(sx, az));
    let ay = _mm256_sub_ps(_mm256_sub_ps(a1, oy), _mm256_mul_ps(sy, az));
    let bx = _mm256_sub_ps(_mm256_sub_ps(b0, ox), _mm256_mul_ps(sx, bz));
    let by = _mm256_sub_ps(_mm256_sub_ps(b1, oy), _mm256_mul_ps(sy, bz));
    let cx = _mm256_sub_ps(_mm256_sub_ps(c0, ox), _mm256_mul_ps(sx, cz));
    let cy = _mm256_sub_ps(_mm256_sub_ps(c1, oy), _mm256_mul_ps(sy, cz));
    let (az, bz, cz) = (_mm256_mul_ps(sz, az), _mm256_mul_ps(sz, bz), _mm256_mul_ps(sz, cz));
    // Edge functions (step 3).
    let u = _mm256_sub_ps(_mm256_mul_ps(cx, by), _mm256_mul_ps(cy, bx));
    let v = _mm256_sub_ps(_mm256_mul_ps(ax, cy), _mm256_mul_ps(ay, cx));
    let w = _mm256_sub_ps(_mm256_mul_ps(bx, ay), _mm256_mul_ps(by, ax));
    let zero = _mm256_setzero_ps();
    let edge = _mm256_and_ps(
        r.act,
        _mm256_or_ps(
            _mm256_or_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(u, zero), _mm256_cmp_ps::<_CMP_EQ_OQ>(v, zero)),
            _mm256_cmp_ps::<_CMP_EQ_OQ>(w, zero),
        ),
    );
    // Mixed signs: outside (no lane with a zero edge function gets here; see `test8v`).
    let mixed = _mm256_or_ps(_mm256_xor_ps(u, v), _mm256_xor_ps(u, w));
    let reject = _mm256_castsi256_ps(_mm256_srai_epi32::<31>(_mm256_castps_si256(mixed)));
    let det = _mm256_add_ps(_mm256_add_ps(u, v), w);
    // Hit distance (step 4).
    let t_scaled =
        _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(u, az), _mm256_mul_ps(v, bz)), _mm256_mul_ps(w, cz));
    let rcp = _mm256_div_ps(_mm256_set1_ps(1.0), det);
    let t = _mm256_mul_ps(t_scaled, rcp);
    (edge, reject, t, _mm256_mul_ps(v, rcp), _mm256_mul_ps(w, rcp))
}

/// Closest hits of the packet's lanes among all triangles of the flat `blas` (ids are
/// its `prim_ids` values; on equal `t` the smallest id wins, as in the single-ray query).
///
/// # Safety
/// The CPU has AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn closest_flat(blas: &Blas, p: &Packet8) -> Closest8 {
    match p.uniform {
        Some(k) => closest_flat_k::<true>(blas, p, k),
        None => closest_flat_k::<false>(blas, p, [0, 1, 2]),
    }
}

#[target_feature(enable = "avx2,fma")]
unsafe fn closest_flat_k<const UNIFORM: bool>(blas: &Blas, p: &Packet8, k: [usize; 3]) -> Closest8 {
    let r = Regs::new(p);
    let mut out = Closest8 { id: I8([NO_HIT; LANES]), ..Closest8::default() };
    // SAFETY (loads and stores): `F8`/`I8` are 32-byte aligned.
    let mut bt = _mm256_load_ps(p.t_max.0.as_ptr());
    let (mut bu, mut bv) = (_mm256_setzero_ps(), _mm256_setzero_ps());
    let mut bid = _mm256_set1_epi32(NO_HIT);
    for (j, tri) in blas.packets.iter().enumerate() {
        for l in 0..4 {
            let id = blas.prim_ids[4 * j + l];
            if id == u32::MAX {
                continue;
            }
            let (edge, reject, t, u, v) = test_tri::<UNIFORM>(tri, l, &r, k);
            if _mm256_movemask_ps(edge) != 0 {
                // Rare: some lane lies exactly on an edge; the scalar test for all lanes.
                _mm256_store_ps(out.t.0.as_mut_ptr(), bt);
                _mm256_store_ps(out.u.0.as_mut_ptr(), bu);
                _mm256_store_ps(out.v.0.as_mut_ptr(), bv);
                _mm256_store_si256(out.id.0.as_mut_ptr() as *mut __m256i, bid);
                closest_scalar(p, &mut out, &tri.lane(l), id as i32);
                bt = _mm256_load_ps(out.t.0.as_ptr());
                bu = _mm256_load_ps(out.u.0.as_ptr());
                bv = _mm256_load_ps(out.v.0.as_ptr());
                bid = _mm256_load_si256(out.id.0.as_ptr() as *const __m256i);
                continue;
            }
            let in_range =
                _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(t, r.t_min), _mm256_cmp_ps::<_CMP_LE_OQ>(t, bt));
            let hit = _mm256_and_ps(_mm256_andnot_ps(reject, in_range), r.act);
            // `t <= bt` here, so closer means `t < bt`, or `t == bt` and a smaller id.
            let idv = _mm256_set1_epi32(id as i32);
            let smaller_id = _mm256_castsi256_ps(_mm256_cmpgt_epi32(bid, idv));
            let closer = _mm256_and_ps(hit, _mm256_or_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(t, bt), smaller_id));
            bt = _mm256_blendv_ps(bt, t, closer);
            bu = _mm256_blendv_ps(bu, u, closer);
            bv = _mm256_blendv_ps(bv, v, closer);
            bid = _mm256_castps_si256(_mm256_blendv_ps(
                _mm256_castsi256_ps(bid),
                _mm256_castsi256_ps(idv),
                closer,
            ));
        }
    }
    _mm256_store_ps(out.t.0.as_mut_ptr(), bt);
    _mm256_store_ps(out.u.0.as_mut_ptr(), bu);
    _mm256_store_ps(out.v.0.as_mut_ptr(), bv);
    _mm256_store_si256(out.id.0.as_mut_ptr() as *mut __m256i, bid);
    out
}

/// One triangle against every active lane with the scalar test, updating `out`.
#[inline(never)]
fn closest_scalar(p: &Packet8, out: &mut Closest8, tri: &crate::triangle::Tri, id: i32) {
    for i in (0..LANES).filter(|i| p.active & (1 << i) != 0) {
        if let Some((t, u, v)) = intersect_watertight(&p.wr[i], tri, p.t_min.0[i], out.t.0[i]) {
            if t < out.t.0[i] || id < out.id.0[i] {
                (out.t.0[i], out.u.0[i], out.v.0[i], out.id.0[i]) = (t, u, v, id);
            }
        }
    }
}

/// Lanes of the packet that hit any triangle of the flat `blas` with `t` in
/// `[t_min, t_max]` (bit `i` for lane `i`).
///
/// # Safety
/// The CPU has AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn occluded_flat(blas: &Blas, p: &Packet8) -> u32 {
    match p.uniform {
        Some(k) => occluded_flat_k::<true>(blas, p, k),
        None => occluded_flat_k::<false>(blas, p, [0, 1, 2]),
    }
}

#[target_feature(enable = "avx2,fma")]
unsafe fn occluded_flat_k<const UNIFORM: bool>(blas: &Blas, p: &Packet8, k: [usize; 3]) -> u32 {
    let mut r = Regs::new(p);
    // SAFETY: `F8` is 32-byte aligned.
    let t_max = _mm256_load_ps(p.t_max.0.as_ptr());
    let mut left = p.active;
    let mut occluded = 0u32;
    for (j, tri) in blas.packets.iter().enumerate() {
        for l in 0..4 {
            if blas.prim_ids[4 * j + l] == u32::MAX {
                continue;
            }
            let (edge, reject, t, _, _) = test_tri::<UNIFORM>(tri, l, &r, k);
            let hit = if _mm256_movemask_ps(edge) != 0 {
                any_scalar(p, left, &tri.lane(l))
            } else {
                let in_range = _mm256_and_ps(
                    _mm256_cmp_ps::<_CMP_GE_OQ>(t, r.t_min),
                    _mm256_cmp_ps::<_CMP_LE_OQ>(t, t_max),
                );
                _mm256_movemask_ps(_mm256_and_ps(_mm256_andnot_ps(reject, in_range), r.act)) as u32
            };
            if hit != 0 {
                occluded |= hit;
                left &= !hit;
                if left == 0 {
                    return occluded;
                }
                let bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
                let m = _mm256_and_si256(_mm256_set1_epi32(left as i32), bits);
                r.act = _mm256_castsi256_ps(_mm256_cmpeq_epi32(m, bits));
            }
        }
    }
    occluded
}

/// Lanes of `lanes` that hit `tri` (scalar test).
#[inline(never)]
fn any_scalar(p: &Packet8, lanes: u32, tri: &crate::triangle::Tri) -> u32 {
    (0..LANES)
        .filter(|&i| lanes & (1 << i) != 0)
        .filter(|&i| intersect_watertight(&p.wr[i], tri, p.t_min.0[i], p.t_max.0[i]).is_some())
        .fold(0, |m, i| m | (1 << i))
}
