//! What the filtered pipeline needs from a path tracer, as a trait: the pipeline owns the
//! frame (which rays, which buffers, which filter); a [`PathSource`] traces one eye ray.
//!
//! The pipeline hands its rays over in batches ([`PathSource::trace_batch`],
//! [`PathSource::first_hits`], [`PathSource::trace_path_batch`]: a row of guide rays, a
//! block of further samples, a block of path slots), so that a source can trace them in
//! SIMD lanes; every batch method must give what the per-key methods give, bit for bit, and
//! their defaults call them one key at a time.
//!
//! The implementation on filtrace's own path tracer lives in [`crate::render_source`]; the
//! tests drive the pipeline with analytic sources.

use std::ops::Range;

use filtrace_core::{Rgb, Vec2, Vec3};

use crate::lookup::HitGeometry;

/// Identifies one eye sample: pixel, index of the sample in the pixel (0 = guide ray) and
/// the frame seed. A source must return the same result for the same key (reproducible
/// frames, Bauszat §4: "a constant seed ... makes the results reproducible").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SampleKey {
    pub x: u32,
    pub y: u32,
    pub sample: u32,
    pub seed: u64,
}

/// One traced eye ray, split as in Bauszat et al. 2011, eq. 2: `L = L_direct + L_indirect`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EyeSample {
    /// Normal and depth at the first hit; `None` when the ray escaped.
    pub hit: Option<HitGeometry>,
    /// Diffuse albedo at the first hit (zero on a miss), used to demodulate the indirect light.
    pub albedo: Rgb,
    /// World-space position of the first hit (zero on a miss), for filters with a position term.
    pub position: Vec3,
    /// Emission seen directly, plus light arriving directly from emitters at the first hit
    /// (one next-event sample), plus the environment for a ray that escaped.
    pub direct: Rgb,
    /// Outgoing indirect radiance at the first hit (light that bounced at least once before
    /// reaching it), the mean of `indirect_paths` paths; zero when none were asked for.
    pub indirect: Rgb,
}

/// A path tracer seen by the pipeline. `Sync`: rows of a frame are traced in parallel.
///
/// Two granularities for the guide rays' indirect paths: [`trace`](PathSource::trace)
/// takes a pixel's whole path count in one call; a source that also implements
/// [`trace_path`](PathSource::trace_path) (and says so with
/// [`traces_single_paths`](PathSource::traces_single_paths)) is driven one path at a time
/// by the batch schedule of Bauszat et al. 2011, §4.3 (see [`crate::pipeline`]).
pub trait PathSource: Sync {
    /// Traces the eye ray of `key` through film position `film` (continuous pixel
    /// coordinates, `(0, 0)` the top-left corner of the image) and estimates its indirect
    /// light with `indirect_paths` paths from the first hit (0: skip, `indirect` is zero).
    fn trace(&self, key: SampleKey, film: Vec2, indirect_paths: u32) -> EyeSample;

    /// Whether [`trace_path`](PathSource::trace_path) is implemented. If so the pipeline
    /// traces the guide rays' indirect paths one per call, in batches; if not (the
    /// default) it calls [`trace`](PathSource::trace) once per pixel with the pixel's count.
    fn traces_single_paths(&self) -> bool {
        false
    }

    /// One indirect path of the guide ray of `key` (`key.sample` is 0): path number
    /// `path` of the pixel's `0..count`. Returns the first hit as [`trace`] does (`hit`,
    /// `albedo`, `position`), and this path's contribution alone in `direct` and
    /// `indirect` (both zero if the path is dropped as non-finite). A ray that escaped
    /// returns what [`trace`] returns (the environment in `direct`, for every `path`).
    ///
    /// Contract: the mean of `direct` and `indirect` over `path in 0..n`, summed in path
    /// order from zero and multiplied by `1 / n`, is `trace(key, film, n)` bit for bit,
    /// so that a frame does not depend on how its paths were batched.
    ///
    /// The default, for sources that do not implement it, forwards to
    /// `trace(key, film, 1)`, which is only right for `path == 0`; the pipeline never calls
    /// it unless [`traces_single_paths`](PathSource::traces_single_paths) is true.
    ///
    /// [`trace`]: PathSource::trace
    fn trace_path(&self, key: SampleKey, film: Vec2, path: u32) -> EyeSample {
        debug_assert!(path == 0, "trace_path is not implemented by this source");
        self.trace(key, film, 1)
    }

