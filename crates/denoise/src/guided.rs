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
//! Every window mean comes from `O(N)` running box sums ([`crate::boxsum`]): the cost does not
//! depend on the radius. The `D x D` system is solved per pixel by Cholesky.
//!
//! Background and invalid pixels: window statistics use only surface pixels with a finite
//! colour (a mask `m` multiplies every sum), windows holding none are skipped in the
//! averaging, so background never leaks into surfaces. Background pixels are passed through
//! (non-finite values replaced by 0); surface pixels with an invalid colour get the fit of
//! their neighbours.
//!
//! When to use: smooth indirect illumination at a fixed cost for any radius (Bauszat uses
//! radius 24-32, eps 0.01 for normals and 0.01-0.03 for depth). Edges that the guidance does
//! not show (shadows, texture) are smoothed away: filter demodulated illumination.

use crate::boxsum::{box_sums, BoxPass};
use crate::error::{invalid, DenoiseError};
use crate::gbuffer::{check_color, to_planes, GBuffer, Guides, Planes3};
use crate::pool::Buf;
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

/// The guidance planes, centred (`I - 0.5`, which leaves `a` unchanged and keeps the running
/// sums small), and the `eps` of each.
pub(crate) fn guidance_planes(g: &Guides, p: &GuidedParams) -> Result<(Vec<Buf>, Vec<f32>), DenoiseError> {
    let n = &g.normal;
    let map = |src: &[f32], f: &(dyn Fn(f32) -> f32 + Sync)| {
        let mut b = Buf::uninit(src.len());
        b.par_iter_mut().zip(src.par_iter()).for_each(|(o, v)| *o = f(*v));
        b
    };
    Ok(match p.guidance {
        Guidance::GreyNormal => {
            let mut grey = Buf::uninit(g.width * g.height);
            grey.par_iter_mut().enumerate().for_each(|(i, o)| *o = (n[0][i] + n[1][i] + n[2][i]) / 6.0);
            (vec![grey], vec![p.eps_normal])
        }
        Guidance::Normal => {
            let planes = (0..3).map(|c| map(&n[c], &|v| 0.5 * v)).collect();
            (planes, vec![p.eps_normal; 3])
        }
        Guidance::NormalDepth => {
            let d = g.depth.as_ref().ok_or(DenoiseError::MissingGuide {
                buffer: "depth",
                needed_by: "guided filter with normal+depth guidance",
            })?;
            let mut planes: Vec<Buf> = (0..3).map(|c| map(&n[c], &|v| 0.5 * v)).collect();
            planes.push(map(d, &|v| v - 0.5));
            (planes, vec![p.eps_normal, p.eps_normal, p.eps_normal, p.eps_depth])
        }
    })
}

/// Filters `color` (3 channels) guided by `guide`. See the module docs.
pub fn guided(color: &Image, guide: &GBuffer, params: &GuidedParams) -> Result<Image, DenoiseError> {
    let mut out = Image::new(color.width(), color.height(), 3);
    guided_into(color, guide, params, &mut out)?;
    Ok(out)
}

/// [`guided`] writing into `out` (resized when it differs).
pub fn guided_into(
    color: &Image,
    guide: &GBuffer,
    params: &GuidedParams,
    out: &mut Image,
) -> Result<(), DenoiseError> {
    check_color(color)?;
    params.validate()?;
    let g = Guides::new(guide, color.width(), color.height())?;
    let (planes, eps) = guidance_planes(&g, params)?;
    let (p, valid) = to_planes(color);
    let mut mask = Buf::uninit(g.width * g.height);
    mask.par_iter_mut().zip(g.surface.par_iter().zip(valid.par_iter())).for_each(|(m, (s, v))| *m = s * v);
    if out.width() != color.width() || out.height() != color.height() || out.channels() != 3 {
        *out = Image::new(color.width(), color.height(), 3);
    }
    let args =
        Args { w: g.width, h: g.height, r: params.radius as usize, mask: &mask, surface: &g.surface, p: &p };
    match planes.len() {
        1 => guided_impl::<1, 16, 8>(&args, &[&planes[0]], [eps[0]], out),
        3 => guided_impl::<3, 24, 16>(
            &args,
            &[&planes[0], &planes[1], &planes[2]],
            [eps[0], eps[1], eps[2]],
            out,
        ),
        _ => guided_impl::<4, 32, 16>(
            &args,
            &[&planes[0], &planes[1], &planes[2], &planes[3]],
            [eps[0], eps[1], eps[2], eps[3]],
            out,
        ),
    }
    Ok(())
}

