//! Eight-ray packets through the top level: [`SceneAccel::intersect_packet`] and
//! [`SceneAccel::occluded_packet`] on scenes of several objects (the merged static
//! instances and the moving ones, `merge.rs`).
//!
//! The packet walks the 4-wide top level once (8 rays x 1 instance box per instruction,
//! each lane with the slab arithmetic of the single-ray top level, near-first by the
//! entry distance of the lowest lane, pending subtrees culled per lane beyond its own
//! closest hit). At a top-level leaf the lanes that reached it are moved into the
//! instance's object space, lane for lane with [`crate::object_ray`] (the single-ray
//! arithmetic), and handed with their running closest hits as `t_max` to the flat
//! bottom-level packet kernels of `avx2_packet` (8 rays x 1 triangle), or, for BVH meshes
//! and too few lanes, to one single-ray bottom-level query per lane.
//!
//! The 8-wide BVH packet traversal (`avx2_packet::closest_bvh`, `occluded_bvh`) is not
//! used below the top level: in renders it cost more than the per-lane queries it replaced
//! (callgrind, `bench suite --res 128x128 --spp 4 --threads 1`, instructions in
//! `intersect_packet`: engine 336 M with it at 4 lanes, 331 M at 6, 272 M without;
//! bunny-room 254 M with, 233 M without; docs/perf-accel.md, "Packets through the top
//! level"). The top-level walk and the flat kernels are what pays: against one
//! single-ray query per lane, closest hits -35 % instructions (bunny-room), -10 %
//! (engine), -7 % (classroom), any hits -41 %, -19 %, -25 %; CPU time -20 %, -5 %, -1 %.
//!
//! Per lane the result is the single-ray query's: a lane's closest hit is the smallest
//! `(t, instance, prim)` over the triangles it reaches with `t` in its `[t_min, t_max]`
//! (`crate::closer`), which no visit order changes, and a lane visits every instance whose
//! box its ray touches before its closest hit (the boxes are those of the single-ray top
//! level, culled with the same `cull_bound` slack).

use crate::avx2_packet::{self, Closest8, NO_HIT};
use crate::blas::Blas;
use crate::packet::{avx512, valid_lanes, MIN_LANES_ANY, MIN_LANES_CLOSEST};
use crate::ray_packet::{HitPacket, RayPacket, LANES};
use crate::sah::MAX_DEPTH;
use crate::wide::{Node4, CULL_SCALE, FAR_SCALE};
use crate::{closer, object_ray, SceneAccel, MERGED};
use filtrace_core::Vec3;
use std::arch::x86_64::*;
use std::mem::MaybeUninit;

/// Top-level stack depth: each 4-wide level pushes at most three entries.
const STACK4: usize = 3 * MAX_DEPTH + 4;

/// The traversal stack, left uninitialised: zeroing its 11 KB per query cost more time
/// than the traversal saved (cachegrind: a quarter of all D1 write misses of a render).
type Stack = [MaybeUninit<Entry>; STACK4];

/// A pending top-level subtree: the lanes that entered it and their entry distances.
#[derive(Clone, Copy)]
struct Entry {
    child: u32,
    count: u32,
    lanes: u32,
    t_near: __m256,
}

/// Per-lane constants of the top-level box test, lane for lane those of
/// `wide::RayBoxes`: origin and reciprocal direction; the near and far bound of each axis
/// are picked per lane by the sign of its direction.
struct TopBoxes {
    org: [__m256; 3],
    inv: [__m256; 3],
    /// The direction (only its sign bits: set where the far bound is the minimum).
    dir: [__m256; 3],
    t_min: __m256,
}

impl TopBoxes {
    #[inline(always)]
    unsafe fn new(rays: &RayPacket) -> Self {
        let ld = |x: &[f32; LANES]| _mm256_loadu_ps(x.as_ptr());
        let one = _mm256_set1_ps(1.0);
        let dir = [ld(&rays.dir[0]), ld(&rays.dir[1]), ld(&rays.dir[2])];
        TopBoxes {
            org: [ld(&rays.origin[0]), ld(&rays.origin[1]), ld(&rays.origin[2])],
            inv: dir.map(|d| _mm256_div_ps(one, d)),
            dir,
            t_min: ld(&rays.t_min),
        }
    }

