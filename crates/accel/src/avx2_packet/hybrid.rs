//! Hybrid packet / single-ray traversal of 8-wide BVHs (Benthin, Boulos, Lacewell and
//! Keller 2012, "Combining single and packet ray tracing for arbitrary ray distributions
//! on the Intel MIC architecture").
//!
//! A packet node test (8 rays x 1 box per child) costs about what eight single-ray node
//! tests (1 ray x 8 boxes) cost, whatever the number of lanes that need the node; what a
//! packet saves is the memory traffic and the per-node bookkeeping it shares between its
//! lanes. So the packet is traversed as one only while enough lanes are active in the
//! subtree: each pending subtree carries the lanes whose rays touched its box (the
//! packet's box test counts them), and a subtree entered by fewer than
//! [`MIN_PACKET_LANES`] lanes is traversed by each of them alone, from that node on, with
//! the single-ray kernel (`avx2::traverse8_from`) and the lane's closest hit so far as its
//! `t_max`. Unlike the coherent kernels of the parent module, any packet is taken: the
//! box test selects each lane's near and far planes by its own direction signs
//! ([`LaneBoxes8`]), and leaves are tested as a packet only when the lanes share their
//! watertight permutation (else the lanes go on alone there too).
//!
//! Per lane the answer is that of the single-ray query, bit for bit: boxes only cull
//! (conservatively, lane for lane the slab test of `avx2::box8`), the packet's triangle
//! test is the single-ray arithmetic per lane, and the closest hit is the smallest
//! `(t, primitive id)` whatever the visit order.
//!
//! `SceneAccel::occluded_packet` takes [`occluded_hybrid`] for the packets the coherent
//! kernel declines; [`closest_hybrid`] is reached only through
//! `SceneAccel::intersect_packet_hybrid`: on the bunny it lost to one single-ray query
//! per lane (docs/perf-accel.md, "Stop 16").

use super::{closest_leaf, occluded_leaf, Best8};
use super::{cull8, expand, ld, setup, slab, ChildBoxes, Closest8, PacketEntry, I8, NO_HIT, STACK8};
use crate::avx2::{traverse8_from, AnyPairs, ClosestPairs, Ray8, RayBoxes8};
use crate::ray_packet::{RayPacket, LANES};
use crate::tri4::TriPackets;
use crate::triangle::WatertightRay;
use crate::wide::{Entry, Node8, FAR_SCALE};
use filtrace_core::Ray;
use std::arch::x86_64::*;
use std::mem::MaybeUninit;

/// Fewest lanes that traverse a subtree as a packet; fewer go on one by one. Any hits on
/// the bunny (`packet_lanes`, single rays / hybrid, two runs): 4 lanes 1.22 and 1.15
/// (incoherent), 1.14 and 1.05 (shadow); 6: 1.04-1.22 and 1.02-1.05; 8: 1.25-1.33 and
/// 1.02-1.07 (docs/perf-accel.md, "Stop 16").
pub(crate) const MIN_PACKET_LANES: u32 = 4;

/// Per-lane constants of the 8 rays x 1 box test for lanes of any direction signs: the
/// slab constants of [`slab`] and, per axis, the lanes whose near plane is the upper one.
struct LaneBoxes8 {
    inv: [__m256; 3],
    oinv_near: [__m256; 3],
    oinv_far: [__m256; 3],
    /// All ones in lanes with `1 / d < 0` on the axis (`avx2::RayBoxes8`'s row choice).
    neg: [__m256; 3],
}

impl LaneBoxes8 {
    #[inline(always)]
    unsafe fn new(rays: &RayPacket) -> Self {
        let zero = _mm256_setzero_ps();
        let mut b = Self { inv: [zero; 3], oinv_near: [zero; 3], oinv_far: [zero; 3], neg: [zero; 3] };
        for k in 0..3 {
            (b.inv[k], b.oinv_near[k], b.oinv_far[k]) = slab(ld(&rays.origin[k]), ld(&rays.dir[k]));
            b.neg[k] = _mm256_cmp_ps::<_CMP_LT_OQ>(b.inv[k], zero);
        }
        b
    }
}

