//! Eight-wide traversal with AVX2, chosen at run time ([`crate::Simd::Avx2`]).
//!
//! The same binary SAH tree as the SSE path, collapsed to 8-wide nodes
//! ([`Node8`], Dammertz et al. 2008 with eight children; Embree's BVH8 on AVX CPUs): one
//! 8-lane slab test (Williams et al. 2005, far distance widened by `1 + 2 gamma_3` as in
//! Ize 2013, the operations of the SSE test in the same order) covers all eight children,
//! so an incoherent ray visits about half as many nodes as with four-wide nodes. Leaves
//! are ranges of the 4-triangle packets ([`Tri4`]) that the SSE path uses; two adjacent
//! packets are tested at once as eight lanes of the watertight test (Woop et al. 2013),
//! bit-identical to the scalar test (no fused multiply-adds: the sheared corners and edge
//! functions round exactly as [`crate::triangle::intersect_watertight`] does).
//!
//! Every function here needs AVX2 and FMA; callers check `filtrace_core::cpu::isa()` first. The small
//! kernels are `#[inline(always)] unsafe fn`s without target features (a function with
//! target features cannot be forced inline): they are only called from functions
//! compiled with `avx2,fma` (`traverse8`, `SceneAccel::intersect_avx2`), into which they
//! are inlined together with their intrinsics. Calling one elsewhere is unsafe on CPUs
//! without AVX2 and slow everywhere.

use crate::sah::MAX_DEPTH;
use crate::tri4::{prefetch_packets, test4_scalar, Tri4};
use crate::triangle::WatertightRay;
use crate::wide::{cull_bound, prefetch, push_children, Entry, Leaves, Node8, FAR_SCALE};
use filtrace_core::Vec3;
use std::arch::x86_64::*;
use std::mem::MaybeUninit;

/// Per-ray constants of the 8-wide box test: reciprocal direction and `origin * inv`
/// splatted to eight lanes, and the offsets (in floats) of the near and far bound rows
/// per axis.
///
/// The slab distance `(b - o) inv` is evaluated as one fused multiply-subtract
/// `b inv - o inv` (two operations per plane fewer than subtract-then-multiply, as
/// Embree's non-robust mode does), made conservative again: `o inv` is rounded once, so
/// the near planes subtract `o inv + e` and the far planes `o inv - e` with
/// `e = |o inv| 2^-21 + 10^-30` (at least twice the rounding error of `o inv` and of the
/// sum), which makes the rounded near distance no larger and the far distance no
/// smaller than `(b - o) inv` before the final rounding; that last rounding is covered by
/// the `1 + 2 gamma_3` widening of the far distance as in Ize 2013. Zero direction
/// components are replaced by `±10^-30` (a reciprocal of `±10^30`, finite, so a ray in a
/// slab plane is inside that slab and a ray outside it is culled).
#[derive(Clone, Copy)]
pub(crate) struct RayBoxes8 {
    pub inv: [__m256; 3],
    /// `o inv + e` (near planes) and `o inv - e` (far planes).
    pub oinv_near: [__m256; 3],
    pub oinv_far: [__m256; 3],
    pub near: [usize; 3],
    pub far: [usize; 3],
}

impl RayBoxes8 {
    #[inline(always)]
    pub unsafe fn new(origin: Vec3, dir: Vec3) -> Self {
        let mut inv = [0.0f32; 3];
        let mut lo = [0.0f32; 3];
        let mut hi = [0.0f32; 3];
        let mut near = [0; 3];
        let mut far = [0; 3];
        for k in 0..3 {
            let d = if dir[k].abs() < 1e-30 { 1e-30f32.copysign(dir[k]) } else { dir[k] };
            inv[k] = 1.0 / d;
            let c = origin[k] * inv[k];
            let e = c.abs() * (1.0 / (1u32 << 21) as f32) + 1e-30;
            (lo[k], hi[k]) = (c + e, c - e);
            // `inv[k] >= 0` exactly when `d` has no sign bit (`d` is never zero or NaN and
            // `1 / d` never rounds to zero); testing `d` keeps the row offsets, which the
            // first node's loads need, off the division's latency.
            (near[k], far[k]) =
                if d.is_sign_positive() { (8 * k, 8 * (k + 3)) } else { (8 * (k + 3), 8 * k) };
        }
        let splat = |v: [f32; 3]| v.map(|x| _mm256_set1_ps(x));
        Self { inv: splat(inv), oinv_near: splat(lo), oinv_far: splat(hi), near, far }
    }
}

