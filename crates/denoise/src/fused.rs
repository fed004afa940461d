//! Two box passes of [`crate::stripbox`] fused into one walk down the rows: the second pass
//! (the guided filter's averaging of the per-window coefficients) consumes the rows of the
//! first (the coefficients) while they are in cache, from a ring of `2r + 2` rows, instead
//! of the first writing a whole plane that the second reads back twice (at 1080p with 4
//! guidance channels, 16 floats per pixel: 133 MB written, 266 MB read).
//!
//! # Same bits as the two passes
//! Each pass keeps its chains: its bands ([`band_rows`]) start where they started, from the
//! direct sum of their first window, and slide row by row in the same order. Only *when* a
//! row of the first pass is computed changes, not how. A walk covers a *run* of whole bands
//! and needs the first pass's rows `r` before and after its own: the rows after are the
//! start of the next band's chain (recomputed by the walk, `3r + 1` row updates); the rows
//! before are the end of the previous band's chain, which only the previous run computes.
//! So every run but the first leaves its first band's second pass for later: it stores the
//! first pass's rows that band needs (its own rows and `r` after), the previous run stores
//! its last `r` rows next to them, and once all walks are done those bands run from the
//! stored rows.
//!
//! # When
//! One run per thread, while the threads are fewer than the bands and whole bands are
//! used ([`fused_runs`]). With more threads, the bands are cut into sub-bands replayed from
//! stored column sums; the second pass's replay needs the whole band of coefficients first,
//! so there the two passes run one after the other over the whole plane.
//!
//! # Memory
//! Per run: a ring of `min(2r + 2, h)` rows of the first pass's output and the two passes'
//! column sums; per run after the first, one band and `2r` rows of the first pass's output.
//! One thread: the ring only (1080p, 4 channels, r = 32: 8 MB instead of the 133 MB plane).

use crate::pool::Buf;
use crate::simd::Isa;
use crate::stripbox::{band_isa, band_rows, sub_band_rows, Cursor, StripPass, Strips};
use rayon::prelude::*;

/// Rows `y` of a plane of `row` values each, stored at slot `(y - base) % n` of `data`: the
/// whole plane (`base` 0), a block of it starting at row `base`, or a ring of the last `n`
/// rows.
#[derive(Clone, Copy)]
pub(crate) struct Rows<'a> {
    data: &'a [f32],
    row: usize,
    base: usize,
    n: usize,
}

impl<'a> Rows<'a> {
    /// Rows `base..` stored one after the other.
    pub fn block(data: &'a [f32], row: usize, base: usize) -> Self {
        Self { data, row, base, n: usize::MAX }
    }

    /// The last `n` rows, row `y` at slot `y % n`.
    fn ring(data: &'a [f32], row: usize, n: usize) -> Self {
        Self { data, row, base: 0, n }
    }

    #[inline(always)]
    pub fn get(&self, y: usize) -> &'a [f32] {
        let s = (y - self.base) % self.n;
        &self.data[s * self.row..(s + 1) * self.row]
    }
}

/// A box pass whose per-pixel quantities are read from [`Rows`] of another pass's output.
pub(crate) trait OnRows<const K: usize>: Sync {
    type Pass<'r>: StripPass<K>
    where
        Self: 'r;
    /// The pass reading `rows`.
    fn on<'r>(&'r self, rows: Rows<'r>) -> Self::Pass<'r>;
}

/// Number of runs for `threads` threads when the passes are fused, `None` when they run one
/// after the other (see the module docs).
pub(crate) fn fused_runs(st: &Strips, threads: usize) -> Option<usize> {
    let rows = band_rows(st.h, st.r);
    let bands = st.h.div_ceil(rows);
    if threads <= 1 {
        Some(1)
    } else if threads < bands && sub_band_rows(st.h, rows, threads) == rows {
        Some(threads)
    } else {
        None
    }
}