pub(crate) struct Args<'a> {
    pub w: usize,
    pub h: usize,
    pub r: usize,
    /// 1 where the pixel takes part in the fit (surface with a finite colour).
    pub mask: &'a [f32],
    pub surface: &'a [f32],
    pub p: &'a Planes3,
}

/// Number of pass-1 quantities: `m, m I (D), m I I^T (upper, D(D+1)/2), m p (3), m I p (3D)`.
const fn k1_used(d: usize) -> usize {
    1 + d + d * (d + 1) / 2 + 3 + 3 * d
}

/// `K1`, `K2`: padded quantity counts of the two box passes (pass 2 sums
/// `[indicator, a (3D), b (3)]`).
fn guided_impl<const D: usize, const K1: usize, const K2: usize>(
    args: &Args,
    guide: &[&[f32]; D],
    eps: [f32; D],
    out: &mut Image,
) {
    assert!(k1_used(D) <= K1 && 4 + 3 * D <= K2);
    let (w, h, r) = (args.w, args.h, args.r);
    let kp = 1 + D + D * (D + 1) / 2; // index of m p
    let kc = kp + 3; // index of m I p

    // Pass 1: window statistics -> per-window coefficients (a_k, b_k) (eqs. 8-9).
    let mut coef = crate::pool::take(w * h * K2);
    let pass1 = Pass1::<D> { args, guide, eps, kp, kc };
    box_sums::<K1, _>(w, h, r, &mut coef, K2, &pass1);
    // Pass 2: average the coefficients over the windows covering each pixel and apply them.
    let pass2 = Pass2::<D, K2> { args, guide, coef: &coef };
    box_sums::<K2, _>(w, h, r, out.data_mut(), 3, &pass2);
    crate::pool::give(coef);
}

struct Pass1<'a, const D: usize> {
    args: &'a Args<'a>,
    guide: &'a [&'a [f32]; D],
    eps: [f32; D],
    kp: usize,
    kc: usize,
}

impl<const D: usize, const K1: usize> BoxPass<K1> for Pass1<'_, D> {
    /// `m, m I, m I I^T, m p, m I p` of a pixel.
    #[inline(always)]
    fn quantities(&self, x: usize, y: usize) -> [f32; K1] {
        let (args, kp, kc) = (self.args, self.kp, self.kc);
        let j = y * args.w + x;
        let m = args.mask[j];
        let mut i = [0.0f32; D];
        for a in 0..D {
            i[a] = m * self.guide[a][j];
        }
        let p = [args.p[0][j], args.p[1][j], args.p[2][j]];
        let mut q = [0.0f32; K1];
        q[0] = m;
        let mut k = 1;
        for a in 0..D {
            q[k] = i[a];
            k += 1;
        }
        // m I_a I_b = (m I_a) I_b / m... m is 0 or 1, so (m I_a)(m I_b) is the same.
        for a in 0..D {
            for b in a..D {
                q[k] = i[a] * i[b];
                k += 1;
            }
        }
        for c in 0..3 {
            q[kp + c] = m * p[c];
        }
        for a in 0..D {
            for c in 0..3 {
                q[kc + a * 3 + c] = i[a] * p[c];
            }
        }
        q
    }

    #[inline(always)]
    fn consume(&self, _x0: usize, _y: usize, sums: &[[f32; K1]], out: &mut [f32]) {
        let k2 = out.len() / sums.len();
        // 8 windows at a time across SIMD lanes; the remainder one by one.
        let full = sums.len() / LANES * LANES;
        for (s, o) in sums[..full].chunks_exact(LANES).zip(out.chunks_exact_mut(k2 * LANES)) {
            solve_windows_lanes::<D, K1>(s, &self.eps, self.kp, self.kc, o);
        }
        for (s, o) in sums[full..].iter().zip(out[full * k2..].chunks_exact_mut(k2)) {
            solve_window::<D, K1>(s, &self.eps, self.kp, self.kc, o);
        }
    }
}

struct Pass2<'a, const D: usize, const K2: usize> {
    args: &'a Args<'a>,
    guide: &'a [&'a [f32]; D],
    coef: &'a [f32],
}

