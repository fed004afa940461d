//! One À-Trous level computed with shared symmetric weights: half the exponentials.
//!
//! The edge-stopping weight of Dammertz et al. 2010 (eqs. 4-5) is symmetric,
//! `w(p,q) = w(q,p)`: each term depends only on `||a_p - a_q||^2` (colour at the current
//! level, normal, position), the class check on `|s_p - s_q|`, and the B3 kernel has
//! `h(o) = h(-o)`. So the 24 off-centre taps of the 5x5 kernel need only the 12 weights of the
//! *half* offsets `o` (`dy > 0`, or `dy = 0, dx > 0`, in units of the step width):
//!
//! `W_o(p) = h(o) w(p, p+o)`; pixel `p` uses `W_o(p)` for its tap `+o` and `W_o(p-o)` for
//! its tap `-o`.
//!
//! Taps connect only rows `step` apart, so the rows are walked chain by chain (the rows `y`,
//! `y + step`, `y + 2 step`, ...; segments of the chains run in parallel, [`crate::chains`]): pass 1 writes the 12 weight rows of row `y` into a
//! ring buffer holding the chain's last 3 rows, pass 2 gathers row `y` (eq. 2 with its
//! normalisation, eq. 3) from the weight rows `y`, `y - step` and `y - 2 step`. Each weight costs the three
//! distances and one `exp`; the gather costs one weight load and four multiply-adds per tap.
//! The direct 25-tap sum of [`crate::kernel`] evaluates every weight twice (once from each
//! end); this evaluates each once and stores it.
//!
//! Same definitions as the direct pass, so it is tested against it and against the naive f64
//! filter: out-of-image taps are skipped (the sum renormalises), background and surface never
//! mix, an invalid neighbour colour (`valid = 0`) gets weight 0, a pixel whose weights sum to
//! less than `1e-30` keeps its value. The summation order differs from the direct pass (not
//! bit-identical, within float rounding). Every pixel's result is independent of the
//! segment split, so results do not depend on the thread count.

use crate::chains::{rows_of, segments, PlanesSink, RgbSink, Sink};
use crate::kernel::{dist2_acc, ld, ld3, RangeTerms};
use crate::simd::{isa, madd, scaled_exp_neg, Isa};
use rayon::prelude::*;

/// The half offsets `(dx, dy)` in units of the step width: `dy > 0`, or `dy = 0, dx > 0`.
const HALF: [(isize, isize); 12] =
    [(1, 0), (2, 0), (-2, 1), (-1, 1), (0, 1), (1, 1), (2, 1), (-2, 2), (-1, 2), (0, 2), (1, 2), (2, 2)];