/// Slab test of a ray against the eight child boxes of `n`: hit mask (bit `i` for child
/// `i`) and entry distances.
#[inline(always)]
pub(crate) unsafe fn box8(n: &Node8, r: &RayBoxes8, t_min: __m256, t_max: f32) -> (u32, __m256) {
    let b = n.bounds.as_ptr() as *const f32;
    // SAFETY: `Node8` is 64-byte aligned and its bound rows are 32 bytes, so every row is
    // 32-byte aligned; the row offsets are `8 * row` with `row < 6`.
    let (nx, fx, ny, fy, nz, fz) = unsafe {
        (
            _mm256_fmsub_ps(_mm256_load_ps(b.add(r.near[0])), r.inv[0], r.oinv_near[0]),
            _mm256_fmsub_ps(_mm256_load_ps(b.add(r.far[0])), r.inv[0], r.oinv_far[0]),
            _mm256_fmsub_ps(_mm256_load_ps(b.add(r.near[1])), r.inv[1], r.oinv_near[1]),
            _mm256_fmsub_ps(_mm256_load_ps(b.add(r.far[1])), r.inv[1], r.oinv_far[1]),
            _mm256_fmsub_ps(_mm256_load_ps(b.add(r.near[2])), r.inv[2], r.oinv_near[2]),
            _mm256_fmsub_ps(_mm256_load_ps(b.add(r.far[2])), r.inv[2], r.oinv_far[2]),
        )
    };
    // Two levels of min/max instead of a chain of three (shorter latency). `max(a, b)`
    // returns `b` when either is NaN, so `t_min` and the cull bound go last and the results
    // are never NaN; a NaN slab distance (only from an overflowing `o inv`; an empty slot's
    // infinite bounds give `±inf`, which fails the comparison as it should) may drop the
    // other slab of its pair, which only widens the box (conservative).
    let t_near = _mm256_max_ps(nz, _mm256_max_ps(ny, _mm256_max_ps(nx, t_min)));
    let t_far = _mm256_min_ps(fz, _mm256_min_ps(fy, _mm256_min_ps(fx, _mm256_set1_ps(cull_bound(t_max)))));
    let t_far = _mm256_mul_ps(t_far, _mm256_set1_ps(FAR_SCALE));
    let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t_near, t_far)) as u32;
    (mask, t_near)
}

/// One compare-exchange layer of the sorting network in [`push_sorted8`]: each lane
/// meets the lane `perm` names; lanes whose bit is set in `LOW` keep the minimum.
#[inline(always)]
unsafe fn sort_layer<const LOW: i32>(x: __m256i, perm: [i32; 8]) -> __m256i {
    // SAFETY: `perm` is 8 `i32`, read unaligned.
    let p = _mm256_permutevar8x32_epi32(x, unsafe { _mm256_loadu_si256(perm.as_ptr() as *const __m256i) });
    _mm256_blend_epi32::<LOW>(_mm256_max_epi32(x, p), _mm256_min_epi32(x, p))
}

