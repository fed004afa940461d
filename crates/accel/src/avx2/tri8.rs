//! The watertight ray/triangle test (Woop et al. 2013) on eight lanes: two [`Tri4`]
//! packets at once, bit-identical to the scalar test.

use crate::tri4::{test4_scalar, Tri4};
use crate::triangle::WatertightRay;
use std::arch::x86_64::*;

/// A ray prepared for the 8-lane triangle test: the origin in the permuted axis order and
/// the row offsets of the permuted axes inside a [`Tri4`] corner (as
/// [`crate::tri4::Ray4`]). The eight-lane splats are made by each test with one
/// broadcast from memory apiece: kept here, they were written to the stack on every query
/// and read back from there by the tests all the same (most rays test one leaf or none).
#[derive(Clone, Copy)]
pub(crate) struct Ray8<'a> {
    org: [f32; 3],
    pub(super) t_min: f32,
    row: [usize; 3],
    /// By reference: copying it into this struct would read back its scalar stores as
    /// one vector (a store-forwarding stall on every ray).
    pub(super) ray: &'a WatertightRay,
}

impl<'a> Ray8<'a> {
    #[inline(always)]
    pub unsafe fn new(ray: &'a WatertightRay, t_min: f32) -> Self {
        Self {
            org: [ray.org[ray.kx], ray.org[ray.ky], ray.org[ray.kz]],
            t_min,
            row: [4 * ray.kx, 4 * ray.ky, 4 * ray.kz],
            ray,
        }
    }

    /// The permuted origin and the shear constants `S_x, S_y, S_z`, eight lanes each.
    #[inline(always)]
    unsafe fn splats(&self) -> ([__m256; 3], [__m256; 3]) {
        let b = |x: &f32| _mm256_broadcast_ss(x);
        let r = self.ray;
        ([b(&self.org[0]), b(&self.org[1]), b(&self.org[2])], [b(&r.sx), b(&r.sy), b(&r.sz)])
    }
}

/// Result of [`test8`]: lanes 0-3 are packet `a`, 4-7 packet `b`.
#[repr(C, align(32))]
pub(crate) struct Hits8 {
    pub t: [f32; 8],
    pub u: [f32; 8],
    pub v: [f32; 8],
    pub mask: u32,
}

/// Per-lane results of [`test8v`], in registers: `hit` is all ones in lanes that hit.
#[derive(Clone, Copy)]
pub(crate) struct Lanes {
    pub hit: __m256,
    pub t: __m256,
    pub u: __m256,
    pub v: __m256,
}

/// Watertight test of the eight triangles of packets `a` and `b` (pass the same packet
/// twice and `lanes = 0x0f` for one packet): hit mask within `lanes` and per-lane
/// `t, u, v` for `t` in `[t_min, t_max]`, stored (for tests).
#[cfg(test)]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn test8(r: &Ray8, a: &Tri4, b: &Tri4, lanes: u32, t_max: f32) -> Hits8 {
    let l = unsafe { test8v(r, a, b, lanes, t_max) };
    let mut out = Hits8 { t: [0.0; 8], u: [0.0; 8], v: [0.0; 8], mask: _mm256_movemask_ps(l.hit) as u32 };
    // SAFETY: `Hits8` is 32-byte aligned and its arrays are 32 bytes each.
    unsafe {
        _mm256_store_ps(out.t.as_mut_ptr(), l.t);
        _mm256_store_ps(out.u.as_mut_ptr(), l.u);
        _mm256_store_ps(out.v.as_mut_ptr(), l.v);
    }
    out
}

/// [`test8`] with its results in registers and no data-dependent branch (the `t`
/// division runs whether or not a lane passed the edge tests: on tiny scenes, where about
/// every other packet holds a candidate, a mispredicted early exit cost more than the
/// division). Same operations, in the same order, as the SSE [`crate::tri4`] test.
#[inline(always)]
pub(crate) unsafe fn test8v(r: &Ray8, a: &Tri4, b: &Tri4, lanes: u32, t_max: f32) -> Lanes {
    let (e, z) = edges8(r, a, b);
    if _mm256_movemask_ps(any_zero(e)) as u32 & lanes != 0 {
        // Rare: a ray exactly on an edge needs the f64 recomputation of the scalar test.
        return edge_fallback(r, a, b, lanes, t_max);
    }
    // Outside when the edge functions have mixed signs. No used lane has a zero edge
    // function here (those went to the fallback), so "some negative and some positive"
    // is "the sign bits differ", and `det = U + V + W` of same-signed non-zero terms is
    // never zero: the scalar test's `det == 0` rejection cannot trigger. Four operations
    // instead of thirteen compares and ors, with the same decisions.
    let reject = mixed_signs(e);
    // Hit distance (step 4); NaN lanes (unused) fail both range tests.
    let (t, u, v) = hit_distance(e, z);
    let hit = _mm256_and_ps(_mm256_andnot_ps(reject, in_range(r, t, t_max)), lane_mask(lanes));
    Lanes { hit, t, u, v }
}

