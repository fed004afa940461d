//! Sliding-window sums in `O(N)` on *lane strips*, independent of the radius (He et al. 2010
//! compute the guided filter's means by box filtering; Bauszat et al. 2011 by summed-area
//! tables).
//!
//! # Layout
//! Each image row is cut into `segs <= S = 16` segments of `len` pixels; pixel `x = i len + j`
//! lives in lane `i` of the vector at position `j` (`[f32; S]`, one vector per position, `len`
//! vectors per row). A vector holds 16 pixels of the same row `len` apart, so every step of
//! the running sums *and* of the per-window work after them (the guided filter's 4x4
//! solves) is one vector operation across 16 windows, with no transposition between "one
//! pixel's quantities" and "one quantity of many pixels" (with the `K` quantities of a pixel
//! contiguous, only the running sums are vector operations: the products entering them and
//! the solves after them are per pixel; docs/perf-filters.md).
//!
//! # Running sums
//! For `K` quantities at once, per band of rows, column sums are updated by adding the row
//! entering the window and subtracting the row leaving it; each output row is then a
//! running sum along `j` of the column sums. Windows of pixels near a segment's ends reach
//! into the neighbouring segments: before each row, `r` positions on each side of the column
//! sums (the *halo*) are filled from the neighbouring lane (one lane shift). The segment
//! count is chosen so that `len >= r` whenever there are two segments or more, so a window
//! reaches at most one segment further; with one segment the other lanes are empty padding
//! (their quantities are 0) and positions beyond the neighbour are 0 as well. Windows are
//! clipped to the image (pixels outside it contribute nothing).
//!
//! Bands of rows run in parallel; each starts by summing its first window directly (cost
//! `2r+1` rows). The band height and the segments depend only on the image size and the
//! radius, never on the thread count: the same input gives the same bits on any number of
//! threads.
//!
//! # More threads than bands
//! A band's column sums are one chain of roundings from its first row, so a band cannot be
//! restarted anywhere without changing bits; but the chain of each position `j` is
//! independent of the others. With many threads each band is cut into sub-bands: first the
//! column sums at every sub-band start are *replayed* (only the vertical updates, the same
//! operations in the same order as [`band`], positions split across tasks), then the
//! sub-bands run in parallel from those states. The results are bit-identical to whole bands;
//! the replay costs one more pass of vertical updates, paid only when the threads outnumber
//! the bands (1080p at r = 32 has only 4 bands).

use crate::simd::Isa;
use rayon::prelude::*;

/// Lanes per vector: pixels processed together.
pub(crate) const S: usize = 16;
/// One value for each of the `S` lanes.
pub(crate) type V = [f32; S];

/// `b` viewed as vectors (`b.len()` a multiple of `S`).
#[inline(always)]
pub(crate) fn vecs(b: &[f32]) -> &[V] {
    let (v, rest) = b.as_chunks::<S>();
    debug_assert!(rest.is_empty());
    v
}

/// `b` viewed as vectors (`b.len()` a multiple of `S`).
#[inline(always)]
pub(crate) fn vecs_mut(b: &mut [f32]) -> &mut [V] {
    let (v, rest) = b.as_chunks_mut::<S>();
    debug_assert!(rest.is_empty());
    v
}

/// Geometry of the lane strips of a `w x h` image for windows of radius `r`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Strips {
    pub w: usize,
    pub h: usize,
    /// Radius, clipped to the image (a larger one gives the same clipped windows).
    pub r: usize,
    /// Segments per row (lanes in use), `1..=S`.
    pub segs: usize,
    /// Pixels per segment: vectors per row.
    pub len: usize,
}

impl Strips {
    pub fn new(w: usize, h: usize, r: usize) -> Self {
        let r = r.min(w.max(h));
        // len >= r whenever segs >= 2 (see the module docs).
        let segs = (w / r.max(1)).clamp(1, S);
        Self { w, h, r, segs, len: w.div_ceil(segs).max(1) }
    }

    /// Number of pixels of row-position `j` that lie in the image: lanes `0..count` (a prefix).
    #[inline(always)]
    pub fn lanes_in_image(&self, j: usize) -> usize {
        if j >= self.w {
            0
        } else {
            self.segs.min((self.w - j - 1) / self.len + 1)
        }
    }

