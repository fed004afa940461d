//! The batches of [`super::RenderSource`] on the lockstep tracer
//! ([`filtrace_render::integrator::lockstep::trace_film_rays`]).
//!
//! The lockstep tracer runs one sampler index in all its lanes (its sampler slots move in
//! step), so a batch is regrouped by index: further samples by their sample number
//! (index `EYE_SAMPLE_INDEX_BASE + sample`, two-segment paths), guide rays by path number
//! `k` (index `k`, full paths; a guide ray with `n` paths is traced `n` times, once per
//! group `k < n`, its first hit found again each time). Each lane computes what the scalar
//! code computes for its key; the sums over a guide ray's paths are then taken here in path
//! order, from zero, scaled last, as [`super::RenderSource::trace`] takes them: so every
//! result is the scalar one bit for bit.

use std::sync::Mutex;

use filtrace_core::sampler::Sampler;
use filtrace_core::{Rgb, Vec2};
use filtrace_render::integrator::lockstep::{trace_film_rays, FilmRay, LaneCode, LaneStats, LockstepContext};
use filtrace_render::integrator::{CameraSample, PathParams};
use filtrace_render::Renderer;

use super::{eye_sample_params, finite_or_zero, surface_sample, EYE_SAMPLE_INDEX_BASE};
use crate::source::{EyeRay, EyeSample, PathSlot, SampleKey};

/// The renderer's lockstep tracer, for one batch.
pub(super) struct LaneTracer<'a> {
    pub renderer: &'a Renderer,
    pub code: LaneCode,
    pub stats: &'a Mutex<LaneStats>,
}

/// The lockstep ray of the eye ray of `key` through `film`.
fn film_ray(key: SampleKey, film: Vec2) -> FilmRay {
    let offset = film - Vec2::new(key.x as f32, key.y as f32);
    FilmRay { x: key.x, y: key.y, key: Sampler::pixel_key(key.x, key.y, key.seed), offset }
}

/// A path's result as `trace_paths` gives it: the environment on a miss, else the hit
/// record with the path's light (none if the path is not finite).
fn path_sample(s: &CameraSample) -> EyeSample {
    match &s.surface {
        None => EyeSample { direct: finite_or_zero(s.radiance.direct), ..Default::default() },
        Some(vs) => {
            let base = surface_sample(vs);
            let (d, i) = (s.radiance.direct, s.radiance.indirect);
            if d.is_finite() && i.is_finite() {
                EyeSample { direct: d, indirect: i, ..base }
            } else {
                base
            }
        }
    }
}

impl LaneTracer<'_> {
    /// Traces `rays` at sampler index `index` with paths of `params` (`None`: first hits).
    fn run(&self, rays: &[FilmRay], index: u32, params: Option<PathParams>, out: &mut [CameraSample]) {
        let base = self.renderer.lockstep_context();
        let lc = LockstepContext { params: params.unwrap_or(base.params), ..base };
        let mut stats = LaneStats::default();
        trace_film_rays(&lc, self.code, rays, index, params.is_some(), &mut stats, out);
        self.stats.lock().unwrap_or_else(|e| e.into_inner()).merge(&stats);
    }

    /// Traces the rays `members` (indices into the batch) of one group at `index`.
    fn run_group(
        &self,
        members: &[usize],
        ray_of: impl Fn(usize) -> FilmRay,
        index: u32,
        params: Option<PathParams>,
    ) -> Vec<CameraSample> {
        let rays: Vec<FilmRay> = members.iter().map(|&i| ray_of(i)).collect();
        let mut out = vec![CameraSample::default(); rays.len()];
        self.run(&rays, index, params, &mut out);
        out
    }

    /// `PathSource::trace_batch`: further samples grouped by sample number, guide rays by
    /// path number.
    pub fn trace_batch(&self, rays: &[EyeRay], out: &mut [EyeSample]) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        let params = self.renderer.path_params();
        let ray_of = |i: usize| film_ray(rays[i].key, rays[i].film);
        // Further samples (and guide rays without paths): two-segment paths.
        for (sample, members) in groups(rays.len(), |i| (rays[i].paths == 0).then_some(rays[i].key.sample)) {
            let index = EYE_SAMPLE_INDEX_BASE + sample;
            let traced = self.run_group(&members, ray_of, index, Some(eye_sample_params(params)));
            for (&i, s) in members.iter().zip(&traced) {
                let direct = finite_or_zero(s.radiance.direct);
                out[i] = match &s.surface {
                    Some(vs) => EyeSample { direct, ..surface_sample(vs) },
                    None => EyeSample { direct, ..Default::default() },
                };
            }
        }
        // Guide rays: path k of every ray with more than k paths, summed in path order.
        let mut live: Vec<usize> = (0..rays.len()).filter(|&i| rays[i].paths > 0).collect();
        let mut k = 0;
        while !live.is_empty() {
            let traced = self.run_group(&live, ray_of, k, Some(params));
            for (&i, s) in live.iter().zip(&traced) {
                let e = path_sample(s);
                let acc = &mut out[i];
                if k == 0 {
                    // The first path names the hit; an escaped ray is final as it is.
                    *acc = if e.hit.is_some() {
                        EyeSample { direct: Rgb::ZERO, indirect: Rgb::ZERO, ..e }
                    } else {
                        e
                    };
                }
                if acc.hit.is_some() {
                    acc.direct += e.direct;
                    acc.indirect += e.indirect;
                }
            }
            k += 1;
            live.retain(|&i| out[i].hit.is_some() && rays[i].paths > k);
        }
        for (r, o) in rays.iter().zip(out.iter_mut()) {
            if r.paths > 0 && o.hit.is_some() {
                let inv = 1.0 / r.paths as f32;
                o.direct *= inv;
                o.indirect *= inv;
            }
        }
    }

    /// `PathSource::first_hits`: the visible surfaces, no light.
    pub fn first_hits(&self, rays: &[EyeRay], out: &mut [EyeSample]) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        let members: Vec<usize> = (0..rays.len()).collect();
        let traced = self.run_group(&members, |i| film_ray(rays[i].key, rays[i].film), 0, None);
        for (o, s) in out.iter_mut().zip(&traced) {
            *o = s.surface.as_ref().map_or_else(EyeSample::default, surface_sample);
        }
    }

    /// `PathSource::trace_path_batch`: slots grouped by path number.
    pub fn trace_path_batch(&self, slots: &[PathSlot], out: &mut [EyeSample]) {
        assert_eq!(slots.len(), out.len(), "one output per slot");
        let params = self.renderer.path_params();
        let ray_of = |i: usize| film_ray(slots[i].key, slots[i].film);
        for (path, members) in groups(slots.len(), |i| Some(slots[i].path)) {
            let traced = self.run_group(&members, ray_of, path, Some(params));
            for (&i, s) in members.iter().zip(&traced) {
                out[i] = path_sample(s);
            }
        }
    }
}

/// The items `0..n` with a group number (`group_of`, `None`: in no group), by group number
/// ascending, each group's items in order.
fn groups(n: usize, group_of: impl Fn(usize) -> Option<u32>) -> Vec<(u32, Vec<usize>)> {
    let mut keyed: Vec<(u32, usize)> = (0..n).filter_map(|i| group_of(i).map(|g| (g, i))).collect();
    keyed.sort_unstable();
    let mut out: Vec<(u32, Vec<usize>)> = Vec::new();
    for (g, i) in keyed {
        match out.last_mut() {
            Some((last, members)) if *last == g => members.push(i),
            _ => out.push((g, vec![i])),
        }
    }
    out
}
