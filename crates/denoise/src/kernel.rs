//! The edge-avoiding weighted sum shared by the À-Trous and cross-bilateral filters:
//!
//! `c_out(p) = sum_q h(q) w(p,q) c(q) / sum_q h(q) w(p,q)` (Dammertz et al. 2010, eqs. 2-3),
//! `w = w_rt * w_n * w_x`, each `exp(-||a_p - a_q||^2 * inv_sigma2)` (eqs. 4-5), over a list of
//! taps `(dx, dy, h)`. Taps outside the image are skipped (the sum renormalises), pixels of
//! the other class (background vs surface) and invalid (non-finite) colours get weight 0.
//!
//! Data layout for auto-vectorisation: planar channels; the outer loop runs over taps, the
//! inner loop over the pixels of one row, so both the centre and the neighbour values are
//! contiguous slices and the three exponentials fold into one [`exp_neg`].

use crate::gbuffer::{Guides, Planes3};
use crate::simd::{exp_neg_g, isa, madd, Isa};
use rayon::prelude::*;

/// The B3-spline generating kernel `h` (Dammertz et al. 2010, §2.2, after [Mur97]); here
/// beside the weighted sum so that the filter passes using it depend on this module only.
pub const B3_SPLINE: [f32; 5] = [1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0];

/// One kernel entry: offset in pixels and kernel weight `h`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Tap {
    pub dx: isize,
    pub dy: isize,
    pub h: f32,
}

/// `1 / sigma^2` of each edge-stopping term; `None` switches the term off.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct RangeTerms {
    pub inv_color: Option<f32>,
    pub inv_normal: Option<f32>,
    pub inv_position: Option<f32>,
}