    /// 1 for the lanes of position `j` inside the image, 0 for the padding.
    pub fn inside(&self, j: usize) -> V {
        let n = self.lanes_in_image(j);
        std::array::from_fn(|l| if l < n { 1.0 } else { 0.0 })
    }
}

/// Rows per parallel band: at least four window heights and 64 rows, so that the `2r+1`
/// start-up rows of a band cost at most about an eighth of its sliding work. Independent of
/// the thread count; a 1080-row image at r = 32 has 4 bands.
fn band_rows(h: usize, r: usize) -> usize {
    // Equal bands (as many as fit at that height), so 2 threads stay balanced.
    let bands = (h / (4 * (2 * r + 1)).max(64)).max(1);
    h.div_ceil(bands).max(1)
}

/// The per-pixel quantities of a box pass and what to do with their window sums.
/// Implemented by structs (not closures) so that `#[inline(always)]` pulls both into the
/// AVX2 / AVX-512 builds of [`strip_box_sums`].
pub(crate) trait StripPass<const K: usize>: Sync {
    /// `col = (col + q(y_add)) - q(y_sub)`, where `q(y)` are the quantities of the pixels at
    /// position `j` of row `y` (one lane per segment; lanes outside the image must give 0);
    /// a row given as `None` contributes nothing. (One call for both rows: the quantities are
    /// computed and added without being stored.)
    fn update(&self, j: usize, y_add: Option<usize>, y_sub: Option<usize>, col: &mut [V; K]);
    /// Uses `sums`, the window sums around the pixels at position `j` of row `y`, to write
    /// their output into `out_row` (row `y` of the output).
    fn consume(&self, y: usize, j: usize, sums: &[V; K], out_row: &mut [f32]);
}

// The `[V; K]` operations below run over the flattened `K * S` values: one contiguous loop
// that the compiler vectorises with plain loads and stores. Nested loops over `k` and the
// lanes are vectorised across `k`, with gathers and scatters.

/// `a + b` lane by lane.
#[inline(always)]
pub(crate) fn vadd(a: V, b: V) -> V {
    std::array::from_fn(|l| a[l] + b[l])
}

/// `a - b` lane by lane.
#[inline(always)]
pub(crate) fn vsub(a: V, b: V) -> V {
    std::array::from_fn(|l| a[l] - b[l])
}

/// `a b` lane by lane.
#[inline(always)]
pub(crate) fn vmul(a: V, b: V) -> V {
    std::array::from_fn(|l| a[l] * b[l])
}

#[inline(always)]
fn add<const K: usize>(acc: &mut [V; K], v: &[V; K]) {
    for (a, b) in acc.as_flattened_mut().iter_mut().zip(v.as_flattened()) {
        *a += *b;
    }
}

#[inline(always)]
fn sub<const K: usize>(acc: &mut [V; K], v: &[V; K]) {
    for (a, b) in acc.as_flattened_mut().iter_mut().zip(v.as_flattened()) {
        *a -= *b;
    }
}

/// The halo of the column sums `col` (index `t + r` for position `t` in `-r..len + r`):
/// position `t < 0` of lane `i` is position `t + len` of lane `i - 1`, position `t >= len`
/// is position `t - len` of lane `i + 1`; 0 beyond.
#[inline(always)]
fn fill_halo<const K: usize>(col: &mut [[V; K]], r: usize, len: usize) {
    // Lane shifts written over the flattened `K * S` values (see `add`): value `i` is lane
    // `i % S` of quantity `i / S`.
    for t in 0..r {
        // Left: position t - r, from lane i - 1 at t - r + len.
        if t + len >= r {
            let (lo, hi) = col.split_at_mut(t + len);
            let (src, dst) = (hi[0].as_flattened(), lo[t].as_flattened_mut());
            dst[0] = 0.0;
            for i in 1..K * S {
                dst[i] = if i % S == 0 { 0.0 } else { src[i - 1] };
            }
        } else {
            col[t] = [[0.0; S]; K];
        }
        // Right: position len + t, from lane i + 1 at t.
        if t < len {
            let (lo, hi) = col.split_at_mut(r + len + t);
            let (src, dst) = (lo[r + t].as_flattened(), hi[0].as_flattened_mut());
            for i in 0..K * S - 1 {
                dst[i] = if i % S == S - 1 { 0.0 } else { src[i + 1] };
            }
            dst[K * S - 1] = 0.0;
        } else {
            col[r + len + t] = [[0.0; S]; K];
        }
    }
}

