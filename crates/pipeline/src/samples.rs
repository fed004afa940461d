//! Passes 3 and 4 of the frame: further eye samples of every pixel (first hit and direct
//! light, jittered in the pixel) and their geometry-aware lookup into the indirect map
//! (Bauszat et al. 2011, §3.2, eqs. 3-5), added to per-pixel sums and box-averaged.

use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use filtrace_core::rng::{splitmix64, unit_f32};
use filtrace_core::{Image, Rgb, Vec2};
use filtrace_render::memory::{try_resize, AllocError};
use rayon::prelude::*;

use crate::buffers::{Buffers, SampleRecord};
use crate::frame::{ms, FrameImages};
use crate::lookup::most_similar_guide;
use crate::settings::{PipelineSettings, DEMODULATION_EPS, SAMPLE_PASS_MAX};
use crate::source::{EyeRay, EyeSample, PathSource, SampleKey};

/// Jitter of further sample `key` inside its pixel, in `[0, 1)^2`: a hash of the key.
fn jitter(key: SampleKey) -> Vec2 {
    let mut h = key.seed ^ 0x243f_6a88_85a3_08d3;
    for v in [key.x as u64, key.y as u64, key.sample as u64] {
        h = splitmix64(h ^ v.wrapping_mul(0x9e37_79b9_7f4a_7c15));
    }
    Vec2::new(unit_f32(h), unit_f32(splitmix64(h)))
}

/// Passes 3 and 4: further samples `1..=extra` of every pixel in passes of sample indices
/// (1, 1, 2, 4, ... up to [`SAMPLE_PASS_MAX`] per pixel), each pass over chunks of at most
/// `chunk` samples: trace a chunk into `buf.samples` ([`trace_samples`]), then add each
/// sample to its pixel's sums ([`lookup_samples`]). The guide ray's own terms start the sums
/// ([`start_sums`]); the box mean is taken last ([`finish_sums`]). Every pixel's sums get
/// its samples in index order whatever the chunk and pass sizes, so the frame is the same
/// bit for bit. A pass cut by `cancel` is undone from a copy of the sums. Returns the
/// milliseconds of tracing and of lookup, the lookup failures and the further samples done.
pub(crate) fn supersample<S: PathSource>(
    source: &S,
    buf: &mut Buffers,
    st: &PipelineSettings,
    chunk: usize,
    cancel: &AtomicBool,
) -> Result<(f64, f64, u64, usize), AllocError> {
    let (w, demod) = (st.width as usize, st.demodulate_albedo);
    let pixels = w * st.height as usize;
    let extra = st.spp as usize - 1;
    let chunk = chunk.clamp(1, (pixels * extra.min(SAMPLE_PASS_MAX)).max(1));
    try_resize(&mut buf.samples, chunk, SampleRecord::default(), "the further samples")?;
    let undo_len = if extra > 0 { pixels * 9 } else { 0 };
    try_resize(&mut buf.undo, undo_len, 0.0, "the copy of the sums for a cancelled pass")?;
    let t = Instant::now();
    start_sums(buf, demod);
    let (mut samples_ms, mut lookup_ms) = (0.0, ms(t));
    let (mut failures, mut done) = (0, 0);
    'passes: while done < extra && !cancel.load(Ordering::Relaxed) {
        let pass = SamplePass { first: done, count: done.clamp(1, SAMPLE_PASS_MAX).min(extra - done) };
        save_sums(buf);
        let total = pixels * pass.count;
        let (mut at, mut pass_failures) = (0, 0);
        while at < total {
            let len = chunk.min(total - at);
            let t = Instant::now();
            let traced = trace_samples(source, &mut buf.samples[..len], at, pass, w, st.seed, cancel);
            samples_ms += ms(t);
            if !traced {
                restore_sums(buf);
                break 'passes;
            }
            let t = Instant::now();
            pass_failures += lookup_samples(buf, at..at + len, pass.count, demod);
            lookup_ms += ms(t);
            at += len;
        }
        failures += pass_failures;
        done += pass.count;
    }
    let t = Instant::now();
    finish_sums(&mut buf.frame.images, done);
    Ok((samples_ms, lookup_ms + ms(t), failures, done))
}