/// Slices of one row span: centre pixels `p` and neighbour pixels `q` (same length).
struct RowArgs<'a> {
    pc: [&'a [f32]; 3],
    qc: [&'a [f32]; 3],
    pn: [&'a [f32]; 3],
    qn: [&'a [f32]; 3],
    px: [&'a [f32]; 3],
    qx: [&'a [f32]; 3],
    ps: &'a [f32],
    qs: &'a [f32],
    /// Validity of the neighbours' colours (`None`: all valid).
    qv: Option<&'a [f32]>,
    h: f32,
    inv: [f32; 3],
}

/// Accumulates one tap over a row span into `acc` (`[r, g, b, weight]`).
#[inline(always)]
fn tap_row<const WC: bool, const WN: bool, const WX: bool, const F: bool>(
    a: &RowArgs,
    acc: &mut [&mut [f32]; 4],
) {
    if a.qv.is_some() {
        tap_row_v::<WC, WN, WX, true, F>(a, acc)
    } else {
        tap_row_v::<WC, WN, WX, false, F>(a, acc)
    }
}

/// [`tap_row`] with the validity check `V` compiled in or out.
#[inline(always)]
fn tap_row_v<const WC: bool, const WN: bool, const WX: bool, const V: bool, const F: bool>(
    a: &RowArgs,
    acc: &mut [&mut [f32]; 4],
) {
    let n = a.ps.len();
    let (pc0, pc1, pc2) = (&a.pc[0][..n], &a.pc[1][..n], &a.pc[2][..n]);
    let (qc0, qc1, qc2) = (&a.qc[0][..n], &a.qc[1][..n], &a.qc[2][..n]);
    let (qs, ps) = (&a.qs[..n], &a.ps[..n]);
    let qv = match a.qv {
        Some(v) => &v[..n],
        None => &[][..],
    };
    let [a0, a1, a2, aw] = acc;
    let (a0, a1, a2, aw) = (&mut a0[..n], &mut a1[..n], &mut a2[..n], &mut aw[..n]);
    // Empty slices for switched-off terms: only indexed when the term is on.
    let (pn, qn) =
        if WN { (a.pn.map(|s| &s[..n]), a.qn.map(|s| &s[..n])) } else { ([&[][..]; 3], [&[][..]; 3]) };
    let (px, qx) =
        if WX { (a.px.map(|s| &s[..n]), a.qx.map(|s| &s[..n])) } else { ([&[][..]; 3], [&[][..]; 3]) };
    for i in 0..n {
        let mut e = 0.0;
        if WC {
            let (d0, d1, d2) = (pc0[i] - qc0[i], pc1[i] - qc1[i], pc2[i] - qc2[i]);
            e = madd::<F>(madd::<F>(d2, d2, madd::<F>(d1, d1, d0 * d0)), a.inv[0], e);
        }
        if WN {
            let (d0, d1, d2) = (pn[0][i] - qn[0][i], pn[1][i] - qn[1][i], pn[2][i] - qn[2][i]);
            e = madd::<F>(madd::<F>(d2, d2, madd::<F>(d1, d1, d0 * d0)), a.inv[1], e);
        }
        if WX {
            let (d0, d1, d2) = (px[0][i] - qx[0][i], px[1][i] - qx[1][i], px[2][i] - qx[2][i]);
            e = madd::<F>(madd::<F>(d2, d2, madd::<F>(d1, d1, d0 * d0)), a.inv[2], e);
        }
        // Same class (surface/background) and a valid neighbour colour.
        let mut w = a.h * (1.0 - (ps[i] - qs[i]).abs());
        if V {
            w *= qv[i];
        }
        if WC || WN || WX {
            w = flush_tiny(w * exp_neg_g::<F>(e));
        }
        a0[i] = madd::<F>(w, qc0[i], a0[i]);
        a1[i] = madd::<F>(w, qc1[i], a1[i]);
        a2[i] = madd::<F>(w, qc2[i], a2[i]);
        aw[i] += w;
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn tap_row_avx2<const WC: bool, const WN: bool, const WX: bool>(
    a: &RowArgs,
    acc: &mut [&mut [f32]; 4],
) {
    tap_row::<WC, WN, WX, true>(a, acc)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn tap_row_avx512<const WC: bool, const WN: bool, const WX: bool>(
    a: &RowArgs,
    acc: &mut [&mut [f32]; 4],
) {
    tap_row::<WC, WN, WX, true>(a, acc)
}

#[inline(always)]
fn tap_row_dispatch<const WC: bool, const WN: bool, const WX: bool>(
    a: &RowArgs,
    acc: &mut [&mut [f32]; 4],
    isa: Isa,
) {
    #[cfg(target_arch = "x86_64")]
    match isa {
        // SAFETY: `isa()` reports Avx512 / Avx2 only when those features were detected.
        Isa::Avx512 => return unsafe { tap_row_avx512::<WC, WN, WX>(a, acc) },
        Isa::Avx2 => return unsafe { tap_row_avx2::<WC, WN, WX>(a, acc) },
        Isa::Base => {}
    }
    let _ = isa;
    tap_row::<WC, WN, WX, false>(a, acc)
}

fn tap_row_any(a: &RowArgs, acc: &mut [&mut [f32]; 4], terms: (bool, bool, bool), isa: Isa) {
    match terms {
        (false, false, false) => tap_row_dispatch::<false, false, false>(a, acc, isa),
        (true, false, false) => tap_row_dispatch::<true, false, false>(a, acc, isa),
        (false, true, false) => tap_row_dispatch::<false, true, false>(a, acc, isa),
        (false, false, true) => tap_row_dispatch::<false, false, true>(a, acc, isa),
        (true, true, false) => tap_row_dispatch::<true, true, false>(a, acc, isa),
        (true, false, true) => tap_row_dispatch::<true, false, true>(a, acc, isa),
        (false, true, true) => tap_row_dispatch::<false, true, true>(a, acc, isa),
        (true, true, true) => tap_row_dispatch::<true, true, true>(a, acc, isa),
    }
}

/// The interior of a row, where every tap lands inside the image: register-blocked, `B`
/// pixels at a time with their centre values and accumulators held in registers while the
/// taps stream past (taps inner, pixels outer). Same arithmetic in the same order as
/// [`tap_row_v`] followed by the normalisation of [`edge_avoiding_pass`], so the results are
/// bit-identical to the tiled path; it only saves re-loading the 10 centre planes and the
/// 4 accumulators per tap.
struct BlockArgs<'a> {
    c: [&'a [f32]; 3],
    n: [&'a [f32]; 3],
    x: [&'a [f32]; 3],
    s: &'a [f32],
    v: Option<&'a [f32]>,
    /// Per tap: flat offset `dy * width + dx` and kernel weight `h`.
    offs: &'a [(isize, f32)],
    inv: [f32; 3],
}

/// `s[i..i + B]` as an array (bounds-checked); shared with the symmetric À-Trous pass.
#[inline(always)]
pub(crate) fn ld<const B: usize>(s: &[f32], i: usize) -> [f32; B] {
    let mut r = [0.0f32; B];
    r.copy_from_slice(&s[i..i + B]);
    r
}

#[inline(always)]
pub(crate) fn ld3<const B: usize>(s: &[&[f32]; 3], i: usize) -> [[f32; B]; 3] {
    [ld::<B>(s[0], i), ld::<B>(s[1], i), ld::<B>(s[2], i)]
}

/// Adds `||p - q||^2 * inv` to the exponents `e` of `B` pixels; `first`: sets them instead
/// (the first term on); shared with the symmetric À-Trous pass.
#[inline(always)]
pub(crate) fn dist2_acc<const B: usize, const F: bool>(
    e: &mut [f32; B],
    p: &[[f32; B]; 3],
    q: &[[f32; B]; 3],
    inv: f32,
    first: bool,
) {
    for i in 0..B {
        let (d0, d1, d2) = (p[0][i] - q[0][i], p[1][i] - q[1][i], p[2][i] - q[2][i]);
        let d = madd::<F>(d2, d2, madd::<F>(d1, d1, d0 * d0));
        e[i] = if first { d * inv } else { madd::<F>(d, inv, e[i]) };
    }
}

/// Filters the pixels `p0 .. p0 + B * blocks` (flat indices, all interior) into `out`
/// (`out[c][0]` is pixel `p0`).
#[inline(always)]
fn blocks_v<const WC: bool, const WN: bool, const WX: bool, const V: bool, const B: usize, const F: bool>(
    a: &BlockArgs,
    p0: usize,
    blocks: usize,
    out: &mut [&mut [f32]; 3],
) {
    let zero = [[0.0f32; B]; 3];
    for b in 0..blocks {
        let p = p0 + b * B;
        let pc = ld3::<B>(&a.c, p);
        let pn = if WN { ld3::<B>(&a.n, p) } else { zero };
        let px = if WX { ld3::<B>(&a.x, p) } else { zero };
        let ps = ld::<B>(a.s, p);
        let mut acc = [[0.0f32; B]; 4];
        for &(off, h) in a.offs {
            let q = (p as isize + off) as usize;
            let qc = ld3::<B>(&a.c, q);
            let mut e = [0.0f32; B];
            if WC {
                dist2_acc::<B, F>(&mut e, &pc, &qc, a.inv[0], false);
            }
            if WN {
                dist2_acc::<B, F>(&mut e, &pn, &ld3::<B>(&a.n, q), a.inv[1], false);
            }
            if WX {
                dist2_acc::<B, F>(&mut e, &px, &ld3::<B>(&a.x, q), a.inv[2], false);
            }
            let qs = ld::<B>(a.s, q);
            let qv = if V { ld::<B>(a.v.unwrap_or(a.s), q) } else { [0.0; B] };
            for i in 0..B {
                let mut w = h * (1.0 - (ps[i] - qs[i]).abs());
                if V {
                    w *= qv[i];
                }
                if WC || WN || WX {
                    w = flush_tiny(w * exp_neg_g::<F>(e[i]));
                }
                acc[0][i] = madd::<F>(w, qc[0][i], acc[0][i]);
                acc[1][i] = madd::<F>(w, qc[1][i], acc[1][i]);
                acc[2][i] = madd::<F>(w, qc[2][i], acc[2][i]);
                acc[3][i] += w;
            }
        }
        let o = b * B;
        for i in 0..B {
            if acc[3][i] > 1e-30 {
                let inv_w = 1.0 / acc[3][i];
                for c in 0..3 {
                    out[c][o + i] = acc[c][i] * inv_w;
                }
            } else {
                for c in 0..3 {
                    out[c][o + i] = pc[c][i];
                }
            }
        }
    }
}

#[inline(always)]
fn blocks<const WC: bool, const WN: bool, const WX: bool, const B: usize, const F: bool>(
    a: &BlockArgs,
    p0: usize,
    n: usize,
    out: &mut [&mut [f32]; 3],
) {
    if a.v.is_some() {
        blocks_v::<WC, WN, WX, true, B, F>(a, p0, n, out)
    } else {
        blocks_v::<WC, WN, WX, false, B, F>(a, p0, n, out)
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn blocks_avx2<const WC: bool, const WN: bool, const WX: bool>(
    a: &BlockArgs,
    p0: usize,
    n: usize,
    out: &mut [&mut [f32]; 3],
) {
    blocks::<WC, WN, WX, 8, true>(a, p0, n, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn blocks_avx512<const WC: bool, const WN: bool, const WX: bool>(
    a: &BlockArgs,
    p0: usize,
    n: usize,
    out: &mut [&mut [f32]; 3],
) {
    blocks::<WC, WN, WX, 16, true>(a, p0, n, out)
}

/// Block width (pixels) of [`blocks_any`] for an instruction set: one vector register.
fn block_width(isa: Isa) -> usize {
    match isa {
        Isa::Avx512 => 16,
        Isa::Avx2 => 8,
        Isa::Base => 4,
    }
}

#[inline(always)]
fn blocks_dispatch<const WC: bool, const WN: bool, const WX: bool>(
    a: &BlockArgs,
    p0: usize,
    n: usize,
    out: &mut [&mut [f32]; 3],
    isa: Isa,
) {
    #[cfg(target_arch = "x86_64")]
    match isa {
        // SAFETY: `isa()` reports Avx512 / Avx2 only when those features were detected.
        Isa::Avx512 => return unsafe { blocks_avx512::<WC, WN, WX>(a, p0, n, out) },
        Isa::Avx2 => return unsafe { blocks_avx2::<WC, WN, WX>(a, p0, n, out) },
        Isa::Base => {}
    }
    let _ = isa;
    blocks::<WC, WN, WX, 4, false>(a, p0, n, out)
}

/// `n` blocks of [`block_width`]`(isa)` pixels from flat index `p0`.
fn blocks_any(
    a: &BlockArgs,
    p0: usize,
    n: usize,
    out: &mut [&mut [f32]; 3],
    terms: (bool, bool, bool),
    isa: Isa,
) {
    match terms {
        (false, false, false) => blocks_dispatch::<false, false, false>(a, p0, n, out, isa),
        (true, false, false) => blocks_dispatch::<true, false, false>(a, p0, n, out, isa),
        (false, true, false) => blocks_dispatch::<false, true, false>(a, p0, n, out, isa),
        (false, false, true) => blocks_dispatch::<false, false, true>(a, p0, n, out, isa),
        (true, true, false) => blocks_dispatch::<true, true, false>(a, p0, n, out, isa),
        (true, false, true) => blocks_dispatch::<true, false, true>(a, p0, n, out, isa),
        (false, true, true) => blocks_dispatch::<false, true, true>(a, p0, n, out, isa),
        (true, true, true) => blocks_dispatch::<true, true, true>(a, p0, n, out, isa),
    }
}

/// Pixels per tile of a row: the tile's centre values (10 planes) and accumulators (4) stay
/// in L1 while the 25 (or `(2r+1)^2`) taps stream over it; whole 1920-pixel rows (77 KB of
/// centre values) spill to L2 (docs/perf-filters.md).
const TILE: usize = 256;

/// One edge-avoiding pass `src -> dst` over all rows (in parallel).
///
/// `valid`: 1 where `src` holds a valid colour (`None`: all valid).
/// Requires `g.position` when `terms.inv_position` is set (callers check).
pub(crate) fn edge_avoiding_pass(
    src: &Planes3,
    valid: Option<&[f32]>,
    g: &Guides,
    taps: &[Tap],
    terms: RangeTerms,
    dst: &mut Planes3,
) {
    let w = g.width;
    if w == 0 || g.height == 0 {
        return;
    }
    let offs: Vec<(isize, f32)> = taps.iter().map(|t| (t.dy * w as isize + t.dx, t.h)).collect();
    let pass = RowPass::new(src, valid, g, taps, terms, &offs);
    let [d0, d1, d2] = dst;
    d0.par_chunks_mut(w).zip(d1.par_chunks_mut(w)).zip(d2.par_chunks_mut(w)).enumerate().for_each_init(
        || vec![0.0f32; 4 * TILE],
        |scratch, (y, ((o0, o1), o2))| pass.row(y, &mut [o0, o1, o2], scratch),
    );
}

/// What every row of one [`edge_avoiding_pass`] reads.
struct RowPass<'a> {
    src: &'a Planes3,
    valid: Option<&'a [f32]>,
    g: &'a Guides,
    taps: &'a [Tap],
    /// The position planes; the normals stand in when the position term is off.
    pos: [&'a [f32]; 3],
    /// Which of the colour, normal and position terms are on.
    flags: (bool, bool, bool),
    inv: [f32; 3],
    isa: Isa,
    /// Smallest and largest tap offsets in x and in y.
    dx: (isize, isize),
    dy: (isize, isize),
    /// The register-blocked interior's view of the same planes.
    blk: BlockArgs<'a>,
}

impl<'a> RowPass<'a> {
    /// `offs`: each tap's flat offset `dy * width + dx` and weight `h`.
    fn new(
        src: &'a Planes3,
        valid: Option<&'a [f32]>,
        g: &'a Guides,
        taps: &'a [Tap],
        terms: RangeTerms,
        offs: &'a [(isize, f32)],
    ) -> Self {
        // Switched-off terms never read their planes: the normals stand in for absent positions.
        let pos: [&[f32]; 3] = match (&g.position, terms.inv_position) {
            (Some(p), Some(_)) => [&p[0], &p[1], &p[2]],
            _ => [&g.normal[0], &g.normal[1], &g.normal[2]],
        };
        let flags = (
            terms.inv_color.is_some(),
            terms.inv_normal.is_some(),
            terms.inv_position.is_some() && g.position.is_some(),
        );
        let inv = [
            terms.inv_color.unwrap_or(0.0),
            terms.inv_normal.unwrap_or(0.0),
            terms.inv_position.unwrap_or(0.0),
        ];
        let extent = |d: fn(&Tap) -> isize| {
            (taps.iter().map(d).min().unwrap_or(0), taps.iter().map(d).max().unwrap_or(0))
        };
        let blk = BlockArgs {
            c: [&src[0], &src[1], &src[2]],
            n: [&g.normal[0], &g.normal[1], &g.normal[2]],
            x: pos,
            s: &g.surface,
            v: valid,
            offs,
            inv,
        };
        let (dx, dy) = (extent(|t| t.dx), extent(|t| t.dy));
        Self { src, valid, g, taps, pos, flags, inv, isa: isa(), dx, dy, blk }
    }

    /// Filters row `y` into `out` (its three planes): the interior by blocks, the borders
    /// by tiles.
    #[inline(always)]
    fn row(&self, y: usize, out: &mut [&mut [f32]; 3], scratch: &mut [f32]) {
        let (fx0, fx1) = self.interior(y, out);
        for (r0, r1) in [(0, fx0), (fx1, self.g.width)] {
            for t0 in (r0..r1).step_by(TILE) {
                self.border_tile(y, t0, (t0 + TILE).min(r1), out, scratch);
            }
        }
    }

    /// Filters the interior blocks `[fx0, fx1)` of row `y`, where every tap lands inside the
    /// image (no per-tap clipping); returns that span (empty when there is none).
    #[inline(always)]
    fn interior(&self, y: usize, out: &mut [&mut [f32]; 3]) -> (usize, usize) {
        let (w, h) = (self.g.width, self.g.height);
        let yi = y as isize;
        if yi + self.dy.0 < 0 || yi + self.dy.1 >= h as isize {
            return (0, 0);
        }
        let a = (-self.dx.0).max(0) as usize;
        let b = (w as isize - self.dx.1.max(0)).max(0) as usize;
        if b <= a {
            return (0, 0);
        }
        let bw = block_width(self.isa);
        let nb = (b - a) / bw;
        let (fx0, fx1) = (a, a + nb * bw);
        if nb > 0 {
            let [o0, o1, o2] = out;
            let mut out = [&mut o0[fx0..fx1], &mut o1[fx0..fx1], &mut o2[fx0..fx1]];
            blocks_any(&self.blk, y * w + fx0, nb, &mut out, self.flags, self.isa);
        }
        (fx0, fx1)
    }

    /// Filters pixels `t0..t1` of row `y`, clipping each tap to the image, with the tile's
    /// sums in `scratch` (4 planes of [`TILE`]).
    #[inline(always)]
    fn border_tile(&self, y: usize, t0: usize, t1: usize, out: &mut [&mut [f32]; 3], scratch: &mut [f32]) {
        scratch.fill(0.0);
        let (s0, rest) = scratch.split_at_mut(TILE);
        let (s1, rest) = rest.split_at_mut(TILE);
        let (s2, sw) = rest.split_at_mut(TILE);
        for t in self.taps {
            self.tap_into_tile(y, t, t0, t1, [&mut *s0, &mut *s1, &mut *s2, &mut *sw]);
        }
        self.normalise_tile(y, t0, t1 - t0, [s0, s1, s2, sw], out);
    }

    /// Adds tap `t` to the sums `acc` of tile `t0..t1` of row `y`, over the tile pixels whose
    /// neighbour lies inside the image.
    #[inline(always)]
    fn tap_into_tile(&self, y: usize, t: &Tap, t0: usize, t1: usize, acc: [&mut [f32]; 4]) {
        let (w, h) = (self.g.width, self.g.height);
        let yq = y as isize + t.dy;
        if yq < 0 || yq >= h as isize {
            return;
        }
        // Tile pixels whose neighbour x + dx lies inside the row.
        let x0 = (-t.dx).max(t0 as isize) as usize;
        let x1 = (w as isize - t.dx).min(t1 as isize);
        if x1 <= x0 as isize {
            return;
        }
        let x1 = x1 as usize;
        let p = y * w;
        let q = (yq as usize * w) as isize + t.dx;
        let (pr, qr) = (p + x0..p + x1, (q + x0 as isize) as usize..(q + x1 as isize) as usize);
        let (src, nrm, pos) = (self.src, &self.g.normal, &self.pos);
        let a = RowArgs {
            pc: [&src[0][pr.clone()], &src[1][pr.clone()], &src[2][pr.clone()]],
            qc: [&src[0][qr.clone()], &src[1][qr.clone()], &src[2][qr.clone()]],
            pn: [&nrm[0][pr.clone()], &nrm[1][pr.clone()], &nrm[2][pr.clone()]],
            qn: [&nrm[0][qr.clone()], &nrm[1][qr.clone()], &nrm[2][qr.clone()]],
            px: [&pos[0][pr.clone()], &pos[1][pr.clone()], &pos[2][pr.clone()]],
            qx: [&pos[0][qr.clone()], &pos[1][qr.clone()], &pos[2][qr.clone()]],
            ps: &self.g.surface[pr.clone()],
            qs: &self.g.surface[qr.clone()],
            qv: self.valid.map(|v| &v[qr]),
            h: t.h,
            inv: self.inv,
        };
        let (l0, l1) = (x0 - t0, x1 - t0);
        let [s0, s1, s2, sw] = acc;
        let mut acc = [&mut s0[l0..l1], &mut s1[l0..l1], &mut s2[l0..l1], &mut sw[l0..l1]];
        tap_row_any(&a, &mut acc, self.flags, self.isa);
    }

    /// Writes the tile's sums `s` divided by their weight (eq. 3) to pixels `t0..t0 + tw`
    /// of row `y`; a pixel with no contributing tap keeps its own value.
    #[inline(always)]
    fn normalise_tile(&self, y: usize, t0: usize, tw: usize, s: [&mut [f32]; 4], out: &mut [&mut [f32]; 3]) {
        let [s0, s1, s2, sw] = s;
        let [o0, o1, o2] = out;
        let (src, p) = (self.src, y * self.g.width);
        for l in 0..tw {
            let x = t0 + l;
            // (Weights below 1e-30 count as none: their reciprocal would overflow.)
            if sw[l] > 1e-30 {
                let inv_w = 1.0 / sw[l];
                o0[x] = s0[l] * inv_w;
                o1[x] = s1[l] * inv_w;
                o2[x] = s2[l] * inv_w;
            } else {
                o0[x] = src[0][p + x];
                o1[x] = src[1][p + x];
                o2[x] = src[2][p + x];
            }
        }
    }
}

/// Weights below 2^-100 set to 0: a spatial weight times `exp(-87)` is subnormal, and
/// subnormal multiply-adds are ~100x slower on x86 (the same flush as
/// [`crate::simd::SCALED_EXP_MIN_LOG2`] in the symmetric À-Trous pass). Every pixel keeps
/// its own tap (weight >= the kernel centre), so the flushed mass is below 2^-100 relative.
#[inline(always)]
fn flush_tiny(w: f32) -> f32 {
    const TINY: f32 = 7.888_609e-31; // 2^-100
    if w < TINY {
        0.0
    } else {
        w
    }
}