/// Closest-hit child ordering for three or more hit children without branches on the
/// distances: keys `(entry distance bits with the low 3 bits replaced by 7 - lane)`, so
/// that among equal distances (boxes around the origin) the later slot, the more likely
/// hit of [`crate::child_order`], goes first; missed lanes `i32::MAX`, sorted by the 19-comparator, depth-6 network for 8 inputs (Knuth,
/// TAOCP 5.3.4); pushes all but the nearest far-first and returns the nearest. Dropping
/// 3 mantissa bits only changes the visiting order of nearly equal children, and closest
/// hits do not depend on the order (the tie rule).
#[inline(always)]
pub(crate) unsafe fn push_sorted8<N: Children8>(
    mask: u32,
    tn: __m256,
    node: &N,
    stack: &mut [MaybeUninit<Entry>],
    sp: &mut usize,
) -> Entry {
    let lane = _mm256_setr_epi32(7, 6, 5, 4, 3, 2, 1, 0);
    let keys = _mm256_or_si256(_mm256_andnot_si256(_mm256_set1_epi32(7), _mm256_castps_si256(tn)), lane);
    let hit = _mm256_cmpgt_epi32(
        _mm256_and_si256(_mm256_set1_epi32(mask as i32), _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128)),
        _mm256_setzero_si256(),
    );
    let mut x = _mm256_blendv_epi8(_mm256_set1_epi32(i32::MAX), keys, hit);
    // SAFETY: AVX2 (the caller's target features).
    unsafe {
        x = sort_layer::<0b0011_0011>(x, [2, 3, 0, 1, 6, 7, 4, 5]);
        x = sort_layer::<0b0000_1111>(x, [4, 5, 6, 7, 0, 1, 2, 3]);
        x = sort_layer::<0b0101_0101>(x, [1, 0, 3, 2, 5, 4, 7, 6]);
        x = sort_layer::<0b0000_1100>(x, [0, 1, 4, 5, 2, 3, 6, 7]);
        x = sort_layer::<0b0000_1010>(x, [0, 4, 2, 6, 1, 5, 3, 7]);
        x = sort_layer::<0b0010_1010>(x, [0, 2, 1, 4, 3, 6, 5, 7]);
    }
    let mut k = [0i32; 8];
    let mut t = Lanes8([0.0; 8]);
    // SAFETY: `k` written unaligned, `Lanes8` is 32-byte aligned.
    unsafe {
        _mm256_storeu_si256(k.as_mut_ptr() as *mut __m256i, x);
        _mm256_store_ps(t.0.as_mut_ptr(), tn);
    }
    let e = |key: i32| {
        let i = 7 - (key & 7) as usize;
        node.entry(i, t.0[i])
    };
    let n = mask.count_ones() as usize;
    debug_assert!(*sp + n <= stack.len(), "BVH deeper than MAX_DEPTH");
    for j in (1..n).rev() {
        stack[*sp] = MaybeUninit::new(e(k[j]));
        *sp += 1;
    }
    e(k[0])
}

/// The child references of an 8-wide node ([`Node8`], `qwide::QNode8`), for
/// [`push_sorted8`].
pub(crate) trait Children8 {
    /// The stack entry of child `i` entered at distance `t`.
    fn entry(&self, i: usize, t: f32) -> Entry;
}

impl Children8 for Node8 {
    #[inline(always)]
    fn entry(&self, i: usize, t: f32) -> Entry {
        Entry { child: self.child[i], count: self.count[i], t }
    }
}

/// Eight 32-byte aligned floats (stored by one aligned store, read back one at a time).
#[repr(C, align(32))]
struct Lanes8([f32; 8]);

/// Traversal stack depth: each 8-wide level pushes at most seven entries.
const STACK8: usize = 7 * MAX_DEPTH + 8;

/// Visits every leaf of the 8-wide BVH `nodes` whose box the ray `[t_min, *t_max]`
/// touches, as [`crate::wide::traverse`] does for four-wide nodes: near-first for
/// closest hits (`ORDERED`), from the last slot down for any hits (the build-time order
/// of [`crate::child_order`]); returns `true` when a visit asked to stop.
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn traverse8<L: Leaves, const ORDERED: bool>(
    nodes: &[Node8],
    r: &RayBoxes8,
    t_min: f32,
    t_max: &mut f32,
    leaves: L,
) -> bool {
    let root = Entry { child: 0, count: 0, t: t_min };
    // SAFETY: AVX2 and FMA (this function's target features).
    unsafe { traversal8::<L, ORDERED>(nodes, root, r, t_min, t_max, leaves) }
}

/// [`traverse8`] of the subtree `start` only (a node, or a leaf range, that the caller
/// found the ray to touch): the single-ray half of the hybrid packet traversal
/// (`avx2_packet::hybrid`).
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn traverse8_from<L: Leaves, const ORDERED: bool>(
    nodes: &[Node8],
    start: Entry,
    r: &RayBoxes8,
    t_min: f32,
    t_max: &mut f32,
    leaves: L,
) -> bool {
    // SAFETY: AVX2 and FMA (this function's target features).
    unsafe { traversal8::<L, ORDERED>(nodes, start, r, t_min, t_max, leaves) }
}

