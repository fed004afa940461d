//! Four triangles in structure-of-arrays layout, tested against one ray at once with SSE:
//! the watertight test of [`crate::triangle`] (Woop et al. 2013) evaluated in four lanes
//! with the same operations in the same order, so every lane gives bit-identical results
//! to the scalar test (tests compare the BVH with the scalar brute force exactly).
//! Unused lanes hold NaN corners, which never produce a hit.

use crate::triangle::{intersect_watertight, Tri, WatertightRay};
use filtrace_core::{Aabb, Vec3};

/// Four triangles: `v[corner][axis][lane]`, 144 bytes.
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Tri4 {
    pub v: [[[f32; 4]; 3]; 3],
}

impl Tri4 {
    /// Packs up to four triangles; missing lanes get NaN corners.
    pub fn pack(tris: &[Tri]) -> Self {
        debug_assert!(tris.len() <= 4);
        let mut v = [[[f32::NAN; 4]; 3]; 3];
        for (lane, t) in tris.iter().enumerate() {
            for c in 0..3 {
                for a in 0..3 {
                    v[c][a][lane] = t[c][a];
                }
            }
        }
        Self { v }
    }

    /// Triangle of one lane (NaN corners for an unused lane).
    pub fn lane(&self, lane: usize) -> Tri {
        let v = &self.v;
        [0, 1, 2].map(|c| [v[c][0][lane], v[c][1][lane], v[c][2][lane]])
    }

    /// True when `lane` holds a triangle (unused lanes are NaN).
    pub fn used(&self, lane: usize) -> bool {
        !self.v[0][0][lane].is_nan()
    }
}

/// The triangles of a bottom level in leaf order, four to a packet; a leaf is a range of
/// packets.
#[derive(Clone, Debug, Default)]
pub(crate) struct TriPackets {
    pub packets: Vec<Tri4>,
    /// Mesh triangle index of lane `l` of packet `p` at `4 p + l` (`u32::MAX`: unused).
    pub prim_ids: Vec<u32>,
    /// Number of triangles stored (those with finite corners).
    pub tri_count: usize,
    /// Object-space bounds of all triangles.
    pub bounds: Aabb,
}

impl TriPackets {
    /// Appends the triangles `ids` (at most four; `tri(id)` gives the corners) as one
    /// packet.
    pub fn push(&mut self, ids: &[u32], tri: impl Fn(u32) -> Tri) {
        self.packets.push(Tri4::pack(&ids.iter().map(|&i| tri(i)).collect::<Vec<_>>()));
        self.prim_ids.extend((0..4).map(|l| ids.get(l).copied().unwrap_or(u32::MAX)));
    }

    /// Box of packet `p`'s triangles.
    pub fn packet_box(&self, p: usize) -> Aabb {
        let pk = &self.packets[p];
        (0..4)
            .filter(|&l| pk.used(l))
            .fold(Aabb::EMPTY, |b, l| b.union(Aabb::from_points(pk.lane(l).map(Vec3::from_array))))
    }
}

/// Prefetches every cache line of packets `first .. first + count` (a leaf of two
/// 144-byte packets spans five or six lines; fetching only the first three left the
/// second packet a cache miss).
#[inline(always)]
pub(crate) fn prefetch_packets(packets: &[Tri4], first: u32, count: u32) {
    // Leaves hold at most two packets unless the build was forced (`MAX_DEPTH`).
    let start = packets.as_ptr().wrapping_add(first as usize) as usize;
    let last = start + count.min(2) as usize * std::mem::size_of::<Tri4>() - 1;
    let mut line = start & !63;
    while line <= last {
        crate::wide::prefetch(line as *const u8, 1);
        line += 64;
    }
}

/// A ray prepared for [`Tri4`] tests: the watertight constants plus, computed once per ray
/// instead of once per packet, the permuted origin and shear factors splatted to four lanes
/// and the row offsets of the permuted axes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Ray4 {
    /// `org[kx], org[ky], org[kz]` in every lane.
    o: [F4; 3],
    /// `S_x, S_y, S_z` in every lane.
    s: [F4; 3],
    /// `t_min` in every lane.
    t_min4: F4,
    t_min: f32,
    /// Offsets (in floats) of the `kx, ky, kz` rows inside a corner of a [`Tri4`].
    row: [usize; 3],
    pub ray: WatertightRay,
}

/// Four lanes: an SSE register where there is one (built with vector instructions, so
/// copies of a [`Ray4`] never read back narrower stores), else an array.
#[cfg(target_arch = "x86_64")]
type F4 = std::arch::x86_64::__m128;
#[cfg(not(target_arch = "x86_64"))]
type F4 = [f32; 4];

