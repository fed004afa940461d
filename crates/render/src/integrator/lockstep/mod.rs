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
//! scenes with at most eight lights, else per lane; area lights sampled in lanes, one packet
//! of shadow rays, BSDF value and density in lanes for diffuse surfaces), BSDF sampling
//! (cosine hemisphere in lanes for diffuse surfaces), Russian roulette, and one packet of
//! closest-hit queries followed by the hit records (`from_hit` in lanes for meshes without
//! vertex attributes: the triangle records are loaded as rows and transposed). Material
//! flags and Lambert reflectances are table lookups in lanes for scenes with at most eight
//! materials.
//!
//! **Exactness is the contract.** Every lane performs the operations of
//! [`super::path::li`] / [`super::path::trace_from_hit`] in the same order (see
//! [`super::lanes`]), and what is not worth a lane version (glossy BSDFs, point, spot,
//! directional and environment lights, emission, misses, meshes with normals or uvs) calls
//! the scalar code for that lane. The film is therefore bit-identical to the scalar
//! renderer's (colour, variance and every AOV), which `tests/lockstep.rs` checks on every
//! built-in scene and on a TOML scene with every material, light type and a texture.
//! Since all lanes start together and every stage is per vertex, the vertex index is the
//! same in all lanes, and so are the sampler slots.
//!
//! Paths that end (miss, roulette, zero throughput, depth limit) leave the pool; the others
//! are moved to the front of it (stream compaction: without it, the lanes of ended paths
//! stayed idle until the slowest path of their group ended, and 43 % of the lane slots
//! paid for were idle on the Cornell box). [`LaneStats`] counts the lanes alive at each
//! vertex and the groups of eight lanes run.

// `!(x <= 0.0)` and `!(!a && b)` are written as in the scalar code they mirror (NaN
// included), not in the form clippy prefers.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::nonminimal_bool)]

use super::lanes::{
    alias_pick8, bits, columns, from_bits, load8_u32, lookup8, lookup8_u32, mask_of, mask_words, per_lane,
    select, F8, LANES, M8, U8, V8,
};
use super::path::visible_surface;
use super::pool::{PathLanes, Pool, POOL};
use super::sampler8::Sampler8;
use super::{
    vertex_slot, CameraSample, PathContext, PathParams, Split, SLOT_BSDF, SLOT_CHOICES, SLOT_LIGHT,
    SLOT_PIXEL, SLOT_RR,
};
use crate::bsdf::SurfaceBsdf;
use crate::camera::PinholeCamera;
use crate::film::VisibleSurface;
use crate::surface::{
    gamma, SurfaceInteraction, OFFSET_FLOOR, OFFSET_SAFETY, SHADOW_END_FRACTION, TRI_FLOATS,
};
use filtrace_accel::{Hit, HitPacket, RayPacket};
use filtrace_core::sampling::power_heuristic;
use filtrace_core::{Ray, Rgb, Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, FRAC_PI_4};
use tables::{AREA_FLOATS, MAT_DIFFUSE, MAT_EMITS, MAT_TWO_SIDED};

mod tables;
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

/// The hit records of eight lanes, structure of arrays (a [`SurfaceInteraction`] per lane).
#[derive(Clone, Copy, Debug, Default)]
struct Surf8<const A: bool> {
    p: V8<A>,
    /// `p_error` (the same value in all three components).
    err: F8<A>,
    n_g: V8<A>,
    n_s: V8<A>,
    n_winding: V8<A>,
    front_face: M8<A>,
    wo: V8<A>,
    /// `u` and `v` rows.
    uv: [[f32; LANES]; 2],
    material: [u32; LANES],
    instance: [u32; LANES],
    prim: [u32; LANES],
    t: F8<A>,
}

impl<const A: bool> Surf8<A> {
    /// Lane `i` as a [`SurfaceInteraction`] (for the per-lane scalar code).
    #[inline(always)]
    fn lane(&self, i: usize) -> SurfaceInteraction {
        SurfaceInteraction {
            p: self.p.lane(i),
            p_error: Vec3::splat(self.err.lane(i)),
            n_g: self.n_g.lane(i),
            n_s: self.n_s.lane(i),
            n_winding: self.n_winding.lane(i),
            front_face: self.front_face.get(i),
            wo: self.wo.lane(i),
            uv: Vec2::new(self.uv[0][i], self.uv[1][i]),
            material: self.material[i],
            instance: self.instance[i],
            prim: self.prim[i],
            t: self.t.lane(i),
        }
    }

