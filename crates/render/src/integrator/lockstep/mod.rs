//! The path tracer of [`super::path`] run on eight paths in lockstep, in structure-of-arrays
//! lanes, stage by stage per bounce (the shape of Mitsuba 3's `llvm_ad_rgb` variant and of
//! pbrt-v4's wavefront integrator, on one core). The camera rays go in groups of eight
//! adjacent pixels of an image row at one sample index; the paths of [`POOL`] pixels then
//! run bounce by bounce in a [`Pool`], packed into full groups of eight after every ray
//! query.
//!
//! Per bounce, for the lanes still alive (`act`): emission found by the previous BSDF
//! sample (MIS against light sampling), the sampler (eight keys per integer instruction,
//! [`Sampler8`]), shading frames, next-event estimation (light selection in lanes for
//! scenes with at most eight lights, else per lane; area and directional lights and the
//! environment sampled in lanes, one packet of shadow rays, BSDF value and density in
//! lanes for diffuse surfaces), BSDF sampling
//! (cosine hemisphere in lanes for diffuse surfaces), Russian roulette, and one packet of
//! closest-hit queries followed by the hit records (`from_hit` in lanes: the triangle
//! records are loaded as rows and transposed, vertex normals gathered per lane and
//! interpolated in lanes). Material
//! flags, Lambert reflectances and the instances' first rows are table lookups in lanes
//! (`vpermps` for up to eight entries, `vgatherdps` for more).
//!
//! **Exactness is the contract.** Every lane performs the operations of
//! [`super::path::li`] / [`super::path::trace_from_hit`] in the same order (see
//! [`super::lanes`]), and what is not worth a lane version (glossy BSDFs, point and spot
//! lights, any light of a scene with more than eight, emission, uv interpolation) calls
//! the scalar code for that lane; paths that leave the scene add the environment in
//! lanes. The film is therefore bit-identical to the scalar
//! renderer's (colour, variance and every AOV), which `tests/lockstep.rs` checks on every
//! built-in scene and on a TOML scene with every material, light type and a texture.
//! Since all lanes start together and every stage is per vertex, the vertex index is the
//! same in all lanes, and so are the sampler slots.
//!
//! The same pools run the filtered pipeline's rays ([`trace_film_rays`]): camera rays
//! through given film positions in any pixels ([`PoolCameras::Given`]), paths of any
//! [`PathParams`] from their hits or first hits alone, under the same contract
//! (`filtrace-pipeline`'s `tests/lockstep_source.rs`).
//!
//! Paths that end (miss, roulette, zero throughput, depth limit) leave the pool; the others
//! are moved to the front of it (stream compaction: without it, the lanes of ended paths
//! stayed idle until the slowest path of their group ended, and 43 % of the lane slots
//! paid for were idle on the Cornell box). [`LaneStats`] counts the lanes alive at each
//! vertex and the groups of eight lanes run.

// `!(x <= 0.0)` and `!(!a && b)` are written as in the scalar code they mirror (NaN
// included), not in the form clippy prefers.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::nonminimal_bool)]

use super::lanes::{bits, from_bits, load8, load8_u32, per_lane, select, F8, LANES, M8, U8, V8};
use super::path::visible_surface;
use super::pool::{PathLanes, Pool, POOL};
use super::sampler8::Sampler8;
use super::sampling8::power_heuristic8;
use super::{CameraSample, PathContext, PathParams, Split, SLOT_PIXEL};
use crate::camera::PinholeCamera;
use crate::film::VisibleSurface;
use filtrace_accel::{HitPacket, RayPacket};
use filtrace_core::Rgb;
use shade::shade;
use surf8::{from_hits, lanes_of, Surf8};

mod film_rays;
mod shade;
mod surf8;
mod tables;
pub use film_rays::{trace_film_rays, FilmRay, LaneCode};
pub use tables::LockstepTables;

/// Longest path (in vertices) [`LaneStats`] tells apart; longer ones count as the last.
pub const STATS_VERTICES: usize = 16;

/// Lane utilisation of the lockstep integrator: how many lanes are alive at each path
/// vertex, summed over the groups traced.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LaneStats {
    /// Groups of eight camera rays traced (one per 8 pixels and sample index).
    pub groups: u64,
    /// Lanes holding a pixel (fewer than 8 only at the right edge of the image).
    pub camera_lanes: u64,
    /// Groups of eight lanes run through a bounce (after packing: `ceil(alive / 8)` per
    /// pool and vertex).
    pub bounces: u64,
    /// `alive[v]`: lanes with a path vertex `v` (first hit = 0) at the start of bounce `v`.
    pub alive: [u64; STATS_VERTICES],
}