#[inline(always)]
fn splat(x: f32) -> F4 {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: SSE is part of the x86_64 baseline.
    unsafe {
        std::arch::x86_64::_mm_set1_ps(x)
    }
    #[cfg(not(target_arch = "x86_64"))]
    [x; 4]
}

impl Ray4 {
    #[inline(always)]
    pub fn new(ray: WatertightRay, t_min: f32) -> Self {
        let k = [ray.kx, ray.ky, ray.kz];
        Self {
            o: k.map(|k| splat(ray.org[k])),
            s: [splat(ray.sx), splat(ray.sy), splat(ray.sz)],
            t_min4: splat(t_min),
            t_min,
            row: k.map(|k| 4 * k),
            ray,
        }
    }
}

/// Result of [`test4`]: 16-byte aligned lanes (stored by aligned vector stores, read back
/// one float at a time, so store forwarding works) and the hit mask.
#[repr(C, align(16))]
struct Hits4 {
    t: [f32; 4],
    u: [f32; 4],
    v: [f32; 4],
    mask: u32,
}

/// Closest hit among the four triangles with `t` in `[t_min, t_max]`:
/// `(t, u, v, lane)`. On equal `t` the lane with the smallest id in `ids` (the lanes'
/// primitive ids) wins, so the answer does not depend on how triangles were packed.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn intersect4(r: &Ray4, p: &Tri4, t_max: f32, ids: &[u32]) -> Option<(f32, f32, f32, usize)> {
    let Hits4 { t, u, v, mask } = test4(r, p, t_max);
    if mask == 0 {
        return None;
    }
    // Lowest t; the smallest id among equal t.
    let mut best = mask.trailing_zeros() as usize;
    let mut rest = mask & (mask - 1);
    while rest != 0 {
        let i = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        if t[i] < t[best] || (t[i] == t[best] && ids[i] < ids[best]) {
            best = i;
        }
    }
    Some((t[best], u[best], v[best], best))
}

/// True when any of the four triangles is hit with `t` in `[t_min, t_max]`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) fn occluded4(r: &Ray4, p: &Tri4, t_max: f32) -> bool {
    test4(r, p, t_max).mask != 0
}

/// Hit mask and per-lane `t, u, v` (valid where the mask bit is set).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn test4(r4: &Ray4, p: &Tri4, t_max: f32) -> Hits4 {
    use std::arch::x86_64::*;
    // SAFETY: SSE is part of the x86_64 baseline; `Tri4` rows and the `Ray4` splats are
    // 16-byte aligned and the row offsets are `4 * k` with `k < 3`.
    unsafe {
        let base = p.v.as_ptr() as *const f32;
        let [rx, ry, rz] = r4.row;
        let row = |corner: usize, off: usize| _mm_load_ps(base.add(12 * corner + off));
        let [ox, oy, oz] = r4.o;
        let [sx, sy, sz] = r4.s;
        // Translate, shear and scale each corner (Woop et al. 2013, steps 1-2).
        let corner = |c: usize| {
            let x = _mm_sub_ps(row(c, rx), ox);
            let y = _mm_sub_ps(row(c, ry), oy);
            let z = _mm_sub_ps(row(c, rz), oz);
            (_mm_sub_ps(x, _mm_mul_ps(sx, z)), _mm_sub_ps(y, _mm_mul_ps(sy, z)), _mm_mul_ps(sz, z))
        };
        let (ax, ay, az) = corner(0);
        let (bx, by, bz) = corner(1);
        let (cx, cy, cz) = corner(2);
        // Edge functions (step 3).
        let u = _mm_sub_ps(_mm_mul_ps(cx, by), _mm_mul_ps(cy, bx));
        let v = _mm_sub_ps(_mm_mul_ps(ax, cy), _mm_mul_ps(ay, cx));
        let w = _mm_sub_ps(_mm_mul_ps(bx, ay), _mm_mul_ps(by, ax));
        let zero = _mm_setzero_ps();
        let on_edge =
            _mm_or_ps(_mm_or_ps(_mm_cmpeq_ps(u, zero), _mm_cmpeq_ps(v, zero)), _mm_cmpeq_ps(w, zero));
        if _mm_movemask_ps(on_edge) != 0 {
            // Rare: a ray exactly on an edge needs the f64 recomputation; use the scalar
            // test lane by lane.
            let (mask, t, u, v) = test4_scalar(&r4.ray, p, r4.t_min, t_max);
            return Hits4 { t, u, v, mask };
        }
        let neg = _mm_or_ps(_mm_or_ps(_mm_cmplt_ps(u, zero), _mm_cmplt_ps(v, zero)), _mm_cmplt_ps(w, zero));
        let pos = _mm_or_ps(_mm_or_ps(_mm_cmpgt_ps(u, zero), _mm_cmpgt_ps(v, zero)), _mm_cmpgt_ps(w, zero));
        let outside = _mm_and_ps(neg, pos);
        let det = _mm_add_ps(_mm_add_ps(u, v), w);
        let mut mask = !(_mm_movemask_ps(_mm_or_ps(outside, _mm_cmpeq_ps(det, zero))) as u32) & 0xf;
        if mask == 0 {
            return Hits4 { t: [0.0; 4], u: [0.0; 4], v: [0.0; 4], mask: 0 };
        }
        // Hit distance (step 4); NaN lanes (unused) fail both range tests.
        let t_scaled = _mm_add_ps(_mm_add_ps(_mm_mul_ps(u, az), _mm_mul_ps(v, bz)), _mm_mul_ps(w, cz));
        let rcp = _mm_div_ps(_mm_set1_ps(1.0), det);
        let t = _mm_mul_ps(t_scaled, rcp);
        let in_range = _mm_and_ps(_mm_cmpge_ps(t, r4.t_min4), _mm_cmple_ps(t, _mm_set1_ps(t_max)));
        mask &= _mm_movemask_ps(in_range) as u32;
        let mut out = Hits4 { t: [0.0; 4], u: [0.0; 4], v: [0.0; 4], mask };
        _mm_store_ps(out.t.as_mut_ptr(), t);
        _mm_store_ps(out.u.as_mut_ptr(), _mm_mul_ps(v, rcp));
        _mm_store_ps(out.v.as_mut_ptr(), _mm_mul_ps(w, rcp));
        out
    }
}

