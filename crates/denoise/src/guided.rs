//! Guided image filter for (indirect) illumination (Bauszat, Eisemann, Magnor 2011, §3.3,
//! after He, Sun, Tang 2010, "Guided Image Filtering").
//!
//! In every window `w_k` (radius `r`) the output is modelled as a linear function of the
//! guidance image `I` (normals, optionally depth, scaled to `[0, 1]`), fitted by ridge
//! regression to the noisy image `p`, per colour channel (eqs. 6-9, multi-channel form of He
//! et al. eq. 14):
//!
//! `a_k = (Sigma_k + eps U)^-1 cov_k(I, p)`, `b_k = mean_k(p) - a_k . mean_k(I)`,
//!
//! with a separate `eps` per guidance channel (`U` diagonal). The coefficients of all windows
//! covering a pixel are averaged and the output is `q_i = mean(a) . I_i + mean(b)`.
//! Every window mean comes from `O(N)` running box sums ([`crate::stripbox`]): the cost does
//! not depend on the radius. The `D x D` system is solved per pixel by Cholesky, 16 windows
//! at a time (one per vector lane).
//!
//! Background and invalid pixels: window statistics use only surface pixels with a finite
//! colour (a mask `m` multiplies every sum), windows holding none are skipped in the
//! averaging, so background never leaks into surfaces. Background pixels (zero normal, or a
//! depth that is not a surface's: [`crate::gbuffer::surface_at`]) are passed through
//! (non-finite values replaced by 0); surface pixels with an invalid colour get the fit of
//! their neighbours.
//!
//! Bounded output. The linear model is not a convex combination: `q` may leave the range of
//! the noisy values it was fitted to (overshoot at guide edges, He et al. 2010 §3.4 "gradient
//! reversal" discussion), and a covariance system spoilt by rounding (huge guide values
//! before background depths were detected: `-1e6` on a Cycles frame) made it explode. So:
//! - the depth guide is the depth over its scale clamped to `[0, DEPTH_GUIDE_MAX]`;
//! - a window whose Cholesky pivot falls below `eps / 2` (impossible in exact arithmetic:
//!   every pivot of `Sigma + eps U` with `Sigma` positive semi-definite is at least its
//!   `eps`, the Schur complement being superadditive) or whose coefficients are not finite
//!   is ill-conditioned by rounding: it falls back to the box mean (`a = 0, b = mean(p)`,
//!   the `eps -> inf` limit of the same ridge regression);
//! - every output is clamped to the per-channel range of the fit pixels' colours, so no
//!   output lies outside what the input holds (tested with huge and NaN guides).
//!
//! When to use: smooth indirect illumination at a fixed cost for any radius (Bauszat uses
//! radius 24-32, eps 0.01 for normals and 0.01-0.03 for depth). Edges that the guidance does
//! not show (shadows, texture) are smoothed away: filter demodulated illumination.

use crate::error::{invalid, DenoiseError};
use crate::fused::{fused_box_sums, fused_runs, OnRows, Rows};
use crate::gbuffer::{check_color, depth_scale, is_valid_color, surface_at, GBuffer};
use crate::pool::Buf;
use crate::simd::Isa;
use crate::stripbox::{strip_box_sums, vadd, vecs, vecs_mut, vmul, vsub, StripPass, Strips, S, V};
use filtrace_core::Image;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Which guidance image `I` the linear model uses (Bauszat's Table 2: 1, 3, 4 dimensions).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Guidance {
    /// 1 channel: the mean of the three `[0,1]`-scaled normal components (a grey normal map).
    GreyNormal,
    /// 3 channels: the normal, `0.5 n + 0.5`.
    Normal,
    /// 4 channels: the normal and the depth divided by the depth scale.
    NormalDepth,
}

impl Guidance {
    pub fn channels(self) -> usize {
        match self {
            Self::GreyNormal => 1,
            Self::Normal => 3,
            Self::NormalDepth => 4,
        }
    }
}

/// Parameters of [`guided`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GuidedParams {
    /// Window radius `r` in pixels (>= 1); cost is independent of it.
    pub radius: u32,
    pub guidance: Guidance,
    /// Regularisation `eps` of each normal channel (guidance scaled to `[0,1]`).
    pub eps_normal: f32,
    /// Regularisation `eps` of the depth channel.
    pub eps_depth: f32,
}