/// Whether any of the eight lanes of [`test8v`] (all used) hits: the same decisions, read
/// off by one `vtestps` of the sign bits (the edge functions' mixed signs against the
/// range test) instead of building the lane mask.
#[inline(always)]
pub(crate) unsafe fn any8(r: &Ray8, a: &Tri4, b: &Tri4, t_max: f32) -> bool {
    let (e, z) = edges8(r, a, b);
    if _mm256_movemask_ps(any_zero(e)) != 0 {
        return _mm256_movemask_ps(edge_fallback(r, a, b, 0xff, t_max).hit) != 0;
    }
    let [u, v, w] = e;
    let mixed = _mm256_or_ps(_mm256_xor_ps(u, v), _mm256_xor_ps(u, w));
    let (t, _, _) = hit_distance(e, z);
    // `testc` is set when no lane has the sign bit of `in_range` without that of `mixed`.
    _mm256_testc_ps(mixed, in_range(r, t, t_max)) == 0
}

/// All ones where `t` lies in `[t_min, t_max]` (NaN lanes fail).
#[inline(always)]
unsafe fn in_range(r: &Ray8, t: __m256, t_max: f32) -> __m256 {
    _mm256_and_ps(
        _mm256_cmp_ps::<_CMP_GE_OQ>(t, _mm256_broadcast_ss(&r.t_min)),
        _mm256_cmp_ps::<_CMP_LE_OQ>(t, _mm256_set1_ps(t_max)),
    )
}

/// The edge functions and scaled corner depths of the eight triangles of packets `a`
/// (low half) and `b` (high half) ([`sheared_edges`]).
#[inline(always)]
unsafe fn edges8(r: &Ray8, a: &Tri4, b: &Tri4) -> ([__m256; 3], [__m256; 3]) {
    let (pa, pb) = (a.v.as_ptr() as *const f32, b.v.as_ptr() as *const f32);
    let [rx, ry, rz] = r.row;
    // Packet `a` in the low half, `b` in the high half of each row.
    // SAFETY: `Tri4` rows are 16-byte aligned; offsets are `12 corner + 4 k`, `k < 3`.
    let row = |c: usize, off: usize| unsafe {
        _mm256_insertf128_ps::<1>(
            _mm256_castps128_ps256(_mm_load_ps(pa.add(12 * c + off))),
            _mm_load_ps(pb.add(12 * c + off)),
        )
    };
    let (p0, p1, p2) = (
        [row(0, rx), row(0, ry), row(0, rz)],
        [row(1, rx), row(1, ry), row(1, rz)],
        [row(2, rx), row(2, ry), row(2, rz)],
    );
    let (o, sh) = r.splats();
    sheared_edges(p0, p1, p2, o, sh)
}

/// Translate, shear and scale the corners `a`, `b`, `c` (x, y, z rows, 8 lanes) into the
/// ray space of origins `o` and shear constants `s` (Woop et al. 2013, steps 1-2), and the
/// edge functions `[U, V, W]` (step 3); returns them with the scaled corner depths.
#[inline(always)]
pub(crate) unsafe fn sheared_edges(
    a: [__m256; 3],
    b: [__m256; 3],
    c: [__m256; 3],
    o: [__m256; 3],
    s: [__m256; 3],
) -> ([__m256; 3], [__m256; 3]) {
    let ([a0, a1, a2], [b0, b1, b2], [c0, c1, c2]) = (a, b, c);
    let ([ox, oy, oz], [sx, sy, sz]) = (o, s);
    let (az, bz, cz) = (_mm256_sub_ps(a2, oz), _mm256_sub_ps(b2, oz), _mm256_sub_ps(c2, oz));
    let ax = _mm256_sub_ps(_mm256_sub_ps(a0, ox), _mm256_mul_ps(sx, az));
    let ay = _mm256_sub_ps(_mm256_sub_ps(a1, oy), _mm256_mul_ps(sy, az));
    let bx = _mm256_sub_ps(_mm256_sub_ps(b0, ox), _mm256_mul_ps(sx, bz));
    let by = _mm256_sub_ps(_mm256_sub_ps(b1, oy), _mm256_mul_ps(sy, bz));
    let cx = _mm256_sub_ps(_mm256_sub_ps(c0, ox), _mm256_mul_ps(sx, cz));
    let cy = _mm256_sub_ps(_mm256_sub_ps(c1, oy), _mm256_mul_ps(sy, cz));
    let z = [_mm256_mul_ps(sz, az), _mm256_mul_ps(sz, bz), _mm256_mul_ps(sz, cz)];
    let u = _mm256_sub_ps(_mm256_mul_ps(cx, by), _mm256_mul_ps(cy, bx));
    let v = _mm256_sub_ps(_mm256_mul_ps(ax, cy), _mm256_mul_ps(ay, cx));
    let w = _mm256_sub_ps(_mm256_mul_ps(bx, ay), _mm256_mul_ps(by, ax));
    ([u, v, w], z)
}

