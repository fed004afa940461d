//! How the samples of a tile are executed (pbrt-v4's `ImageTileIntegrator::Render`, which
//! calls `EvaluatePixelSample` per pixel and sample): [`trace_tile`], the scalar loop any
//! integrator runs through its `li`, and [`lockstep_tile`], the path tracer run on pools of
//! eight pixels in lockstep ([`super::lockstep`]). Both add each pixel's samples in index
//! order, so for the path tracer they give the same film, bit for bit (`tests/lockstep.rs`):
//! the lockstep tracer is a way of running the path integrator, not a second one.

use super::lockstep::{self, LaneStats, LockstepContext, LockstepTables, RayQueries};
use super::pool::{Pool, POOL};
use super::{CameraSample, Tile, SLOT_PIXEL};
use crate::film::FilmPixel;
use filtrace_core::sampler::Sampler;
use filtrace_core::Ray;
use std::sync::atomic::Ordering;

/// How the path tracer walks its paths. All give the same film, bit for bit
/// (`tests/lockstep.rs`); the choice is speed only. Integrators without a lane version
/// always run [`trace_tile`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TraceMode {
    /// Eight adjacent pixels of a row in lockstep ([`super::lockstep`]), AVX2 lane code
    /// when the CPU has AVX2 and FMA, else the portable lane code. The default: with the
    /// accel crate's packet queries it is ~20% faster per CPU second than [`TraceMode::Scalar`]
    /// on the Cornell box (docs/perf-render.md).
    #[default]
    Lockstep,
    /// [`TraceMode::Lockstep`] with the portable lane code even on AVX2 CPUs (for tests and
    /// comparisons).
    LockstepPortable,
    /// One path at a time ([`super::path::li`]), the reference.
    Scalar,
}

/// What the lockstep executor needs: the renderer's lane tables and choices.
#[derive(Clone, Copy)]
pub struct Lanes<'a> {
    pub tables: &'a LockstepTables,
    pub mode: TraceMode,
    pub queries: RayQueries,
}

/// Adds samples `tile.first..tile.end` of every pixel of the tile, one pixel at a time,
/// each sample from `sample(ray, sampler, want_surface)` with the pixel's sampler after the
/// pixel jitter (slot [`SLOT_PIXEL`]); the visible surface is asked for at sample 0. False
/// when `tile.cancel` stopped it (each pixel keeps the samples it has added).
pub fn trace_tile(
    tile: &Tile,
    pixels: &mut [FilmPixel],
    mut sample: impl FnMut(&Ray, &mut Sampler, bool) -> CameraSample,
) -> bool {
    let width = tile.width;
    for (i, px) in pixels.iter_mut().enumerate() {
        let (x, y) = ((i % width) as u32, (tile.y0 + i / width) as u32);
        // The pixel's hash is shared by its samples; the sums stay in a local copy (in
        // registers) and are stored once, in the same order of additions.
        let key = Sampler::pixel_key(x, y, tile.seed);
        let mut acc = *px;
        for index in tile.first..tile.end {
            if tile.cancel.load(Ordering::Relaxed) {
                *px = acc;
                return false;
            }
            let mut sampler = Sampler::from_pixel_key(key, index);
            sampler.set_slot(SLOT_PIXEL);
            let jitter = sampler.next_2d();
            let ray = tile.camera.sample_ray(x, y, index, jitter);
            let s = sample(&ray, &mut sampler, index == 0);
            if let Some(surface) = s.surface {
                acc.surface = surface;
            }
            acc.add(&s.radiance.to_pixel_sample());
        }
        *px = acc;
    }
    true
}

/// The path tracer's tile in lockstep with the best lane code the CPU runs (portable lane
/// code for [`TraceMode::LockstepPortable`]); `stats` counts the lanes used.
pub fn lockstep_tile(tile: &Tile, pixels: &mut [FilmPixel], stats: &mut LaneStats) -> bool {
    #[cfg(target_arch = "x86_64")]
    if tile.lanes.mode != TraceMode::LockstepPortable && filtrace_core::cpu::isa().has_avx2() {
        // SAFETY: the CPU has AVX2 and FMA (checked just above).
        return unsafe { lockstep_tile_avx2(tile, pixels, stats) };
    }
    pools::<false>(tile, pixels, stats)
}

/// The lane code compiled for AVX2 + FMA (the same source; only instruction selection
/// differs, as Rust never contracts into FMAs).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn lockstep_tile_avx2(tile: &Tile, pixels: &mut [FilmPixel], stats: &mut LaneStats) -> bool {
    pools::<true>(tile, pixels, stats)
}

/// Pools of [`POOL`] adjacent pixels of each row, one sample index at a time; each pixel
/// adds its samples in index order, as [`trace_tile`] does, so the film is the same bit for
/// bit. False when `tile.cancel` stopped it.
#[inline(always)]
fn pools<const AVX2: bool>(tile: &Tile, pixels: &mut [FilmPixel], stats: &mut LaneStats) -> bool {
    let lanes = &tile.lanes;
    let lc = LockstepContext {
        ctx: tile.ctx,
        tables: lanes.tables,
        params: tile.params,
        camera: tile.camera,
        queries: lanes.queries,
    };
    let mut pool = Pool::default();
    let mut out = [CameraSample::default(); POOL];
    for (row, row_pixels) in pixels.chunks_mut(tile.width).enumerate() {
        let y = (tile.y0 + row) as u32;
        for (c, chunk) in row_pixels.chunks_mut(POOL).enumerate() {
            let x0 = (c * POOL) as u32;
            let n = chunk.len();
            let keys: [u32; POOL] = std::array::from_fn(|j| Sampler::pixel_key(x0 + j as u32, y, tile.seed));
            for index in tile.first..tile.end {
                // One relaxed load per pool of paths: negligible, and bounds how long a
                // Ctrl-C waits whatever the pass size.
                if tile.cancel.load(Ordering::Relaxed) {
                    return false;
                }
                lockstep::trace_pool::<AVX2>(&lc, x0, y, &keys, n, index, &mut pool, stats, &mut out);
                for (px, s) in chunk.iter_mut().zip(out.iter()) {
                    if let Some(surface) = s.surface {
                        px.surface = surface;
                    }
                    px.add(&s.radiance.to_pixel_sample());
                }
            }
        }
    }
    true
}