impl ChildBoxes for LaneBoxes8 {
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
        let mut near = [_mm256_setzero_ps(); 3];
        let mut far = [_mm256_setzero_ps(); 3];
        for k in 0..3 {
            let (lo, hi) = (_mm256_set1_ps(b[k][i]), _mm256_set1_ps(b[k + 3][i]));
            let (bn, bf) = (_mm256_blendv_ps(lo, hi, self.neg[k]), _mm256_blendv_ps(hi, lo, self.neg[k]));
            near[k] = _mm256_fmsub_ps(bn, self.inv[k], self.oinv_near[k]);
            far[k] = _mm256_fmsub_ps(bf, self.inv[k], self.oinv_far[k]);
        }
        let t_near = _mm256_max_ps(near[2], _mm256_max_ps(near[1], _mm256_max_ps(near[0], t_min)));
        let t_far = _mm256_min_ps(far[2], _mm256_min_ps(far[1], _mm256_min_ps(far[0], t_cull)));
        let t_far = _mm256_mul_ps(t_far, _mm256_set1_ps(FAR_SCALE));
        let hit = _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t_near, t_far), lanes);
        (_mm256_movemask_ps(hit) as u32, t_near)
    }
}

/// Closest hits of the lanes of `rays` set in `active` in the 8-wide BVH `nodes`/`tris`,
/// as a packet where at least `min_lanes` lanes share a subtree and one lane at a time
/// below ([`MIN_PACKET_LANES`] in `SceneAccel::intersect_packet_hybrid`; the tests also
/// take 0, 1 and 9).
///
/// # Safety
/// The CPU has AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn closest_hybrid(
    nodes: &[Node8],
    tris: &TriPackets,
    rays: &RayPacket,
    active: u8,
    min_lanes: u32,
) -> Closest8 {
    let r = setup(rays, active as u32);
    let mut best = Best8::new(r.t_max);
    let mut out = Closest8 { id: I8([NO_HIT; LANES]), ..Closest8::default() };
    if r.active == 0 || nodes.is_empty() {
        return out;
    }
    let b = LaneBoxes8::new(rays);
    let mut alone = Alone::new(rays);
    // Uninitialised: zeroing its 6.4 KB per query cost D1 write misses (packet_two_level.rs).
    let mut stack = [MaybeUninit::<PacketEntry>::uninit(); STACK8];
    let mut sp = 0usize;
    let mut cur = PacketEntry { child: 0, count: 0, lanes: r.active, t: 0.0 };
    loop {
        match r.uniform {
            _ if cur.lanes.count_ones() < min_lanes => {
                best.store(&mut out);
                closest_alone(nodes, tris, &mut alone, &cur, &mut out);
                best = Best8::load(&out);
            }
            _ if cur.count == 0 => {
                let node = &nodes[cur.child as usize];
                let t_cull = cull8(best.t);
                if let Some(next) =
                    expand::<true, _>(node, &b, r.t_min, t_cull, cur.lanes, &mut stack, &mut sp)
                {
                    cur = next;
                    continue;
                }
            }
            Some(k) => closest_leaf::<false>(tris, &r, k, &cur, &mut best, &mut out),
            None => {
                best.store(&mut out);
                closest_alone(nodes, tris, &mut alone, &cur, &mut out);
                best = Best8::load(&out);
            }
        }
        if sp == 0 {
            best.store(&mut out);
            return out;
        }
        sp -= 1;
        // SAFETY: entries below `sp` were written by `expand` before `sp` was raised past them.
        cur = stack[sp].assume_init();
    }
}

/// Lanes of `rays` set in `active` that hit any triangle of the 8-wide BVH with `t` in
/// `[t_min, t_max]`: as [`closest_hybrid`], lanes leaving the packet as soon as they hit.
///
/// # Safety
/// The CPU has AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn occluded_hybrid(
    nodes: &[Node8],
    tris: &TriPackets,
    rays: &RayPacket,
    active: u8,
    min_lanes: u32,
) -> u8 {
    let r = setup(rays, active as u32);
    if r.active == 0 || nodes.is_empty() {
        return 0;
    }
    let b = LaneBoxes8::new(rays);
    let mut alone = Alone::new(rays);
    // Uninitialised, as in `closest_hybrid`.
    let mut stack = [MaybeUninit::<PacketEntry>::uninit(); STACK8];
    let mut sp = 0usize;
    let t_cull = cull8(r.t_max);
    let mut left = r.active;
    let mut cur = PacketEntry { child: 0, count: 0, lanes: r.active, t: 0.0 };
    loop {
        match r.uniform {
            _ if cur.lanes.count_ones() < min_lanes => left &= !occluded_alone(nodes, tris, &mut alone, &cur),
            _ if cur.count == 0 => {
                let node = &nodes[cur.child as usize];
                if let Some(next) =
                    expand::<false, _>(node, &b, r.t_min, t_cull, cur.lanes, &mut stack, &mut sp)
                {
                    cur = next;
                    continue;
                }
            }
            Some(k) => left &= !occluded_leaf(tris, &r, k, &cur),
            None => left &= !occluded_alone(nodes, tris, &mut alone, &cur),
        }
        if left == 0 {
            return r.active as u8;
        }
        loop {
            if sp == 0 {
                return (r.active & !left) as u8;
            }
            sp -= 1;
            // SAFETY: as in `closest_hybrid`.
            cur = stack[sp].assume_init();
            cur.lanes &= left;
            if cur.lanes != 0 {
                break;
            }
        }
    }
}