impl GuidedParams {
    /// Bauszat et al.'s setting: radius 24, normal + depth guidance, eps 0.01 (normals) and
    /// 0.02 (depth, middle of their 0.01-0.03).
    pub fn paper() -> Self {
        Self { radius: 24, guidance: Guidance::NormalDepth, eps_normal: 0.01, eps_depth: 0.02 }
    }
    /// The paper's widest window, radius 32.
    pub fn paper_wide() -> Self {
        Self { radius: 32, ..Self::paper() }
    }
    /// Normal-only guidance (3 channels), for inputs without depth (e.g. Mitsuba AOVs).
    pub fn normal_only() -> Self {
        Self { guidance: Guidance::Normal, ..Self::paper() }
    }
    /// Grey-normal guidance (1 channel, He et al.'s grey-scale guide).
    pub fn grey() -> Self {
        Self { guidance: Guidance::GreyNormal, ..Self::paper() }
    }
    pub fn presets() -> [(&'static str, Self); 4] {
        [
            ("paper", Self::paper()),
            ("paper_wide", Self::paper_wide()),
            ("normal_only", Self::normal_only()),
            ("grey", Self::grey()),
        ]
    }

    pub fn validate(&self) -> Result<(), DenoiseError> {
        if self.radius == 0 {
            return Err(invalid("radius", "must be >= 1"));
        }
        for (name, e) in [("eps_normal", self.eps_normal), ("eps_depth", self.eps_depth)] {
            if !(e.is_finite() && e > 0.0) {
                return Err(invalid(name, format!("must be finite and > 0, got {e}")));
            }
        }
        Ok(())
    }
}

impl Default for GuidedParams {
    fn default() -> Self {
        Self::paper()
    }
}

/// Filters `color` (3 channels) guided by `guide`. See the module docs.
pub fn guided(color: &Image, guide: &GBuffer, params: &GuidedParams) -> Result<Image, DenoiseError> {
    let mut out = Image::new(color.width(), color.height(), 3);
    guided_into(color, guide, params, &mut out)?;
    Ok(out)
}

/// [`guided`] with the instruction set chosen by the caller (tests compare the builds).
#[cfg(test)]
pub(crate) fn guided_with_isa(
    color: &Image,
    guide: &GBuffer,
    params: &GuidedParams,
    isa: Isa,
) -> Result<Image, DenoiseError> {
    guided_with_plan(color, guide, params, isa, Plan::Auto)
}

/// [`guided`] with the instruction set and the plan of the box passes chosen by the caller.
#[cfg(test)]
pub(crate) fn guided_with_plan(
    color: &Image,
    guide: &GBuffer,
    params: &GuidedParams,
    isa: Isa,
    plan: Plan,
) -> Result<Image, DenoiseError> {
    let mut out = Image::new(color.width(), color.height(), 3);
    guided_into_isa(color, guide, params, &mut out, (isa, plan))?;
    Ok(out)
}

/// How the two box passes run: fused ([`crate::fused`]) in `runs` parallel walks, or one
/// after the other over the whole coefficient plane. Same bits either way (tested).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(not(test), allow(dead_code))] // the tests force each plan
pub(crate) enum Plan {
    /// The default: [`Plan::TwoPasses`] (see `guided_impl`).
    Auto,
    /// Fused while the threads are fewer than the bands ([`fused_runs`]).
    FusedAuto,
    TwoPasses,
    Fused {
        runs: usize,
    },
}

/// [`guided`] writing into `out` (resized when it differs).
pub fn guided_into(
    color: &Image,
    guide: &GBuffer,
    params: &GuidedParams,
    out: &mut Image,
) -> Result<(), DenoiseError> {
    guided_into_isa(color, guide, params, out, (crate::simd::isa(), Plan::Auto))
}

fn guided_into_isa(
    color: &Image,
    guide: &GBuffer,
    params: &GuidedParams,
    out: &mut Image,
    how: (Isa, Plan),
) -> Result<(), DenoiseError> {
    check_color(color)?;
    params.validate()?;
    let (w, h) = (color.width(), color.height());
    guide.validate(w, h)?;
    if params.guidance == Guidance::NormalDepth && guide.depth.is_none() {
        return Err(DenoiseError::MissingGuide {
            buffer: "depth",
            needed_by: "guided filter with normal+depth guidance",
        });
    }
    if out.width() != w || out.height() != h || out.channels() != 3 {
        *out = Image::new(w, h, 3);
    }
    if w == 0 || h == 0 {
        return Ok(());
    }
    let (en, ed) = (params.eps_normal, params.eps_depth);
    let r = params.radius as usize;
    match params.guidance {
        Guidance::GreyNormal => guided_impl::<1, { k1(1) }, { k2(1) }>(color, guide, r, [en], out, how),
        Guidance::Normal => guided_impl::<3, { k1(3) }, { k2(3) }>(color, guide, r, [en; 3], out, how),
        Guidance::NormalDepth => {
            guided_impl::<4, { k1(4) }, { k2(4) }>(color, guide, r, [en, en, en, ed], out, how)
        }
    }
    Ok(())
}

/// Number of pass-1 quantities: `m, m I (D), m I I^T (upper, D(D+1)/2), m p (3), m I p (3D)`.
const fn k1(d: usize) -> usize {
    1 + d + d * (d + 1) / 2 + 3 + 3 * d
}

/// Number of pass-2 quantities (per-window coefficients): `[indicator, a (3D), b (3)]`.
const fn k2(d: usize) -> usize {
    4 + 3 * d
}

/// The depth guide `depth / scale` is clamped to `[0, DEPTH_GUIDE_MAX]`: everything beyond
/// 4 depth scales is "far" alike, and the running sums of its squares stay small enough for
/// f32 (the scale is the 99th percentile of surface depths, so few pixels reach it).
const DEPTH_GUIDE_MAX: f32 = 4.0;

/// Planes of [`Inputs`] after the `D` guidance planes.
const P_COLOR: usize = 0;
const P_MASK: usize = 3;
const P_SURFACE: usize = 4;

/// The per-pixel inputs of both passes in the lane-strip layout of [`crate::stripbox`]: per
/// row, `D + 5` planes of `len` vectors: the guidance `I_a` centred (`I - 0.5`, which leaves
/// `a` unchanged and keeps the running sums small), the sanitised colour `p` (non-finite
/// values replaced by 0), the fit mask `m` (1 on surface pixels with a finite colour) and the
/// surface indicator `s`. Padding lanes are all 0.
struct Inputs<const D: usize> {
    st: Strips,
    data: Buf,
}

impl<const D: usize> Inputs<D> {
    const PLANES: usize = D + 5;

