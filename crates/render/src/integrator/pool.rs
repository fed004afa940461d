//! The paths of the lockstep integrator between two bounces, kept packed: after each ray
//! query the paths still alive are moved to the front (stream compaction, one `vpermps`
//! and one store per lane value), so that the next bounce runs on full groups of eight
//! lanes instead of groups thinned out by misses and Russian roulette.
//!
//! A pool holds up to [`POOL`] paths: the camera samples of [`POOL_GROUPS`] groups of
//! eight pixels at one sample index. Since all paths of a pool are at the same vertex,
//! the sampler slots stay the same in every lane (as in [`super::lockstep`] without
//! compaction), and which lane a path occupies changes nothing in its arithmetic, so the
//! film stays bit-identical to the scalar tracer's.

use super::lanes::{compress_store, compress_store_u32, load8, load8_u32, F8, LANES, M8, U8, V8};
use filtrace_accel::HitPacket;

/// Groups of eight pixels in a pool. Larger pools pack the last, sparse bounces better:
/// lane utilisation on the Cornell box 0.874 / 0.93 / 0.963 with 8 / 16 / 32 groups, and
/// 16 was as fast as 32 (and 4 % faster than 8) with the pool (14 kB) in the L1 cache.
pub const POOL_GROUPS: usize = 16;
/// Paths in a pool.
pub const POOL: usize = POOL_GROUPS * LANES;
/// Room for the eight-lane store that packs the last lanes.
const CAP: usize = POOL + LANES;

/// What a path carries from one vertex to the next (the loop variables of
/// [`super::path::trace_from_hit`]), for eight paths.
#[derive(Clone, Copy, Debug, Default)]
pub struct PathLanes<const A: bool> {
    pub beta: V8<A>,
    pub l_direct: V8<A>,
    pub l_indirect: V8<A>,
    /// Density of the BSDF sample that led here (for MIS at an emitter hit).
    pub p_b: F8<A>,
    pub specular: M8<A>,
    /// The previous vertex.
    pub prev_p: V8<A>,
    /// The pixel's sampler key.
    pub key: U8<A>,
    /// Index of the path's camera sample among the pool's pixels.
    pub pixel: U8<A>,
}

/// Three lane columns of a pool.
type Columns3 = [[f32; CAP]; 3];

/// [`POOL`] paths, structure of arrays, the live ones at the front: each path's state,
/// the direction of the ray that found its next vertex and that ray's hit.
pub struct Pool {
    len: usize,
    beta: Columns3,
    l_direct: Columns3,
    l_indirect: Columns3,
    prev_p: Columns3,
    dir: Columns3,
    p_b: [f32; CAP],
    t: [f32; CAP],
    u: [f32; CAP],
    v: [f32; CAP],
    specular: [u32; CAP],
    key: [u32; CAP],
    pixel: [u32; CAP],
    instance: [u32; CAP],
    prim: [u32; CAP],
}

impl Default for Pool {
    fn default() -> Self {
        let c3 = [[0.0; CAP]; 3];
        Pool {
            len: 0,
            beta: c3,
            l_direct: c3,
            l_indirect: c3,
            prev_p: c3,
            dir: c3,
            p_b: [0.0; CAP],
            t: [0.0; CAP],
            u: [0.0; CAP],
            v: [0.0; CAP],
            specular: [0; CAP],
            key: [0; CAP],
            pixel: [0; CAP],
            instance: [0; CAP],
            prim: [0; CAP],
        }
    }
}

#[inline(always)]
fn load3<const A: bool>(c: &Columns3, at: usize) -> V8<A> {
    V8::new(load8(&c[0], at), load8(&c[1], at), load8(&c[2], at))
}

#[inline(always)]
fn store3<const A: bool>(v: &V8<A>, keep: u8, c: &mut Columns3, at: usize) {
    compress_store(v.x, keep, &mut c[0], at);
    compress_store(v.y, keep, &mut c[1], at);
    compress_store(v.z, keep, &mut c[2], at);
}

impl Pool {
    /// Paths in the pool.
    #[inline(always)]
    pub fn len(&self) -> usize {
        self.len
    }

    /// No path left.
    #[inline(always)]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Groups of eight lanes the paths fill (the last one possibly in part).
    #[inline(always)]
    pub fn batches(&self) -> usize {
        self.len.div_ceil(LANES)
    }

    /// Empties the pool.
    #[inline(always)]
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Keeps the first `len` paths (those [`Pool::store`] packed in a pass over the pool).
    #[inline(always)]
    pub fn truncate(&mut self, len: usize) {
        self.len = len.min(self.len);
    }