    #[inline(always)]
    fn set_lane(&mut self, i: usize, si: &SurfaceInteraction) {
        self.p.set_lane(i, si.p);
        self.err.set_lane(i, si.p_error.x);
        self.n_g.set_lane(i, si.n_g);
        self.n_s.set_lane(i, si.n_s);
        self.n_winding.set_lane(i, si.n_winding);
        self.front_face.set(i, si.front_face);
        self.wo.set_lane(i, si.wo);
        (self.uv[0][i], self.uv[1][i]) = (si.uv.x, si.uv.y);
        self.material[i] = si.material;
        self.instance[i] = si.instance;
        self.prim[i] = si.prim;
        self.t.set_lane(i, si.t);
    }

    /// [`SurfaceInteraction::offset_origin`] in lanes: `p` pushed along `n_g` to the side
    /// of `w` by `|n_g| . p_error`.
    #[inline(always)]
    fn offset_origin(&self, w: V8<A>) -> V8<A> {
        let a = self.n_g.abs();
        let d = a.x * self.err + a.y * self.err + a.z * self.err;
        let below = w.dot(self.n_g).lt(F8::splat(0.0));
        let s = select(below, -d, d);
        self.p + self.n_g * s
    }
}

/// Iterates over the set lanes of `m`.
#[inline(always)]
fn lanes_of<const A: bool>(m: M8<A>) -> impl Iterator<Item = usize> {
    let mut b = bits(m) as u32;
    std::iter::from_fn(move || {
        if b == 0 {
            return None;
        }
        let i = b.trailing_zeros() as usize;
        b &= b - 1;
        Some(i)
    })
}