/// Further samples `first + 1 ..= first + count` of every pixel. Sample `r` of a pass is
/// sample `first + r % count + 1` of row-major pixel `r / count`.
#[derive(Clone, Copy)]
struct SamplePass {
    first: usize,
    count: usize,
}

/// The sums a pass adds to (direct, indirect, filtered indirect), copied before it.
fn save_sums(buf: &mut Buffers) {
    let im = &buf.frame.images;
    let n = im.direct.data().len();
    for (k, layer) in [&im.direct, &im.indirect, &im.filtered_indirect].into_iter().enumerate() {
        buf.undo[k * n..(k + 1) * n].copy_from_slice(layer.data());
    }
}

fn restore_sums(buf: &mut Buffers) {
    let im = &mut buf.frame.images;
    let n = im.direct.data().len();
    for (k, layer) in [&mut im.direct, &mut im.indirect, &mut im.filtered_indirect].into_iter().enumerate() {
        layer.data_mut().copy_from_slice(&buf.undo[k * n..(k + 1) * n]);
    }
}

/// Pixels whose samples of a pass make one [`PathSource::trace_batch`] call (one parallel
/// task): per sample index, enough rays for a source tracing in lanes to fill them.
pub const SAMPLE_BLOCK_PIXELS: usize = 128;

/// Pass 3 on samples `first..first + out.len()` of `pass`: first hit and direct light of
/// each further eye ray, jittered in its pixel, in blocks of the samples of
/// [`SAMPLE_BLOCK_PIXELS`] pixels. Returns false, with `out` incomplete, when `cancel` was
/// set (polled per block).
fn trace_samples<S: PathSource>(
    source: &S,
    out: &mut [SampleRecord],
    first: usize,
    pass: SamplePass,
    w: usize,
    seed: u64,
    cancel: &AtomicBool,
) -> bool {
    let block = SAMPLE_BLOCK_PIXELS * pass.count;
    out.par_chunks_mut(block)
        .enumerate()
        .try_for_each_init(
            || (Vec::with_capacity(block), vec![EyeSample::default(); block]),
            |(rays, traced), (b, recs)| {
                if cancel.load(Ordering::Relaxed) {
                    return Err(());
                }
                rays.clear();
                rays.extend((0..recs.len()).map(|k| {
                    let r = first + b * block + k;
                    let (p, s) = (r / pass.count, (pass.first + r % pass.count) as u32 + 1);
                    let key = SampleKey { x: (p % w) as u32, y: (p / w) as u32, sample: s, seed };
                    EyeRay { key, film: Vec2::new(key.x as f32, key.y as f32) + jitter(key), paths: 0 }
                }));
                let traced = &mut traced[..recs.len()];
                source.trace_batch(rays, traced);
                for ((rec, ray), e) in recs.iter_mut().zip(rays.iter()).zip(traced.iter()) {
                    *rec = SampleRecord { film: ray.film, hit: e.hit, albedo: e.albedo, direct: e.direct };
                }
                Ok(())
            },
        )
        .is_ok()
}

/// Factor that re-modulates a demodulated map entry at a sample of albedo `albedo`.
#[inline]
fn remodulation(albedo: Rgb, demod: bool) -> Rgb {
    if demod {
        albedo + DEMODULATION_EPS
    } else {
        Rgb::ONE
    }
}

/// The RGB value of one pixel's 3 values.
#[inline]
fn load(layer: &[f32]) -> Rgb {
    Rgb::new(layer[0], layer[1], layer[2])
}