/// The loop of [`traverse8`] and [`traverse8_from`], inlined into each: as one function
/// called from both, it was no longer inlined into `traverse8`, and incoherent any hits
/// lost 7-9 % on the bunny (stop 16). Safety: the caller runs with AVX2 and FMA.
#[inline(always)]
unsafe fn traversal8<L: Leaves, const ORDERED: bool>(
    nodes: &[Node8],
    start: Entry,
    r: &RayBoxes8,
    t_min: f32,
    t_max: &mut f32,
    mut leaves: L,
) -> bool {
    if nodes.is_empty() {
        return false;
    }
    let t_min8 = _mm256_set1_ps(t_min);
    let mut stack = [MaybeUninit::<Entry>::uninit(); STACK8];
    let mut sp = 0usize;
    let mut cur = start;
    let mut t_near = Lanes8([0.0; 8]);
    loop {
        if cur.count == 0 {
            debug_assert!((cur.child as usize) < nodes.len());
            // SAFETY: child indices of a built tree are in range (`wide::validate`).
            let node = unsafe { nodes.get_unchecked(cur.child as usize) };
            // SAFETY: this function runs with AVX2 (its target features).
            let (mask, tn) = unsafe { box8(node, r, t_min8, *t_max) };
            if mask != 0 {
                // SAFETY: `Lanes8` is 32-byte aligned.
                unsafe { _mm256_store_ps(t_near.0.as_mut_ptr(), tn) };
                let e = |i: usize| Entry { child: node.child[i], count: node.count[i], t: t_near.0[i] };
                // Start fetching every child to be visited while the order is worked out,
                // without a branch on node or leaf (it was mispredicted near the leaves):
                // the 4 lines of a node, or the up to 6 lines of a two-packet leaf from
                // the line holding its first byte (a node gets its first two lines again).
                let mut bits = mask;
                while bits != 0 {
                    let i = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    let (c, n) = (node.child[i], node.count[i]);
                    let inner = nodes.as_ptr().wrapping_add(c as usize) as usize;
                    let leaf = leaves.leaf_addr(c) & !63;
                    let p = if n == 0 { inner } else { leaf };
                    let rest = if n == 0 { p } else { p + 256 };
                    prefetch(p as *const u8, 4);
                    prefetch(rest as *const u8, 2);
                }
                cur = if ORDERED && mask.count_ones() >= 3 {
                    // SAFETY: AVX2 (this function's target features); at most 8 entries
                    // are pushed and `STACK8` leaves room for 7 per level.
                    unsafe { push_sorted8(mask, tn, node, &mut stack, &mut sp) }
                } else {
                    push_children::<ORDERED>(mask, e, &mut stack, &mut sp)
                };
                continue;
            }
        } else if ORDERED {
            // Closest hits: the leaf test out of line (see `visit_leaf`).
            // SAFETY: AVX2 (this function's target features).
            unsafe {
                std::hint::black_box(visit_leaf::<L> as VisitLeaf<L>)(
                    &mut leaves,
                    cur.child,
                    cur.count,
                    t_max,
                )
            };
        } else if leaves.visit(cur.child, cur.count, t_max) {
            return true;
        }
        // Pop the nearest pending entry that can still hold a closer hit.
        loop {
            if sp == 0 {
                return false;
            }
            sp -= 1;
            // SAFETY: entries below `sp` were written before `sp` was raised past them
            // (and `sp < STACK8`).
            let e = unsafe { stack.get_unchecked(sp).assume_init() };
            if e.t <= cull_bound(*t_max) {
                cur = e;
                break;
            }
        }
    }
}

/// `leaves.visit(first, count, t_max)` out of line, for closest hits: the traversal loop
/// then keeps its ray constants in registers (the triangle test needs most of the 16
/// vector registers). Bunny, 1 thread: primary rays +3 %, incoherent closest hits even;
/// any-hit queries stay inline (a call per leaf cost them 9 %). Called through a
/// `black_box`ed pointer: `#[inline(never)]` on a `#[target_feature]` function was
/// ignored (rustc 1.95), and the function was inlined all the same.
#[target_feature(enable = "avx2,fma")]
#[inline(never)]
fn visit_leaf<L: Leaves>(leaves: &mut L, first: u32, count: u32, t_max: &mut f32) -> bool {
    leaves.visit(first, count, t_max)
}

type VisitLeaf<L> = unsafe fn(&mut L, u32, u32, &mut f32) -> bool;

/// A ray prepared for the 8-lane triangle test: the watertight constants with the
/// permuted origin and the shear factors splatted, and the row offsets of the permuted
/// axes inside a [`Tri4`] corner (as [`crate::tri4::Ray4`]).
#[derive(Clone, Copy)]
pub(crate) struct Ray8<'a> {
    o: [__m256; 3],
    s: [__m256; 3],
    t_min8: __m256,
    t_min: f32,
    row: [usize; 3],
    /// By reference: copying it into this struct would read back its scalar stores as
    /// one vector (a store-forwarding stall on every ray).
    ray: &'a WatertightRay,
}