/// The two passes fused: `second`'s window sums over the rows of `first`'s output (`mid`
/// values per row), written into `out` (`row_len` values per row); `runs` walks in parallel.
/// Bit-identical to [`crate::stripbox::strip_box_sums`] of `first` into a plane, then of
/// `second` over it, for any `runs`.
pub(crate) fn fused_box_sums<const K1: usize, const K2: usize, P1, P2>(
    st: &Strips,
    (first, mid): (&P1, usize),
    second: &P2,
    (out, row_len): (&mut [f32], usize),
    runs: usize,
    isa: Isa,
) where
    P1: StripPass<K1>,
    P2: OnRows<K2>,
{
    assert_eq!(out.len(), st.h * row_len, "fused_box_sums: output size");
    if st.w == 0 || st.h == 0 {
        return;
    }
    let rows = band_rows(st.h, st.r);
    let bands = st.h.div_ceil(rows);
    let runs = runs.clamp(1, bands);
    let b0 = |k: usize| k * bands / runs;
    let y0 = |k: usize| (b0(k) * rows).min(st.h);
    // Per run after the first: the first pass's rows its first band needs, from `r` before
    // it (written by the previous run) to `r` after it.
    let mut kept: Vec<(usize, Buf)> = (1..runs)
        .map(|k| {
            let from = y0(k) - st.r.min(y0(k));
            let to = (y0(k) + rows + st.r).min(st.h);
            (from, Buf::uninit((to - from) * mid))
        })
        .collect();
    let mut walks = Vec::with_capacity(runs);
    let mut deferred = Vec::with_capacity(runs);
    let (mut rest, mut kept_rest) = (out, &mut kept[..]);
    let mut head: Option<&mut [f32]> = None;
    for k in 0..runs {
        let (run_out, more) = rest.split_at_mut((y0(k + 1) - y0(k)) * row_len);
        rest = more;
        let (walk_out, keep) = if k == 0 {
            (run_out, None)
        } else {
            let band = (rows.min(st.h - y0(k))) * row_len;
            let (d, w) = run_out.split_at_mut(band);
            deferred.push(d);
            (w, head.take())
        };
        let tail = match std::mem::take(&mut kept_rest).split_first_mut() {
            Some(((from, buf), more)) => {
                kept_rest = more;
                let (t, h) = buf.split_at_mut((y0(k + 1) - *from) * mid);
                head = Some(h);
                Some(t)
            }
            None => None,
        };
        walks.push(Walk { bands: (b0(k), b0(k + 1)), keep, tail, out: walk_out });
    }
    walks.into_par_iter().for_each(|walk| walk_isa(st, (rows, mid, row_len), walk, first, second, isa));
    deferred.into_par_iter().zip(kept.par_iter()).enumerate().for_each(|(i, (out, (from, buf)))| {
        let pass = second.on(Rows::block(&buf[..], mid, *from));
        band_isa::<K2, _>(st, y0(i + 1), None, out, row_len, &pass, isa)
    });
}

/// One run of bands `bands.0..bands.1`: the first pass's rows from the run's first row to
/// `r` after its last, the second pass's rows of every band but the first when `keep` is
/// given.
struct Walk<'a> {
    bands: (usize, usize),
    /// The first pass's rows of the first band and `r` after, for its later second pass.
    keep: Option<&'a mut [f32]>,
    /// The first pass's last `r` rows of the run, for the next run's first band.
    tail: Option<&'a mut [f32]>,
    /// The second pass's rows of the bands the walk covers.
    out: &'a mut [f32],
}

/// The first pass of a walk, computed row by row on demand into the ring.
struct Producer<'a, const K1: usize> {
    cur: Option<Cursor<K1>>,
    /// Next row to compute, first row of the run, its end, end of the rows computed.
    next: usize,
    start: usize,
    run_end: usize,
    end: usize,
    keep: Option<&'a mut [f32]>,
    tail: Option<&'a mut [f32]>,
}

impl<const K1: usize> Producer<'_, K1> {
    /// Computes the rows up to `t` (at most to the end) into `ring` (`n` rows of `mid`), and
    /// copies those the deferred bands need.
    #[inline(always)]
    fn through<P1: StripPass<K1>>(
        &mut self,
        st: &Strips,
        (rows, mid, n): (usize, usize, usize),
        t: usize,
        ring: &mut [f32],
        first: &P1,
    ) {
        while self.next <= t.min(self.end - 1) {
            let y = self.next;
            if y.is_multiple_of(rows) {
                self.cur = Some(Cursor::new(st, y, (y + rows).min(st.h), None, first));
            }
            let row = &mut ring[(y % n) * mid..(y % n + 1) * mid];
            self.cur.as_mut().expect("a walk starts at a band").row(st, row, first);
            let at = |buf: &mut [f32], from: usize| {
                let i = y.wrapping_sub(from);
                if i < buf.len() / mid {
                    buf[i * mid..(i + 1) * mid].copy_from_slice(row);
                }
            };
            if let Some(keep) = self.keep.as_deref_mut() {
                at(keep, self.start);
            }
            if let Some(tail) = self.tail.as_deref_mut() {
                let from = self.run_end - tail.len() / mid;
                at(tail, from);
            }
            self.next += 1;
        }
    }
}