/// [`SurfaceInteraction::from_hit`] for the lanes of `hits`: in lanes for meshes without
/// vertex normals and uvs, else the scalar function. Returns the records and the lanes
/// with a usable hit (a hit on a degenerate triangle counts as a miss, as in the scalar
/// `PathContext::intersect`).
#[inline(always)]
fn from_hits<const A: bool>(lc: &LockstepContext, dir: &V8<A>, hits: &HitPacket, s: &mut Surf8<A>) -> M8<A> {
    let ctx = &lc.ctx;
    // Per-lane loads into plain arrays, then one vector load each (setting lanes of a
    // vector value one by one goes through memory every time).
    // Rows of the plain lanes' triangle records (row 0 for the other lanes: read, unused).
    let mut start = [0usize; LANES];
    let mut plain = 0u8;
    let mut scalar_ok = 0u8;
    let mut scalar = [None; LANES];
    s.instance = hits.instance;
    s.prim = hits.prim;
    // The uvs of a mesh without vertex uvs are the barycentrics (the scalar lanes'
    // records overwrite theirs below).
    s.uv = [hits.u, hits.v];
    if let Some(first_tri) = lc.tables.plain_first_tris() {
        // Every instance plain: the rows by one table lookup, the materials from the rows.
        plain = hits.mask;
        let rows = lookup8_u32(first_tri, U8::<A>::from_array(hits.instance))
            .wrapping_add(U8::from_array(hits.prim))
            .and(mask_words(from_bits::<A>(plain)))
            .to_array();
        start = per_lane(|i| rows[i] as usize * TRI_FLOATS);
    } else {
        let mut b = hits.mask as u32;
        while b != 0 {
            let i = b.trailing_zeros() as usize;
            b &= b - 1;
            match ctx.geometry.plain_row(hits.instance[i], hits.prim[i]) {
                Some(row) => {
                    plain |= 1 << i;
                    start[i] = row * TRI_FLOATS;
                }
                None => {
                    let h = Hit {
                        t: hits.t[i],
                        u: hits.u[i],
                        v: hits.v[i],
                        instance: hits.instance[i],
                        prim: hits.prim[i],
                    };
                    let ray = Ray::new(Vec3::ZERO, dir.lane(i));
                    scalar[i] = SurfaceInteraction::from_hit(ctx.scene, ctx.geometry, &ray, &h);
                    if scalar[i].is_some() {
                        scalar_ok |= 1 << i;
                    }
                }
            }
        }
    }
    // The records as lanes: words 0..8 and 6..14 of each row, transposed (a row lies in
    // the table: `plain_row` indexed the record).
    let (p0, p1, p2, n, scale, material) = if plain != 0 {
        let words = ctx.geometry.tri_words();
        let a = columns::<A>(words, &start).expect("triangle rows in the table");
        let b = columns::<A>(words, &start.map(|s| s + 6)).expect("triangle rows in the table");
        (
            V8::new(a[0], a[1], a[2]),
            V8::new(a[3], a[4], a[5]),
            V8::new(a[6], a[7], b[2]),
            V8::new(b[3], b[4], b[5]),
            b[6],
            b[7].to_bits(),
        )
    } else {
        (V8::default(), V8::default(), V8::default(), V8::default(), F8::default(), U8::default())
    };
    // Word 13 of a row: the material's bits (the scalar lanes' records overwrite theirs).
    s.material = material.to_array();
    // The lane version of `from_hit` (mesh without normals and uvs: n_s = n_g = winding).
    let (b1, b2) = (F8::from_array(hits.u), F8::from_array(hits.v));
    let b0 = F8::splat(1.0) - b1 - b2;
    s.p = p0 * b0 + p1 * b1 + p2 * b2;
    s.err = scale * F8::splat(gamma(7) * OFFSET_SAFETY) + F8::splat(OFFSET_FLOOR);
    let dir_len = dir.length();
    s.wo = *dir * (F8::splat(-1.0) / dir_len);
    let d = n.dot(s.wo);
    s.front_face = d.gt(F8::splat(0.0));
    // `n_s . n_winding < 0` never holds here (n_s = n_winding, unit length); `facing`:
    let flip = d.lt(F8::splat(0.0));
    s.n_winding = n;
    s.n_g = V8::select(flip, -n, n);
    s.n_s = s.n_g;
    s.t = F8::from_array(hits.t) * dir_len;
    let ok_plain = from_bits::<A>(plain) & !n.is_zero();
    let mut b = scalar_ok as u32;
    while b != 0 {
        let i = b.trailing_zeros() as usize;
        b &= b - 1;
        if let Some(si) = &scalar[i] {
            s.set_lane(i, si);
        }
    }
    ok_plain | from_bits(scalar_ok)
}