impl LaneStats {
    /// Adds `other`'s counts.
    pub fn merge(&mut self, other: &LaneStats) {
        self.groups += other.groups;
        self.camera_lanes += other.camera_lanes;
        self.bounces += other.bounces;
        for (a, b) in self.alive.iter_mut().zip(other.alive.iter()) {
            *a += b;
        }
    }

    /// Fraction of all lane slots (8 per group) alive at vertex `v`.
    pub fn utilisation(&self, v: usize) -> f64 {
        self.alive[v.min(STATS_VERTICES - 1)] as f64 / (self.groups.max(1) * LANES as u64) as f64
    }

    /// Lane slots used over lane slots paid for: alive lanes summed over vertices, divided
    /// by 8 x the bounces the groups ran.
    pub fn mean_utilisation(&self) -> f64 {
        self.alive.iter().sum::<u64>() as f64 / (self.bounces.max(1) * LANES as u64) as f64
    }
}

/// How the lockstep tracer asks the acceleration structure (same hits either way).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RayQueries {
    /// One single-ray query per active lane (`SceneAccel::intersect_packet_lanes`).
    PerLane,
    /// `SceneAccel::intersect_packet` / `occluded_packet` (the accel crate's packet kernels).
    /// Default since accel `bdd40e2`/`250de66` (BVH packet traversal, per-lane below 4-5
    /// active lanes): Cornell 512², 8 spp, 1 thread, 3 interleaved runs: 1.32-1.37 M
    /// samples per CPU s vs 1.08-1.11 per lane (and 1.10-1.12 for the scalar tracer). With
    /// the first flat-mesh packet kernels (`5168423`) packets were 3.6x slower.
    #[default]
    Packet,
}

/// Everything a group of eight lanes needs besides the pixels.
pub struct LockstepContext<'a> {
    pub ctx: PathContext<'a>,
    /// The tracer's lookup tables for the scene of `ctx`.
    pub tables: &'a LockstepTables,
    pub params: PathParams,
    pub camera: &'a PinholeCamera,
    pub queries: RayQueries,
}

impl LockstepContext<'_> {
    #[inline(always)]
    fn intersect<const A: bool>(&self, rays: &RayPacket, active: M8<A>) -> HitPacket {
        match self.queries {
            RayQueries::PerLane => self.ctx.accel.intersect_packet_lanes(rays, bits(active)),
            RayQueries::Packet => self.ctx.accel.intersect_packet(rays, bits(active)),
        }
    }

    #[inline(always)]
    fn occluded<const A: bool>(&self, rays: &RayPacket, active: M8<A>) -> M8<A> {
        from_bits(match self.queries {
            RayQueries::PerLane => self.ctx.accel.occluded_packet_lanes(rays, bits(active)),
            RayQueries::Packet => self.ctx.accel.occluded_packet(rays, bits(active)),
        })
    }
}

/// Where the camera rays of a pool go and what is traced from their hits.
#[derive(Clone, Copy)]
pub enum PoolCameras<'a> {
    /// The renderer's sample `index` of pixels `x0..x0 + n` of row `y`: through the pixel
    /// centre at sample 0, else at the sampler's jitter (slot [`SLOT_PIXEL`]); paths from
    /// every hit; the visible surface at sample 0 (the all-zero record on a miss).
    Row { x0: u32, y: u32 },
    /// Given film positions (the filtered pipeline's eye rays); the visible surface of every
    /// lane that hit (`None` on a miss); paths from the hits when `paths`, else first hits
    /// only.
    Given { films: &'a FilmLanes, paths: bool },
}

/// Film positions of a pool's lanes as [`PinholeCamera::generate_ray`] takes them: pixel
/// `(px, py)` (as `f32`) and the offset `(ox, oy)` in it.
#[derive(Clone, Copy, Debug)]
pub struct FilmLanes {
    pub px: [f32; POOL],
    pub py: [f32; POOL],
    pub ox: [f32; POOL],
    pub oy: [f32; POOL],
}

impl Default for FilmLanes {
    fn default() -> Self {
        FilmLanes { px: [0.0; POOL], py: [0.0; POOL], ox: [0.0; POOL], oy: [0.0; POOL] }
    }
}

/// Traces sample `index` of the `n` pixels `(x0 + j, y)`, `j < n <= POOL`, of one image
/// row into `out[j]`; `keys[j]` is pixel `j`'s [`filtrace_core::sampler::Sampler::pixel_key`].
/// `out[j]` equals `Renderer::trace_sample(x0 + j, y, index)` bit for bit (visible surface
/// at sample 0). The camera rays go in groups of eight pixels; the paths then run bounce by
/// bounce, packed into full groups of eight lanes after every ray query ([`Pool`]).
/// `AVX2 = true` only in code compiled with AVX2 enabled (see [`Sampler8`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn trace_pool<const AVX2: bool>(
    lc: &LockstepContext,
    x0: u32,
    y: u32,
    keys: &[u32; POOL],
    n: usize,
    index: u32,
    pool: &mut Pool,
    stats: &mut LaneStats,
    out: &mut [CameraSample; POOL],
) {
    trace_pool_at::<AVX2>(lc, PoolCameras::Row { x0, y }, keys, n, index, pool, stats, out);
}