/// [`Walk`]: the first pass runs ahead of the second by `r + 1` rows; the ring holds the
/// `2r + 2` rows from the one leaving the second pass's window to the one entering it.
#[inline(always)]
fn walk<const K1: usize, const K2: usize, P1: StripPass<K1>, P2: OnRows<K2>>(
    st: &Strips,
    (rows, mid, row_len): (usize, usize, usize),
    w: Walk,
    first: &P1,
    second: &P2,
) {
    let (r, h) = (st.r, st.h);
    let (start, run_end) = (w.bands.0 * rows, (w.bands.1 * rows).min(h));
    let n = (2 * r + 2).min(h);
    let mut ring = Buf::uninit(n * mid);
    let deferred = w.keep.is_some();
    let end = (run_end + r).min(h);
    let mut p = Producer { cur: None, next: start, start, run_end, end, keep: w.keep, tail: w.tail };
    let geo = (rows, mid, n);
    let from = if deferred { (start + rows).min(run_end) } else { start };
    let mut out_rows = w.out.chunks_exact_mut(row_len);
    for b0 in (from..run_end).step_by(rows) {
        let b1 = (b0 + rows).min(h);
        p.through(st, geo, b0 + r, &mut ring, first);
        let mut cur = Cursor::<K2>::new(st, b0, b1, None, &second.on(Rows::ring(&ring, mid, n)));
        for _ in b0..b1 {
            p.through(st, geo, cur.y() + r + 1, &mut ring, first);
            let out_row = out_rows.next().expect("output rows of the walk");
            cur.row(st, out_row, &second.on(Rows::ring(&ring, mid, n)));
        }
    }
    // A walk whose only band is deferred still computes the rows the next run needs.
    p.through(st, geo, end, &mut ring, first);
}

/// [`walk`] compiled for each instruction set (the same operations in each).
macro_rules! walk_build {
    ($name:ident, $feat:literal) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $feat)]
        unsafe fn $name<const K1: usize, const K2: usize, P1: StripPass<K1>, P2: OnRows<K2>>(
            st: &Strips,
            geo: (usize, usize, usize),
            w: Walk,
            first: &P1,
            second: &P2,
        ) {
            walk::<K1, K2, P1, P2>(st, geo, w, first, second)
        }
    };
}
walk_build!(walk_avx2, "avx2,fma");
walk_build!(walk_avx512, "avx512f,avx2,fma");