/// Starts each pixel's sums with its guide ray: its direct light, and its own map entry
/// (unfiltered and filtered) re-modulated by its albedo.
fn start_sums(buf: &mut Buffers, demod: bool) {
    let im = &mut buf.frame.images;
    let (map, fmap, albedo) = (&im.indirect_map, &im.filtered_map, &im.guide.albedo);
    let guide_direct = &buf.guide_direct;
    im.direct
        .data_mut()
        .par_chunks_mut(3)
        .zip(im.indirect.data_mut().par_chunks_mut(3))
        .zip(im.filtered_indirect.data_mut().par_chunks_mut(3))
        .enumerate()
        .for_each(|(own, ((d, ind), find))| {
            let m = remodulation(map_rgb(albedo, own), demod);
            d.copy_from_slice(&guide_direct[own].to_array());
            ind.copy_from_slice(&(m * map_rgb(map, own)).to_array());
            find.copy_from_slice(&(m * map_rgb(fmap, own)).to_array());
        });
}

/// Pass 4 on samples `range` of a pass of `per_pixel` samples per pixel (traced into `buf.samples[..range.len()]`): each
/// sample's direct light, and its indirect light from the unfiltered and the filtered map
/// at the most similar neighbouring guide ray, added to its pixel's sums in sample order.
/// Returns the number of samples whose lookup found no guide that hit.
fn lookup_samples(buf: &mut Buffers, range: Range<usize>, per_pixel: usize, demod: bool) -> u64 {
    let Buffers { guides, samples, frame, .. } = buf;
    let im = &mut frame.images;
    let (map, fmap) = (&im.indirect_map, &im.filtered_map);
    let pixels = range.start / per_pixel..(range.end - 1) / per_pixel + 1;
    let values = pixels.start * 3..pixels.end * 3;
    im.direct.data_mut()[values.clone()]
        .par_chunks_mut(3)
        .zip(im.indirect.data_mut()[values.clone()].par_chunks_mut(3))
        .zip(im.filtered_indirect.data_mut()[values].par_chunks_mut(3))
        .enumerate()
        .map(|(i, ((d, ind), find))| {
            let p = pixels.start + i;
            let own = range.start.max(p * per_pixel)..range.end.min((p + 1) * per_pixel);
            let (mut sd, mut si, mut sf) = (load(d), load(ind), load(find));
            let mut fails = 0u64;
            for rec in &samples[own.start - range.start..own.end - range.start] {
                sd += rec.direct;
                let Some(hit) = &rec.hit else { continue };
                match most_similar_guide(guides, rec.film, hit) {
                    Some(g) => {
                        let m = remodulation(rec.albedo, demod);
                        si += m * map_rgb(map, g);
                        sf += m * map_rgb(fmap, g);
                    }
                    None => fails += 1,
                }
            }
            d.copy_from_slice(&sd.to_array());
            ind.copy_from_slice(&si.to_array());
            find.copy_from_slice(&sf.to_array());
            fails
        })
        .sum()
}

/// Box reconstruction: the sums of `done + 1` samples become means; `noisy` and `color`
/// are direct + unfiltered and direct + filtered indirect.
fn finish_sums(im: &mut FrameImages, done: usize) {
    let inv = 1.0 / (done + 1) as f32;
    im.color
        .data_mut()
        .par_chunks_mut(3)
        .zip(im.noisy.data_mut().par_chunks_mut(3))
        .zip(im.direct.data_mut().par_chunks_mut(3))
        .zip(im.indirect.data_mut().par_chunks_mut(3))
        .zip(im.filtered_indirect.data_mut().par_chunks_mut(3))
        .for_each(|((((color, noisy), direct), indirect), filtered)| {
            let (d, ind, find) = (load(direct) * inv, load(indirect) * inv, load(filtered) * inv);
            direct.copy_from_slice(&d.to_array());
            indirect.copy_from_slice(&ind.to_array());
            filtered.copy_from_slice(&find.to_array());
            noisy.copy_from_slice(&(d + ind).to_array());
            color.copy_from_slice(&(d + find).to_array());
        });
}

#[inline]
fn map_rgb(map: &Image, i: usize) -> Rgb {
    let p = &map.data()[i * 3..i * 3 + 3];
    Rgb::new(p[0], p[1], p[2])
}
