//! The 8-wide slab test of one ray against a node's eight child boxes, and the node
//! layouts the traversal loop ([`super::traverse`]) runs over.

use crate::wide::{octant_rows, Entry, Node8, FAR_SCALE};
use filtrace_core::Vec3;
use std::arch::x86_64::*;

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
///
/// The row offsets are rows of a constant table picked by the direction's octant: one
/// address per ray instead of six offsets worked out and stored (the loop reloads them
/// either way: it has too few registers to keep them).
#[derive(Clone, Copy)]
pub(crate) struct RayBoxes8 {
    pub inv: [__m256; 3],
    /// `o inv + e` (near planes) and `o inv - e` (far planes).
    pub oinv_near: [__m256; 3],
    pub oinv_far: [__m256; 3],
    pub near: &'static [usize; 3],
    pub far: &'static [usize; 3],
}

/// Offsets (in floats) of the near and far bound rows of a `Node8` per axis, for each
/// octant (bit `k` set: `dir[k]` negative, the far row first).
static ROWS8: [[[usize; 3]; 8]; 2] = [octant_rows(8, false), octant_rows(8, true)];

impl RayBoxes8 {
    /// The three axes at once in one SSE register (lane `k` = axis `k`; the same
    /// operations, each rounded once, as a scalar loop per axis), then splatted.
    #[inline(always)]
    pub unsafe fn new(origin: Vec3, dir: Vec3) -> Self {
        let d = _mm_setr_ps(dir.x, dir.y, dir.z, 1.0);
        let o = _mm_setr_ps(origin.x, origin.y, origin.z, 0.0);
        let sign = _mm_set1_ps(-0.0);
        let tiny = _mm_set1_ps(1e-30);
        let abs = |v: __m128| _mm_andnot_ps(sign, v);
        // `±10^-30` (the sign of `d`) where `|d| < 10^-30`.
        let small = _mm_cmplt_ps(abs(d), tiny);
        let d = _mm_blendv_ps(d, _mm_or_ps(_mm_and_ps(d, sign), tiny), small);
        let inv = _mm_div_ps(_mm_set1_ps(1.0), d);
        let c = _mm_mul_ps(o, inv);
        let e = _mm_add_ps(_mm_mul_ps(abs(c), _mm_set1_ps(1.0 / (1u32 << 21) as f32)), tiny);
        let (lo, hi) = (_mm_add_ps(c, e), _mm_sub_ps(c, e));
        // `inv[k] >= 0` exactly when `d` has no sign bit (`d` is never zero or NaN and
        // `1 / d` never rounds to zero); testing `d` keeps the row offsets, which the
        // first node's loads need, off the division's latency.
        let octant = _mm_movemask_ps(d) as usize & 7;
        let splat = |v: __m128| {
            let v = _mm256_castps128_ps256(v);
            [0, 1, 2].map(|k| _mm256_permutevar8x32_ps(v, _mm256_set1_epi32(k)))
        };
        Self {
            inv: splat(inv),
            oinv_near: splat(lo),
            oinv_far: splat(hi),
            near: &ROWS8[0][octant],
            far: &ROWS8[1][octant],
        }
    }
}

/// Slab test of a ray on `[t_min, t_max]` against the eight child boxes of `n`, given
/// `cull`, the cull bound `cull_bound(t_max)` splatted: hit mask (bit `i` for child `i`)
/// and entry distances.
#[inline(always)]
pub(crate) unsafe fn box8(n: &Node8, r: &RayBoxes8, t_min: __m256, cull: __m256) -> (u32, __m256) {
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
    let t_far = _mm256_min_ps(fz, _mm256_min_ps(fy, _mm256_min_ps(fx, cull)));
    let t_far = _mm256_mul_ps(t_far, _mm256_set1_ps(FAR_SCALE));
    let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t_near, t_far)) as u32;
    (mask, t_near)
}

/// What the 8-wide traversal loop needs of a node layout ([`Node8`], and the compressed
/// `qwide::QNode8`): the slab test of its eight child boxes and its child references.
/// Everything is `#[inline(always)]`, so each layout's loop is compiled as if written out.
pub(crate) trait Node8Layout {
    /// Cache lines of one node (2 or 4), prefetched before a child node is visited.
    const LINES: usize;

    /// Slab test of the ray `r` on `[t_min, t_max]` against the eight child boxes, given
    /// `cull`, `cull_bound(t_max)` splatted (the loop works it out again only when a
    /// leaf visit may have shortened `t_max`; at every node, a closest-hit query spent 7
    /// instructions on it): hit mask (bit `i` for child `i`, empty slots never set) and
    /// entry distances. Safety: the caller runs with AVX2 and FMA.
    unsafe fn boxes(&self, r: &RayBoxes8, t_min: __m256, cull: __m256) -> (u32, __m256);

    /// Child `i`: `(node index, 0)` for an inner node, `(first packet, packet count)` for
    /// a leaf.
    fn child(&self, i: usize) -> (u32, u32);

    /// The stack entry of child `i` entered at distance `t`.
    #[inline(always)]
    fn entry(&self, i: usize, t: f32) -> Entry {
        let (child, count) = self.child(i);
        Entry { child, count, t }
    }
}

impl Node8Layout for Node8 {
    const LINES: usize = 4;

    #[inline(always)]
    unsafe fn boxes(&self, r: &RayBoxes8, t_min: __m256, cull: __m256) -> (u32, __m256) {
        // SAFETY: AVX2 and FMA (the caller's).
        unsafe { box8(self, r, t_min, cull) }
    }

    #[inline(always)]
    fn child(&self, i: usize) -> (u32, u32) {
        (self.child[i], self.count[i])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh::{grazing_ray, SplitMix64};
    use crate::wide::cull_bound;

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
            let Some((o, d, t_max)) =
                grazing_ray(k, &mut rnd, (lo, hi), |r| lo + (hi - lo) * r * 3.0 - (hi - lo))
            else {
                continue;
            };
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
            let mask = unsafe {
                box8(&node, &RayBoxes8::new(o, d), _mm256_setzero_ps(), _mm256_set1_ps(cull_bound(t_max))).0
            };
            assert_eq!(mask & !(1 << (k % 8)), 0, "empty slots never hit");
            if exact(o, d, lo, hi, t_max) {
                touched += 1;
                assert_ne!(mask, 0, "culled a touched box: o {o} d {d} box {lo} {hi} t_max {t_max}");
            }
            hits += (mask != 0) as usize;
        }
        assert!(touched > 50_000 && hits < 190_000, "{touched} {hits}");
    }
}