/// [`trace_pool`] with the camera rays of `cams`: lane `j < n` is the pixel whose sampler
/// key is `keys[j]` at sample `index`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn trace_pool_at<const AVX2: bool>(
    lc: &LockstepContext,
    cams: PoolCameras,
    keys: &[u32; POOL],
    n: usize,
    index: u32,
    pool: &mut Pool,
    stats: &mut LaneStats,
    out: &mut [CameraSample; POOL],
) {
    debug_assert!(n <= POOL);
    // (`camera_group` writes every field of `out[..n]`: no 8.7 kB `memset` per pool.)
    pool.clear();
    // The hit records of the batch at hand (`from_hits` writes every field; one record
    // per pool, not a 672-byte `memset` per batch).
    let mut si = Surf8::<AVX2>::default();
    for first in (0..n).step_by(LANES) {
        let lanes = from_bits::<AVX2>(((1u32 << (n - first).min(LANES)) - 1) as u8);
        camera_group(lc, cams, keys, first, lanes, index, pool, &mut si, stats, out);
    }
    let mut vertex = 0u32;
    while !pool.is_empty() {
        let mut kept = 0;
        for b in 0..pool.batches() {
            kept = bounce_batch::<AVX2>(lc, pool, b, kept, vertex, index, &mut si, stats, out);
        }
        pool.truncate(kept);
        vertex += 1;
    }
}

/// The camera rays of pixels `first..first + 8` (lanes set in `lanes`): visible surfaces,
/// the environment seen directly, and the paths that hit something into the pool.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn camera_group<const AVX2: bool>(
    lc: &LockstepContext,
    cams: PoolCameras,
    keys: &[u32; POOL],
    first: usize,
    lanes: M8<AVX2>,
    index: u32,
    pool: &mut Pool,
    si: &mut Surf8<AVX2>,
    stats: &mut LaneStats,
    out: &mut [CameraSample; POOL],
) {
    let ctx = &lc.ctx;
    let cam = lc.camera;
    let key = load8_u32::<AVX2>(keys, first);
    stats.groups += 1;
    stats.camera_lanes += lanes.count() as u64;

    // Camera rays: `PinholeCamera::generate_ray` at the film positions of `cams`.
    let (px, py, ox, oy) = match cams {
        PoolCameras::Row { x0, y } => {
            // `PinholeCamera::sample_ray` (sample 0 through the pixel centre).
            let (jx, jy) = Sampler8::<AVX2>::from_keys(key, index).next_2d(SLOT_PIXEL);
            let (ox, oy) = if index == 0 { (F8::splat(0.5), F8::splat(0.5)) } else { (jx, jy) };
            let px = F8::<AVX2>::from_array(per_lane(|i| (x0 as usize + first + i) as f32));
            (px, F8::splat(y as f32), ox, oy)
        }
        PoolCameras::Given { films: f, .. } => {
            (load8(&f.px, first), load8(&f.py, first), load8(&f.ox, first), load8(&f.oy, first))
        }
    };
    let sx = (px + ox) * F8::splat(cam.two_over_size.x) - F8::splat(1.0);
    let sy = F8::splat(1.0) - (py + oy) * F8::splat(cam.two_over_size.y);
    let dir =
        (V8::splat(cam.forward) + V8::splat(cam.right_half) * sx + V8::splat(cam.up_half) * sy).normalize();
    let rays = RayPacket {
        origin: [[cam.eye.x; LANES], [cam.eye.y; LANES], [cam.eye.z; LANES]],
        dir: dir.to_arrays(),
        t_min: [0.0; LANES],
        t_max: [f32::INFINITY; LANES],
    };
    let hits = lc.intersect(&rays, lanes);
    let hit = from_hits(lc, &dir, &hits, si);
    // (visible surface of a hit, all-zero record of a miss, paths from the hits)
    let (on_hit, on_miss, paths) = match cams {
        PoolCameras::Row { .. } => (index == 0, index == 0, true),
        PoolCameras::Given { paths, .. } => (true, false, paths),
    };
    // Every field of the lanes' samples: the paths write their radiance when they end.
    for i in lanes_of(lanes & hit) {
        let surface = if on_hit { Some(visible_surface(ctx, &si.lane(i))) } else { None };
        out[first + i] = CameraSample { radiance: Split::default(), surface };
    }
    let missed = lanes & !hit;
    if missed.any() {
        // `environment_radiance` (zero without an environment), in lanes (no closure:
        // it would not inherit AVX2).
        let le = match ctx.lights.environment() {
            Some(e) => e.radiance8(dir.y),
            None => V8::default(),
        };
        let surface = if on_miss { Some(VisibleSurface::default()) } else { None };
        for i in lanes_of(missed) {
            out[first + i] =
                CameraSample { radiance: Split { direct: le.lane(i), indirect: Rgb::ZERO }, surface };
        }
    }
    if !paths {
        return;
    }
    let paths = PathLanes {
        beta: V8::splat(Rgb::ONE),
        key,
        pixel: U8::from_array(per_lane(|i| (first + i) as u32)),
        ..PathLanes::default()
    };
    pool.append(bits(hit), &paths, &dir, &hits);
}