/// The column sums of the window around row `y0` (rows `y0 - r..=y0 + r`), summed directly
/// into the zeroed `col` of positions `j0..j0 + col.len()`.
#[inline(always)]
fn start_sums<const K: usize, P: StripPass<K>>(
    st: &Strips,
    y0: usize,
    j0: usize,
    col: &mut [[V; K]],
    pass: &P,
) {
    for yy in y0.saturating_sub(st.r)..=(y0 + st.r).min(st.h - 1) {
        for (j, c) in col.iter_mut().enumerate() {
            pass.update(j0 + j, Some(yy), None, c);
        }
    }
}

/// Slides the column sums `col` of positions `j0..` from row `y` down to row `y + 1`: adds
/// row `y + r + 1`, removes row `y - r`.
#[inline(always)]
fn slide<const K: usize, P: StripPass<K>>(st: &Strips, y: usize, j0: usize, col: &mut [[V; K]], pass: &P) {
    let enter = (y + st.r + 1 < st.h).then_some(y + st.r + 1);
    let leave = (y >= st.r).then(|| y - st.r);
    if enter.is_some() || leave.is_some() {
        for (j, c) in col.iter_mut().enumerate() {
            pass.update(j0 + j, enter, leave, c);
        }
    }
}

/// The work of rows `y0..y0 + rows` (`out` holds them): a whole band (`init` `None`: its
/// column sums start from the direct sum) or a sub-band (`init`: the replayed column sums of
/// its first row, `len` positions of `K` vectors).
#[inline(always)]
fn band<const K: usize, P: StripPass<K>>(
    st: &Strips,
    y0: usize,
    init: Option<&[f32]>,
    out: &mut [f32],
    row_len: usize,
    pass: &P,
) {
    let (r, len) = (st.r, st.len);
    let rows = out.len() / row_len;
    let y1 = y0 + rows;
    // Column sums at positions -r..len + r (halo included).
    let mut buf = crate::pool::Buf::zeros((len + 2 * r) * K * S);
    let col: &mut [[V; K]] = vecs_mut(&mut buf).as_chunks_mut::<K>().0;
    match init {
        Some(state) => col[r..r + len].as_flattened_mut().as_flattened_mut().copy_from_slice(state),
        None => start_sums(st, y0, 0, &mut col[r..r + len], pass),
    }
    for (y, out_row) in (y0..y1).zip(out.chunks_exact_mut(row_len)) {
        fill_halo(col, r, len);
        // Running sum along the row: acc = sum of positions j - r ..= j + r.
        let mut acc = [[0.0f32; S]; K];
        for c in &col[..2 * r] {
            add(&mut acc, c);
        }
        for j in 0..len {
            add(&mut acc, &col[j + 2 * r]);
            pass.consume(y, j, &acc, out_row);
            sub(&mut acc, &col[j]);
        }
        if y + 1 < y1 {
            slide(st, y, 0, &mut col[r..r + len], pass);
        }
    }
}

/// The column sums of positions `j0..j0 + n` at the starts of sub-bands `1, 2, ...` of the
/// band starting at row `y0` (`sub` rows each), one state of `n` positions of `K` vectors
/// after the other in `states`: the vertical half of [`band`], same operations, same order.
#[inline(always)]
fn replay<const K: usize, P: StripPass<K>>(
    st: &Strips,
    y0: usize,
    sub: usize,
    (j0, n): (usize, usize),
    states: &mut [f32],
    pass: &P,
) {
    let mut buf = crate::pool::Buf::zeros(n * K * S);
    let col: &mut [[V; K]] = vecs_mut(&mut buf).as_chunks_mut::<K>().0;
    start_sums(st, y0, j0, col, pass);
    for (i, state) in states.chunks_exact_mut(n * K * S).enumerate() {
        for y in y0 + i * sub..y0 + (i + 1) * sub {
            slide(st, y, j0, col, pass);
        }
        state.copy_from_slice(col.as_flattened().as_flattened());
    }
}