/// The lanes' single-ray constants, made when a lane first leaves the packet and kept for
/// the other subtrees it enters alone.
struct Alone<'a> {
    rays: &'a RayPacket,
    /// Lanes whose entries below are written.
    ready: u32,
    wr: [MaybeUninit<WatertightRay>; LANES],
    rb: [MaybeUninit<RayBoxes8>; LANES],
}

impl<'a> Alone<'a> {
    #[inline(always)]
    fn new(rays: &'a RayPacket) -> Self {
        // Uninitialised: written lane by lane on first use (most packets need few lanes).
        Self { rays, ready: 0, wr: [MaybeUninit::uninit(); LANES], rb: [MaybeUninit::uninit(); LANES] }
    }

    /// Lane `i`'s ray, watertight constants and box constants.
    #[inline(always)]
    unsafe fn lane(&mut self, i: usize) -> (Ray, &WatertightRay, &RayBoxes8) {
        let ray = self.rays.lane(i);
        if self.ready & (1 << i) == 0 {
            self.wr[i] = MaybeUninit::new(WatertightRay::new(ray.origin, ray.dir));
            self.rb[i] = MaybeUninit::new(RayBoxes8::new(ray.origin, ray.dir));
            self.ready |= 1 << i;
        }
        // SAFETY: written above or on an earlier call (bit `i` of `ready`).
        (ray, self.wr[i].assume_init_ref(), self.rb[i].assume_init_ref())
    }
}

/// The single-ray closest-hit traversal of the subtree `e` by each of its lanes, from the
/// lane's closest hit so far in `out` (kept when the subtree has no closer one).
#[target_feature(enable = "avx2,fma")]
#[inline]
fn closest_alone(
    nodes: &[Node8],
    tris: &TriPackets,
    alone: &mut Alone<'_>,
    e: &PacketEntry,
    out: &mut Closest8,
) {
    let mut lanes = e.lanes;
    while lanes != 0 {
        let i = lanes.trailing_zeros() as usize;
        lanes &= lanes - 1;
        // SAFETY: this function runs with AVX2 and FMA.
        let (ray, wr, rb) = unsafe { alone.lane(i) };
        // SAFETY: as above.
        let ray8 = unsafe { Ray8::new(wr, ray.t_min) };
        let mut leaves =
            ClosestPairs { packets: &tris.packets, prim_ids: &tris.prim_ids, ray: ray8, best: None };
        let start = Entry { child: e.child, count: e.count, t: ray.t_min };
        let mut t_max = out.t.0[i];
        traverse8_from::<_, true>(nodes, start, rb, ray.t_min, &mut t_max, &mut leaves);
        // The subtree's hit is at most as far as the lane's: closer, or as close with a smaller id.
        if let Some((t, u, v, k)) = leaves.best {
            let id = tris.prim_ids[k] as i32;
            if t < out.t.0[i] || id < out.id.0[i] {
                (out.t.0[i], out.u.0[i], out.v.0[i], out.id.0[i]) = (t, u, v, id);
            }
        }
    }
}

/// The lanes of `e` whose single-ray any-hit traversal of the subtree `e` hits.
#[target_feature(enable = "avx2,fma")]
#[inline]
fn occluded_alone(nodes: &[Node8], tris: &TriPackets, alone: &mut Alone<'_>, e: &PacketEntry) -> u32 {
    let (mut lanes, mut hits) = (e.lanes, 0);
    while lanes != 0 {
        let i = lanes.trailing_zeros() as usize;
        lanes &= lanes - 1;
        // SAFETY: this function runs with AVX2 and FMA.
        let (ray, wr, rb) = unsafe { alone.lane(i) };
        // SAFETY: as above.
        let leaves = AnyPairs { packets: &tris.packets, ray: unsafe { Ray8::new(wr, ray.t_min) } };
        let start = Entry { child: e.child, count: e.count, t: ray.t_min };
        let mut t_max = ray.t_max;
        if traverse8_from::<_, false>(nodes, start, rb, ray.t_min, &mut t_max, leaves) {
            hits |= 1 << i;
        }
    }
    hits
}