    /// Paths `paths` of the guide ray of `key`, path `paths.start + i` into `out[i]`
    /// (`out.len() == paths.len()`): the slots one pixel owns in one batch. The default calls
    /// [`trace_path`](PathSource::trace_path) for each; a source may override it to trace
    /// the shared first hit once (same results, the contract of `trace_path`).
    fn trace_paths(&self, key: SampleKey, film: Vec2, paths: Range<u32>, out: &mut [EyeSample]) {
        debug_assert_eq!(out.len(), paths.len());
        for (o, k) in out.iter_mut().zip(paths) {
            *o = self.trace_path(key, film, k);
        }
    }

    /// The first hit of the eye ray of `key` through `film`: `hit`, `albedo` and `position`
    /// as [`trace`](PathSource::trace) returns them; `direct` and `indirect` are not part of
    /// the answer (a source may leave them zero). For G-buffer passes (the adaptive
    /// sampler's pre-pass), which need no light. The default calls `trace(key, film, 0)`.
    fn first_hit(&self, key: SampleKey, film: Vec2) -> EyeSample {
        self.trace(key, film, 0)
    }

    /// The resolution the source was built for (its camera's), if it has one; the
    /// pipeline refuses other frame sizes.
    fn resolution(&self) -> Option<(u32, u32)> {
        None
    }

    /// A batch of eye rays (a row of guide rays, a block of further samples): `out[i]` is
    /// `trace(rays[i].key, rays[i].film, rays[i].paths)` bit for bit. The pipeline hands
    /// its rays over in batches so that a source may trace them together (in SIMD lanes,
    /// [`crate::RenderSource`]); the default traces them one at a time ([`trace_each`]).
    fn trace_batch(&self, rays: &[EyeRay], out: &mut [EyeSample]) {
        trace_each(self, rays, out)
    }

    /// [`first_hit`](PathSource::first_hit) of each ray of a batch (`paths` is not used).
    fn first_hits(&self, rays: &[EyeRay], out: &mut [EyeSample]) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        for (o, r) in out.iter_mut().zip(rays) {
            *o = self.first_hit(r.key, r.film);
        }
    }

    /// [`trace_path`](PathSource::trace_path) of each slot of a batch of the §4.3 schedule.
    /// The default gives each run of consecutive paths of one key to
    /// [`trace_paths`](PathSource::trace_paths) ([`trace_path_runs`]).
    fn trace_path_batch(&self, slots: &[PathSlot], out: &mut [EyeSample]) {
        trace_path_runs(self, slots, out)
    }
}

/// One eye ray of a batch: the arguments of [`PathSource::trace`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EyeRay {
    pub key: SampleKey,
    pub film: Vec2,
    pub paths: u32,
}

/// One indirect path of a guide ray: the arguments of [`PathSource::trace_path`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathSlot {
    pub key: SampleKey,
    pub film: Vec2,
    pub path: u32,
}

/// Paths traced per [`PathSource::trace_paths`] call by [`trace_each`]: bounds the scratch
/// buffer of a pixel with many paths (the sums do not depend on it).
pub const GUIDE_PATH_CHUNK: u32 = 64;