/// [`band`] and [`replay`] compiled for each instruction set (the same operations in each:
/// the results are bit-identical).
macro_rules! isa_builds {
    ($band:ident, $replay:ident, $feat:literal) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $feat)]
        unsafe fn $band<const K: usize, P: StripPass<K>>(
            st: &Strips,
            y0: usize,
            init: Option<&[f32]>,
            out: &mut [f32],
            row_len: usize,
            pass: &P,
        ) {
            band::<K, P>(st, y0, init, out, row_len, pass)
        }

        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $feat)]
        unsafe fn $replay<const K: usize, P: StripPass<K>>(
            st: &Strips,
            y0: usize,
            sub: usize,
            js: (usize, usize),
            states: &mut [f32],
            pass: &P,
        ) {
            replay::<K, P>(st, y0, sub, js, states, pass)
        }
    };
}
isa_builds!(band_avx2, replay_avx2, "avx2,fma");
isa_builds!(band_avx512, replay_avx512, "avx512f,avx2,fma");

/// [`band`] in the build `isa` picks.
fn band_isa<const K: usize, P: StripPass<K>>(
    st: &Strips,
    y0: usize,
    init: Option<&[f32]>,
    out: &mut [f32],
    row_len: usize,
    pass: &P,
    isa: Isa,
) {
    #[cfg(target_arch = "x86_64")]
    match isa {
        // SAFETY: callers pass `crate::simd::isa()` or a narrower one: Avx512 / Avx2 only
        // when those features were detected.
        Isa::Avx512 => return unsafe { band_avx512::<K, P>(st, y0, init, out, row_len, pass) },
        Isa::Avx2 => return unsafe { band_avx2::<K, P>(st, y0, init, out, row_len, pass) },
        Isa::Base => {}
    }
    let _ = isa;
    band::<K, P>(st, y0, init, out, row_len, pass)
}

/// [`replay`] in the build `isa` picks.
fn replay_isa<const K: usize, P: StripPass<K>>(
    st: &Strips,
    y0: usize,
    sub: usize,
    js: (usize, usize),
    states: &mut [f32],
    pass: &P,
    isa: Isa,
) {
    #[cfg(target_arch = "x86_64")]
    match isa {
        // SAFETY: as in `band_isa`.
        Isa::Avx512 => return unsafe { replay_avx512::<K, P>(st, y0, sub, js, states, pass) },
        Isa::Avx2 => return unsafe { replay_avx2::<K, P>(st, y0, sub, js, states, pass) },
        Isa::Base => {}
    }
    let _ = isa;
    replay::<K, P>(st, y0, sub, js, states, pass)
}

/// Rows per sub-band when `threads` threads share bands of `rows` rows: `rows` (whole bands)
/// while they are as fast, else about four sub-bands per thread, at least [`MIN_SUB_ROWS`]
/// rows each. Whole bands take `ceil(bands / threads)` rounds of `1 / bands` of the work;
/// sub-bands about `1.4 / threads` (the replay adds its vertical updates, ~40%).
fn sub_band_rows(h: usize, rows: usize, threads: usize) -> usize {
    let bands = h.div_ceil(rows.max(1));
    if 5 * threads * bands.div_ceil(threads.max(1)) <= 7 * bands {
        return rows;
    }
    let per_band = (4 * threads).div_ceil(bands);
    rows.div_ceil(per_band).clamp(MIN_SUB_ROWS.min(rows), rows)
}

/// Fewest rows per sub-band: each costs a copy of the column sums (`len` positions).
const MIN_SUB_ROWS: usize = 8;

