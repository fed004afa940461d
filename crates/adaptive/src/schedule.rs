//! Sample generation in batches (Bauszat et al. 2011, §4.3).
//!
//! The per-pixel counts are turned once into a *sample-offset buffer* by an
//! exclusive prefix scan: pixel `p` owns the global sample indices
//! `offsets[p] .. offsets[p + 1]`. Samples are then processed in batches of a fixed
//! size (the paper uses a resolution-sized buffer, the one that also holds the
//! primary rays). For each batch a *sample-to-pixel buffer* maps every slot to its
//! pixel; it is filled in parallel with one task per pixel, as in the paper. Because
//! the slots of one pixel are contiguous, results are accumulated per pixel without
//! atomics or locks: each pixel reduces its own slot range ([`Batch::accumulate`]).
//!
//! A slot carries `(pixel, sample index within the pixel)`, which is a stable name of
//! the sample independent of the batch size: seed random numbers with it and the
//! frame is the same for any batch size and thread count.
//!
//! Used for indirect-light samples at the guide-ray hit points (the paper's setting),
//! or for pixel-domain samples (camera rays).

use crate::{AdaptiveError, SampleCounts};
use rayon::prelude::*;
use std::ops::{AddAssign, Range};

/// Batch size used by the paper: one slot per pixel of the frame.
pub fn resolution_batch(counts: &SampleCounts) -> usize {
    counts.counts().len().max(1)
}

/// Exclusive prefix sum: `out[0] = 0`, `out[i + 1] = out[i] + counts[i]`
/// (length `counts.len() + 1`; the last entry is the total). Sequential reference.
pub fn exclusive_scan(counts: &[u32]) -> Vec<u64> {
    let mut out = Vec::with_capacity(counts.len() + 1);
    let mut acc = 0u64;
    out.push(0);
    for &c in counts {
        acc += c as u64;
        out.push(acc);
    }
    out
}

/// Block size of the parallel scan: 64 Ki counts keep each block in L2.
const SCAN_BLOCK: usize = 1 << 16;

/// [`exclusive_scan`] in parallel (Blelloch-style three phases over blocks: block
/// sums in parallel, a sequential scan of the few block sums, then each block scanned
/// from its offset in parallel). Same output as the sequential scan.
pub fn exclusive_scan_parallel(counts: &[u32]) -> Vec<u64> {
    if counts.len() <= SCAN_BLOCK {
        return exclusive_scan(counts);
    }
    // Phase 1: sum of each block.
    let sums: Vec<u64> = counts.par_chunks(SCAN_BLOCK).map(|b| b.iter().map(|&c| c as u64).sum()).collect();
    // Phase 2: exclusive scan of the block sums.
    let mut starts = Vec::with_capacity(sums.len());
    let mut acc = 0u64;
    for s in &sums {
        starts.push(acc);
        acc += s;
    }
    // Phase 3: each block from its start. out[i] for i in block b, plus the total.
    let mut out = vec![0u64; counts.len() + 1];
    out[..counts.len()]
        .par_chunks_mut(SCAN_BLOCK)
        .zip(counts.par_chunks(SCAN_BLOCK))
        .zip(starts.par_iter())
        .for_each(|((o, c), &start)| {
            let mut a = start;
            for (o, &c) in o.iter_mut().zip(c) {
                *o = a;
                a += c as u64;
            }
        });
    out[counts.len()] = acc;
    out
}

/// One slot of a batch: which pixel, and which of that pixel's samples.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Slot {
    pub pixel: u32,
    /// Index of this sample among the pixel's samples, `0..count[pixel]`.
    pub sample: u32,
}

/// The sample-offset buffer and the batch layout of one frame.
#[derive(Clone, Debug)]
pub struct BatchSchedule {
    offsets: Vec<u64>,
    batch_size: usize,
}

impl BatchSchedule {
    /// Scans `counts` into sample offsets; batches hold `batch_size` (> 0) slots.
    pub fn new(counts: &SampleCounts, batch_size: usize) -> Result<Self, AdaptiveError> {
        Self::from_counts(counts.counts(), batch_size)
    }

    /// As [`BatchSchedule::new`], from raw per-pixel counts.
    pub fn from_counts(counts: &[u32], batch_size: usize) -> Result<Self, AdaptiveError> {
        if batch_size == 0 {
            return Err(AdaptiveError::InvalidParameter {
                name: "batch_size",
                value: "0".into(),
                expected: "> 0",
            });
        }
        if counts.len() > u32::MAX as usize {
            return Err(AdaptiveError::Overflow);
        }
        Ok(Self { offsets: exclusive_scan_parallel(counts), batch_size })
    }

