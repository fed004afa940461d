//! The AVX2 slab test of compressed 8-wide nodes ([`QNode8`]), the node layout that the
//! traversal loop of the uncompressed nodes (`avx2::traverse8`) also runs over.
//!
//! Each plane of the slab test first decodes its eight grid values to floats, one
//! `vpmovzxbd` (8 bytes to 8 integers), one `vcvtdq2ps` and one fused multiply-add
//! `q s + o` (the exact [`crate::qwide::decode`] the quantisation checked), then takes the
//! fused slab distance of the uncompressed test (`avx2::RayBoxes8`, conservative as
//! Ize 2013). The decoded boxes contain the exact ones, so the test culls no box the
//! uncompressed one keeps; the leaves are the uncompressed tree's, tested by the same
//! kernels (`avx2::ClosestPairs`, `avx2::AnyPairs`), so hits are bit-identical.
//!
//! Every function here needs AVX2 and FMA (see `avx2.rs` for the inlining scheme).

use crate::avx2::{Node8Layout, RayBoxes8};
use crate::qwide::QNode8;
use crate::wide::FAR_SCALE;
use std::arch::x86_64::*;

/// The eight decoded bounds of grid row `row` (byte offset `8 row`, as the float row
/// offsets of [`RayBoxes8`] for the 8-float rows of `Node8`) on axis `k`.
#[inline(always)]
unsafe fn plane(n: &QNode8, offset: usize, k: usize) -> __m256 {
    // SAFETY: `offset = 8 row`, `row < 6`: the eight bytes lie inside `q`.
    let q = unsafe { _mm_loadl_epi64(n.q.as_ptr().cast::<u8>().add(offset) as *const __m128i) };
    let q = _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(q));
    _mm256_fmadd_ps(q, _mm256_set1_ps(n.scale[k]), _mm256_set1_ps(n.origin[k]))
}

/// Slab test of a ray against the eight decoded child boxes of `n`, given `cull`
/// (`cull_bound(t_max)` splatted): hit mask (bit `i` for child `i`, unused slots never
/// set) and entry distances. The operations after decoding are those of `avx2::box8`.
#[inline(always)]
pub(crate) unsafe fn qbox8(n: &QNode8, r: &RayBoxes8, t_min: __m256, cull: __m256) -> (u32, __m256) {
    // SAFETY: AVX2 and FMA (the caller's target features); row offsets are below 48.
    // (Written out: a closure would not inherit the target features.)
    let (nx, fx, ny, fy, nz, fz) = unsafe {
        (
            _mm256_fmsub_ps(plane(n, r.near[0], 0), r.inv[0], r.oinv_near[0]),
            _mm256_fmsub_ps(plane(n, r.far[0], 0), r.inv[0], r.oinv_far[0]),
            _mm256_fmsub_ps(plane(n, r.near[1], 1), r.inv[1], r.oinv_near[1]),
            _mm256_fmsub_ps(plane(n, r.far[1], 1), r.inv[1], r.oinv_far[1]),
            _mm256_fmsub_ps(plane(n, r.near[2], 2), r.inv[2], r.oinv_near[2]),
            _mm256_fmsub_ps(plane(n, r.far[2], 2), r.inv[2], r.oinv_far[2]),
        )
    };
    let t_near = _mm256_max_ps(nz, _mm256_max_ps(ny, _mm256_max_ps(nx, t_min)));
    let t_far = _mm256_min_ps(fz, _mm256_min_ps(fy, _mm256_min_ps(fx, cull)));
    let t_far = _mm256_mul_ps(t_far, _mm256_set1_ps(FAR_SCALE));
    let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t_near, t_far)) as u32;
    (mask & n.valid, t_near)
}

/// The compressed layout of the traversal loop (`avx2::traverse8`): the decoded box test,
/// and leaf counts widened from bytes.
impl Node8Layout for QNode8 {
    const LINES: usize = 2;

    #[inline(always)]
    unsafe fn boxes(&self, r: &RayBoxes8, t_min: __m256, cull: __m256) -> (u32, __m256) {
        // SAFETY: AVX2 and FMA (the caller's).
        unsafe { qbox8(self, r, t_min, cull) }
    }

    #[inline(always)]
    fn child(&self, i: usize) -> (u32, u32) {
        (self.child[i], self.count[i] as u32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::avx2::box8;
    use crate::testmesh::{grazing_ray, SplitMix64};
    use crate::wide::{cull_bound, Node8};
    use filtrace_core::{Aabb, Vec3};

    /// The compressed test keeps every box the uncompressed test keeps (its boxes contain
    /// the exact ones), on rays grazing random boxes: origins on faces, directions aimed at
    /// corners or with zero components.
    #[test]
    fn compressed_box_test_keeps_every_box_the_exact_test_keeps() {
        if !filtrace_core::cpu::isa().has_avx2() {
            println!("SKIPPED: no AVX2 on this CPU");
            return;
        }
        let mut rng = SplitMix64(5);
        let mut rnd = move || rng.next_f32();
        let (mut kept, mut extra) = (0, 0);
        for k in 0..50_000 {
            let scale = [1e-3f32, 1.0, 1e3][k % 3];
            let mut node = Node8::EMPTY;
            for slot in 0..(1 + k % 8) {
                let lo = Vec3::new(rnd(), rnd(), rnd()) * scale * 10.0;
                let hi = lo + Vec3::new(rnd(), rnd(), rnd()) * scale * if k % 11 == 0 { 0.0 } else { 1.0 };
                node.set_child_box(slot, &Aabb::new(lo, hi));
            }
            let target = node.child_box(k % (1 + k % 8));
            let box_ = (target.min, target.max);
            let Some((o, d, t_max)) = grazing_ray(k, &mut rnd, box_, |r| r * scale * 12.0 - scale) else {
                continue;
            };
            let q = QNode8::compress(&node).unwrap();
            // SAFETY: checked `has_avx2()` above.
            let (exact, coarse) = unsafe {
                let (r, cull) = (RayBoxes8::new(o, d), _mm256_set1_ps(cull_bound(t_max)));
                (box8(&node, &r, _mm256_setzero_ps(), cull).0, qbox8(&q, &r, _mm256_setzero_ps(), cull).0)
            };
            assert_eq!(exact & !coarse, 0, "culled a box the exact test keeps: o {o} d {d} node {node:?}");
            assert_eq!(coarse & !q.valid, 0, "unused slots never hit");
            kept += exact.count_ones();
            extra += (coarse & !exact).count_ones();
        }
        assert!(kept > 20_000 && extra < kept, "{kept} {extra}");
    }
}