    /// Converts the interleaved colour and guides (one pass over them, rows in parallel).
    fn new(color: &Image, g: &GBuffer, st: Strips, isa: Isa) -> Self {
        let (w, len) = (st.w, st.len);
        let row = Self::PLANES * len * S;
        let mut data = Buf::uninit(st.h * row);
        // Depth divided by the depth scale, as `Guides` does.
        let depth = g.depth.as_ref().filter(|_| D == 4).map(|d| (d.data(), 1.0 / depth_scale(g, d)));
        let src = Src { c: color.data(), n: g.normal.data(), g, depth };
        // (`convert_row` writes every lane, padding included: no need to clear `data`.)
        let rows_per_item = (16 * 1024 / w).max(1);
        data.par_chunks_mut(rows_per_item * row).enumerate().for_each(|(item, rows)| {
            for (ry, out) in rows.chunks_exact_mut(row).enumerate() {
                convert_row_isa::<D>(&st, &src, item * rows_per_item + ry, vecs_mut(out), isa);
            }
        });
        Self { st, data }
    }

    /// Per colour channel, `[min, max]` over the fit pixels (`[0, 0]` when there are none).
    fn fit_range(&self) -> [[f32; 2]; 3] {
        let row = Self::PLANES * self.st.len * S;
        let merge = |a: [[f32; 2]; 3], b: [[f32; 2]; 3]| -> [[f32; 2]; 3] {
            std::array::from_fn(|c| [a[c][0].min(b[c][0]), a[c][1].max(b[c][1])])
        };
        let empty = [[f32::INFINITY, f32::NEG_INFINITY]; 3];
        let r = self
            .data
            .par_chunks(row)
            .map(|row| {
                let v = vecs(row);
                let len = self.st.len;
                let mut r = empty;
                for j in 0..len {
                    let m = v[(D + P_MASK) * len + j];
                    for c in 0..3 {
                        let p = v[(D + P_COLOR + c) * len + j];
                        for l in 0..S {
                            if m[l] > 0.0 {
                                r[c] = [r[c][0].min(p[l]), r[c][1].max(p[l])];
                            }
                        }
                    }
                }
                r
            })
            .reduce(|| empty, merge);
        r.map(|[lo, hi]| if lo <= hi { [lo, hi] } else { [0.0, 0.0] })
    }

