//! Pass 1 of the frame: one guide ray per pixel through the pixel centre, its first hit,
//! direct light and indirect paths (Bauszat et al. 2011, §3.1-3.2), written into the
//! G-buffer layers and the (demodulated) indirect map.
//!
//! Rows go to the source as batches ([`PathSource::trace_batch`]); with an explicit batch
//! size, the paths go as blocks of the §4.3 schedule's slots
//! ([`PathSource::trace_path_batch`]). Every way gives the same bits as one
//! `trace(key, film, count)` call per pixel.

use std::sync::atomic::{AtomicBool, Ordering};

use filtrace_adaptive::{BatchSchedule, Slot};
use filtrace_core::{Rgb, Vec2};
use filtrace_render::memory::try_resize;
use rayon::prelude::*;

use crate::buffers::{BatchBuffers, Buffers};
use crate::frame::FrameImages;
use crate::lookup::HitGeometry;
use crate::settings::{PipelineError, PipelineSettings, DEMODULATION_EPS};
use crate::source::{EyeRay, EyeSample, PathSlot, PathSource, SampleKey};

/// Slots of the §4.3 schedule per [`PathSource::trace_path_batch`] call (one parallel
/// task): enough for a source tracing in lanes to fill them.
pub const SLOT_BLOCK: usize = 512;

/// Indirect path counts of the guide rays: one for every pixel, or one per pixel.
#[derive(Clone, Copy)]
pub(crate) enum PathCounts<'a> {
    Uniform(u32),
    PerPixel(&'a [u32]),
}

impl PathCounts<'_> {
    #[inline]
    fn of(&self, pixel: usize) -> u32 {
        match self {
            Self::Uniform(c) => *c,
            Self::PerPixel(c) => c[pixel],
        }
    }
}

/// Pass 1 into `buf` (the guide geometry, direct light and layers, sized here): rows of the
/// whole frame as one batch ([`guide_pass`]), or with `batch_size` and a source that
/// traces single paths, the §4.3 batches ([`guide_pass_batched`]). A `cancel` set during
/// it leaves the layers incomplete (the caller drops the frame).
pub(crate) fn trace_guides<S: PathSource>(
    source: &S,
    buf: &mut Buffers,
    st: &PipelineSettings,
    counts: PathCounts<'_>,
    batch_size: Option<usize>,
    cancel: &AtomicBool,
) -> Result<(), PipelineError> {
    let (w, h) = (st.width as usize, st.height as usize);
    let n = w * h;
    // Every entry is written by the pass: resize, no clearing.
    (buf.guides.width, buf.guides.height) = (w, h);
    try_resize(&mut buf.guides.hits, n, None, "the guide rays' hits")?;
    try_resize(&mut buf.guide_direct, n, Rgb::ZERO, "the guide rays' direct light")?;
    match batch_size {
        Some(batch) if source.traces_single_paths() => {
            // Explicit batches (§4.3): trace into per-slot buffers, then store.
            let counts: std::borrow::Cow<'_, [u32]> = match counts {
                PathCounts::PerPixel(c) => c.into(),
                PathCounts::Uniform(c) => vec![c; n].into(),
            };
            let schedule = BatchSchedule::from_counts(&counts, batch)
                .map_err(|e| PipelineError::Batch(e.to_string()))?;
            try_resize(&mut buf.guide_samples, n, EyeSample::default(), "the guide rays")?;
            let bb = &mut buf.batch;
            guide_pass_batched(source, &schedule, bb, &mut buf.guide_samples, w, st.seed, cancel);
            let rows = guide_rows(&mut buf.guides.hits, &mut buf.guide_direct, &mut buf.frame.images, w);
            store_guides(&buf.guide_samples, rows, st.demodulate_albedo);
        }
        _ => {
            // The whole frame as one batch: each row's rays in one task, stored as they
            // are traced.
            let rows = guide_rows(&mut buf.guides.hits, &mut buf.guide_direct, &mut buf.frame.images, w);
            guide_pass(source, counts, rows, w, (st.seed, st.demodulate_albedo), cancel);
        }
    }
    Ok(())
}

/// The guide ray of pixel `(x, y)` with `paths` indirect paths.
fn guide_ray(x: usize, y: usize, seed: u64, paths: u32) -> EyeRay {
    EyeRay { key: SampleKey { x: x as u32, y: y as u32, sample: 0, seed }, film: guide_film(x, y), paths }
}

