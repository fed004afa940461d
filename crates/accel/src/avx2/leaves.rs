//! Leaf tests of the 8-wide traversal: closest and any hit over ranges of packet pairs.

use super::tri8::{any8, test8v, Ray8};
use super::Lanes8;
use crate::tri4::{prefetch_packets, test4_scalar, Tri4};
use crate::wide::{prefetch, Leaves};
use std::arch::x86_64::*;

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
        // A lone last packet is tested twice (as both halves, all eight lanes used): the
        // same answer without the lane mask.
        let (mut i, end) = (first as usize, (first + count) as usize);
        assert!(end <= self.packets.len());
        while i < end {
            let j = if i + 1 < end { i + 1 } else { i };
            // SAFETY: `i <= j < end <= packets.len()`; AVX2 as in `ClosestPairs`.
            // The ray's constants are read through `black_box`, so each test loads its
            // splats where it uses them: hoisted out of the traversal loop, they were
            // splatted and spilled on every query, leaf or not, and reloaded all the same.
            let ray = std::hint::black_box(&self.ray);
            let hit = unsafe {
                let (a, b) = (self.packets.get_unchecked(i), self.packets.get_unchecked(j));
                any8(ray, a, b, *t_max)
            };
            if hit {
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
    use super::super::tri8::{test8, test8_scalar};
    use super::*;
    use crate::testmesh::SplitMix64;
    use crate::triangle::{Tri, WatertightRay};
    use filtrace_core::Vec3;

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
            // The any-hit form (a lone packet tested as both halves) agrees with the mask.
            // SAFETY: checked `has_avx2()` above.
            let any = unsafe { any8(&Ray8::new(&WatertightRay::new(o, d), t_min), &a, b, t_max) };
            assert_eq!(any, slow.mask != 0);
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
}
