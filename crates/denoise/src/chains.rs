//! The parallel work of one À-Trous level ([`crate::symmetric`]): segments of its row
//! chains `c, c + step, c + 2 step, ...`, and the output rows each segment writes.
//!
//! Taps of a level connect only rows `step` apart, so every chain is independent of the
//! others, and a segment of a chain needs two rows of start-up (the weight rows of the two
//! chain rows before it). Bands of consecutive rows cost `2 step` start-up rows each and have
//! to be at least `8 step` rows high to keep that share small, so the coarse levels
//! (step 8, 16) would run as 8-16 bands with a quarter of extra weight rows, too few for
//! many cores (docs/perf-filters.md). Chain segments cost two rows at every step width, and there are
//! as many as the threads need. Every pixel's result is independent of the split.

/// A segment of a chain: output rows `first, first + step, ...`, `rows` of them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Segment {
    pub first: usize,
    pub rows: usize,
}

/// Fewest chain rows per segment (beside a chain's last one): each costs two start-up rows.
const MIN_SEGMENT_ROWS: usize = 8;

/// The segments of a level of `h` rows with step width `step`, cut for `threads` threads;
/// one thread walks each chain whole, as one band did.
pub(crate) fn segments(h: usize, step: usize, threads: usize) -> Vec<Segment> {
    let chains = step.clamp(1, h.max(1));
    let longest = h.div_ceil(chains);
    let seg_rows = longest.div_ceil(segments_per_chain(chains, longest, threads));
    let mut v = Vec::new();
    for c in 0..chains {
        let len = (h - c).div_ceil(step);
        let mut k = 0;
        while k < len {
            let rows = seg_rows.min(len - k);
            v.push(Segment { first: c + k * step, rows });
            k += rows;
        }
    }
    v
}

/// Segments per chain: enough for every thread, a multiple of the thread count in all when
/// the chains allow it (equal tasks, no idle round), else about four tasks per thread.
fn segments_per_chain(chains: usize, longest: usize, threads: usize) -> usize {
    if threads <= 1 {
        return 1;
    }
    let even = threads.div_ceil(chains);
    let m = if (chains * even).is_multiple_of(threads) { even } else { (4 * threads).div_ceil(chains) };
    m.min(longest.div_ceil(MIN_SEGMENT_ROWS)).max(1)
}

/// Per segment, its rows of `plane` (`stride` values per row), in chain order.
pub(crate) fn rows_of<'a>(
    plane: &'a mut [f32],
    stride: usize,
    step: usize,
    segs: &[Segment],
) -> Vec<Vec<&'a mut [f32]>> {
    let mut slots: Vec<Option<&mut [f32]>> = plane.chunks_mut(stride).map(Some).collect();
    segs.iter()
        .map(|s| {
            (0..s.rows).map(|k| slots[s.first + k * step].take().expect("rows of one segment")).collect()
        })
        .collect()
}

/// The rows of one segment that the gather writes: a separate instance of the level's loop
/// per kind, so that the planes' loop compiles as before (one `match` inside it made every
/// level ~8% slower).
pub(crate) trait Sink: Send {
    /// Number of rows of the segment.
    fn rows(&self) -> usize;
    /// The three output rows of segment row `r` (at least `width` values each).
    fn row(&mut self, r: usize) -> [&mut [f32]; 3];
    /// Called once segment row `r` is written.
    fn done(&mut self, r: usize);
}

/// Rows of three planes (the input of the next level).
pub(crate) struct PlanesSink<'a> {
    pub rows: Vec<[&'a mut [f32]; 3]>,
}

impl<'a> PlanesSink<'a> {
    /// One sink per segment over the planes `d` (`stride` values per row).
    pub fn per_segment(d: [&'a mut [f32]; 3], stride: usize, step: usize, segs: &[Segment]) -> Vec<Self> {
        let [r0, r1, r2] = d.map(|p| rows_of(p, stride, step, segs));
        r0.into_iter()
            .zip(r1)
            .zip(r2)
            .map(|((a, b), c)| Self {
                rows: a.into_iter().zip(b).zip(c).map(|((a, b), c)| [a, b, c]).collect(),
            })
            .collect()
    }
}

impl Sink for PlanesSink<'_> {
    #[inline(always)]
    fn rows(&self) -> usize {
        self.rows.len()
    }
    #[inline(always)]
    fn row(&mut self, r: usize) -> [&mut [f32]; 3] {
        let [o0, o1, o2] = &mut self.rows[r];
        [&mut o0[..], &mut o1[..], &mut o2[..]]
    }
    #[inline(always)]
    fn done(&mut self, _: usize) {}
}

/// Interleaved RGB rows of `width` pixels: the last level writes the output image directly
/// (each row gathered into three row buffers, then interleaved while they are in L1).
pub(crate) struct RgbSink<'a> {
    pub rows: Vec<&'a mut [f32]>,
    pub width: usize,
    pub tmp: [Vec<f32>; 3],
}

impl Sink for RgbSink<'_> {
    #[inline(always)]
    fn rows(&self) -> usize {
        self.rows.len()
    }
    #[inline(always)]
    fn row(&mut self, _: usize) -> [&mut [f32]; 3] {
        let [t0, t1, t2] = &mut self.tmp;
        [&mut t0[..], &mut t1[..], &mut t2[..]]
    }
    #[inline(always)]
    fn done(&mut self, r: usize) {
        let [t0, t1, t2] = &self.tmp;
        for (i, px) in self.rows[r][..3 * self.width].chunks_exact_mut(3).enumerate() {
            px[0] = t0[i];
            px[1] = t1[i];
            px[2] = t2[i];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every row belongs to exactly one segment, segments follow their chain, and the
    /// split gives each thread work.
    #[test]
    fn segments_cover_every_row_once() {
        for h in [1, 2, 7, 64, 131, 1080] {
            for step in [1, 2, 4, 8, 16, 32, 512] {
                for threads in [1, 2, 3, 7, 16, 64] {
                    let segs = segments(h, step, threads);
                    let mut seen = vec![0u8; h];
                    for s in &segs {
                        assert!(s.rows > 0);
                        for k in 0..s.rows {
                            seen[s.first + k * step] += 1;
                        }
                    }
                    assert!(seen.iter().all(|&n| n == 1), "h {h} step {step} threads {threads}");
                    if threads == 1 {
                        assert_eq!(segs.len(), step.min(h), "one segment per chain on one thread");
                    } else if h >= threads * MIN_SEGMENT_ROWS * 2 {
                        assert!(segs.len() >= threads, "h {h} step {step} threads {threads}: {}", segs.len());
                    }
                }
            }
        }
    }
}