/// Band `y0..y0 + out rows` cut into sub-bands of `sub` rows: the column sums at the
/// sub-band starts replayed (positions split into about `tasks` chunks), then the sub-bands
/// in parallel.
#[allow(clippy::too_many_arguments)]
fn band_in_parts<const K: usize, P: StripPass<K>>(
    st: &Strips,
    y0: usize,
    sub: usize,
    tasks: usize,
    out: &mut [f32],
    row_len: usize,
    pass: &P,
    isa: Isa,
) {
    let parts = (out.len() / row_len).div_ceil(sub);
    if parts == 1 {
        return band_isa::<K, P>(st, y0, None, out, row_len, pass, isa);
    }
    let chunk = st.len.div_ceil(tasks.clamp(1, st.len));
    // Per chunk of positions: the states of sub-bands 1..parts, one after the other.
    let replayed: Vec<crate::pool::Buf> = (0..st.len.div_ceil(chunk))
        .into_par_iter()
        .map(|c| {
            let js = (c * chunk, chunk.min(st.len - c * chunk));
            let mut states = crate::pool::Buf::uninit((parts - 1) * js.1 * K * S);
            replay_isa::<K, P>(st, y0, sub, js, &mut states, pass, isa);
            states
        })
        .collect();
    out.par_chunks_mut(sub * row_len).enumerate().for_each(|(i, rows)| {
        if i == 0 {
            return band_isa::<K, P>(st, y0, None, rows, row_len, pass, isa);
        }
        let mut init = crate::pool::Buf::uninit(st.len * K * S);
        let mut at = 0;
        for states in &replayed {
            let n = states.len() / (parts - 1);
            init[at..at + n].copy_from_slice(&states[(i - 1) * n..i * n]);
            at += n;
        }
        band_isa::<K, P>(st, y0 + i * sub, Some(&init), rows, row_len, pass, isa)
    });
}

/// Calls `pass.consume(y, j, sums, out_row)` for every row `y` and position `j`, where lane
/// `i` of `sums[k]` is the sum of quantity `k` over the window of radius `st.r` around pixel
/// `(i len + j, y)` clipped to the image. `out` has `row_len` values per row; `out_row` is row
/// `y` of it. `isa` picks the build (the same operations in each: the results are
/// bit-identical).
pub(crate) fn strip_box_sums<const K: usize, P: StripPass<K>>(
    st: &Strips,
    out: &mut [f32],
    row_len: usize,
    pass: &P,
    isa: Isa,
) {
    assert_eq!(out.len(), st.h * row_len, "strip_box_sums: output size");
    if st.w == 0 || st.h == 0 {
        return;
    }
    sums_for_threads(st, out, row_len, pass, isa, rayon::current_num_threads())
}