impl<'a> Ray8<'a> {
    #[inline(always)]
    pub unsafe fn new(ray: &'a WatertightRay, t_min: f32) -> Self {
        Self {
            o: [
                _mm256_set1_ps(ray.org[ray.kx]),
                _mm256_set1_ps(ray.org[ray.ky]),
                _mm256_set1_ps(ray.org[ray.kz]),
            ],
            s: [_mm256_set1_ps(ray.sx), _mm256_set1_ps(ray.sy), _mm256_set1_ps(ray.sz)],
            t_min8: _mm256_set1_ps(t_min),
            t_min,
            row: [4 * ray.kx, 4 * ray.ky, 4 * ray.kz],
            ray,
        }
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
    hit: __m256,
    t: __m256,
    u: __m256,
    v: __m256,
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
    let (e, z) = sheared_edges(p0, p1, p2, r.o, r.s);
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
    let in_range = _mm256_and_ps(
        _mm256_cmp_ps::<_CMP_GE_OQ>(t, r.t_min8),
        _mm256_cmp_ps::<_CMP_LE_OQ>(t, _mm256_set1_ps(t_max)),
    );
    let hit = _mm256_and_ps(_mm256_andnot_ps(reject, in_range), lane_mask(lanes));
    Lanes { hit, t, u, v }
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
fn test8_scalar(r: &Ray8, a: &Tri4, b: &Tri4, lanes: u32, t_max: f32) -> Hits8 {
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

/// Closest hit among `packets` with `t` in `[t_min, t_max]`: `(t, u, v, 4 packet +
/// lane)` relative to the slice, `ids` the primitive ids of the slice's lanes,
/// ascending (leaves and flat meshes are stored in id order). Packets are tested in
/// pairs; each lane keeps its nearest hit in registers (no branch per pair; on equal `t`
/// the earlier pair stays, which has the smaller id), and one horizontal minimum at the
/// end picks the lane. Equal `t` in two lanes (rare: shared edges, coincident
/// triangles) sends the leaf to [`closest_exact`], which applies the tie rule (smallest
/// id) of the other kernels. (Tracking equal `t` within a lane instead cost 5-7 % of
/// the Cornell box's single-ray closest hits.)
#[inline(always)]
pub(crate) unsafe fn closest_in(
    r: &Ray8,
    packets: &[Tri4],
    ids: &[u32],
    t_max: f32,
) -> Option<(f32, f32, f32, usize)> {
    let inf = _mm256_set1_ps(f32::INFINITY);
    let (mut bt, mut bu, mut bv) = (inf, _mm256_setzero_ps(), _mm256_setzero_ps());
    let mut bp = _mm256_set1_epi32(-1);
    for (j, pair) in packets.chunks(2).enumerate() {
        let (b, lanes) = if pair.len() == 2 { (&pair[1], 0xff) } else { (&pair[0], 0x0f) };
        let l = test8v(r, &pair[0], b, lanes, t_max);
        let closer = _mm256_and_ps(l.hit, _mm256_cmp_ps::<_CMP_LT_OQ>(l.t, bt));
        bt = _mm256_blendv_ps(bt, l.t, closer);
        bu = _mm256_blendv_ps(bu, l.u, closer);
        bv = _mm256_blendv_ps(bv, l.v, closer);
        bp = _mm256_castps_si256(_mm256_blendv_ps(
            _mm256_castsi256_ps(bp),
            _mm256_castsi256_ps(_mm256_set1_epi32(j as i32)),
            closer,
        ));
    }
    let hit = _mm256_movemask_ps(_mm256_castsi256_ps(bp)) as u32 ^ 0xff;
    if hit == 0 {
        return None;
    }
    // Horizontal minimum of `bt` (missed lanes hold +inf).
    let m = _mm256_min_ps(bt, _mm256_permute2f128_ps::<1>(bt, bt));
    let m = _mm256_min_ps(m, _mm256_permute_ps::<0b01_00_11_10>(m));
    let m = _mm256_min_ps(m, _mm256_permute_ps::<0b10_11_00_01>(m));
    let at_min = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(bt, m)) as u32 & hit;
    if at_min & (at_min - 1) != 0 {
        return closest_exact(r, packets, ids, t_max);
    }
    let lane = at_min.trailing_zeros() as usize;
    let (mut t, mut u, mut v, mut p) = (Lanes8([0.0; 8]), Lanes8([0.0; 8]), Lanes8([0.0; 8]), [0i32; 8]);
    // SAFETY: `Lanes8` is 32-byte aligned; `p` is written with an unaligned store.
    unsafe {
        _mm256_store_ps(t.0.as_mut_ptr(), bt);
        _mm256_store_ps(u.0.as_mut_ptr(), bu);
        _mm256_store_ps(v.0.as_mut_ptr(), bv);
        _mm256_storeu_si256(p.as_mut_ptr() as *mut __m256i, bp);
    }
    Some((t.0[lane], u.0[lane], v.0[lane], 4 * 2 * p[lane] as usize + lane))
}

/// [`closest_in`] by the scalar test (bit-identical lanes), keeping the smallest id among
/// equal `t`.
#[inline(never)]
fn closest_exact(r: &Ray8, packets: &[Tri4], ids: &[u32], t_max: f32) -> Option<(f32, f32, f32, usize)> {
    let mut best: Option<(f32, f32, f32, usize)> = None;
    for (p, packet) in packets.iter().enumerate() {
        let (mask, t, u, v) = test4_scalar(r.ray, packet, r.t_min, t_max);
        for l in (0..4).filter(|l| mask & (1 << l) != 0) {
            let k = 4 * p + l;
            if crate::closer(t[l], best.map(|b| b.0), || best.is_some_and(|b| ids[k] < ids[b.3])) {
                best = Some((t[l], u[l], v[l], k));
            }
        }
    }
    best
}

/// Closest-hit leaf test over packet pairs; `best` holds `(t, u, v, 4 packet + lane)`.
pub(crate) struct ClosestPairs<'a> {
    pub packets: &'a [Tri4],
    /// The mesh triangle ids of the packet lanes (prefetched on a hit: without that, the
    /// id lookup after traversal was a cache miss costing ~15 % of a closest-hit query
    /// on the 270k-triangle sphere).
    pub prim_ids: &'a [u32],
    pub ray: Ray8<'a>,
    pub best: Option<(f32, f32, f32, usize)>,
}

impl Leaves for &mut ClosestPairs<'_> {
    #[inline(always)]
    fn visit(&mut self, first: u32, count: u32, t_max: &mut f32) -> bool {
        let leaf = &self.packets[first as usize..(first + count) as usize];
        let ids = &self.prim_ids[4 * first as usize..4 * (first + count) as usize];
        // SAFETY: the AVX2 traversal runs only where `Simd::Avx2.available()`.
        if let Some((t, u, v, i)) = unsafe { closest_in(&self.ray, leaf, ids, *t_max) } {
            let k = 4 * first as usize + i;
            let best = self.best;
            if crate::closer(t, best.map(|b| b.0), || {
                best.is_some_and(|b| self.prim_ids[k] < self.prim_ids[b.3])
            }) {
                *t_max = t;
                prefetch(self.prim_ids.as_ptr().wrapping_add(k) as *const u8, 1);
                self.best = Some((t, u, v, k));
            }
        }
        false
    }