    /// The sample-offset buffer: `pixel_count() + 1` entries, the last is the total.
    pub fn offsets(&self) -> &[u64] {
        &self.offsets
    }
    pub fn pixel_count(&self) -> usize {
        self.offsets.len() - 1
    }
    pub fn total_samples(&self) -> u64 {
        *self.offsets.last().expect("offsets has pixel_count + 1 entries")
    }
    pub fn batch_size(&self) -> usize {
        self.batch_size
    }
    /// Samples of `pixel`.
    pub fn count(&self, pixel: usize) -> u32 {
        (self.offsets[pixel + 1] - self.offsets[pixel]) as u32
    }
    pub fn num_batches(&self) -> usize {
        self.total_samples().div_ceil(self.batch_size as u64) as usize
    }

    /// The pixel owning global sample `g < total_samples()` (binary search in the offsets).
    pub fn pixel_of(&self, g: u64) -> usize {
        // Last p with offsets[p] <= g; pixels with zero samples share offsets and are skipped.
        self.offsets.partition_point(|&o| o <= g) - 1
    }

    /// Batch `index < num_batches()`.
    pub fn batch(&self, index: usize) -> Batch<'_> {
        let start = index as u64 * self.batch_size as u64;
        let end = (start + self.batch_size as u64).min(self.total_samples());
        debug_assert!(start < end, "batch {index} is out of range");
        let first_pixel = self.pixel_of(start);
        let end_pixel = self.pixel_of(end - 1) + 1;
        Batch { schedule: self, index, start, len: (end - start) as usize, first_pixel, end_pixel }
    }

    /// All batches in order.
    pub fn batches(&self) -> impl Iterator<Item = Batch<'_>> + '_ {
        (0..self.num_batches()).map(|i| self.batch(i))
    }
}

/// One batch: the global samples `start .. start + len`.
#[derive(Clone, Copy, Debug)]
pub struct Batch<'a> {
    schedule: &'a BatchSchedule,
    index: usize,
    start: u64,
    len: usize,
    first_pixel: usize,
    end_pixel: usize,
}

impl<'a> Batch<'a> {
    pub fn index(&self) -> usize {
        self.index
    }
    /// Global index of the first sample.
    pub fn start(&self) -> u64 {
        self.start
    }
    /// Number of slots in use (`batch_size`, less in the last batch).
    pub fn len(&self) -> usize {
        self.len
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    /// Pixels with at least one slot in this batch (and zero-sample pixels between them).
    pub fn pixels(&self) -> Range<usize> {
        self.first_pixel..self.end_pixel
    }

    /// Slots of `pixel` in this batch, as a range of slot indices (empty if none).
    pub fn slots_of(&self, pixel: usize) -> Range<usize> {
        let o = &self.schedule.offsets;
        let end = self.start + self.len as u64;
        let a = o[pixel].clamp(self.start, end);
        let b = o[pixel + 1].clamp(self.start, end);
        (a - self.start) as usize..(b - self.start) as usize
    }

    /// Fills the sample-to-pixel buffer (`out.len() >= len()`), one parallel task per
    /// pixel as in the paper.
    pub fn fill_sample_to_pixel(&self, out: &mut [Slot]) {
        assert!(out.len() >= self.len, "sample-to-pixel buffer smaller than the batch");
        // Disjoint, ordered slot ranges per pixel: split the buffer into per-pixel
        // chunks sequentially (cheap), fill them in parallel.
        let mut rest = &mut out[..self.len];
        let mut chunks = Vec::with_capacity(self.end_pixel - self.first_pixel);
        for p in self.pixels() {
            let r = self.slots_of(p);
            let (head, tail) = rest.split_at_mut(r.len());
            rest = tail;
            chunks.push((p, r, head));
        }
        chunks.into_par_iter().for_each(|(p, r, chunk)| {
            let first_sample = (self.start + r.start as u64 - self.schedule.offsets[p]) as u32;
            for (k, slot) in chunk.iter_mut().enumerate() {
                *slot = Slot { pixel: p as u32, sample: first_sample + k as u32 };
            }
        });
    }

    /// The slots of this batch in order.
    pub fn slots(&self) -> impl Iterator<Item = Slot> + 'a {
        let (s, start, len) = (self.schedule, self.start, self.len as u64);
        let mut pixel = self.first_pixel;
        (start..start + len).map(move |g| {
            while s.offsets[pixel + 1] <= g {
                pixel += 1;
            }
            Slot { pixel: pixel as u32, sample: (g - s.offsets[pixel]) as u32 }
        })
    }

    /// Adds the results of this batch (`values[slot]`, `values.len() >= len()`) into
    /// per-pixel sums (`sums.len() == pixel_count()`). Race-free without atomics:
    /// parallel over pixels, each adds its own contiguous slot range.
    pub fn accumulate<T>(&self, values: &[T], sums: &mut [T])
    where
        T: Copy + AddAssign + Send + Sync,
    {
        assert!(values.len() >= self.len, "fewer values than slots");
        assert_eq!(sums.len(), self.schedule.pixel_count(), "sums must have one entry per pixel");
        let first = self.first_pixel;
        sums[self.pixels()].par_iter_mut().enumerate().for_each(|(i, sum)| {
            for v in &values[self.slots_of(first + i)] {
                *sum += *v;
            }
        });
    }
}