/// Bounce `vertex` of the pool's batch `b` (`trace_from_hit`'s loop body): the hit
/// records, emission, next-event estimation, the BSDF sample and the next ray query. The
/// paths that go on are packed into the pool from path `kept` on; the others write their
/// radiance to `out`. Returns the paths kept so far.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn bounce_batch<const AVX2: bool>(
    lc: &LockstepContext,
    pool: &mut Pool,
    b: usize,
    kept: usize,
    vertex: u32,
    index: u32,
    si: &mut Surf8<AVX2>,
    stats: &mut LaneStats,
    out: &mut [CameraSample; POOL],
) -> usize {
    let ctx = &lc.ctx;
    let (mut p, dir, hits) = pool.load::<AVX2>(b);
    let stored = from_bits::<AVX2>(hits.mask);
    let found = from_hits(lc, &dir, &hits, si);
    // A hit on a degenerate triangle counts as a miss (as in `PathContext::intersect`).
    add_environment(ctx, stored & !found, &dir, &mut p, vertex);
    let act = stored & found;
    stats.alive[(vertex as usize).min(STATS_VERTICES - 1)] += act.count() as u64;
    stats.bounces += 1;

    let (cont, org, wi) = shade(lc, &mut p, si, act, vertex, index);
    let mut alive = M8::none();
    let mut next = HitPacket::default();
    if cont.any() {
        // Find the next vertex; a miss adds the environment, MIS-weighted.
        let rays = RayPacket {
            origin: org.to_arrays(),
            dir: wi.to_arrays(),
            t_min: [0.0; LANES],
            t_max: [f32::INFINITY; LANES],
        };
        next = lc.intersect(&rays, cont);
        let hit = cont & from_bits(next.mask);
        add_environment(ctx, cont & !hit, &wi, &mut p, vertex + 1);
        alive = hit;
    }
    // The radiance of every path of the batch (those that go on overwrite theirs at a later
    // bounce): a loop over the batch's lanes, not over the ended ones, whose count is random
    // (its exit branch mispredicted).
    let (ld, li, pixel) = (p.l_direct.to_arrays(), p.l_indirect.to_arrays(), p.pixel.to_array());
    for i in 0..hits.mask.count_ones() as usize {
        out[pixel[i] as usize].radiance = Split {
            direct: Rgb::new(ld[0][i], ld[1][i], ld[2][i]),
            indirect: Rgb::new(li[0][i], li[1][i], li[2][i]),
        };
    }
    pool.store(kept, bits(alive), &p, &wi, &next);
    kept + alive.count() as usize
}

/// The environment's radiance, MIS-weighted, for the `lanes` whose ray `dir` left the
/// scene, added to the radiance of path vertex `vertex` (in lanes: on open scenes most
/// paths end here).
#[inline(always)]
fn add_environment<const A: bool>(
    ctx: &PathContext,
    lanes: M8<A>,
    dir: &V8<A>,
    p: &mut PathLanes<A>,
    vertex: u32,
) {
    let Some(env) = ctx.lights.environment() else { return };
    if !lanes.any() {
        return;
    }
    let le = env.radiance8(dir.y);
    let adds = lanes & !le.is_zero();
    if !adds.any() {
        return;
    }
    let p_l = F8::splat(ctx.lights.environment_pmf()) * env.pdf8(dir.y);
    let w_b = select(p.specular, F8::splat(1.0), power_heuristic8(p.p_b, p_l));
    let l = p.beta * w_b * le;
    if vertex <= 1 {
        p.l_direct = V8::select(adds, p.l_direct + l, p.l_direct);
    } else {
        p.l_indirect = V8::select(adds, p.l_indirect + l, p.l_indirect);
    }
}