    /// Lanes of `lanes` whose rays touch child `i` of `n` before `t_cull`, and their entry
    /// distances: `wide::box4` per lane (`(b - o) inv`, NaN slabs skipped, the far distance
    /// widened by `FAR_SCALE`).
    #[inline(always)]
    unsafe fn child(&self, n: &Node4, i: usize, t_cull: __m256, lanes: __m256) -> (u32, __m256) {
        let mut t_near = self.t_min;
        let mut t_far = t_cull;
        for k in [0, 1, 2] {
            let lo = _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(n.bounds[k][i]), self.org[k]), self.inv[k]);
            let hi =
                _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(n.bounds[k + 3][i]), self.org[k]), self.inv[k]);
            let near = _mm256_blendv_ps(lo, hi, self.dir[k]);
            let far = _mm256_blendv_ps(hi, lo, self.dir[k]);
            // `max(a, b)` returns `b` when either is NaN: as in `box4`, NaN slabs are skipped.
            t_near = _mm256_max_ps(near, t_near);
            t_far = _mm256_min_ps(far, t_far);
        }
        let t_far = _mm256_mul_ps(t_far, _mm256_set1_ps(FAR_SCALE));
        let hit = _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t_near, t_far), lanes);
        (_mm256_movemask_ps(hit) as u32, t_near)
    }
}

/// `cull_bound` of every lane.
#[inline(always)]
unsafe fn cull8(t_max: __m256) -> __m256 {
    _mm256_max_ps(_mm256_mul_ps(t_max, _mm256_set1_ps(CULL_SCALE)), t_max)
}

/// All ones in the lanes whose bit is set in `m`.
#[inline(always)]
unsafe fn lane_mask(m: u32) -> __m256 {
    let bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    let v = _mm256_and_si256(_mm256_set1_epi32(m as i32), bits);
    _mm256_castsi256_ps(_mm256_cmpeq_epi32(v, bits))
}

/// The lanes of `e` whose entry distance is not beyond their closest hit.
#[inline(always)]
unsafe fn still_open(e: &Entry, t_max: &[f32; LANES]) -> u32 {
    let open = _mm256_cmp_ps::<_CMP_LE_OQ>(e.t_near, cull8(_mm256_loadu_ps(t_max.as_ptr())));
    e.lanes & _mm256_movemask_ps(open) as u32
}

/// Pushes the children of `node` that some lane of `lanes` touches onto `stack` (the
/// farthest deepest when `ORDERED`, by the entry distance of each child's lowest lane) and
/// returns the one to visit next.
#[inline(always)]
unsafe fn expand<const ORDERED: bool>(
    node: &Node4,
    b: &TopBoxes,
    t_max: &[f32; LANES],
    lanes: u32,
    stack: &mut Stack,
    sp: &mut usize,
) -> Option<Entry> {
    let lane_vec = lane_mask(lanes);
    let t_cull = cull8(_mm256_loadu_ps(t_max.as_ptr()));
    let base = *sp;
    let mut keys = [0f32; 4];
    for i in 0..4 {
        if node.count[i] == 0 && node.child[i] == 0 {
            continue; // empty slot (node 0 is the root, never a child)
        }
        let (m, t_near) = b.child(node, i, t_cull, lane_vec);
        if m == 0 {
            continue;
        }
        let e = Entry { child: node.child[i], count: node.count[i], lanes: m, t_near };
        let mut j = *sp;
        if ORDERED {
            let mut tn = [0f32; LANES];
            _mm256_storeu_ps(tn.as_mut_ptr(), t_near);
            keys[j - base] = tn[m.trailing_zeros() as usize];
            while j > base && keys[j - 1 - base] < keys[j - base] {
                keys.swap(j - 1 - base, j - base);
                stack[j] = stack[j - 1];
                j -= 1;
            }
        }
        stack[j] = MaybeUninit::new(e);
        *sp += 1;
    }
    if *sp == base {
        return None;
    }
    *sp -= 1;
    // SAFETY: entries below `sp` were written before `sp` was raised past them.
    Some(stack[*sp].assume_init())
}