/// Pass 1 with the whole frame as one batch: rows in parallel, each row's guide rays one
/// [`PathSource::trace_batch`] call, written straight into the G-buffer layers (no
/// per-slot buffer, no sample-to-pixel map).
fn guide_pass<'a, S: PathSource>(
    source: &S,
    counts: PathCounts<'_>,
    rows: impl IndexedParallelIterator<Item = GuideRow<'a>>,
    w: usize,
    (seed, demod): (u64, bool),
    cancel: &AtomicBool,
) {
    rows.enumerate().for_each_init(
        || (Vec::with_capacity(w), vec![EyeSample::default(); w]),
        |(rays, traced), (y, mut row)| {
            if cancel.load(Ordering::Relaxed) {
                return; // the frame is abandoned
            }
            rays.clear();
            rays.extend((0..w).map(|x| guide_ray(x, y, seed, counts.of(y * w + x))));
            source.trace_batch(rays, traced);
            for (x, e) in traced.iter().enumerate() {
                row.store(x, e, demod);
            }
        },
    );
}

/// Pass 1 with a source that traces one path per call, after Bauszat et al. 2011, §4.3:
/// the per-pixel counts are scanned into sample offsets (`schedule`); each batch fills its
/// sample-to-pixel map, traces its slots in parallel (blocks of [`SLOT_BLOCK`] slots, one
/// [`PathSource::trace_path_batch`] call each) into the per-slot buffer, then each pixel
/// adds its own contiguous slot range in sample order (parallel over pixels, no atomics).
/// Pixels span batches; their sums carry over in `out`. Summing from zero in path order
/// and scaling by `1 / count` last gives what `trace(key, film, count)` gives (the
/// [`PathSource::trace_path`] contract), bit for bit, whatever the batch size and the
/// thread count. Pixels with no path get `trace(key, film, 0)` (first hit, direct).
fn guide_pass_batched<S: PathSource>(
    source: &S,
    schedule: &BatchSchedule,
    bb: &mut BatchBuffers,
    out: &mut [EyeSample],
    w: usize,
    seed: u64,
    cancel: &AtomicBool,
) {
    // Pixels without paths: first hit and direct light (as `trace(.., 0)`), a batch per
    // row. The others are written by the batches (their first path resets the sum).
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let (xs, rays): (Vec<usize>, Vec<EyeRay>) =
            (0..w).filter(|&x| schedule.count(y * w + x) == 0).map(|x| (x, guide_ray(x, y, seed, 0))).unzip();
        let mut traced = vec![EyeSample::default(); rays.len()];
        source.trace_batch(&rays, &mut traced);
        for (x, e) in xs.into_iter().zip(traced) {
            row[x] = e;
        }
    });
    let size = schedule.batch_size().min(schedule.total_samples() as usize);
    bb.slots.resize(size, Slot::default());
    bb.results.resize(size, EyeSample::default());
    for batch in schedule.batches() {
        if cancel.load(Ordering::Relaxed) {
            return; // the frame is abandoned
        }
        let len = batch.len();
        batch.fill_sample_to_pixel(&mut bb.slots);
        // Trace the batch in blocks of slots, in parallel.
        let slots = &bb.slots[..len];
        bb.results[..len].par_chunks_mut(SLOT_BLOCK).zip(slots.par_chunks(SLOT_BLOCK)).for_each(
            |(results, slots)| {
                let paths: Vec<PathSlot> = slots
                    .iter()
                    .map(|s| {
                        let p = s.pixel as usize;
                        let (x, y) = (p % w, p / w);
                        let key = SampleKey { x: x as u32, y: y as u32, sample: 0, seed };
                        PathSlot { key, film: guide_film(x, y), path: s.sample }
                    })
                    .collect();
                source.trace_path_batch(&paths, results);
            },
        );
        reduce_batch(schedule, &batch, bb, out);
    }
}