/// `Frame::from_z(n)` in lanes (Duff et al. 2017), as `(x, y)` (`z = n`).
#[inline(always)]
fn frame_from_z<const A: bool>(n: V8<A>) -> (V8<A>, V8<A>) {
    let sign = n.z.one_with_sign();
    let a = F8::splat(-1.0) / (sign + n.z);
    let b = n.x * n.y * a;
    let x = V8::new(F8::splat(1.0) + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let y = V8::new(b, sign + n.y * n.y * a, -n.y);
    (x, y)
}

/// `Frame::to_local`.
#[inline(always)]
fn to_local<const A: bool>(fx: &V8<A>, fy: &V8<A>, n: &V8<A>, v: V8<A>) -> V8<A> {
    V8::new(v.dot(*fx), v.dot(*fy), v.dot(*n))
}

/// `Frame::to_world`.
#[inline(always)]
fn to_world<const A: bool>(fx: &V8<A>, fy: &V8<A>, n: &V8<A>, v: V8<A>) -> V8<A> {
    *fx * v.x + *fy * v.y + *n * v.z
}

/// `power_heuristic(1, f_pdf, 1, g_pdf)` in lanes.
#[inline(always)]
fn power_heuristic8<const A: bool>(f_pdf: F8<A>, g_pdf: F8<A>) -> F8<A> {
    let f = F8::splat(1.0) * f_pdf;
    let g = F8::splat(1.0) * g_pdf;
    let f2 = f * f;
    let denom = f2 + g * g;
    let w = select(denom.gt(F8::splat(0.0)), f2 / denom, F8::splat(0.0));
    select(f2.is_infinite(), F8::splat(1.0), w)
}

/// `sin_cos_quarter_pi` in lanes (same Horner polynomials).
#[inline(always)]
fn sin_cos_quarter_pi8<const A: bool>(x: F8<A>) -> (F8<A>, F8<A>) {
    let k = F8::<A>::splat;
    let x2 = x * x;
    let s = x
        * (k(1.0)
            + x2 * (k(-1.0 / 6.0)
                + x2 * (k(1.0 / 120.0) + x2 * (k(-1.0 / 5040.0) + x2 * k(1.0 / 362_880.0)))));
    let c = k(1.0)
        + x2 * (k(-0.5)
            + x2 * (k(1.0 / 24.0)
                + x2 * (k(-1.0 / 720.0) + x2 * (k(1.0 / 40_320.0) + x2 * k(-1.0 / 3_628_800.0)))));
    (s, c)
}

/// `sample_cosine_hemisphere` in lanes: the concentric disk's two branches become a
/// select of numerator, denominator and the roles of sine and cosine.
#[inline(always)]
fn sample_cosine_hemisphere8<const A: bool>(ux: F8<A>, uy: F8<A>) -> V8<A> {
    let ox = F8::splat(2.0) * ux - F8::splat(1.0);
    let oy = F8::splat(2.0) * uy - F8::splat(1.0);
    let zero = F8::splat(0.0);
    let origin = ox.eq(zero) & oy.eq(zero);
    let first = ox.abs().gt(oy.abs());
    let num = select(first, oy, ox);
    let den = select(first, ox, oy);
    let (s, c) = sin_cos_quarter_pi8(F8::splat(FRAC_PI_4) * (num / den));
    let dx = select(origin, zero, den * select(first, c, s));
    let dy = select(origin, zero, den * select(first, s, c));
    let z = (F8::splat(1.0) - dx * dx - dy * dy).max(zero).sqrt();
    V8::new(dx, dy, z)
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
    debug_assert!(n <= POOL);
    *out = [CameraSample::default(); POOL];
    pool.clear();
    // The hit records of the batch at hand (`from_hits` writes every field; one record
    // per pool, not a 672-byte `memset` per batch).
    let mut si = Surf8::<AVX2>::default();
    for first in (0..n).step_by(LANES) {
        let lanes = from_bits::<AVX2>(((1u32 << (n - first).min(LANES)) - 1) as u8);
        camera_group(lc, x0, y, keys, first, lanes, index, pool, &mut si, stats, out);
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
    x0: u32,
    y: u32,
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
    let sampler = Sampler8::<AVX2>::from_keys(key, index);
    stats.groups += 1;
    stats.camera_lanes += lanes.count() as u64;

    // Camera rays: `PinholeCamera::sample_ray` (sample 0 through the pixel centre).
    let (jx, jy) = sampler.next_2d(SLOT_PIXEL);
    let (ox, oy) = if index == 0 { (F8::splat(0.5), F8::splat(0.5)) } else { (jx, jy) };
    let px = F8::<AVX2>::from_array(per_lane(|i| (x0 as usize + first + i) as f32));
    let sx = (px + ox) * F8::splat(cam.two_over_size.x) - F8::splat(1.0);
    let sy = F8::splat(1.0) - (F8::splat(y as f32) + oy) * F8::splat(cam.two_over_size.y);
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
    let want_surface = index == 0;
    if want_surface {
        for i in lanes_of(lanes & hit) {
            out[first + i].surface = Some(visible_surface(ctx, &si.lane(i)));
        }
    }
    for i in lanes_of(lanes & !hit) {
        let o = &mut out[first + i];
        o.radiance.direct = ctx.lights.environment_radiance(dir.lane(i));
        o.surface = want_surface.then(VisibleSurface::default);
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
/// scene (per lane: few lanes miss), added to the radiance of path vertex `vertex`.
#[inline(always)]
fn add_environment<const A: bool>(
    ctx: &PathContext,
    lanes: M8<A>,
    dir: &V8<A>,
    p: &mut PathLanes<A>,
    vertex: u32,
) {
    if !ctx.lights.has_environment() {
        return;
    }
    for i in lanes_of(lanes) {
        let w = dir.lane(i);
        let le = ctx.lights.environment_radiance(w);
        if le != Rgb::ZERO {
            let w_b = if p.specular.get(i) {
                1.0
            } else {
                power_heuristic(1.0, p.p_b.lane(i), 1.0, ctx.lights.pdf_environment(w))
            };
            let l = p.beta.lane(i) * w_b * le;
            if vertex <= 1 {
                p.l_direct.set_lane(i, p.l_direct.lane(i) + l);
            } else {
                p.l_indirect.set_lane(i, p.l_indirect.lane(i) + l);
            }
        }
    }
}

/// The shading at path vertex `vertex` of the lanes `act` with hit records `si`:
/// emission (MIS against light sampling), next-event estimation with one packet of shadow
/// rays, the BSDF sample and Russian roulette. Returns the lanes that go on with the next
/// ray's origin and direction.
#[inline(always)]
fn shade<const AVX2: bool>(
    lc: &LockstepContext,
    p: &mut PathLanes<AVX2>,
    si: &Surf8<AVX2>,
    act: M8<AVX2>,
    vertex: u32,
    index: u32,
) -> (M8<AVX2>, V8<AVX2>, V8<AVX2>) {
    let ctx = &lc.ctx;
    let params = &lc.params;
    let zero = F8::<AVX2>::splat(0.0);
    let materials = &ctx.scene.materials;
    let sampler = Sampler8::<AVX2>::from_keys(p.key, index);
    let (mut beta, mut l_direct, mut l_indirect) = (p.beta, p.l_direct, p.l_indirect);
    let (mut p_b, mut specular, mut prev_p) = (p.p_b, p.specular, p.prev_p);

    // The material flags and Lambert reflectances of the lanes by table lookups when
    // the scene has at most eight materials (else every lane looks its material up).
    let small_mats = match lc.tables.small_materials() {
        Some(sm) => {
            let id = U8::from_array(si.material);
            Some((lookup8_u32(&sm.flags, id), sm, id))
        }
        None => None,
    };

    // Emitted radiance at the vertex (per lane: few lanes hit an emitter).
    let emitting = match &small_mats {
        Some((flags, ..)) => {
            let emits = mask_of(flags.and(U8::splat(MAT_EMITS)));
            let two = mask_of(flags.and(U8::splat(MAT_TWO_SIDED)));
            act & emits & (si.front_face | two)
        }
        None => act,
    };
    for i in lanes_of(emitting) {
        let m = &materials[si.material[i] as usize];
        if !(m.is_emissive() && (si.front_face.get(i) || m.two_sided_emission)) {
            continue;
        }
        let le = m.emission;
        if le != Rgb::ZERO {
            let w_b = if vertex == 0 || specular.get(i) {
                1.0
            } else {
                let p_l = ctx.lights.pdf_area(
                    si.instance[i],
                    si.prim[i],
                    prev_p.lane(i),
                    si.p.lane(i),
                    si.n_winding.lane(i),
                );
                power_heuristic(1.0, p_b.lane(i), 1.0, p_l)
            };
            let l = beta.lane(i) * w_b * le;
            if vertex <= 1 {
                l_direct.set_lane(i, l_direct.lane(i) + l);
            } else {
                l_indirect.set_lane(i, l_indirect.lane(i) + l);
            }
        }
    }

    // Stop when one more segment would exceed max_depth.
    if !params.allows(vertex + 2) {
        (p.l_direct, p.l_indirect) = (l_direct, l_indirect);
        return (M8::none(), V8::default(), V8::default());
    }

    // The BSDFs, the shading frames and wo in them.
    // `None` stores one tag byte per lane (a default BSDF copied into eight lanes
    // was a memset/memcpy per bounce); only the glossy lanes read their BSDF.
    let mut bsdf: [Option<SurfaceBsdf>; LANES] = [None; LANES];
    let mut diffuse = 0u8;
    let mut lobe = 0u8;
    let mut rho = [[0.0f32; LANES]; 3];
    let const_diffuse = match &small_mats {
        Some((flags, ..)) => act & mask_of(flags.and(U8::splat(MAT_DIFFUSE))),
        None => M8::none(),
    };
    for i in lanes_of(act & !const_diffuse) {
        // Untextured Lambert (most surfaces): its reflectance only, no BSDF record.
        if let Some(r) = ctx.geometry.constant_diffuse(si.material[i]) {
            diffuse |= 1 << i;
            (rho[0][i], rho[1][i], rho[2][i]) = (r.x, r.y, r.z);
            continue;
        }
        let b = ctx.geometry.bsdf(ctx.scene, si.material[i], Vec2::new(si.uv[0][i], si.uv[1][i]));
        match &b {
            SurfaceBsdf::Diffuse(d) => {
                diffuse |= 1 << i;
                let r = d.reflectance;
                (rho[0][i], rho[1][i], rho[2][i]) = (r.x, r.y, r.z);
            }
            b => lobe |= (b.has_lobe_choice() as u8) << i,
        }
        bsdf[i] = Some(b);
    }
    let (diffuse, lobe) = (const_diffuse | from_bits::<AVX2>(diffuse), from_bits::<AVX2>(lobe));
    let rho = match &small_mats {
        Some((_, sm, id)) => V8::select(
            const_diffuse,
            V8::new(lookup8(&sm.rho[0], *id), lookup8(&sm.rho[1], *id), lookup8(&sm.rho[2], *id)),
            V8::from_arrays(&rho),
        ),
        None => V8::from_arrays(&rho),
    };
    let glossy = act & !diffuse;
    let (fx, fy) = frame_from_z(si.n_s);
    let n = si.n_s;
    let wo = to_local(&fx, &fy, &n, si.wo);

    // The vertex's random numbers (`VertexSamples::draw`).
    let base = vertex_slot(vertex);
    let (ulx, uly) = sampler.next_2d(base + SLOT_LIGHT);
    let (ubx, uby) = sampler.next_2d(base + SLOT_BSDF);
    let (u_select, u_lobe) = if lobe.any() {
        let (cx, cy) = sampler.next_2d(base + SLOT_CHOICES);
        (cx, select(lobe, cy, zero))
    } else {
        (sampler.next_1d(base + SLOT_CHOICES), zero)
    };

    // Next-event estimation (`sample_one_light`): light choice per lane, area lights
    // sampled in lanes, other lights by the scalar `sample_li`.
    // Per-lane values go to plain arrays first (one vector load each afterwards).
    let mut area = 0u8;
    let mut ls_ok = 0u8;
    let mut ls_delta = 0u8;
    let mut a_two = 0u8;
    let mut ls_wi = [[0.0f32; LANES]; 3];
    let mut ls_li = [[0.0f32; LANES]; 3];
    let mut ls_pdf = [0.0f32; LANES];
    let mut ls_dist = [0.0f32; LANES];
    let mut pmf = [0.0f32; LANES];
    // Rows of the chosen area lights in `area_words` (row 0 for the other lanes).
    let mut a_start = [0usize; LANES];
    let u_sel = u_select.to_array();
    // With at most eight lights the choice and the area lights' data are lanes
    // (`SmallLights`: the alias pick and one `vpermps` per field); only the lanes that
    // chose another kind of light take the per-lane code.
    let small = match lc.tables.small_lights() {
        Some(sl) => {
            let (k, pm) = alias_pick8(u_select, sl.n, &sl.q, &sl.alias, &sl.pmf);
            let chosen = act & pm.gt(zero);
            let is_area = mask_of(lookup8_u32(&sl.is_area, k));
            Some((sl, k, pm, chosen & is_area, chosen & !is_area))
        }
        None => None,
    };
    let per_lane_lights = match &small {
        Some(sm) => sm.4,
        None => act,
    };
    for i in lanes_of(per_lane_lights) {
        let (li, pm) = ctx.lights.select(u_sel[i]);
        if pm > 0.0 {
            if let Some(a) = ctx.lights.area_light(li) {
                area |= 1 << i;
                pmf[i] = pm;
                a_start[i] = li * AREA_FLOATS;
                a_two |= (a.two_sided as u8) << i;
                continue;
            }
        }
        if let Some(ls) = ctx.lights.sample_li(si.p.lane(i), u_sel[i], Vec2::new(ulx.lane(i), uly.lane(i))) {
            ls_ok |= 1 << i;
            (ls_wi[0][i], ls_wi[1][i], ls_wi[2][i]) = (ls.wi.x, ls.wi.y, ls.wi.z);
            (ls_li[0][i], ls_li[1][i], ls_li[2][i]) = (ls.li.x, ls.li.y, ls.li.z);
            ls_pdf[i] = ls.pdf;
            ls_dist[i] = ls.dist;
            ls_delta |= (ls.delta as u8) << i;
        }
    }
    let (area, pmf) = match &small {
        Some(sm) => (sm.3, sm.2),
        None => (from_bits::<AVX2>(area), F8::from_array(pmf)),
    };
    let mut ls_ok = from_bits::<AVX2>(ls_ok);
    let ls_delta = from_bits::<AVX2>(ls_delta);
    let mut ls_wi = V8::from_arrays(&ls_wi);
    let mut ls_li = V8::from_arrays(&ls_li);
    let mut ls_pdf = F8::from_array(ls_pdf);
    let mut ls_dist = F8::from_array(ls_dist);
    if area.any() {
        let (a, b, a_two) = match &small {
            Some(sm) => {
                let (sl, k) = (sm.0, sm.1);
                // A macro, not a closure (closures do not inherit AVX2).
                macro_rules! field {
                    ($j:expr) => {
                        lookup8(&sl.field[$j], k)
                    };
                }
                let a =
                    [field!(0), field!(1), field!(2), field!(3), field!(4), field!(5), field!(6), field!(7)];
                let b = [
                    field!(8),
                    field!(9),
                    field!(10),
                    field!(11),
                    field!(12),
                    field!(13),
                    field!(14),
                    field!(15),
                ];
                (a, b, mask_of(lookup8_u32(&sl.two_sided, k)))
            }
            None => {
                // The chosen lights' rows as lanes (words 0..8 and 8..16, transposed;
                // the rows exist: `area_light` found the lights).
                let words = lc.tables.area_words();
                let a = columns::<AVX2>(words, &a_start).expect("area light rows in the table");
                let b =
                    columns::<AVX2>(words, &a_start.map(|s| s + 8)).expect("area light rows in the table");
                (a, b, from_bits::<AVX2>(a_two))
            }
        };
        let (a_p0, a_e1, a_e2) =
            (V8::new(a[0], a[1], a[2]), V8::new(a[3], a[4], a[5]), V8::new(a[6], a[7], b[0]));
        let (a_n, a_area) = (V8::new(b[1], b[2], b[3]), b[4]);
        ls_li = V8::select(area, V8::new(b[5], b[6], b[7]), ls_li);
        // `AreaLight::sample` with `sample_uniform_triangle`.
        let m = F8::splat(0.5) * ulx.min(uly);
        let b0 = ulx - m;
        let b1 = uly - m;
        let b2 = F8::splat(1.0) - b0 - b1;
        let xp = a_p0 + a_e1 * b1 + a_e2 * b2;
        let d = xp - si.p;
        let dist2 = d.dot(d);
        let dist = dist2.sqrt();
        let wi = d / dist;
        let cos_l = -a_n.dot(wi);
        let c = cos_l.abs();
        let pdf_a = dist2 / (c * a_area);
        // Lane masks combined with `&` (a `&&` chain in a closure was left out of line,
        // compiled without AVX, 3% of the profile).
        let front = !(!a_two & cos_l.le(zero));
        let ok = (dist2.gt(zero) & front) & (!c.le(zero) & (pdf_a.gt(zero) & pdf_a.is_finite()));
        let ok = area & ok;
        let pdf = pmf * pdf_a;
        ls_ok = M8::select(area, ok, ls_ok);
        ls_wi = V8::select(area, wi, ls_wi);
        ls_pdf = select(area, pdf, ls_pdf);
        ls_dist = select(area, dist, ls_dist);
    }
    let p_l = ls_pdf;
    let usable = (ls_ok & !(p_l.is_nan() | p_l.le(zero))) & !ls_li.is_zero();
    let wi_l = to_local(&fx, &fy, &n, ls_wi);
    // Lambert: f = rho / pi above both horizons; times |cos|.
    let above = !wo.z.le(zero) & !wi_l.z.le(zero);
    let f_d = rho * F8::splat(FRAC_1_PI);
    let mut f = V8::select(above, f_d, V8::default()) * wi_l.z.abs();
    let mut pdf_b = select(above, wi_l.z.max(zero) * F8::splat(FRAC_1_PI), zero);
    for i in lanes_of(glossy & usable) {
        if let Some(b) = &bsdf[i] {
            let (wo_i, wi_i) = (wo.lane(i), wi_l.lane(i));
            f.set_lane(i, b.f(wo_i, wi_i) * wi_i.z.abs());
            pdf_b.set_lane(i, b.pdf(wo_i, wi_i));
        }
    }
    let shadow = usable & !f.is_zero();
    let s_org = si.offset_origin(ls_wi);
    let far =
        select(ls_dist.is_finite(), ls_dist * F8::splat(1.0 - SHADOW_END_FRACTION), F8::splat(f32::INFINITY));
    let srays = RayPacket {
        origin: s_org.to_arrays(),
        dir: ls_wi.to_arrays(),
        t_min: [0.0; LANES],
        t_max: far.to_array(),
    };
    let occluded = lc.occluded(&srays, shadow);
    let lit = shadow & !occluded;
    let w_l = select(ls_delta, F8::splat(1.0), power_heuristic8(p_l, pdf_b));
    let contrib = V8::select(lit, f * ls_li * (w_l / p_l), V8::default());
    // The light reaches the eye over vertices 0..=vertex: component of vertex + 1.
    let add = beta * contrib;
    if vertex < 1 {
        l_direct = V8::select(act, l_direct + add, l_direct);
    } else {
        l_indirect = V8::select(act, l_indirect + add, l_indirect);
    }

    // BSDF sampling for the next direction (cosine hemisphere in lanes for Lambert).
    let mut bs_wi = sample_cosine_hemisphere8(ubx, uby);
    let mut bs_pdf = bs_wi.z.max(zero) * F8::splat(FRAC_1_PI);
    let mut bs_f = f_d;
    let mut bs_ok = !wo.z.le(zero) & !bs_pdf.le(zero);
    let mut bs_spec = M8::none();
    for i in lanes_of(glossy) {
        let sample = bsdf[i]
            .as_ref()
            .and_then(|b| b.sample(wo.lane(i), Vec2::new(ubx.lane(i), uby.lane(i)), u_lobe.lane(i)));
        match sample {
            Some(bs) => {
                bs_ok.set(i, true);
                bs_wi.set_lane(i, bs.wi);
                bs_f.set_lane(i, bs.f);
                bs_pdf.set_lane(i, bs.pdf);
                bs_spec.set(i, bs.specular);
            }
            None => bs_ok.set(i, false),
        }
    }
    let mut cont = act & bs_ok;
    let wi = to_world(&fx, &fy, &n, bs_wi);
    let new_beta = beta * (bs_f * (bs_wi.z.abs() / bs_pdf));
    beta = V8::select(cont, new_beta, beta);
    p_b = select(cont, bs_pdf, p_b);
    specular = M8::select(cont, bs_spec, specular);
    prev_p = V8::select(cont, si.p, prev_p);
    cont = cont & (!beta.is_zero() & beta.is_finite());
    let org = si.offset_origin(wi);

    // Russian roulette once the path has rr_depth segments.
    if vertex + 2 >= params.rr_depth {
        let q = beta.max_element().min(F8::splat(0.95));
        let u_rr = sampler.next_1d(vertex_slot(vertex) + SLOT_RR);
        cont = cont & !u_rr.ge(q);
        beta = V8::select(cont, beta / q, beta);
    }
    (p.beta, p.l_direct, p.l_indirect) = (beta, l_direct, l_indirect);
    (p.p_b, p.specular, p.prev_p) = (p_b, specular, prev_p);
    (cont, org, wi)
}
