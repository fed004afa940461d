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
//! (`boxes::LaneBoxes`), and leaves are tested as a packet only when the lanes share their
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

use super::boxes::LaneBoxes;
use super::lanes::{setup, Closest8};
use super::traverse::{closest_packet, occluded_packet, PacketEntry, PerLane};
use crate::avx2::{traverse8_from, AnyPairs, ClosestPairs, Ray8, RayBoxes8};
use crate::ray_packet::{RayPacket, LANES};
use crate::tri4::TriPackets;
use crate::triangle::WatertightRay;
use crate::wide::{Entry, Node8};
use filtrace_core::Ray;
use std::mem::MaybeUninit;

/// Fewest lanes that traverse a subtree as a packet; fewer go on one by one. Any hits on
/// the bunny (`packet_lanes`, single rays / hybrid, two runs): 4 lanes 1.22 and 1.15
/// (incoherent), 1.14 and 1.05 (shadow); 6: 1.04-1.22 and 1.02-1.05; 8: 1.25-1.33 and
/// 1.02-1.07 (docs/perf-accel.md, "Stop 16").
pub(crate) const MIN_PACKET_LANES: u32 = 4;

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
    let b = LaneBoxes::new(rays);
    closest_packet::<_, _, false>(nodes, tris, &r, &b, &mut Alone::new(nodes, tris, rays), min_lanes)
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
    let b = LaneBoxes::new(rays);
    occluded_packet(nodes, tris, &r, &b, &mut Alone::new(nodes, tris, rays), min_lanes)
}

/// The lanes' single-ray constants, made when a lane first leaves the packet and kept for
/// the other subtrees it enters alone.
struct Alone<'a> {
    nodes: &'a [Node8],
    tris: &'a TriPackets,
    rays: &'a RayPacket,
    /// Lanes whose entries below are written.
    ready: u32,
    wr: [MaybeUninit<WatertightRay>; LANES],
    rb: [MaybeUninit<RayBoxes8>; LANES],
}

impl<'a> Alone<'a> {
    #[inline(always)]
    fn new(nodes: &'a [Node8], tris: &'a TriPackets, rays: &'a RayPacket) -> Self {
        // Uninitialised: written lane by lane on first use (most packets need few lanes).
        let (wr, rb) = ([MaybeUninit::uninit(); LANES], [MaybeUninit::uninit(); LANES]);
        Self { nodes, tris, rays, ready: 0, wr, rb }
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

/// The hybrid traversal's lanes alone: the single-ray kernel from the subtree on.
impl PerLane for Alone<'_> {
    #[inline(always)]
    fn closest(&mut self, e: &PacketEntry, out: &mut Closest8) {
        // SAFETY: the packet kernels run only where AVX2 and FMA are available.
        unsafe { closest_alone(self, e, out) }
    }

    #[inline(always)]
    fn occluded(&mut self, e: &PacketEntry) -> u32 {
        // SAFETY: as in `closest`.
        unsafe { occluded_alone(self, e) }
    }
}

/// The single-ray closest-hit traversal of the subtree `e` by each of its lanes, from the
/// lane's closest hit so far in `out` (kept when the subtree has no closer one).
#[target_feature(enable = "avx2,fma")]
#[inline]
fn closest_alone(alone: &mut Alone<'_>, e: &PacketEntry, out: &mut Closest8) {
    let (nodes, tris) = (alone.nodes, alone.tris);
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
        traverse8_from::<_, _, true>(nodes, start, rb, ray.t_min, &mut t_max, &mut leaves);
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
fn occluded_alone(alone: &mut Alone<'_>, e: &PacketEntry) -> u32 {
    let (nodes, tris) = (alone.nodes, alone.tris);
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
        if traverse8_from::<_, _, false>(nodes, start, rb, ray.t_min, &mut t_max, leaves) {
            hits |= 1 << i;
        }
    }
    hits
}