    /// Batch `b`: paths `8b..8b + 8`, their ray directions and hits (`mask`: the lanes
    /// holding a path, always the first ones).
    #[inline(always)]
    pub fn load<const A: bool>(&self, b: usize) -> (PathLanes<A>, V8<A>, HitPacket) {
        let at = b * LANES;
        let n = self.len.saturating_sub(at).min(LANES);
        let paths = PathLanes {
            beta: load3(&self.beta, at),
            l_direct: load3(&self.l_direct, at),
            l_indirect: load3(&self.l_indirect, at),
            p_b: load8(&self.p_b, at),
            specular: super::lanes::mask_of(load8_u32(&self.specular, at)),
            prev_p: load3(&self.prev_p, at),
            key: load8_u32(&self.key, at),
            pixel: load8_u32(&self.pixel, at),
        };
        let hits = HitPacket {
            mask: ((1u32 << n) - 1) as u8,
            t: self.t[at..at + LANES].try_into().expect("eight words"),
            u: self.u[at..at + LANES].try_into().expect("eight words"),
            v: self.v[at..at + LANES].try_into().expect("eight words"),
            instance: self.instance[at..at + LANES].try_into().expect("eight words"),
            prim: self.prim[at..at + LANES].try_into().expect("eight words"),
        };
        (paths, load3(&self.dir, at), hits)
    }

    /// Stores the lanes set in `keep` packed from path `at` on. In a pass over the pool,
    /// `at` (the paths kept so far) never exceeds `8b` for batch `b`, so the store only
    /// overwrites lanes already loaded.
    #[inline(always)]
    pub fn store<const A: bool>(
        &mut self,
        at: usize,
        keep: u8,
        p: &PathLanes<A>,
        dir: &V8<A>,
        hits: &HitPacket,
    ) {
        store3(&p.beta, keep, &mut self.beta, at);
        store3(&p.l_direct, keep, &mut self.l_direct, at);
        store3(&p.l_indirect, keep, &mut self.l_indirect, at);
        compress_store(p.p_b, keep, &mut self.p_b, at);
        compress_store_u32(super::lanes::mask_words(p.specular), keep, &mut self.specular, at);
        store3(&p.prev_p, keep, &mut self.prev_p, at);
        compress_store_u32(p.key, keep, &mut self.key, at);
        compress_store_u32(p.pixel, keep, &mut self.pixel, at);
        store3(dir, keep, &mut self.dir, at);
        compress_store(F8::<A>::from_array(hits.t), keep, &mut self.t, at);
        compress_store(F8::<A>::from_array(hits.u), keep, &mut self.u, at);
        compress_store(F8::<A>::from_array(hits.v), keep, &mut self.v, at);
        compress_store_u32(U8::<A>::from_array(hits.instance), keep, &mut self.instance, at);
        compress_store_u32(U8::<A>::from_array(hits.prim), keep, &mut self.prim, at);
    }

    /// [`Pool::store`] after the last path (filling the pool with camera paths).
    #[inline(always)]
    pub fn append<const A: bool>(&mut self, keep: u8, p: &PathLanes<A>, dir: &V8<A>, hits: &HitPacket) {
        debug_assert!(self.len + keep.count_ones() as usize <= POOL);
        self.store(self.len, keep, p, dir, hits);
        self.len += keep.count_ones() as usize;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Packing batch by batch in place keeps the kept paths, in order, with every field.
    #[test]
    fn store_packs_in_place() {
        let mut pool = Pool::default();
        for g in 0..POOL_GROUPS {
            let base = (g * LANES) as f32;
            let p = PathLanes::<false> {
                p_b: F8::from_array(std::array::from_fn(|i| base + i as f32)),
                pixel: U8::from_array(std::array::from_fn(|i| (g * LANES + i) as u32)),
                ..Default::default()
            };
            let hits = HitPacket {
                mask: 0xff,
                prim: std::array::from_fn(|i| (g * LANES + i) as u32),
                ..Default::default()
            };
            pool.append(0xff, &p, &V8::default(), &hits);
        }
        assert_eq!(pool.len(), POOL);
        // Keep every path whose index is not a multiple of 3.
        let mut kept = 0;
        for b in 0..pool.batches() {
            let (p, dir, hits) = pool.load::<false>(b);
            let keep = (0..LANES).filter(|i| !(b * LANES + i).is_multiple_of(3)).fold(0u8, |m, i| m | 1 << i);
            pool.store(kept, keep, &p, &dir, &hits);
            kept += keep.count_ones() as usize;
        }
        pool.truncate(kept);
        let expected: Vec<u32> = (0..POOL as u32).filter(|j| !j.is_multiple_of(3)).collect();
        assert_eq!(pool.len(), expected.len());
        for (j, &e) in expected.iter().enumerate() {
            let (p, _, hits) = pool.load::<false>(j / LANES);
            let i = j % LANES;
            assert_eq!((p.pixel.to_array()[i], hits.prim[i], p.p_b.lane(i)), (e, e, e as f32));
        }
        assert_eq!(
            pool.load::<false>(pool.batches() - 1).2.mask.count_ones() as usize,
            expected.len() % LANES
        );
    }
}