    /// Plane `q` at position `j` of row `y`.
    #[inline(always)]
    fn get(&self, q: usize, y: usize, j: usize) -> V {
        vecs(&self.data)[(y * Self::PLANES + q) * self.st.len + j]
    }
}

/// The interleaved inputs of [`Inputs::new`]: colour, normal, the G-buffer (for
/// [`surface_at`]), `(depth, 1 / depth scale)` when depth guides.
struct Src<'a> {
    c: &'a [f32],
    n: &'a [f32],
    g: &'a GBuffer,
    depth: Option<(&'a [f32], f32)>,
}

/// Row `y` of [`Inputs`] (`out`: its `D + 5` planes of `len` vectors): position by
/// position, the 16 pixels `len` apart gathered into lanes and converted as vectors.
#[inline(always)]
fn convert_row<const D: usize>(st: &Strips, src: &Src, y: usize, out: &mut [V]) {
    let (w, len) = (st.w, st.len);
    for j in 0..len {
        let mut v = [[0.0f32; S]; 9]; // D + 5 <= 9 planes
                                      // One lane per segment; lanes past the image's end stay 0 (background, no fit).
        for l in 0..st.lanes_in_image(j) {
            let i = y * w + l * len + j;
            let px = &src.n[3 * i..3 * i + 3];
            // Surface (`surface_at`: normal set, depth valid): normal normalised; 0 on background.
            let surface = surface_at(src.g, i);
            let inv =
                if surface { 1.0 / (px[0] * px[0] + px[1] * px[1] + px[2] * px[2]).sqrt() } else { 0.0 };
            let nn = if surface { [px[0] * inv, px[1] * inv, px[2] * inv] } else { [0.0; 3] };
            if D == 1 {
                // The mean of the [0,1]-scaled normal, centred: (n0 + n1 + n2) / 6.
                v[0][l] = (nn[0] + nn[1] + nn[2]) / 6.0;
            } else {
                for a in 0..3 {
                    v[a][l] = 0.5 * nn[a];
                }
            }
            if let Some((d, inv_scale)) = src.depth {
                let dv = d[i];
                v[3][l] = if surface { (dv * inv_scale).clamp(0.0, DEPTH_GUIDE_MAX) } else { 0.0 } - 0.5;
            }
            let cp = &src.c[3 * i..3 * i + 3];
            let valid = cp.iter().all(|v| is_valid_color(*v));
            for k in 0..3 {
                v[D + P_COLOR + k][l] = if valid { cp[k] } else { 0.0 };
            }
            let s = if surface { 1.0 } else { 0.0 };
            v[D + P_MASK][l] = if valid { s } else { 0.0 };
            v[D + P_SURFACE][l] = s;
        }
        for (q, v) in v[..D + 5].iter().enumerate() {
            out[q * len + j] = *v;
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn convert_row_avx512<const D: usize>(st: &Strips, src: &Src, y: usize, out: &mut [V]) {
    convert_row::<D>(st, src, y, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn convert_row_avx2<const D: usize>(st: &Strips, src: &Src, y: usize, out: &mut [V]) {
    convert_row::<D>(st, src, y, out)
}

fn convert_row_isa<const D: usize>(st: &Strips, src: &Src, y: usize, out: &mut [V], isa: Isa) {
    #[cfg(target_arch = "x86_64")]
    match isa {
        // SAFETY: `isa()` reports Avx512 / Avx2 only when those features were detected.
        Isa::Avx512 => return unsafe { convert_row_avx512::<D>(st, src, y, out) },
        Isa::Avx2 => return unsafe { convert_row_avx2::<D>(st, src, y, out) },
        Isa::Base => {}
    }
    let _ = isa;
    convert_row::<D>(st, src, y, out)
}

/// `K1`, `K2`: quantity counts of the two box passes (see [`k1`], [`k2`]).
fn guided_impl<const D: usize, const K1: usize, const K2: usize>(
    color: &Image,
    g: &GBuffer,
    r: usize,
    eps: [f32; D],
    out: &mut Image,
    (isa, plan): (Isa, Plan),
) {
    let (w, h) = (color.width(), color.height());
    let st = Strips::new(w, h, r);
    let inputs = Inputs::<D>::new(color, g, st, isa);
    // Pass 1: window statistics -> per-window coefficients (a_k, b_k) (eqs. 8-9), written per
    // row as `len` positions of K2 vectors.
    let coef_row = st.len * K2 * S;
    let inside: Vec<V> = (0..st.len).map(|j| st.inside(j)).collect();
    let pass1 = Pass1::<D> { inputs: &inputs, eps, inside: &inside };
    // Pass 2: average the coefficients over the windows covering each pixel and apply them.
    let apply = Apply::<D> { inputs: &inputs, range: inputs.fit_range() };
    let runs = match plan {
        // Not yet the default: 7 % more CPU time than the two passes on 1 thread (dev build,
        // 2-core machine, docs/performance.md "Stop 16"); to be timed on the idle machine.
        Plan::Auto => None,
        Plan::FusedAuto => fused_runs(&st, rayon::current_num_threads()),
        Plan::TwoPasses => None,
        Plan::Fused { runs } => Some(runs),
    };
    let out = out.data_mut();
    match runs {
        Some(runs) => {
            fused_box_sums::<K1, K2, _, _>(&st, (&pass1, coef_row), &apply, (out, 3 * w), runs, isa)
        }
        None => {
            let mut coef = Buf::uninit(h * coef_row);
            strip_box_sums::<K1, _>(&st, &mut coef, coef_row, &pass1, isa);
            let pass2 = <Apply<D> as OnRows<K2>>::on(&apply, Rows::block(&coef, coef_row, 0));
            strip_box_sums::<K2, _>(&st, out, 3 * w, &pass2, isa);
        }
    }
}

struct Pass1<'a, const D: usize> {
    inputs: &'a Inputs<D>,
    eps: [f32; D],
    /// Per position, 1 on the lanes inside the image: windows centred on padding are empty.
    inside: &'a [V],
}

/// The inputs of 16 pixels that the pass-1 quantities are products of.
struct Px<const D: usize> {
    m: V,
    /// `m I_a` (m is 0 or 1, so `(m I_a)(m I_b) = m I_a I_b`).
    i: [V; D],
    p: [V; 3],
}

impl<const D: usize> Px<D> {
    #[inline(always)]
    fn load(inp: &Inputs<D>, y: usize, j: usize) -> Self {
        // Loops into zeroed arrays rather than `array::from_fn`, which was compiled out of line.
        let mut px = Self::zero();
        px.m = inp.get(D + P_MASK, y, j);
        for a in 0..D {
            px.i[a] = vmul(px.m, inp.get(a, y, j));
        }
        for c in 0..3 {
            px.p[c] = inp.get(D + P_COLOR + c, y, j);
        }
        px
    }

    /// A row outside the image: contributes nothing.
    #[inline(always)]
    fn zero() -> Self {
        Self { m: [0.0; S], i: [[0.0; S]; D], p: [[0.0; S]; 3] }
    }
}

impl<const D: usize, const K1: usize> StripPass<K1> for Pass1<'_, D> {
    /// Adds / subtracts `m, m I, m I I^T, m p, m I p` of 16 pixels, in the order of [`k1`].
    /// (Written out without closures: a closure per quantity was compiled out of line,
    /// without the AVX-512 features, 1.6x slower.) A missing row is taken as zeros:
    /// `(c + q) - 0 = c + q` and `(c + 0) - q = c - q` exactly.
    #[inline(always)]
    fn update(&self, j: usize, y_add: Option<usize>, y_sub: Option<usize>, col: &mut [V; K1]) {
        if y_add.is_none() && y_sub.is_none() {
            return;
        }
        let inp = self.inputs;
        // (`match`, not `map_or_else`: its closure was compiled out of line.)
        let a = match y_add {
            Some(y) => Px::load(inp, y, j),
            None => Px::zero(),
        };
        let s = match y_sub {
            Some(y) => Px::load(inp, y, j),
            None => Px::zero(),
        };
        let mut k = 0;
        macro_rules! upd {
            ($qa:expr, $qs:expr) => {{
                col[k] = vsub(vadd(col[k], $qa), $qs);
                k += 1;
            }};
        }
        upd!(a.m, s.m);
        for t in 0..D {
            upd!(a.i[t], s.i[t]);
        }
        for t in 0..D {
            for u in t..D {
                upd!(vmul(a.i[t], a.i[u]), vmul(s.i[t], s.i[u]));
            }
        }
        for c in 0..3 {
            upd!(vmul(a.m, a.p[c]), vmul(s.m, s.p[c]));
        }
        for t in 0..D {
            for c in 0..3 {
                upd!(vmul(a.i[t], a.p[c]), vmul(s.i[t], s.p[c]));
            }
        }
        debug_assert_eq!(k, K1);
    }

    #[inline(always)]
    fn consume(&self, _y: usize, j: usize, sums: &[V; K1], out_row: &mut [f32]) {
        let k2 = 4 + 3 * D;
        let o = vecs_mut(&mut out_row[j * k2 * S..(j + 1) * k2 * S]);
        solve_lanes::<D, K1>(sums, &self.eps, &self.inside[j], o);
    }
}

/// What pass 2 needs beside the coefficients.
struct Apply<'a, const D: usize> {
    inputs: &'a Inputs<D>,
    /// Per channel, `[min, max]` of the fit pixels' colours: outputs are clamped to it.
    range: [[f32; 2]; 3],
}

impl<'a, const D: usize, const K2: usize> OnRows<K2> for Apply<'a, D> {
    type Pass<'r>
        = Pass2<'r, D, K2>
    where
        Self: 'r;
    fn on<'r>(&'r self, coef: Rows<'r>) -> Pass2<'r, D, K2> {
        Pass2 { inputs: self.inputs, coef, range: self.range }
    }
}

struct Pass2<'a, const D: usize, const K2: usize> {
    inputs: &'a Inputs<D>,
    /// The coefficient rows (a plane, a block of it or a ring: [`crate::fused`]).
    coef: Rows<'a>,
    range: [[f32; 2]; 3],
}

impl<const D: usize, const K2: usize> StripPass<K2> for Pass2<'_, D, K2> {
    #[inline(always)]
    fn update(&self, j: usize, y_add: Option<usize>, y_sub: Option<usize>, col: &mut [V; K2]) {
        let coef = |y: usize| &self.coef.get(y)[j * K2 * S..][..K2 * S];
        let c = col.as_flattened_mut();
        // Flat loops over the K2 * S values (see `stripbox::add`).
        match (y_add, y_sub) {
            (Some(a), Some(s)) => {
                for (c, (a, s)) in c.iter_mut().zip(coef(a).iter().zip(coef(s))) {
                    *c = (*c + a) - s;
                }
            }
            (Some(a), None) => c.iter_mut().zip(coef(a)).for_each(|(c, a)| *c += a),
            (None, Some(s)) => c.iter_mut().zip(coef(s)).for_each(|(c, s)| *c -= s),
            (None, None) => {}
        }
    }

    /// `q_i = mean(a) . I_i + mean(b)` over the windows that hold fit pixels, clamped to the
    /// fit range; background (or an isolated invalid pixel) passes the sanitised input
    /// through.
    #[inline(always)]
    fn consume(&self, y: usize, j: usize, s: &[V; K2], out_row: &mut [f32]) {
        let inp = self.inputs;
        let st = &inp.st;
        let n = s[0];
        let surface = inp.get(D + P_SURFACE, y, j);
        let fit: [bool; S] = std::array::from_fn(|l| surface[l] > 0.0 && n[l] > 0.5);
        let inv: V = std::array::from_fn(|l| 1.0 / if fit[l] { n[l] } else { 1.0 });
        let mut guide = [[0.0f32; S]; D];
        for a in 0..D {
            guide[a] = inp.get(a, y, j);
        }
        let mut q = [[0.0f32; S]; 3];
        for c in 0..3 {
            let p = inp.get(D + P_COLOR + c, y, j);
            let mut v = s[1 + 3 * D + c];
            for a in 0..D {
                v = vadd(v, vmul(s[1 + a * 3 + c], guide[a]));
            }
            let v = vmul(v, inv);
            let [lo, hi] = self.range[c];
            // (`max(lo).min(hi)` maps NaN to `hi`; `!is_finite` catches it first.)
            let v: V = v.map(|v| if v.is_finite() { v.max(lo).min(hi) } else { f32::NAN });
            q[c] = std::array::from_fn(|l| if fit[l] && !v[l].is_nan() { v[l] } else { p[l] });
        }
        for l in 0..st.lanes_in_image(j) {
            let x = l * st.len + j;
            for c in 0..3 {
                out_row[3 * x + c] = q[c][l];
            }
        }
    }
}

/// From the window sums `s` of 16 windows (one per lane), the ridge-regression coefficients
/// of each window, written as `[1, a (a*3+c), b (c)]`, or all zeros when the window holds no
/// fit pixel or is centred outside the image (`inside` 0). Every scalar of the solve is one
/// vector across the windows; branch-free, the divisions by the Cholesky diagonal done
/// once as reciprocals. Same operations per lane as [`solve_window`] (bit-identical, tested).
#[inline(always)]
fn solve_lanes<const D: usize, const K1: usize>(s: &[V; K1], eps: &[f32; D], inside: &V, o: &mut [V]) {
    let kp = 1 + D + D * (D + 1) / 2; // index of m p
    let kc = kp + 3; // index of m I p
                     // `c - a b` lane by lane (the same rounding as the scalar solve: no fused multiply-add).
    let fms = |c: V, a: V, b: V| -> V { vsub(c, vmul(a, b)) };
    let n = s[0];
    let inv: V = n.map(|n| 1.0 / if n >= 0.5 { n } else { 1.0 });
    let mut mi = [[0.0f32; S]; D];
    for a in 0..D {
        mi[a] = vmul(s[1 + a], inv);
    }
    // Sigma_k + eps U
    let mut sig = [[[0.0f32; S]; D]; D];
    let mut k = 1 + D;
    for a in 0..D {
        for b in a..D {
            let v = fms(vmul(s[k], inv), mi[a], mi[b]);
            sig[a][b] = v;
            sig[b][a] = v;
            k += 1;
        }
    }
    for a in 0..D {
        sig[a][a] = sig[a][a].map(|v| v.max(0.0) + eps[a]);
    }
    let mut mp = [[0.0f32; S]; 3];
    for c in 0..3 {
        mp[c] = vmul(s[kp + c], inv);
    }
    // A window counts when it holds fit pixels, is centred inside and its mean is finite.
    let ok: [bool; S] =
        std::array::from_fn(|l| n[l] >= 0.5 && inside[l] > 0.0 && (0..3).all(|c| mp[c][l].is_finite()));
    // cov_k(I, p)
    let mut cov = [[[0.0f32; S]; 3]; D];
    for a in 0..D {
        for c in 0..3 {
            cov[a][c] = fms(vmul(s[kc + a * 3 + c], inv), mi[a], mp[c]);
        }
    }
    // Cholesky Sigma = L L^T (SPD: the diagonal holds at least eps > 0); rl = 1 / L_jj.
    // `well`: every pivot at least eps / 2 (see the module docs), else the box mean.
    let mut well = [true; S];
    let mut lm = [[[0.0f32; S]; D]; D];
    let mut rl = [[0.0f32; S]; D];
    for j in 0..D {
        let mut d = sig[j][j];
        for k in 0..j {
            d = fms(d, lm[j][k], lm[j][k]);
        }
        for l in 0..S {
            well[l] &= d[l] >= 0.5 * eps[j];
        }
        let floor = 1e-12 + eps[j] * 1e-6;
        rl[j] = d.map(|v| 1.0 / v.max(floor).sqrt());
        for i in j + 1..D {
            let mut v = sig[i][j];
            for k in 0..j {
                v = fms(v, lm[i][k], lm[j][k]);
            }
            lm[i][j] = vmul(v, rl[j]);
        }
    }
    let mut a_all = [[[0.0f32; S]; D]; 3];
    let mut b_all = [[0.0f32; S]; 3];
    for c in 0..3 {
        // L y = cov_c, then L^T a = y.
        let mut y = [[0.0f32; S]; D];
        for i in 0..D {
            let mut v = cov[i][c];
            for k in 0..i {
                v = fms(v, lm[i][k], y[k]);
            }
            y[i] = vmul(v, rl[i]);
        }
        let mut a = [[0.0f32; S]; D];
        for i in (0..D).rev() {
            let mut v = y[i];
            for k in i + 1..D {
                v = fms(v, lm[k][i], a[k]);
            }
            a[i] = vmul(v, rl[i]);
        }
        let mut b = mp[c];
        for i in 0..D {
            b = fms(b, a[i], mi[i]);
        }
        for l in 0..S {
            well[l] &= b[l].is_finite() && a.iter().all(|a| a[l].is_finite());
        }
        (a_all[c], b_all[c]) = (a, b);
    }
    // Out: zeros; ill-conditioned: the box mean (a = 0, b = mean p).
    let pick = |v: V, fallback: V| -> V {
        std::array::from_fn(|l| {
            if !ok[l] {
                0.0
            } else if well[l] {
                v[l]
            } else {
                fallback[l]
            }
        })
    };
    o[0] = std::array::from_fn(|l| if ok[l] { 1.0 } else { 0.0 });
    for c in 0..3 {
        for i in 0..D {
            o[1 + i * 3 + c] = pick(a_all[c][i], [0.0; S]);
        }
        o[1 + 3 * D + c] = pick(b_all[c], mp[c]);
    }
}

/// [`solve_lanes`] for one window, written plainly: the reference the lane solve is
/// tested against (`o` as in [`solve_lanes`], 4 + 3D values).
#[cfg(test)]
fn solve_window<const D: usize, const K1: usize>(s: &[f32; K1], eps: &[f32; D], o: &mut [f32]) {
    let kp = 1 + D + D * (D + 1) / 2;
    let kc = kp + 3;
    o.fill(0.0);
    let n = s[0];
    if n < 0.5 {
        return;
    }
    let mut well = true;
    let inv = 1.0 / n;
    let mut mi = [0.0f32; D];
    for a in 0..D {
        mi[a] = s[1 + a] * inv;
    }
    let mut sig = [[0.0f32; D]; D];
    let mut k = 1 + D;
    for a in 0..D {
        for b in a..D {
            let v = s[k] * inv - mi[a] * mi[b];
            sig[a][b] = v;
            sig[b][a] = v;
            k += 1;
        }
    }
    for a in 0..D {
        sig[a][a] = sig[a][a].max(0.0) + eps[a];
    }
    let mp = [s[kp] * inv, s[kp + 1] * inv, s[kp + 2] * inv];
    if !mp.iter().all(|v| v.is_finite()) {
        return;
    }
    let mut cov = [[0.0f32; 3]; D];
    for a in 0..D {
        for c in 0..3 {
            cov[a][c] = s[kc + a * 3 + c] * inv - mi[a] * mp[c];
        }
    }
    let mut l = [[0.0f32; D]; D];
    let mut rl = [0.0f32; D];
    for j in 0..D {
        let mut d = sig[j][j];
        for k in 0..j {
            d -= l[j][k] * l[j][k];
        }
        well &= d >= 0.5 * eps[j];
        rl[j] = 1.0 / d.max(1e-12 + eps[j] * 1e-6).sqrt();
        for i in j + 1..D {
            let mut v = sig[i][j];
            for k in 0..j {
                v -= l[i][k] * l[j][k];
            }
            l[i][j] = v * rl[j];
        }
    }
    let mut ab = [([0.0f32; D], 0.0f32); 3];
    for c in 0..3 {
        let mut y = [0.0f32; D];
        for i in 0..D {
            let mut v = cov[i][c];
            for k in 0..i {
                v -= l[i][k] * y[k];
            }
            y[i] = v * rl[i];
        }
        let mut a = [0.0f32; D];
        for i in (0..D).rev() {
            let mut v = y[i];
            for k in i + 1..D {
                v -= l[k][i] * a[k];
            }
            a[i] = v * rl[i];
        }
        let mut b = mp[c];
        for i in 0..D {
            b -= a[i] * mi[i];
        }
        well &= b.is_finite() && a.iter().all(|a| a.is_finite());
        ab[c] = (a, b);
    }
    o[0] = 1.0;
    for (c, (a, b)) in ab.into_iter().enumerate() {
        for i in 0..D {
            o[1 + i * 3 + c] = if well { a[i] } else { 0.0 };
        }
        o[1 + 3 * D + c] = if well { b } else { mp[c] };
    }
}

#[cfg(test)]
mod lane_tests {
    use super::*;