/// Lanes where an edge function is exactly zero (the ray meets an edge or vertex: the
/// scalar test's f64 recomputation decides).
#[inline(always)]
pub(crate) unsafe fn any_zero([u, v, w]: [__m256; 3]) -> __m256 {
    let zero = _mm256_setzero_ps();
    _mm256_or_ps(
        _mm256_or_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(u, zero), _mm256_cmp_ps::<_CMP_EQ_OQ>(v, zero)),
        _mm256_cmp_ps::<_CMP_EQ_OQ>(w, zero),
    )
}

/// All ones where the (non-zero) edge functions have mixed signs: outside the triangle.
#[inline(always)]
pub(crate) unsafe fn mixed_signs([u, v, w]: [__m256; 3]) -> __m256 {
    let mixed = _mm256_or_ps(_mm256_xor_ps(u, v), _mm256_xor_ps(u, w));
    _mm256_castsi256_ps(_mm256_srai_epi32::<31>(_mm256_castps_si256(mixed)))
}

/// Step 4: the hit distance and barycentrics `(t, V / det, W / det)`, `det = U + V + W`,
/// from the edge functions `e` and scaled corner depths `z`.
#[inline(always)]
pub(crate) unsafe fn hit_distance(
    [u, v, w]: [__m256; 3],
    [az, bz, cz]: [__m256; 3],
) -> (__m256, __m256, __m256) {
    let det = _mm256_add_ps(_mm256_add_ps(u, v), w);
    let t_scaled =
        _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(u, az), _mm256_mul_ps(v, bz)), _mm256_mul_ps(w, cz));
    let rcp = _mm256_div_ps(_mm256_set1_ps(1.0), det);
    (_mm256_mul_ps(t_scaled, rcp), _mm256_mul_ps(v, rcp), _mm256_mul_ps(w, rcp))
}

/// All ones in the lanes set in `lanes` (`0xff` or `0x0f`).
#[inline(always)]
unsafe fn lane_mask(lanes: u32) -> __m256 {
    let high = if lanes == 0xff { -1 } else { 0 };
    _mm256_castsi256_ps(_mm256_setr_epi32(-1, -1, -1, -1, high, high, high, high))
}

/// The scalar test on the lanes of [`test8`] (its edge fallback, and the reference of
/// the tests).
#[inline(never)]
pub(super) fn test8_scalar(r: &Ray8, a: &Tri4, b: &Tri4, lanes: u32, t_max: f32) -> Hits8 {
    let mut out = Hits8 { t: [0.0; 8], u: [0.0; 8], v: [0.0; 8], mask: 0 };
    for (half, p) in [a, b].into_iter().enumerate() {
        let (mask, t, u, v) = test4_scalar(r.ray, p, r.t_min, t_max);
        out.mask |= mask << (4 * half);
        out.t[4 * half..4 * half + 4].copy_from_slice(&t);
        out.u[4 * half..4 * half + 4].copy_from_slice(&u);
        out.v[4 * half..4 * half + 4].copy_from_slice(&v);
    }
    out.mask &= lanes;
    out
}

/// [`test8_scalar`] as [`Lanes`].
#[target_feature(enable = "avx2,fma")]
#[inline(never)]
fn edge_fallback(r: &Ray8, a: &Tri4, b: &Tri4, lanes: u32, t_max: f32) -> Lanes {
    let h = test8_scalar(r, a, b, lanes, t_max);
    let bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    let m = _mm256_and_si256(_mm256_set1_epi32(h.mask as i32), bits);
    // SAFETY: `Hits8` arrays are 32-byte aligned.
    unsafe {
        Lanes {
            hit: _mm256_castsi256_ps(_mm256_cmpeq_epi32(m, bits)),
            t: _mm256_load_ps(h.t.as_ptr()),
            u: _mm256_load_ps(h.u.as_ptr()),
            v: _mm256_load_ps(h.v.as_ptr()),
        }
    }
}