impl<const D: usize, const K2: usize> BoxPass<K2> for Pass2<'_, D, K2> {
    #[inline(always)]
    fn quantities(&self, x: usize, y: usize) -> [f32; K2] {
        let j = (y * self.args.w + x) * K2;
        let mut q = [0.0f32; K2];
        q.copy_from_slice(&self.coef[j..j + K2]);
        q
    }

    /// `q_i = mean(a) . I_i + mean(b)` over the windows that hold fit pixels.
    #[inline(always)]
    fn consume(&self, x0: usize, y: usize, sums: &[[f32; K2]], out: &mut [f32]) {
        let (args, guide) = (self.args, self.guide);
        let o = y * args.w + x0;
        for (x, (s, px)) in sums.iter().zip(out.chunks_exact_mut(3)).enumerate() {
            let i = o + x;
            let n = s[0];
            if args.surface[i] > 0.0 && n > 0.5 {
                let inv = 1.0 / n;
                for c in 0..3 {
                    let mut q = s[1 + 3 * D + c];
                    for a in 0..D {
                        q += s[1 + a * 3 + c] * guide[a][i];
                    }
                    px[c] = q * inv;
                }
            } else {
                // Background (or an isolated invalid pixel): pass the sanitised input through.
                for c in 0..3 {
                    px[c] = args.p[c][i];
                }
            }
        }
    }
}

/// Windows solved together by [`solve_windows_lanes`].
const LANES: usize = 8;

/// [`solve_window`] for `LANES` windows at once, every scalar of the solve held as one value
/// per window (`[f32; LANES]`) so that each step is a vector operation across windows.
/// Same operations in the same order per window, so the results are bit-identical to
/// [`solve_window`] (tested); windows without a fit pixel are computed with `n = 1` and
/// then written as zeros.
#[inline(always)]
fn solve_windows_lanes<const D: usize, const K1: usize>(
    s: &[[f32; K1]],
    eps: &[f32; D],
    kp: usize,
    kc: usize,
    o: &mut [f32],
) {
    type V = [f32; LANES];
    let s: &[[f32; K1]; LANES] = s.try_into().expect("LANES windows");
    let k2 = o.len() / LANES;
    let get = |k: usize| -> V { std::array::from_fn(|l| s[l][k]) };
    let n = get(0);
    let ok: [bool; LANES] = std::array::from_fn(|l| n[l] >= 0.5);
    let inv: V = std::array::from_fn(|l| 1.0 / if ok[l] { n[l] } else { 1.0 });
    let mut mi = [[0.0f32; LANES]; D];
    for a in 0..D {
        let v = get(1 + a);
        mi[a] = std::array::from_fn(|l| v[l] * inv[l]);
    }
    let mut sig = [[[0.0f32; LANES]; D]; D];
    let mut k = 1 + D;
    for a in 0..D {
        for b in a..D {
            let sk = get(k);
            let v: V = std::array::from_fn(|l| sk[l] * inv[l] - mi[a][l] * mi[b][l]);
            sig[a][b] = v;
            sig[b][a] = v;
            k += 1;
        }
    }
    for a in 0..D {
        for l in 0..LANES {
            sig[a][a][l] = sig[a][a][l].max(0.0) + eps[a];
        }
    }
    let mut mp = [[0.0f32; LANES]; 3];
    for c in 0..3 {
        let v = get(kp + c);
        mp[c] = std::array::from_fn(|l| v[l] * inv[l]);
    }
    let mut cov = [[[0.0f32; LANES]; 3]; D];
    for a in 0..D {
        for c in 0..3 {
            let v = get(kc + a * 3 + c);
            cov[a][c] = std::array::from_fn(|l| v[l] * inv[l] - mi[a][l] * mp[c][l]);
        }
    }
    let mut lm = [[[0.0f32; LANES]; D]; D];
    for j in 0..D {
        let mut d = sig[j][j];
        for k in 0..j {
            for l in 0..LANES {
                d[l] -= lm[j][k][l] * lm[j][k][l];
            }
        }
        let ljj: V = std::array::from_fn(|l| d[l].max(1e-12 + eps[j] * 1e-6).sqrt());
        lm[j][j] = ljj;
        for i in j + 1..D {
            let mut v = sig[i][j];
            for k in 0..j {
                for l in 0..LANES {
                    v[l] -= lm[i][k][l] * lm[j][k][l];
                }
            }
            lm[i][j] = std::array::from_fn(|l| v[l] / ljj[l]);
        }
    }
    let mut res = [[[0.0f32; LANES]; 3]; D];
    let mut bres = [[0.0f32; LANES]; 3];
    for c in 0..3 {
        let mut y = [[0.0f32; LANES]; D];
        for i in 0..D {
            let mut v = cov[i][c];
            for k in 0..i {
                for l in 0..LANES {
                    v[l] -= lm[i][k][l] * y[k][l];
                }
            }
            y[i] = std::array::from_fn(|l| v[l] / lm[i][i][l]);
        }
        let mut a = [[0.0f32; LANES]; D];
        for i in (0..D).rev() {
            let mut v = y[i];
            for k in i + 1..D {
                for l in 0..LANES {
                    v[l] -= lm[k][i][l] * a[k][l];
                }
            }
            a[i] = std::array::from_fn(|l| v[l] / lm[i][i][l]);
        }
        let mut b = mp[c];
        for i in 0..D {
            res[i][c] = a[i];
            for l in 0..LANES {
                b[l] -= a[i][l] * mi[i][l];
            }
        }
        bres[c] = b;
    }
    for (l, ol) in o.chunks_exact_mut(k2).enumerate() {
        ol.fill(0.0);
        if !ok[l] {
            continue;
        }
        ol[0] = 1.0;
        for c in 0..3 {
            for i in 0..D {
                ol[1 + i * 3 + c] = res[i][c][l];
            }
            ol[1 + 3 * D + c] = bres[c][l];
        }
    }
}