    /// A window whose sums are spoilt by rounding (a computed `Sigma` that is not positive
    /// semi-definite, or sums that overflowed) falls back to the box mean `a = 0`,
    /// `b = mean(p)`, or is skipped when even the mean is not finite; lanes and the scalar
    /// solve agree bit for bit.
    #[test]
    fn ill_conditioned_windows_fall_back_to_the_box_mean() {
        const D: usize = 4;
        const K1: usize = k1(D);
        let kp = 1 + D + D * (D + 1) / 2;
        let eps = [0.01, 0.01, 0.01, 0.02];
        let mut sums = [[0.0f32; K1]; S];
        for (l, s) in sums.iter_mut().enumerate() {
            s[0] = 10.0;
            // Mean guide 0.5 but mean square ~0: variance -0.25 (impossible).
            s[1..1 + D].fill(5.0);
            // Off-diagonal `I_0 I_1` sums huge: an indefinite Sigma.
            s[1 + D + 1] = 1e6 * l as f32;
            s[kp..kp + 3].copy_from_slice(&[3.0, 4.0, 5.0]);
            s[kp + 3..].fill(1e5);
            if l == 5 {
                s[kp] = f32::INFINITY; // an overflowed colour sum: window skipped
            }
        }
        let lanes: [V; K1] = std::array::from_fn(|k| std::array::from_fn(|l| sums[l][k]));
        let mut o = [[7.0f32; S]; k2(D)];
        solve_lanes::<D, K1>(&lanes, &eps, &[1.0; S], &mut o);
        for l in 0..S {
            let mut one = [7.0f32; k2(D)];
            solve_window::<D, K1>(&sums[l], &eps, &mut one);
            let got: Vec<f32> = o.iter().map(|v| v[l]).collect();
            assert_eq!(got, one, "lane {l}");
            let want: Vec<f32> = if l == 5 {
                vec![0.0; k2(D)]
            } else {
                [1.0].into_iter().chain([0.0; 3 * D]).chain([0.3, 0.4, 0.5]).collect()
            };
            assert_eq!(got, want, "lane {l}");
        }
    }