/// The planes one level reads (row-major, `stride >= width` values per row; the padding
/// columns hold finite values, they are read by masked lanes only).
pub(crate) struct LevelInput<'a> {
    /// Colour of the current level `c_i`.
    pub c: [&'a [f32]; 3],
    /// Unit normals (zero on background).
    pub n: [&'a [f32]; 3],
    /// Positions (only read when the position term is on).
    pub x: [&'a [f32]; 3],
    /// 1 on surface pixels, 0 on background.
    pub s: &'a [f32],
    /// 1 where `c` holds a valid colour (`None`: all valid).
    pub v: Option<&'a [f32]>,
    pub width: usize,
    pub height: usize,
    /// Values per row of every plane (and of the output).
    pub stride: usize,
}

/// Geometry of one level: half offsets, kernel weights, ring layout.
struct Level {
    step: usize,
    /// Per half offset: `dx`, `dy` in pixels, flat offset `dy * stride + dx`, `(h(o), log2 h(o))`.
    half: [(isize, usize, usize, (f32, f32)); 12],
    /// `h` of the centre tap.
    h_centre: f32,
    inv: [f32; 3],
    /// Ring rows per half offset: rows `y`, `y - step`, `y - 2 step` of one chain.
    ring_rows: usize,
    /// Values per ring row: the image row with `2 step` zeros on each side.
    ring_width: usize,
}

impl Level {
    fn new(width: usize, stride: usize, step: usize, inv: [f32; 3]) -> Self {
        let b3 = crate::kernel::B3_SPLINE;
        let s = step as isize;
        let half = HALF.map(|(kx, ky)| {
            let (dx, dy) = (kx * s, (ky * s) as usize);
            // Flat offset modulo 2^64: applied with wrapping arithmetic to in-image pixels only.
            let off = ((dy * stride) as isize + dx) as usize;
            let h = b3[(kx + 2) as usize] * b3[(ky + 2) as usize];
            (dx, dy, off, (h, h.log2()))
        });
        Self { step, half, h_centre: b3[2] * b3[2], inv, ring_rows: 3, ring_width: width + 4 * step }
    }

    /// Start of the ring row of half offset `k` for image row `y`.
    #[inline(always)]
    fn ring_row(&self, k: usize, y: usize) -> usize {
        (k * self.ring_rows + (y / self.step) % self.ring_rows) * self.ring_width
    }
}

/// `s[i..i + B]` without the bounds check, for the interior loops whose index ranges are
/// in bounds by construction (checked in debug builds, which the tests run).
#[inline(always)]
fn ldu<const B: usize>(s: &[f32], i: usize) -> [f32; B] {
    debug_assert!(i <= s.len() && s.len() - i >= B, "{i} + {B} > {}", s.len());
    // SAFETY: callers pass in-bounds ranges (interior pixels, valid rows; see the callers).
    unsafe { std::ptr::read_unaligned(s.as_ptr().add(i) as *const [f32; B]) }
}

#[inline(always)]
fn ldu3<const B: usize>(s: &[&[f32]; 3], i: usize) -> [[f32; B]; 3] {
    [ldu::<B>(s[0], i), ldu::<B>(s[1], i), ldu::<B>(s[2], i)]
}

/// The centre values of `B` pixels, loaded once for all 12 weights.
struct Centre<const B: usize> {
    c: [[f32; B]; 3],
    n: [[f32; B]; 3],
    x: [[f32; B]; 3],
    s: [f32; B],
}

#[inline(always)]
fn centre<const WN: bool, const WX: bool, const B: usize>(a: &LevelInput, p: usize) -> Centre<B> {
    let zero = [[0.0f32; B]; 3];
    Centre {
        c: ld3::<B>(&a.c, p),
        n: if WN { ld3::<B>(&a.n, p) } else { zero },
        x: if WX { ld3::<B>(&a.x, p) } else { zero },
        s: ld::<B>(a.s, p),
    }
}

/// `h w(p, q)` for the `B` pixels `p..p+B` and their neighbours `q..q+B` (eqs. 4-5 and the
/// class check); the validity of `q` is applied in the gather.
#[inline(always)]
fn weight<const WC: bool, const WN: bool, const WX: bool, const B: usize, const F: bool>(
    a: &LevelInput,
    inv: [f32; 3],
    pc: &Centre<B>,
    q: usize,
    (h, log2_h): (f32, f32),
) -> [f32; B] {
    // The first term initialises `e` (a multiply), the others add to it.
    let mut e = [0.0f32; B];
    if WC {
        dist2_acc::<B, F>(&mut e, &pc.c, &ldu3::<B>(&a.c, q), inv[0], true);
    }
    if WN {
        dist2_acc::<B, F>(&mut e, &pc.n, &ldu3::<B>(&a.n, q), inv[1], !WC);
    }
    if WX {
        dist2_acc::<B, F>(&mut e, &pc.x, &ldu3::<B>(&a.x, q), inv[2], !WC && !WN);
    }
    let qs = ldu::<B>(a.s, q);
    let mut w = [0.0f32; B];
    for i in 0..B {
        let hw = if WC || WN || WX { scaled_exp_neg::<F>(e[i], log2_h) } else { h };
        // Background and surface never mix (s is 0 or 1).
        w[i] = if pc.s[i] == qs[i] { hw } else { 0.0 };
    }
    w
}

/// Block starts of a row of `w` pixels: `0, B, 2B, ...` and, when `B` does not divide `w`, a
/// last block `w - B` overlapping the one before (both passes are idempotent per pixel).
/// Rows narrower than `B` get no block.
#[inline(always)]
fn block_starts<const B: usize>(w: usize) -> impl Iterator<Item = usize> {
    let full = if w >= B { w / B } else { 0 };
    let tail = if w >= B && full * B != w { Some(w - B) } else { None };
    (0..full).map(|b| b * B).chain(tail)
}

/// True when the flat ranges `p + off .. p + off + B` (`off` modulo 2^64) lie in `0..n`:
/// the block's loads are in bounds even where lanes fall outside their row.
#[inline(always)]
fn in_flat<const B: usize>(p: usize, off: usize, n: usize) -> bool {
    let q = p.wrapping_add(off);
    q <= n && n - q >= B
}

/// Pass 1: the 12 weight rows of image row `y` into the ring.
#[inline(always)]
fn weight_row<const WC: bool, const WN: bool, const WX: bool, const B: usize, const F: bool>(
    a: &LevelInput,
    lv: &Level,
    y: usize,
    ring: &mut [f32],
) {
    let (w, h) = (a.width, a.height);
    let n = a.s.len().min(a.c[0].len());
    let s2 = 2 * lv.step;
    let pad = s2;
    let rr: [usize; 12] = std::array::from_fn(|k| lv.ring_row(k, y) + pad);
    // The half offsets are sorted by dy (0, step, 2 step): the ones whose row lies in the
    // image are a prefix.
    let nk = lv.half.iter().filter(|(_, dy, _, _)| y + dy < h).count();
    for x in block_starts::<B>(w) {
        let p = y * a.stride + x;
        let interior = x >= s2 && x + B + s2 <= w;
        // A border block whose neighbours are all in memory: lanes outside the row read
        // pixels of the next or previous row, and get weight 0 from the lane mask.
        if !interior && !lv.half[..nk].iter().all(|t| in_flat::<B>(p, t.2, n)) {
            weight_pixels::<WC, WN, WX, F>(a, lv, y, x..x + B, nk, &rr, ring);
            continue;
        }
        let pc = centre::<WN, WX, B>(a, p);
        for k in 0..nk {
            let (dx, _, off, hk) = lv.half[k];
            // In bounds: interior (x -/+ 2 step in the row) or checked by `in_flat`; the
            // row y + dy < h.
            let mut wk = weight::<WC, WN, WX, B, F>(a, lv.inv, &pc, p.wrapping_add(off), hk);
            if !interior {
                for i in 0..B {
                    let xq = (x + i) as isize + dx;
                    wk[i] = if xq >= 0 && xq < w as isize { wk[i] } else { 0.0 };
                }
            }
            ring[rr[k] + x..rr[k] + x + B].copy_from_slice(&wk);
        }
    }
    if w < B {
        weight_pixels::<WC, WN, WX, F>(a, lv, y, 0..w, nk, &rr, ring);
    }
}

/// [`weight_row`] for the pixels `xs` of row `y` one at a time, each neighbour clipped to
/// the row.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn weight_pixels<const WC: bool, const WN: bool, const WX: bool, const F: bool>(
    a: &LevelInput,
    lv: &Level,
    y: usize,
    xs: std::ops::Range<usize>,
    nk: usize,
    rr: &[usize; 12],
    ring: &mut [f32],
) {
    let w = a.width;
    for x in xs {
        let p = y * a.stride + x;
        let pc = centre::<WN, WX, 1>(a, p);
        for k in 0..nk {
            let (dx, _, off, hk) = lv.half[k];
            let xq = x as isize + dx;
            let wk = if xq >= 0 && xq < w as isize {
                weight::<WC, WN, WX, 1, F>(a, lv.inv, &pc, p.wrapping_add(off), hk)[0]
            } else {
                0.0
            };
            ring[rr[k] + x] = wk;
        }
    }
}

/// Pass 2: row `y` of the output from the weight rows `y`, `y - step`, `y - 2 step`.
#[inline(always)]
fn gather_row<const V: bool, const B: usize, const F: bool>(
    a: &LevelInput,
    lv: &Level,
    y: usize,
    ring: &[f32],
    out: [&mut [f32]; 3],
) {
    let (w, h) = (a.width, a.height);
    let n = a.c[0].len();
    let s2 = 2 * lv.step;
    let pad = s2;
    // Valid forward / backward taps are prefixes of the half offsets (sorted by dy).
    let nf = lv.half.iter().filter(|(_, dy, _, _)| y + dy < h).count();
    let nb = lv.half.iter().filter(|(_, dy, _, _)| y >= *dy).count();
    // Ring positions of pixel x = 0 in the forward weight rows (row y) and of its backward
    // neighbour x - dx (row y - dy).
    let fr: [usize; 12] = std::array::from_fn(|k| lv.ring_row(k, y) + pad);
    let br: [usize; 12] = std::array::from_fn(|k| {
        let (dx, dy, _, _) = lv.half[k];
        if k < nb {
            (lv.ring_row(k, y - dy) + pad).wrapping_add_signed(-dx)
        } else {
            0
        }
    });
    // The off-centre taps of the row: (ring position of pixel x = 0, flat colour offset
    // modulo 2^64), forward then backward.
    let mut taps = [(0usize, 0usize); 24];
    let mut nt = 0;
    for k in 0..nf {
        taps[nt] = (fr[k], lv.half[k].2);
        nt += 1;
    }
    for k in 0..nb {
        taps[nt] = (br[k], lv.half[k].2.wrapping_neg());
        nt += 1;
    }
    let [o0, o1, o2] = out;
    for x in block_starts::<B>(w) {
        let p = y * a.stride + x;
        let interior = x >= s2 && x + B + s2 <= w;
        // Border blocks: lanes whose neighbour is outside the row read weight 0 (set by pass
        // 1 for forward taps; the ring's zero padding for backward ones) and a finite colour
        // of the next or previous row, as long as the loads stay in memory.
        let in_memory = || {
            lv.half[..nf].iter().all(|t| in_flat::<B>(p, t.2, n))
                && lv.half[..nb].iter().all(|t| in_flat::<B>(p, t.2.wrapping_neg(), n))
        };
        if !interior && !in_memory() {
            gather_pixels::<V, F>(a, lv, y, x..x + B, (nf, nb), (&fr, &br), ring, [o0, o1, o2]);
            continue;
        }
        let pc = ldu3::<B>(&a.c, p);
        let vp = if V { ldu::<B>(a.v.unwrap_or(a.s), p) } else { [0.0; B] };
        // The centre tap, then the off-centre taps of the list alternately into two sets of
        // accumulators (two independent multiply-add chains: one chain waited on the
        // multiply-add latency at every tap), added at the end. The accumulators are plain
        // locals carried through the loop: with a closure per tap they were kept in memory,
        // a store and a reload per tap (perf annotate).
        let mut acc = [[[0.0f32; B]; 4]; 2];
        for i in 0..B {
            let wi = if V { lv.h_centre * vp[i] } else { lv.h_centre };
            for c in 0..3 {
                acc[0][c][i] = wi * pc[c][i];
            }
            acc[0][3][i] = wi;
        }
        // In bounds: interior (x -/+ 2 step inside the row) or checked by `in_flat`; rows
        // y -/+ dy checked by nf / nb; ring rows padded by 2 step.
        let tap = |acc: &mut [[f32; B]; 4], (rb, off): (usize, usize)| {
            let wq = ldu::<B>(ring, rb.wrapping_add(x));
            let q = p.wrapping_add(off);
            let qc = ldu3::<B>(&a.c, q);
            let qv = if V { ldu::<B>(a.v.unwrap_or(a.s), q) } else { [0.0; B] };
            for i in 0..B {
                let wi = if V { wq[i] * qv[i] } else { wq[i] };
                for c in 0..3 {
                    acc[c][i] = madd::<F>(wi, qc[c][i], acc[c][i]);
                }
                acc[3][i] += wi;
            }
        };
        let [mut s0, mut s1] = acc;
        let pairs = taps[..nt].chunks_exact(2);
        let rest = pairs.remainder();
        for t in pairs {
            tap(&mut s0, t[0]);
            tap(&mut s1, t[1]);
        }
        for t in rest {
            tap(&mut s0, *t);
        }
        let sum: [[f32; B]; 4] = std::array::from_fn(|c| std::array::from_fn(|i| s0[c][i] + s1[c][i]));
        normalise::<B>(&sum, &pc, [&mut o0[x..x + B], &mut o1[x..x + B], &mut o2[x..x + B]]);
    }
    if w < B {
        gather_pixels::<V, F>(a, lv, y, 0..w, (nf, nb), (&fr, &br), ring, [o0, o1, o2]);
    }
}

/// [`gather_row`] for the pixels `xs` of row `y` one at a time, each neighbour clipped to
/// the row.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn gather_pixels<const V: bool, const F: bool>(
    a: &LevelInput,
    lv: &Level,
    y: usize,
    xs: std::ops::Range<usize>,
    (nf, nb): (usize, usize),
    (fr, br): (&[usize; 12], &[usize; 12]),
    ring: &[f32],
    out: [&mut [f32]; 3],
) {
    let w = a.width;
    let [o0, o1, o2] = out;
    for x in xs {
        let p = y * a.stride + x;
        let pc = ld3::<1>(&a.c, p);
        let mut acc = [[0.0f32; 1]; 4];
        let mut tap = |wq: f32, q: usize| {
            let wi = if V { wq * a.v.unwrap_or(a.s)[q] } else { wq };
            for c in 0..3 {
                acc[c][0] = madd::<F>(wi, a.c[c][q], acc[c][0]);
            }
            acc[3][0] += wi;
        };
        tap(lv.h_centre, p);
        for k in 0..nf {
            let (dx, _, off, _) = lv.half[k];
            let xq = x as isize + dx;
            if xq >= 0 && xq < w as isize {
                tap(ring[fr[k] + x], p.wrapping_add(off));
            }
        }
        for k in 0..nb {
            let (dx, _, off, _) = lv.half[k];
            let xq = x as isize - dx;
            if xq >= 0 && xq < w as isize {
                tap(ring[br[k].wrapping_add(x)], p.wrapping_sub(off));
            }
        }
        normalise::<1>(&acc, &pc, [&mut o0[x..x + 1], &mut o1[x..x + 1], &mut o2[x..x + 1]]);
    }
}

