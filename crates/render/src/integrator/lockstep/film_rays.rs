//! The lockstep tracer on eye rays through given film positions, any pixels in any order:
//! the filtered pipeline's guide rays, their indirect paths and its further eye samples
//! (`filtrace_pipeline::RenderSource`). The rays are cut into pools of [`POOL`] lanes and
//! traced as the renderer's tiles are ([`super::trace_pool_at`]); each lane equals the
//! scalar code on its ray bit for bit (the contract of [`super`]).

use super::{trace_pool_at, FilmLanes, LaneStats, LockstepContext, PoolCameras};
use crate::integrator::pool::{Pool, POOL};
use crate::integrator::CameraSample;
use filtrace_core::Vec2;

/// One eye ray: pixel `(x, y)`, its [`filtrace_core::sampler::Sampler::pixel_key`] `key`,
/// and the film offset in the pixel (`PinholeCamera::generate_ray(x, y, offset)`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FilmRay {
    pub x: u32,
    pub y: u32,
    pub key: u32,
    pub offset: Vec2,
}

/// Which lane code runs (same bits either way).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LaneCode {
    /// AVX2 + FMA instructions when the CPU has them, else the portable code.
    #[default]
    Best,
    /// The portable code on every CPU (tests and comparisons).
    Portable,
}

/// Traces `rays` at sample `index` into `out` (`out.len() == rays.len()`): `out[i]` is the
/// ray's visible surface (`None` on a miss) and, when `paths`, the radiance of the path of
/// `lc.params` from its hit (`trace_from_hit` with the sampler of `(rays[i].key, index)`)
/// or the environment seen on a miss; without `paths`, first hits only.
pub fn trace_film_rays(
    lc: &LockstepContext,
    code: LaneCode,
    rays: &[FilmRay],
    index: u32,
    paths: bool,
    stats: &mut LaneStats,
    out: &mut [CameraSample],
) {
    assert_eq!(rays.len(), out.len(), "one output per ray");
    #[cfg(target_arch = "x86_64")]
    if code == LaneCode::Best && filtrace_core::cpu::isa().has_avx2() {
        // SAFETY: the CPU has AVX2 and FMA (checked just above).
        unsafe { film_rays_avx2(lc, rays, index, paths, stats, out) };
        return;
    }
    film_rays::<false>(lc, rays, index, paths, stats, out);
}

/// The lane code compiled for AVX2 + FMA (as the renderer's tile loop).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn film_rays_avx2(
    lc: &LockstepContext,
    rays: &[FilmRay],
    index: u32,
    paths: bool,
    stats: &mut LaneStats,
    out: &mut [CameraSample],
) {
    film_rays::<true>(lc, rays, index, paths, stats, out)
}

#[inline(always)]
fn film_rays<const AVX2: bool>(
    lc: &LockstepContext,
    rays: &[FilmRay],
    index: u32,
    paths: bool,
    stats: &mut LaneStats,
    out: &mut [CameraSample],
) {
    let mut pool = Pool::default();
    let mut films = FilmLanes::default();
    let mut keys = [0u32; POOL];
    let mut samples = [CameraSample::default(); POOL];
    for (rays, out) in rays.chunks(POOL).zip(out.chunks_mut(POOL)) {
        for (j, r) in rays.iter().enumerate() {
            (films.px[j], films.py[j]) = (r.x as f32, r.y as f32);
            (films.ox[j], films.oy[j]) = (r.offset.x, r.offset.y);
            keys[j] = r.key;
        }
        let cams = PoolCameras::Given { films: &films, paths };
        trace_pool_at::<AVX2>(lc, cams, &keys, rays.len(), index, &mut pool, stats, &mut samples);
        out.copy_from_slice(&samples[..rays.len()]);
    }
}