    /// The 16-lane solve is bit-identical to the per-window solve, empty windows and windows
    /// centred outside the image included.
    #[test]
    fn lane_solve_matches_scalar_solve() {
        const D: usize = 4;
        const K1: usize = k1(D);
        let (kp, kc) = (1 + D + D * (D + 1) / 2, 1 + D + D * (D + 1) / 2 + 3);
        let mut state = 12345u32;
        let mut rnd = move || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
        let eps = [1e-3, 2e-3, 1e-2, 5e-4];
        for trial in 0..50 {
            // Window sums of random pixel sets (so Sigma is a real covariance).
            let mut sums = [[0.0f32; K1]; S];
            for (l, s) in sums.iter_mut().enumerate() {
                let count = if (trial + l) % 7 == 0 { 0 } else { 1 + (trial * 3 + l) % 20 };
                for _ in 0..count {
                    let i: [f32; D] = std::array::from_fn(|_| rnd());
                    let p: [f32; 3] = std::array::from_fn(|_| rnd() * 2.0);
                    s[0] += 1.0;
                    let mut k = 1;
                    for a in 0..D {
                        s[k] += i[a];
                        k += 1;
                    }
                    for a in 0..D {
                        for b in a..D {
                            s[k] += i[a] * i[b];
                            k += 1;
                        }
                    }
                    for c in 0..3 {
                        s[kp + c] += p[c];
                    }
                    for a in 0..D {
                        for c in 0..3 {
                            s[kc + a * 3 + c] += i[a] * p[c];
                        }
                    }
                }
            }
            let lanes: [V; K1] = std::array::from_fn(|k| std::array::from_fn(|l| sums[l][k]));
            let inside: V = std::array::from_fn(|l| if (trial + l) % 11 == 3 { 0.0 } else { 1.0 });
            let mut o = [[7.0f32; S]; k2(D)];
            solve_lanes::<D, K1>(&lanes, &eps, &inside, &mut o);
            for l in 0..S {
                let mut one = [7.0f32; k2(D)];
                if inside[l] > 0.0 {
                    solve_window::<D, K1>(&sums[l], &eps, &mut one);
                } else {
                    one = [0.0; k2(D)];
                }
                let got: Vec<f32> = o.iter().map(|v| v[l]).collect();
                assert_eq!(got, one, "trial {trial} lane {l}");
            }
        }
    }
}