/// [`strip_box_sums`] with the work cut for `threads` threads (the bits do not depend on it).
fn sums_for_threads<const K: usize, P: StripPass<K>>(
    st: &Strips,
    out: &mut [f32],
    row_len: usize,
    pass: &P,
    isa: Isa,
    threads: usize,
) {
    let rows = band_rows(st.h, st.r);
    let sub = sub_band_rows(st.h, rows, threads);
    let bands = st.h.div_ceil(rows);
    out.par_chunks_mut(rows * row_len).enumerate().for_each(|(b, chunk)| {
        if sub < rows {
            let tasks = (2 * threads).div_ceil(bands);
            band_in_parts::<K, P>(st, b * rows, sub, tasks, chunk, row_len, pass, isa)
        } else {
            band_isa::<K, P>(st, b * rows, None, chunk, row_len, pass, isa)
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simd::isa;

    /// Two quantities per pixel from a row-major image, window sums written row-major.
    struct CopyPass<'a> {
        st: Strips,
        data: &'a [[f32; 2]],
    }
    impl StripPass<2> for CopyPass<'_> {
        fn update(&self, j: usize, y_add: Option<usize>, y_sub: Option<usize>, col: &mut [V; 2]) {
            let q = |y: Option<usize>| {
                let mut q = [[0.0; S]; 2];
                for l in 0..self.st.lanes_in_image(j) {
                    let v = y.map_or([0.0; 2], |y| self.data[y * self.st.w + l * self.st.len + j]);
                    q[0][l] = v[0];
                    q[1][l] = v[1];
                }
                q
            };
            let (a, s) = (q(y_add), q(y_sub));
            for k in 0..2 {
                for l in 0..S {
                    col[k][l] = (col[k][l] + a[k][l]) - s[k][l];
                }
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

    fn run(w: usize, h: usize, r: usize, data: &[[f32; 2]], isa: Isa) -> Vec<f32> {
        let st = Strips::new(w, h, r);
        let mut out = vec![f32::NAN; w * h * 2];
        strip_box_sums::<2, _>(&st, &mut out, w * 2, &CopyPass { st, data }, isa);
        out
    }

    /// The O(N) running sums on lane strips against direct O(r^2) window sums on random data,
    /// for sizes around the segment and halo cases (one segment with r > len, r = len,
    /// narrow images, r beyond the image), in every instruction-set build.
    #[test]
    fn strip_box_sums_match_direct_window_sums() {
        let mut state = 12345u64;
        let mut rnd = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 40) as f32) / (1u64 << 24) as f32
        };
        let cases = [
            (13, 7, 2),
            (40, 150, 5),
            (9, 11, 20),
            (1, 1, 3),
            (70, 200, 1),
            (100, 131, 33),
            (64, 9, 4),
            (65, 9, 4),
            (33, 40, 16),
            (17, 5, 1),
            (300, 70, 7),
            (26, 21, 40),
        ];
        for &(w, h, r) in &cases {
            let data: Vec<[f32; 2]> = (0..w * h).map(|_| [rnd(), rnd() * 10.0 - 5.0]).collect();
            let fast = run(w, h, r, &data, isa());
            assert_eq!(fast, run(w, h, r, &data, Isa::Base), "{w}x{h} r={r}: builds differ");
            for y in 0..h {
                for x in 0..w {
                    let mut s = [0.0f64; 2];
                    for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                        for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                            s[0] += data[yy * w + xx][0] as f64;
                            s[1] += data[yy * w + xx][1] as f64;
                        }
                    }
                    let n = ((y + r + 1).min(h) - y.saturating_sub(r))
                        * ((x + r + 1).min(w) - x.saturating_sub(r));
                    for k in 0..2 {
                        let got = fast[(y * w + x) * 2 + k] as f64;
                        let tol = 1e-4 * n as f64 * 5.0;
                        assert!((got - s[k]).abs() < tol, "{w}x{h} r={r} ({x},{y}) k={k}: {got} vs {}", s[k]);
                    }
                }
            }
        }
    }

    /// Sub-bands started from replayed column sums give the bits of whole bands, for every
    /// shape of the cases above (short last bands, one-row sub-bands, r beyond the image).
    #[test]
    fn sub_bands_are_bit_identical_to_whole_bands() {
        for &(w, h, r) in
            &[(37, 300, 5), (70, 200, 1), (100, 131, 33), (300, 70, 7), (9, 11, 20), (40, 1000, 2)]
        {
            let data: Vec<[f32; 2]> =
                (0..w * h).map(|i| [((i * 7919) % 1000) as f32 * 0.001 + 0.1, (i % 13) as f32]).collect();
            let st = Strips::new(w, h, r);
            let pass = CopyPass { st, data: &data };
            for isa in [isa(), Isa::Base] {
                let mut whole = vec![f32::NAN; w * h * 2];
                sums_for_threads::<2, _>(&st, &mut whole, w * 2, &pass, isa, 1);
                for threads in [3, 16, 64] {
                    let mut parts = vec![f32::NAN; w * h * 2];
                    sums_for_threads::<2, _>(&st, &mut parts, w * 2, &pass, isa, threads);
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&whole), bits(&parts), "{w}x{h} r={r} {threads} threads {isa:?}");
                }
            }
        }
    }

    /// The band split does not follow the thread count, so the sums are bit-identical on
    /// 1, 2, 3 and 7 threads (here several bands: h = 300, r = 5 gives 64-row bands).
    #[test]
    fn strip_box_sums_bit_identical_across_thread_counts() {
        let (w, h, r) = (37, 300, 5);
        let data: Vec<[f32; 2]> =
            (0..w * h).map(|i| [((i * 7919) % 1000) as f32 * 0.001 + 0.1, (i % 13) as f32]).collect();
        let on = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| run(w, h, r, &data, isa())).iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        };
        let one = on(1);
        for t in [2, 3, 7] {
            assert_eq!(one, on(t), "{t} threads");
        }
    }
}