    #[inline(always)]
    fn prefetch(&self, first: u32, count: u32) {
        prefetch_packets(self.packets, first, count);
    }

    #[inline(always)]
    fn leaf_addr(&self, first: u32) -> usize {
        self.packets.as_ptr().wrapping_add(first as usize) as usize
    }
}

/// Any-hit leaf test over packet pairs.
pub(crate) struct AnyPairs<'a> {
    pub packets: &'a [Tri4],
    pub ray: Ray8<'a>,
}

impl Leaves for AnyPairs<'_> {
    #[inline(always)]
    fn visit(&mut self, first: u32, count: u32, t_max: &mut f32) -> bool {
        // A plain loop: a closure would not inherit the AVX2 target features and would
        // keep the kernels from being inlined.
        let (mut i, end) = (first as usize, (first + count) as usize);
        while i < end {
            let (b, lanes) =
                if i + 1 < end { (&self.packets[i + 1], 0xff) } else { (&self.packets[i], 0x0f) };
            // SAFETY: as in `ClosestPairs`.
            if unsafe { _mm256_movemask_ps(test8v(&self.ray, &self.packets[i], b, lanes, *t_max).hit) } != 0 {
                return true;
            }
            i += 2;
        }
        false
    }

    #[inline(always)]
    fn prefetch(&self, first: u32, count: u32) {
        prefetch_packets(self.packets, first, count);
    }

    #[inline(always)]
    fn leaf_addr(&self, first: u32) -> usize {
        self.packets.as_ptr().wrapping_add(first as usize) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh::SplitMix64;
    use crate::triangle::Tri;

    /// The fused box test never culls a box that the ray touches, checked against an
    /// `f64` slab test on rays that graze boxes: origins on faces, edges and corners,
    /// directions with zero components, and rays aimed at corners.
    #[test]
    fn fused_box_test_is_conservative() {
        if !filtrace_core::cpu::isa().has_avx2() {
            println!("SKIPPED: no AVX2 on this CPU");
            return;
        }
        let mut rng = SplitMix64(21);
        let mut rnd = move || rng.next_f32();
        let exact = |o: Vec3, d: Vec3, lo: Vec3, hi: Vec3, t_max: f32| {
            let (mut tn, mut tf) = (0.0f64, t_max as f64);
            for k in 0..3 {
                let (o, d, lo, hi) = (o[k] as f64, d[k] as f64, lo[k] as f64, hi[k] as f64);
                if d == 0.0 {
                    if o < lo || o > hi {
                        return false;
                    }
                    continue;
                }
                let (a, b) = ((lo - o) / d, (hi - o) / d);
                tn = tn.max(a.min(b));
                tf = tf.min(a.max(b));
            }
            tn <= tf
        };
        let (mut touched, mut hits) = (0, 0);
        for k in 0..200_000 {
            let scale = [1e-3f32, 1.0, 1e3][k % 3];
            let offset = Vec3::new(rnd(), rnd(), rnd()) * scale * 10.0;
            let lo = offset + Vec3::new(rnd(), rnd(), rnd()) * scale;
            let hi = lo + Vec3::new(rnd(), rnd(), rnd()) * scale;
            let corner = Vec3::select(glam::BVec3::new(rnd() < 0.5, rnd() < 0.5, rnd() < 0.5), lo, hi);
            let mut o = lo + (hi - lo) * Vec3::new(rnd(), rnd(), rnd()) * 3.0 - (hi - lo);
            // Put the origin on a face plane now and then.
            if k % 4 == 0 {
                o[k % 3] = corner[k % 3];
            }
            let mut d = if k % 2 == 0 { corner - o } else { Vec3::new(rnd(), rnd(), rnd()) - 0.5 };
            if k % 5 == 0 {
                d[(k / 5) % 3] = 0.0;
            }
            if d == Vec3::ZERO {
                continue;
            }
            let t_max = if k % 7 == 0 { 1.0 } else { f32::INFINITY };
            let mut node = Node8 {
                bounds: [
                    [f32::INFINITY; 8],
                    [f32::INFINITY; 8],
                    [f32::INFINITY; 8],
                    [f32::NEG_INFINITY; 8],
                    [f32::NEG_INFINITY; 8],
                    [f32::NEG_INFINITY; 8],
                ],
                child: [0; 8],
                count: [0; 8],
            };
            for a in 0..3 {
                node.bounds[a][k % 8] = lo[a];
                node.bounds[a + 3][k % 8] = hi[a];
            }
            // SAFETY: checked `has_avx2()` above.
            let mask = unsafe { box8(&node, &RayBoxes8::new(o, d), _mm256_setzero_ps(), t_max).0 };
            assert_eq!(mask & !(1 << (k % 8)), 0, "empty slots never hit");
            if exact(o, d, lo, hi, t_max) {
                touched += 1;
                assert_ne!(mask, 0, "culled a touched box: o {o} d {d} box {lo} {hi} t_max {t_max}");
            }
            hits += (mask != 0) as usize;
        }
        assert!(touched > 50_000 && hits < 190_000, "{touched} {hits}");
    }

    /// Every lane of the 8-lane test equals the scalar test bit for bit, for pairs and
    /// single packets.
    #[test]
    fn avx2_lanes_equal_the_scalar_test() {
        if !filtrace_core::cpu::isa().has_avx2() {
            println!("SKIPPED: no AVX2 on this CPU");
            return;
        }
        let mut rng = SplitMix64(12);
        let mut rnd = move || 2.0 * rng.next_f32() - 1.0;
        let mut hits = 0;
        for k in 0..20_000 {
            let n = 1 + k % 8;
            let tris: Vec<Tri> = (0..n).map(|_| [0, 1, 2].map(|_| [rnd(), rnd(), rnd()])).collect();
            let a = Tri4::pack(&tris[..n.min(4)]);
            let b = Tri4::pack(&tris[n.min(4)..]);
            let lanes = if n > 4 { 0xff } else { 0x0f };
            let b = if n > 4 { &b } else { &a };
            let o = Vec3::new(rnd(), rnd(), rnd()) * 2.0;
            let d = Vec3::from_array(tris[k % n][0]) * 0.6 - o;
            let (t_min, t_max) = (0.1 * rnd().abs(), 1.0 + 3.0 * rnd().abs());
            // SAFETY: checked `has_avx2()` above.
            let (fast, slow) = unsafe {
                let wr = WatertightRay::new(o, d);
                let r = Ray8::new(&wr, t_min);
                (test8(&r, &a, b, lanes, t_max), test8_scalar(&r, &a, b, lanes, t_max))
            };
            assert_eq!(fast.mask, slow.mask);
            for lane in 0..8 {
                if fast.mask & (1 << lane) != 0 {
                    assert_eq!(
                        (fast.t[lane], fast.u[lane], fast.v[lane]),
                        (slow.t[lane], slow.u[lane], slow.v[lane])
                    );
                }
            }
            hits += fast.mask.count_ones();
            // The closest of the lanes, as the scalar test sees it.
            let packets = if n > 4 { vec![a, *b] } else { vec![a] };
            // SAFETY: checked `has_avx2()` above.
            let ids: Vec<u32> = (0..4 * packets.len() as u32).collect();
            let closest =
                unsafe { closest_in(&Ray8::new(&WatertightRay::new(o, d), t_min), &packets, &ids, t_max) };
            let best =
                (0..8).filter(|l| slow.mask & (1 << l) != 0).min_by(|&i, &j| slow.t[i].total_cmp(&slow.t[j]));
            match (closest, best) {
                (None, None) => {}
                (Some((t, u, v, lane)), Some(b)) => {
                    assert_eq!(t, slow.t[b]);
                    assert_eq!((t, u, v), (slow.t[lane], slow.u[lane], slow.v[lane]));
                }
                other => panic!("closest_in {other:?}"),
            }
        }
        assert!(hits > 2000, "{hits}");
    }

    /// The sorting-network ordering pushes exactly the hit children, nearest returned and
    /// the rest far-first (the stack pops near-first), as the insertion sort of
    /// `wide::push_children` does; distances that differ only in the 3 dropped mantissa
    /// bits may come in either order.
    #[test]
    fn sorted_push_matches_a_plain_sort() {
        if !filtrace_core::cpu::isa().has_avx2() {
            println!("SKIPPED: no AVX2 on this CPU");
            return;
        }
        let mut rng = SplitMix64::new(11);
        let node = Node8 {
            bounds: [[0.0; 8]; 6],
            child: std::array::from_fn(|i| 100 + i as u32),
            count: std::array::from_fn(|i| i as u32 % 3),
        };
        for case in 0..20_000 {
            let mask = loop {
                let m = (rng.next_u64() & 0xff) as u32;
                if m.count_ones() >= 3 {
                    break m;
                }
            };
            // Mostly spread distances, sometimes equal ones and zeros.
            let t: [f32; 8] = std::array::from_fn(|_| match rng.next_u64() % 4 {
                0 => 0.0,
                1 => 1.5,
                _ => 10.0 * rng.next_f32(),
            });
            let mut stack = [MaybeUninit::<Entry>::uninit(); STACK8];
            let mut sp = 1usize;
            // SAFETY: AVX2 checked above; `t` is 8 floats, read unaligned.
            let near = unsafe { push_sorted8(mask, _mm256_loadu_ps(t.as_ptr()), &node, &mut stack, &mut sp) };
            let mut order = vec![near];
            // SAFETY: entries `1..sp` were written by `push_sorted8`.
            order.extend((1..sp).rev().map(|j| unsafe { stack[j].assume_init() }));
            let mut lanes: Vec<usize> = order.iter().map(|e| (e.child - 100) as usize).collect();
            for (e, &i) in order.iter().zip(&lanes) {
                assert_eq!((e.count, e.t.to_bits()), (node.count[i], t[i].to_bits()), "case {case}");
            }
            let key = |x: f32| x.to_bits() & !7;
            assert!(
                order.windows(2).all(|w| key(w[0].t) <= key(w[1].t)),
                "case {case}: {:?}",
                order.iter().map(|e| e.t).collect::<Vec<_>>()
            );
            lanes.sort_unstable();
            let want: Vec<usize> = (0..8).filter(|i| mask & (1 << i) != 0).collect();
            assert_eq!(lanes, want, "case {case}");
        }
    }
}