fn walk_isa<const K1: usize, const K2: usize, P1: StripPass<K1>, P2: OnRows<K2>>(
    st: &Strips,
    geo: (usize, usize, usize),
    w: Walk,
    first: &P1,
    second: &P2,
    isa: Isa,
) {
    #[cfg(target_arch = "x86_64")]
    match isa {
        // SAFETY: as in `stripbox::band_isa`.
        Isa::Avx512 => return unsafe { walk_avx512::<K1, K2, P1, P2>(st, geo, w, first, second) },
        Isa::Avx2 => return unsafe { walk_avx2::<K1, K2, P1, P2>(st, geo, w, first, second) },
        Isa::Base => {}
    }
    let _ = isa;
    walk::<K1, K2, P1, P2>(st, geo, w, first, second)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simd::isa;
    use crate::stripbox::{strip_box_sums, S, V};

    /// First pass: window sums of two quantities of a row-major image, written per row as
    /// `len` positions of 2 vectors (the lane layout of the guided filter's coefficients).
    struct Sums<'a> {
        st: Strips,
        data: &'a [[f32; 2]],
    }
    impl StripPass<2> for Sums<'_> {
        fn update(&self, j: usize, y_add: Option<usize>, y_sub: Option<usize>, col: &mut [V; 2]) {
            let q = |y: Option<usize>, k: usize| -> V {
                std::array::from_fn(|l| match y {
                    Some(y) if l < self.st.lanes_in_image(j) => {
                        self.data[y * self.st.w + l * self.st.len + j][k]
                    }
                    _ => 0.0,
                })
            };
            for k in 0..2 {
                let (a, s) = (q(y_add, k), q(y_sub, k));
                col[k] = std::array::from_fn(|l| (col[k][l] + a[l]) - s[l]);
            }
        }
        fn consume(&self, _: usize, j: usize, sums: &[V; 2], out_row: &mut [f32]) {
            // A nonlinear step, as the guided filter's solve: rounding differs if rows mix.
            for k in 0..2 {
                for l in 0..S {
                    out_row[(j * 2 + k) * S + l] = sums[k][l] * sums[k][l] / (1.0 + sums[1 - k][l].abs());
                }
            }
        }
    }

    /// Second pass: window sums of the first pass's rows, written row-major.
    struct Again {
        st: Strips,
    }
    struct AgainOn<'r> {
        st: Strips,
        rows: Rows<'r>,
    }
    impl OnRows<2> for Again {
        type Pass<'r> = AgainOn<'r>;
        fn on<'r>(&'r self, rows: Rows<'r>) -> AgainOn<'r> {
            AgainOn { st: self.st, rows }
        }
    }
    impl StripPass<2> for AgainOn<'_> {
        fn update(&self, j: usize, y_add: Option<usize>, y_sub: Option<usize>, col: &mut [V; 2]) {
            let q = |y: Option<usize>, k: usize| -> V {
                y.map_or([0.0; S], |y| std::array::from_fn(|l| self.rows.get(y)[(j * 2 + k) * S + l]))
            };
            for k in 0..2 {
                let (a, s) = (q(y_add, k), q(y_sub, k));
                col[k] = std::array::from_fn(|l| (col[k][l] + a[l]) - s[l]);
            }
        }
        fn consume(&self, _: usize, j: usize, sums: &[V; 2], out_row: &mut [f32]) {
            for l in 0..self.st.lanes_in_image(j) {
                let x = l * self.st.len + j;
                out_row[2 * x] = sums[0][l];
                out_row[2 * x + 1] = sums[1][l];
            }
        }
    }

    /// The fused walks give the bits of the two passes one after the other, for 1 to 5 runs
    /// (runs of one band whose second pass is all deferred, runs of several), in every
    /// build: several bands with a short last one, one band, `r` beyond the image, `2r + 2`
    /// beyond the height (a ring as tall as the image).
    #[test]
    fn fused_passes_are_bit_identical_to_two_passes() {
        for &(w, h, r) in
            &[(37, 300, 5), (70, 203, 1), (100, 131, 33), (9, 11, 20), (40, 1000, 2), (300, 70, 7)]
        {
            let data: Vec<[f32; 2]> =
                (0..w * h).map(|i| [((i * 7919) % 1000) as f32 * 0.001 + 0.1, (i % 13) as f32]).collect();
            let st = Strips::new(w, h, r);
            let first = Sums { st, data: &data };
            let second = Again { st };
            let mid = st.len * 2 * S;
            for isa in [isa(), Isa::Base] {
                let mut plane = vec![f32::NAN; h * mid];
                strip_box_sums::<2, _>(&st, &mut plane, mid, &first, isa);
                let mut two = vec![f32::NAN; w * h * 2];
                strip_box_sums::<2, _>(&st, &mut two, w * 2, &second.on(Rows::block(&plane, mid, 0)), isa);
                for runs in 1..=5 {
                    let mut fused = vec![f32::NAN; w * h * 2];
                    fused_box_sums::<2, 2, _, _>(&st, (&first, mid), &second, (&mut fused, w * 2), runs, isa);
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&two), bits(&fused), "{w}x{h} r={r} {runs} runs {isa:?}");
                }
            }
        }
    }

    /// Fused while the threads are fewer than the bands (and on one thread), with one run
    /// per thread.
    #[test]
    fn fused_runs_follow_the_bands() {
        let st = Strips::new(1920, 1080, 32); // 4 bands
        assert_eq!(fused_runs(&st, 1), Some(1));
        assert_eq!(fused_runs(&st, 2), Some(2));
        assert_eq!(fused_runs(&st, 4), None);
        assert_eq!(fused_runs(&st, 16), None);
        let small = Strips::new(96, 64, 24); // 1 band
        assert_eq!(fused_runs(&small, 1), Some(1));
        assert_eq!(fused_runs(&small, 2), None);
    }
}