/// Eq. 3; a pixel with no contributing tap (weights below `1e-30`, whose reciprocal would
/// overflow) keeps its own value.
#[inline(always)]
fn normalise<const B: usize>(acc: &[[f32; B]; 4], pc: &[[f32; B]; 3], out: [&mut [f32]; 3]) {
    for i in 0..B {
        if acc[3][i] > 1e-30 {
            let inv_w = 1.0 / acc[3][i];
            for c in 0..3 {
                out[c][i] = acc[c][i] * inv_w;
            }
        } else {
            for c in 0..3 {
                out[c][i] = pc[c][i];
            }
        }
    }
}

/// Where a level writes its rows.
pub(crate) enum BandOut<'a> {
    /// Three planes of `stride` values per row (the input of the next level).
    Planes([&'a mut [f32]; 3]),
    /// Interleaved RGB rows of `width` pixels: the last level writes the output image
    /// directly instead of writing planes and interleaving them in a separate pass.
    Rgb(&'a mut [f32]),
}

/// One segment of a chain ([`crate::chains`]): output rows `first, first + step, ...`, weight
/// rows from two chain rows before `first` on (the ring's start-up). Walking a chain on its
/// own keeps the ring at 3 rows with the chain's next rows still in the cache (walking all
/// rows in order needs `2 step + 1` ring rows, which fall out of L2 at the coarse levels).
#[inline(always)]
fn segment<
    const WC: bool,
    const WN: bool,
    const WX: bool,
    const V: bool,
    const B: usize,
    const F: bool,
    O: Sink,
>(
    a: &LevelInput,
    lv: &Level,
    first: usize,
    out: &mut O,
    ring: &mut [f32],
) {
    let s = lv.step;
    let start = if first >= 2 * s { first - 2 * s } else { first % s };
    for y in (start..first + out.rows() * s).step_by(s) {
        weight_row::<WC, WN, WX, B, F>(a, lv, y, ring);
        if y >= first {
            let r = (y - first) / s;
            // (The gather writes the first `a.width` values of each output row.)
            gather_row::<V, B, F>(a, lv, y, ring, out.row(r));
            out.done(r);
        }
    }
}

/// The instantiations of [`segment`] for each instruction set.
macro_rules! segment_isa {
    ($name:ident, $feat:literal, $b:literal) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $feat)]
        unsafe fn $name<const WC: bool, const WN: bool, const WX: bool, const V: bool, O: Sink>(
            a: &LevelInput,
            lv: &Level,
            first: usize,
            out: &mut O,
            ring: &mut [f32],
        ) {
            segment::<WC, WN, WX, V, $b, true, O>(a, lv, first, out, ring)
        }
    };
}
segment_isa!(segment_avx512, "avx512f,avx2,fma", 16);
segment_isa!(segment_avx2, "avx2,fma", 8);

