//! The samples each record has seen during a frame, kept across the frame's passes for the
//! `optimized` sampler (He and Owen 2014: the optimiser's pilot sample grows with every
//! pass). G(α', β) can be estimated at any parameters from samples drawn with any
//! mixture q0 > 0 (each carries its own `1/q0`), so the samples of earlier passes stay
//! valid after the parameters moved: the per-record objective, gradient and Hessian are
//! recomputed at the current parameters over all of them, not averaged from stale ones.
//!
//! Memory is bounded by `capacity` samples per record: beyond it a reservoir keeps a
//! uniform random subset of every sample that arrived (Vitter's algorithm R), with random
//! numbers hashed from (record, arrival number), so the kept set depends only on the order
//! of the feedback, never on the thread count.

use super::feedback::SampleFeedback;
use super::TECHNIQUES;
use filtrace_core::rng::splitmix64;
use rayon::prelude::*;

/// One sample as its record keeps it: what G needs, with the record's interpolation weight.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StoredSample {
    /// `P_k(j)`.
    pub pmf: [f32; TECHNIQUES],
    /// `Q_k(j)`.
    pub cv: [f32; TECHNIQUES],
    /// `1 / q0(j)`.
    pub inv_pdf: f32,
    /// Luminance of f(j).
    pub value: f32,
    /// The record's interpolation weight `w_i` at the sample's shading point.
    pub weight: f32,
}

/// Per record, the samples kept so far this frame.
#[derive(Clone, Debug, Default)]
pub struct SampleHistory {
    records: Vec<RecordSamples>,
    capacity: usize,
    /// [`SampleHistory::add_parts`]'s per-record lists, kept so that a frame's passes
    /// (and, after [`SampleHistory::reset`], its next frames) reuse their memory.
    arrivals: Arrivals,
}

/// A pass's feedback entries grouped by record (compressed rows): record `l`'s entries
/// are `list[start[l]..start[l + 1]]`, each (part, index in it, weight), in feedback order.
#[derive(Clone, Debug, Default)]
struct Arrivals {
    start: Vec<usize>,
    list: Vec<(u32, u32, f32)>,
}

/// A record's mixture and control-variate weights `(α', β)`.
pub(crate) type Weights = ([f32; TECHNIQUES], [f32; TECHNIQUES]);

#[derive(Clone, Debug, Default)]
struct RecordSamples {
    kept: Vec<StoredSample>,
    /// Samples that arrived (kept or not).
    seen: u64,
    /// The weights the last optimisation step kept on exactly these samples.
    settled: Option<Weights>,
}

impl SampleHistory {
    /// An empty history of `records` records keeping at most `capacity` samples each.
    pub fn new(records: usize, capacity: usize) -> Self {
        SampleHistory {
            records: vec![RecordSamples::default(); records],
            capacity: capacity.max(1),
            arrivals: Arrivals::default(),
        }
    }

    /// Empties the history for a frame of `records` records keeping at most `capacity`
    /// samples each, as [`SampleHistory::new`] would, but keeping the memory of the
    /// records it had (a sequence's frames usually have the same records).
    pub fn reset(&mut self, records: usize, capacity: usize) {
        self.records.truncate(records);
        self.records.iter_mut().for_each(RecordSamples::clear);
        self.records.resize_with(records, RecordSamples::default);
        self.capacity = capacity.max(1);
    }

    /// Number of records.
    pub fn len(&self) -> usize {
        self.records.len()
    }

    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    /// The samples record `l` keeps.
    pub fn samples(&self, l: usize) -> &[StoredSample] {
        self.records.get(l).map_or(&[], |r| &r.kept)
    }

    /// Samples that arrived at record `l` (kept or not).
    pub fn seen(&self, l: usize) -> u64 {
        self.records.get(l).map_or(0, |r| r.seen)
    }

    /// The weights the last step of [`super::ImportanceCache::optimize_pass`] kept on
    /// record `l`'s current samples (`None` once new samples arrived).
    pub(crate) fn settled(&self, l: usize) -> Option<Weights> {
        self.records.get(l).and_then(|r| r.settled)
    }

    /// Notes that a step kept record `l`'s weights on its current samples.
    pub(crate) fn settle(&mut self, l: usize, weights: Weights) {
        if let Some(r) = self.records.get_mut(l) {
            r.settled = Some(weights);
        }
    }

    /// Adds a pass's feedback, which must come in a fixed order (pixel order): each record
    /// sees its samples in that order. Records out of range and zero weights are skipped.
    pub fn add(&mut self, feedback: &[SampleFeedback]) {
        self.add_parts(&[feedback]);
    }

    /// [`SampleHistory::add`] of the parts' feedback one after the other (e.g. per tile,
    /// in tile order), without gathering it into one list first.
    pub fn add_parts(&mut self, parts: &[&[SampleFeedback]]) {
        let arrivals = &mut self.arrivals;
        arrivals.group(parts, self.records.len());
        let (capacity, arrivals) = (self.capacity, &self.arrivals);
        self.records.par_iter_mut().enumerate().with_min_len(16).for_each(|(l, record)| {
            let list = arrivals.of(l);
            // One allocation per record and frame: the samples it will keep are known.
            let keep = (record.kept.len() + list.len()).min(capacity);
            record.kept.reserve_exact(keep - record.kept.len());
            for &(p, i, weight) in list {
                let fb = &parts[p as usize][i as usize];
                let s = StoredSample { pmf: fb.pmf, cv: fb.cv, inv_pdf: fb.inv_pdf, value: fb.value, weight };
                record.push(s, l, capacity);
            }
        });
    }
}

impl Arrivals {
    /// Groups the parts' entries `(record, weight)` by record (a counting sort, stable),
    /// skipping records out of `0..records` and zero weights.
    fn group(&mut self, parts: &[&[SampleFeedback]], records: usize) {
        let n = records;
        let start = &mut self.start;
        start.clear();
        start.resize(n + 1, 0);
        for fb in parts.iter().flat_map(|fbs| fbs.iter()) {
            for (l, w) in fb.records() {
                if l < n && w > 0.0 {
                    start[l + 1] += 1;
                }
            }
        }
        for l in 0..n {
            start[l + 1] += start[l];
        }
        // Filled at `start[l]`, which moves to `start[l + 1]`; shifted back after.
        self.list.clear();
        self.list.resize(start[n], (0, 0, 0.0));
        for (p, fbs) in parts.iter().enumerate() {
            for (i, fb) in fbs.iter().enumerate() {
                for (l, w) in fb.records() {
                    if l < n && w > 0.0 {
                        self.list[start[l]] = (p as u32, i as u32, w);
                        start[l] += 1;
                    }
                }
            }
        }
        start.copy_within(0..n, 1);
        start[0] = 0;
    }

    /// Record `l`'s entries.
    fn of(&self, l: usize) -> &[(u32, u32, f32)] {
        &self.list[self.start[l]..self.start[l + 1]]
    }
}

impl RecordSamples {
    fn clear(&mut self) {
        self.kept.clear();
        self.seen = 0;
        self.settled = None;
    }

    /// Algorithm R: the first `capacity` samples are kept; arrival `n` then replaces a
    /// uniformly chosen slot with probability `capacity / (n + 1)`.
    fn push(&mut self, s: StoredSample, record: usize, capacity: usize) {
        self.settled = None;
        let n = self.seen;
        self.seen += 1;
        if self.kept.len() < capacity {
            self.kept.push(s);
            return;
        }
        let slot = splitmix64(((record as u64) << 40) ^ n) % (n + 1);
        if (slot as usize) < capacity {
            self.kept[slot as usize] = s;
        }
    }
}