/// [`PathSource::trace_batch`] one ray at a time: a source that traces single paths gets
/// a guide ray's paths in [`PathSource::trace_paths`] calls ([`guide_paths`]), the others
/// one [`PathSource::trace`] call per ray. Both give what `trace` gives, bit for bit (the
/// `trace_path` contract).
pub fn trace_each<S: PathSource + ?Sized>(source: &S, rays: &[EyeRay], out: &mut [EyeSample]) {
    assert_eq!(rays.len(), out.len(), "one output per ray");
    let single = source.traces_single_paths();
    let mut scratch = Vec::new();
    for (o, r) in out.iter_mut().zip(rays) {
        *o = if single && r.paths > 0 {
            guide_paths(source, r.key, r.film, r.paths, &mut scratch)
        } else {
            source.trace(r.key, r.film, r.paths)
        };
    }
}

/// The guide ray of `key` with `count > 0` indirect paths traced one path at a time
/// ([`PathSource::trace_paths`], at most [`GUIDE_PATH_CHUNK`] per call): the first path
/// names the hit, the paths are summed from zero in path order and scaled by `1 / count`
/// last, as `trace` does.
pub fn guide_paths<S: PathSource + ?Sized>(
    source: &S,
    key: SampleKey,
    film: Vec2,
    count: u32,
    scratch: &mut Vec<EyeSample>,
) -> EyeSample {
    let mut acc = EyeSample::default();
    let mut first = 0;
    while first < count {
        let len = (count - first).min(GUIDE_PATH_CHUNK);
        scratch.resize(len as usize, EyeSample::default());
        source.trace_paths(key, film, first..first + len, scratch);
        if first == 0 {
            let e = scratch[0];
            // An escaped ray is final as it is (the environment in `direct`).
            if e.hit.is_none() {
                return e;
            }
            acc = EyeSample { direct: Rgb::ZERO, indirect: Rgb::ZERO, ..e };
        }
        for e in scratch.iter() {
            acc.direct += e.direct;
            acc.indirect += e.indirect;
        }
        first += len;
    }
    let inv = 1.0 / count as f32;
    acc.direct *= inv;
    acc.indirect *= inv;
    acc
}

/// [`PathSource::trace_path_batch`] as [`PathSource::trace_paths`] calls, one per run of
/// consecutive paths of one key (a pixel's slots in a batch share its first hit).
pub fn trace_path_runs<S: PathSource + ?Sized>(source: &S, slots: &[PathSlot], out: &mut [EyeSample]) {
    assert_eq!(slots.len(), out.len(), "one output per slot");
    let mut at = 0;
    while at < slots.len() {
        let s = slots[at];
        let run = slots[at..]
            .iter()
            .enumerate()
            .take_while(|(i, t)| t.key == s.key && t.film == s.film && t.path == s.path + *i as u32)
            .count();
        source.trace_paths(s.key, s.film, s.path..s.path + run as u32, &mut out[at..at + run]);
        at += run;
    }
}

impl<S: PathSource + ?Sized> PathSource for &S {
    fn trace(&self, key: SampleKey, film: Vec2, indirect_paths: u32) -> EyeSample {
        (**self).trace(key, film, indirect_paths)
    }
    fn traces_single_paths(&self) -> bool {
        (**self).traces_single_paths()
    }
    fn trace_path(&self, key: SampleKey, film: Vec2, path: u32) -> EyeSample {
        (**self).trace_path(key, film, path)
    }
    fn trace_paths(&self, key: SampleKey, film: Vec2, paths: Range<u32>, out: &mut [EyeSample]) {
        (**self).trace_paths(key, film, paths, out)
    }
    fn first_hit(&self, key: SampleKey, film: Vec2) -> EyeSample {
        (**self).first_hit(key, film)
    }
    fn resolution(&self) -> Option<(u32, u32)> {
        (**self).resolution()
    }
    fn trace_batch(&self, rays: &[EyeRay], out: &mut [EyeSample]) {
        (**self).trace_batch(rays, out)
    }
    fn first_hits(&self, rays: &[EyeRay], out: &mut [EyeSample]) {
        (**self).first_hits(rays, out)
    }
    fn trace_path_batch(&self, slots: &[PathSlot], out: &mut [EyeSample]) {
        (**self).trace_path_batch(slots, out)
    }
}