#[inline(always)]
fn segment_v<const WC: bool, const WN: bool, const WX: bool, const V: bool, O: Sink>(
    a: &LevelInput,
    lv: &Level,
    first: usize,
    out: &mut O,
    ring: &mut [f32],
    isa: Isa,
) {
    #[cfg(target_arch = "x86_64")]
    match isa {
        // SAFETY: `isa()` reports Avx512 / Avx2 only when those features were detected.
        Isa::Avx512 => return unsafe { segment_avx512::<WC, WN, WX, V, O>(a, lv, first, out, ring) },
        Isa::Avx2 => return unsafe { segment_avx2::<WC, WN, WX, V, O>(a, lv, first, out, ring) },
        Isa::Base => {}
    }
    let _ = isa;
    segment::<WC, WN, WX, V, 4, false, O>(a, lv, first, out, ring)
}

#[inline(always)]
fn segment_t<const WC: bool, const WN: bool, const WX: bool, O: Sink>(
    a: &LevelInput,
    lv: &Level,
    first: usize,
    out: &mut O,
    ring: &mut [f32],
    isa: Isa,
) {
    if a.v.is_some() {
        segment_v::<WC, WN, WX, true, O>(a, lv, first, out, ring, isa)
    } else {
        segment_v::<WC, WN, WX, false, O>(a, lv, first, out, ring, isa)
    }
}