/// From the window sums `s`, the ridge-regression coefficients of one window, written as
/// `[1, a (a*3+c), b (c), 0...]`, or all zeros when the window holds no fit pixel.
#[inline(always)]
fn solve_window<const D: usize, const K1: usize>(
    s: &[f32; K1],
    eps: &[f32; D],
    kp: usize,
    kc: usize,
    o: &mut [f32],
) {
    o.fill(0.0);
    let n = s[0];
    if n < 0.5 {
        return;
    }
    let inv = 1.0 / n;
    let mut mi = [0.0f32; D];
    for a in 0..D {
        mi[a] = s[1 + a] * inv;
    }
    // Sigma_k + eps U
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
    // cov_k(I, p)
    let mut cov = [[0.0f32; 3]; D];
    for a in 0..D {
        for c in 0..3 {
            cov[a][c] = s[kc + a * 3 + c] * inv - mi[a] * mp[c];
        }
    }
    // Cholesky Sigma = L L^T (SPD: the diagonal holds at least eps > 0).
    let mut l = [[0.0f32; D]; D];
    for j in 0..D {
        let mut d = sig[j][j];
        for k in 0..j {
            d -= l[j][k] * l[j][k];
        }
        let ljj = d.max(1e-12 + eps[j] * 1e-6).sqrt();
        l[j][j] = ljj;
        for i in j + 1..D {
            let mut v = sig[i][j];
            for k in 0..j {
                v -= l[i][k] * l[j][k];
            }
            l[i][j] = v / ljj;
        }
    }
    o[0] = 1.0;
    for c in 0..3 {
        // L y = cov_c, then L^T a = y.
        let mut y = [0.0f32; D];
        for i in 0..D {
            let mut v = cov[i][c];
            for k in 0..i {
                v -= l[i][k] * y[k];
            }
            y[i] = v / l[i][i];
        }
        let mut a = [0.0f32; D];
        for i in (0..D).rev() {
            let mut v = y[i];
            for k in i + 1..D {
                v -= l[k][i] * a[k];
            }
            a[i] = v / l[i][i];
        }
        let mut b = mp[c];
        for i in 0..D {
            o[1 + i * 3 + c] = a[i];
            b -= a[i] * mi[i];
        }
        o[1 + 3 * D + c] = b;
    }
}

#[cfg(test)]
mod lane_tests {
    use super::*;

    /// The 8-lane solve is bit-identical to the per-window solve, empty windows included.
    #[test]
    fn lane_solve_matches_scalar_solve() {
        const D: usize = 4;
        const K1: usize = 32;
        let (kp, kc) = (1 + D + D * (D + 1) / 2, 1 + D + D * (D + 1) / 2 + 3);
        let mut state = 12345u32;
        let mut rnd = move || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
        let eps = [1e-3, 2e-3, 1e-2, 5e-4];
        for trial in 0..50 {
            // Window sums of random pixel sets (so Sigma is a real covariance).
            let mut sums = [[0.0f32; K1]; LANES];
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
            let k2 = 4 + 3 * D;
            let mut lanes = vec![7.0f32; k2 * LANES];
            solve_windows_lanes::<D, K1>(&sums, &eps, kp, kc, &mut lanes);
            for l in 0..LANES {
                let mut one = vec![7.0f32; k2];
                solve_window::<D, K1>(&sums[l], &eps, kp, kc, &mut one);
                assert_eq!(&lanes[l * k2..(l + 1) * k2], &one[..], "trial {trial} lane {l}");
            }
        }
    }
}
