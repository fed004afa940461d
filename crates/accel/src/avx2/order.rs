//! Near-first ordering of three or more hit children by a sorting network (closest hits).

use super::boxes::Node8Layout;
use super::Lanes8;
use crate::wide::Entry;
use std::arch::x86_64::*;
use std::mem::MaybeUninit;

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
pub(crate) unsafe fn push_sorted8<N: Node8Layout>(
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

#[cfg(test)]
mod tests {
    use super::super::traverse::STACK8;
    use super::*;
    use crate::testmesh::SplitMix64;
    use crate::wide::Node8;

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