fn segment_any<O: Sink>(a: &LevelInput, lv: &Level, first: usize, out: &mut O, ring: &mut [f32], isa: Isa) {
    let terms = (lv.inv[0] > 0.0, lv.inv[1] > 0.0, lv.inv[2] > 0.0);
    match terms {
        (false, false, false) => segment_t::<false, false, false, O>(a, lv, first, out, ring, isa),
        (true, false, false) => segment_t::<true, false, false, O>(a, lv, first, out, ring, isa),
        (false, true, false) => segment_t::<false, true, false, O>(a, lv, first, out, ring, isa),
        (false, false, true) => segment_t::<false, false, true, O>(a, lv, first, out, ring, isa),
        (true, true, false) => segment_t::<true, true, false, O>(a, lv, first, out, ring, isa),
        (true, false, true) => segment_t::<true, false, true, O>(a, lv, first, out, ring, isa),
        (false, true, true) => segment_t::<false, true, true, O>(a, lv, first, out, ring, isa),
        (true, true, true) => segment_t::<true, true, true, O>(a, lv, first, out, ring, isa),
    }
}

/// Largest ring of weight rows per segment (bytes): 16 MB, rows up to ~100 000 pixels wide.
const MAX_RING_BYTES: usize = 16 << 20;

/// True when the ring of weight rows of a level with step width `step` stays below
/// [`MAX_RING_BYTES`] (else the caller takes the direct pass).
pub(crate) fn ring_fits(width: usize, step: usize) -> bool {
    12 * 3 * (width + 4 * step) * 4 <= MAX_RING_BYTES
}