impl SceneAccel {
    /// [`SceneAccel::intersect_packet`] through the top level (see the module docs).
    ///
    /// Safety: the CPU has AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub(crate) unsafe fn intersect_two_level(&self, rays: &RayPacket, active: u8) -> HitPacket {
        let mut out = HitPacket::default();
        let lanes = (active & valid_lanes(rays)) as u32;
        if lanes == 0 || self.tlas.is_empty() {
            return out;
        }
        let b = TopBoxes::new(rays);
        let mut t_max = rays.t_max;
        let mut stack: Stack = [MaybeUninit::uninit(); STACK4];
        let mut sp = 0usize;
        let mut cur = Entry { child: 0, count: 0, lanes, t_near: b.t_min };
        loop {
            if cur.count == 0 {
                let node = &self.tlas[cur.child as usize];
                if let Some(next) = expand::<true>(node, &b, &t_max, cur.lanes, &mut stack, &mut sp) {
                    cur = next;
                    continue;
                }
            } else {
                for k in cur.child..cur.child + cur.count {
                    let object = self.tlas_order[k as usize];
                    self.closest_in_object(object, rays, cur.lanes as u8, &mut t_max, &mut out);
                }
            }
            // The nearest pending subtree some lane can still find a closer hit in.
            loop {
                if sp == 0 {
                    return out;
                }
                sp -= 1;
                // SAFETY: as in `expand`.
                cur = stack[sp].assume_init();
                cur.lanes = still_open(&cur, &t_max);
                if cur.lanes != 0 {
                    break;
                }
            }
        }
    }

    /// [`SceneAccel::occluded_packet`] through the top level (see the module docs).
    ///
    /// Safety: the CPU has AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub(crate) unsafe fn occluded_two_level(&self, rays: &RayPacket, active: u8) -> u8 {
        let lanes = (active & valid_lanes(rays)) as u32;
        if lanes == 0 || self.tlas.is_empty() {
            return 0;
        }
        let b = TopBoxes::new(rays);
        let t_max = rays.t_max;
        let mut stack: Stack = [MaybeUninit::uninit(); STACK4];
        let mut sp = 0usize;
        let mut left = lanes;
        let mut cur = Entry { child: 0, count: 0, lanes, t_near: b.t_min };
        loop {
            if cur.count == 0 {
                let node = &self.tlas[cur.child as usize];
                if let Some(next) = expand::<false>(node, &b, &t_max, cur.lanes, &mut stack, &mut sp) {
                    cur = next;
                    continue;
                }
            } else {
                for k in cur.child..cur.child + cur.count {
                    let object = self.tlas_order[k as usize];
                    left &= !(self.occluded_in_object(object, rays, (cur.lanes & left) as u8) as u32);
                    if left == 0 {
                        return lanes as u8;
                    }
                }
            }
            loop {
                if sp == 0 {
                    return (lanes & !left) as u8;
                }
                sp -= 1;
                // SAFETY: as in `expand`.
                cur = stack[sp].assume_init();
                cur.lanes &= left;
                if cur.lanes != 0 {
                    break;
                }
            }
        }
    }

    /// The lanes `lanes` of `rays` in `object`'s space, each searching up to `t_max`; the
    /// lanes whose rays cannot be moved there are dropped, as in the single-ray query.
    #[inline(always)]
    fn object_packet(
        &self,
        object: u32,
        rays: &RayPacket,
        lanes: u8,
        t_max: &[f32; LANES],
    ) -> (RayPacket, u8) {
        let mut local = *rays;
        local.t_max = *t_max;
        if object == MERGED || self.instances[object as usize].identity {
            return (local, lanes);
        }
        let rec = &self.instances[object as usize];
        let mut ok = 0u8;
        let mut left = lanes;
        while left != 0 {
            let i = left.trailing_zeros() as usize;
            left &= left - 1;
            let ray = rays.lane(i);
            if let Some((o, d)) = object_ray(&rec.world_to_object, false, &ray) {
                for k in 0..3 {
                    local.origin[k][i] = o[k];
                    local.dir[k][i] = d[k];
                }
                ok |= 1 << i;
            }
        }
        (local, ok)
    }

    /// Closest hits of the lanes `lanes` in `object`, merged into `out` (and `t_max`) with
    /// the single-ray rule (`closer`, ties to the smaller `(instance, prim)`).
    #[inline(always)]
    unsafe fn closest_in_object(
        &self,
        object: u32,
        rays: &RayPacket,
        lanes: u8,
        t_max: &mut [f32; LANES],
        out: &mut HitPacket,
    ) {
        if let Blas::Flat(f) = self.object_blas(object) {
            if lanes.count_ones() >= MIN_LANES_CLOSEST {
                let (local, lanes) = self.object_packet(object, rays, lanes, t_max);
                let c = if avx512() {
                    avx2_packet::closest_flat_avx512(f, &local, lanes)
                } else {
                    avx2_packet::closest_flat(f, &local, lanes)
                };
                return self.merge_closest(object, &c, t_max, out);
            }
        }
        // BVH meshes and single lanes: per lane (see the module docs).
        self.closest_per_lane(object, rays, lanes, t_max, out);
    }

    /// Lane `i` of `rays` in `object`'s space (`None`: it cannot be moved there), as in
    /// the single-ray query.
    #[inline(always)]
    fn lane_in_object(&self, object: u32, rays: &RayPacket, i: usize) -> Option<(Vec3, Vec3)> {
        let ray = rays.lane(i);
        if object == MERGED {
            return Some((ray.origin, ray.dir));
        }
        let rec = &self.instances[object as usize];
        object_ray(&rec.world_to_object, rec.identity, &ray)
    }

    /// One single-ray bottom-level query per lane of `lanes` (world-space `rays`, moved
    /// into object space lane by lane: no packet copy for the one or two lanes that
    /// typically reach a BVH instance).
    #[inline(always)]
    fn closest_per_lane(
        &self,
        object: u32,
        rays: &RayPacket,
        lanes: u8,
        t_max: &mut [f32; LANES],
        out: &mut HitPacket,
    ) {
        let blas = self.object_blas(object);
        let mut left = lanes;
        while left != 0 {
            let i = left.trailing_zeros() as usize;
            left &= left - 1;
            let Some((o, d)) = self.lane_in_object(object, rays, i) else { continue };
            let mut t = t_max[i];
            if let Some((t, u, v, id)) = blas.intersect::<true>(o, d, rays.t_min[i], &mut t) {
                self.merge_lane(object, i, (t, u, v, id), t_max, out);
            }
        }
    }

    /// The bottom-level kernel's hits `c` (of lanes searching up to `t_max`) merged into `out`.
    #[inline(always)]
    fn merge_closest(&self, object: u32, c: &Closest8, t_max: &mut [f32; LANES], out: &mut HitPacket) {
        for i in 0..LANES {
            if c.id.0[i] != NO_HIT {
                self.merge_lane(object, i, (c.t.0[i], c.u.0[i], c.v.0[i], c.id.0[i] as u32), t_max, out);
            }
        }
    }

    /// Lane `i`'s hit `(t, u, v, id)` in `object` (`id` a `prim_ids` value) replaces its
    /// closest hit so far when closer, as in the single-ray top-level traversal.
    #[inline(always)]
    fn merge_lane(
        &self,
        object: u32,
        i: usize,
        (t, u, v, id): (f32, f32, f32, u32),
        t_max: &mut [f32; LANES],
        out: &mut HitPacket,
    ) {
        let (instance, prim) = if object == MERGED { self.merged_refs[id as usize] } else { (object, id) };
        let had = out.mask & (1 << i) != 0;
        let smaller = || (instance, prim) < (out.instance[i], out.prim[i]);
        if closer(t, had.then_some(t_max[i]), smaller) {
            out.mask |= 1 << i;
            (out.t[i], out.u[i], out.v[i], out.instance[i], out.prim[i]) = (t, u, v, instance, prim);
            t_max[i] = t;
        }
    }

    /// Lanes of `lanes` occluded within `object`.
    #[inline(always)]
    unsafe fn occluded_in_object(&self, object: u32, rays: &RayPacket, lanes: u8) -> u8 {
        if let Blas::Flat(f) = self.object_blas(object) {
            if lanes.count_ones() >= MIN_LANES_ANY {
                let (local, lanes) = self.object_packet(object, rays, lanes, &rays.t_max);
                return if avx512() {
                    avx2_packet::occluded_flat_avx512(f, &local, lanes)
                } else {
                    avx2_packet::occluded_flat(f, &local, lanes)
                };
            }
        }
        let blas = self.object_blas(object);
        let mut hit = 0u8;
        let mut left = lanes;
        while left != 0 {
            let i = left.trailing_zeros() as usize;
            left &= left - 1;
            let Some((o, d)) = self.lane_in_object(object, rays, i) else { continue };
            if blas.occluded::<true>(o, d, rays.t_min[i], rays.t_max[i]) {
                hit |= 1 << i;
            }
        }
        hit
    }
}