/// Per-pixel reduction of a batch over each pixel's own slot range, in sample order; a
/// pixel spanning batches carries its sum over in `out`.
fn reduce_batch(
    schedule: &BatchSchedule,
    batch: &filtrace_adaptive::Batch,
    bb: &BatchBuffers,
    out: &mut [EyeSample],
) {
    let first = batch.pixels().start;
    let (slots, results) = (&bb.slots, &bb.results);
    out[batch.pixels()].par_iter_mut().enumerate().for_each(|(i, acc)| {
        let p = first + i;
        for k in batch.slots_of(p) {
            let e = &results[k];
            if slots[k].sample == 0 {
                // The first path names the hit; an escaped ray is final as it is.
                *acc = if e.hit.is_some() {
                    EyeSample { direct: Rgb::ZERO, indirect: Rgb::ZERO, ..*e }
                } else {
                    *e
                };
            }
            if acc.hit.is_some() {
                acc.direct += e.direct;
                acc.indirect += e.indirect;
                // After the pixel's last path: the mean, scaled last as `trace` does.
                let count = schedule.count(p);
                if slots[k].sample + 1 == count {
                    let inv = 1.0 / count as f32;
                    acc.direct *= inv;
                    acc.indirect *= inv;
                }
            }
        }
    });
}

/// Film position of the guide ray of pixel `(x, y)`: the pixel centre.
pub(crate) fn guide_film(x: usize, y: usize) -> Vec2 {
    Vec2::new(x as f32 + 0.5, y as f32 + 0.5)
}

/// One row of the guide layers: the G-buffer, the lookup's geometry, the guide ray's direct
/// light and the (demodulated) indirect map.
struct GuideRow<'a> {
    hits: &'a mut [Option<HitGeometry>],
    direct: &'a mut [Rgb],
    normal: &'a mut [f32],
    depth: &'a mut [f32],
    albedo: &'a mut [f32],
    position: &'a mut [f32],
    coverage: &'a mut [f32],
    map: &'a mut [f32],
}

/// The rows of the guide layers (already sized `w x h`), for a parallel pass.
fn guide_rows<'a>(
    hits: &'a mut [Option<HitGeometry>],
    direct: &'a mut [Rgb],
    im: &'a mut FrameImages,
    w: usize,
) -> impl IndexedParallelIterator<Item = GuideRow<'a>> {
    let g = &mut im.guide;
    (
        hits.par_chunks_mut(w),
        direct.par_chunks_mut(w),
        g.normal.data_mut().par_chunks_mut(3 * w),
        g.depth.data_mut().par_chunks_mut(w),
        g.albedo.data_mut().par_chunks_mut(3 * w),
        g.position.data_mut().par_chunks_mut(3 * w),
        g.coverage.data_mut().par_chunks_mut(w),
        im.indirect_map.data_mut().par_chunks_mut(3 * w),
    )
        .into_par_iter()
        .map(|(hits, direct, normal, depth, albedo, position, coverage, map)| GuideRow {
            hits,
            direct,
            normal,
            depth,
            albedo,
            position,
            coverage,
            map,
        })
}

impl GuideRow<'_> {
    /// Writes guide ray `e` of column `x` into the G-buffer and the (demodulated) indirect map.
    #[inline]
    fn store(&mut self, x: usize, e: &EyeSample, demod: bool) {
        let set = |dst: &mut [f32], c: Rgb| dst[3 * x..3 * x + 3].copy_from_slice(&c.to_array());
        self.hits[x] = e.hit;
        self.direct[x] = e.direct;
        let (n, d) = e.hit.map_or((Rgb::ZERO, 0.0), |h| (h.normal, h.depth));
        // A surface that reflects nothing (a pure emitter, like the Cornell light) has no
        // irradiance estimate: its map entry is 0 by construction, not a sample. Its normal
        // is zeroed in the filter's G-buffer so that filters treat it as background and do
        // not blend that 0 into coplanar neighbours (the ceiling around the light).
        let reflects = !demod || e.albedo.max_element() > 0.0;
        set(self.normal, if reflects { n } else { Rgb::ZERO });
        self.depth[x] = d;
        set(self.albedo, e.albedo);
        set(self.position, e.position);
        self.coverage[x] = if e.hit.is_some() && reflects { 1.0 } else { 0.0 };
        let ind = if demod { e.indirect / (e.albedo + DEMODULATION_EPS) } else { e.indirect };
        debug_assert!(ind.is_finite(), "non-finite indirect light at guide column {x}: {ind}");
        set(self.map, ind);
    }
}

/// Writes the guide rays traced by [`guide_pass_batched`] into the guide layers, rows in
/// parallel.
fn store_guides<'a>(g: &[EyeSample], rows: impl IndexedParallelIterator<Item = GuideRow<'a>>, demod: bool) {
    let w = g.len() / rows.len().max(1);
    rows.zip(g.par_chunks(w.max(1))).for_each(|(mut row, src)| {
        for (x, e) in src.iter().enumerate() {
            row.store(x, e, demod);
        }
    });
}