/// One À-Trous level `c_{i+1} = c_i * h_i` with step width `step` (Dammertz et al. 2010,
/// eqs. 2-5) into `dst`. Terms set to `None` in `terms` are off; `a.x` is only read when the
/// position term is on.
pub(crate) fn atrous_level(a: &LevelInput, step: usize, terms: RangeTerms, dst: BandOut) {
    let (w, h) = (a.width, a.height);
    if w == 0 || h == 0 {
        return;
    }
    debug_assert!(a.stride >= w && a.c.iter().chain(&a.n).chain(&a.x).all(|p| p.len() == a.stride * h));
    debug_assert!(a.s.len() == a.stride * h && a.v.is_none_or(|v| v.len() == a.stride * h));
    let inv =
        [terms.inv_color.unwrap_or(0.0), terms.inv_normal.unwrap_or(0.0), terms.inv_position.unwrap_or(0.0)];
    debug_assert!(inv.iter().all(|v| v.is_finite() && *v >= 0.0));
    let lv = Level::new(w, a.stride, step, inv);
    let isa = isa();
    let segs = segments(h, step, rayon::current_num_threads());
    let ring_len = 12 * lv.ring_rows * lv.ring_width;
    // Zero padding of the ring: out-of-row neighbours of the gather read weight 0.
    match dst {
        BandOut::Planes(d) => {
            let sinks = PlanesSink::per_segment(d, a.stride, step, &segs);
            segs.into_par_iter().zip(sinks).for_each(|(seg, mut sink)| {
                let mut ring = crate::pool::Buf::zeros(ring_len);
                segment_any(a, &lv, seg.first, &mut sink, &mut ring, isa);
            })
        }
        BandOut::Rgb(img) => {
            debug_assert_eq!(img.len(), 3 * w * h);
            let rows = rows_of(img, 3 * w, step, &segs);
            segs.into_par_iter().zip(rows).for_each(|(seg, rows)| {
                let mut ring = crate::pool::Buf::zeros(ring_len);
                let tmp = [vec![0.0f32; a.stride], vec![0.0f32; a.stride], vec![0.0f32; a.stride]];
                segment_any(a, &lv, seg.first, &mut RgbSink { rows, width: w, tmp }, &mut ring, isa);
            })
        }
    }
}