/// The scalar test lane by lane (with its `f64` edge fallback).
#[inline(never)]
pub(crate) fn test4_scalar(
    r: &WatertightRay,
    p: &Tri4,
    t_min: f32,
    t_max: f32,
) -> (u32, [f32; 4], [f32; 4], [f32; 4]) {
    let mut out = (0u32, [0.0f32; 4], [0.0f32; 4], [0.0f32; 4]);
    for lane in 0..4 {
        if let Some((t, u, v)) = intersect_watertight(r, &p.lane(lane), t_min, t_max) {
            out.0 |= 1 << lane;
            (out.1[lane], out.2[lane], out.3[lane]) = (t, u, v);
        }
    }
    out
}

/// Portable fallback: the scalar test per lane.
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
pub(crate) fn intersect4(r4: &Ray4, p: &Tri4, t_max: f32, ids: &[u32]) -> Option<(f32, f32, f32, usize)> {
    let (r, t_min) = (&r4.ray, r4.t_min);
    let mut best: Option<(f32, f32, f32, usize)> = None;
    let mut t_max = t_max;
    for lane in 0..4 {
        if let Some((t, u, v)) = intersect_watertight(r, &p.lane(lane), t_min, t_max) {
            if best.is_none_or(|b| t < b.0 || (t == b.0 && ids[lane] < ids[b.3])) {
                best = Some((t, u, v, lane));
                t_max = t;
            }
        }
    }
    best
}

#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
pub(crate) fn occluded4(r4: &Ray4, p: &Tri4, t_max: f32) -> bool {
    test4_scalar(&r4.ray, p, r4.t_min, t_max).0 != 0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh::SplitMix64;

    /// Every lane of the SIMD test equals the scalar test bit for bit.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn simd_lanes_equal_the_scalar_test() {
        let mut rng = SplitMix64(11);
        let mut rnd = move || 2.0 * rng.next_f32() - 1.0;
        let mut hits = 0;
        for k in 0..20_000 {
            let n = 1 + k % 4;
            let tris: Vec<Tri> = (0..n).map(|_| [0, 1, 2].map(|_| [rnd(), rnd(), rnd()])).collect();
            let p = Tri4::pack(&tris);
            let o = Vec3::new(rnd(), rnd(), rnd()) * 2.0;
            let target = Vec3::from_array(tris[0][0]) * 0.6;
            let d = target - o;
            let wr = WatertightRay::new(o, d);
            let (t_min, t_max) = (0.1 * rnd().abs(), 1.0 + 3.0 * rnd().abs());
            let scalar = test4_scalar(&wr, &p, t_min, t_max);
            let r4 = Ray4::new(wr, t_min);
            let Hits4 { t, u, v, mask } = test4(&r4, &p, t_max);
            assert_eq!(mask, scalar.0);
            for lane in 0..4 {
                if mask & (1 << lane) != 0 {
                    assert_eq!((t[lane], u[lane], v[lane]), (scalar.1[lane], scalar.2[lane], scalar.3[lane]));
                }
            }
            hits += mask.count_ones();
            assert_eq!(occluded4(&r4, &p, t_max), mask != 0);
        }
        assert!(hits > 2000, "{hits}");
    }
}
