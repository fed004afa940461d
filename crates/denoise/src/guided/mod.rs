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
//! reversal" discussion), and a covariance system spoilt by rounding (huge guide values,
//! such as undetected background depths: docs/perf-filters.md, Cycles frames) can make it
//! explode. So:
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

use crate::error::{invalid, require_positive, DenoiseError};
use crate::gbuffer::{check_color, GBuffer};
use crate::pool::Buf;
use crate::simd::Isa;
use crate::stripbox::{strip_box_sums, Strips, S, V};
use filtrace_core::Image;
use serde::{Deserialize, Serialize};

mod inputs;
mod passes;
mod solve;

use inputs::Inputs;
use passes::{Pass1, Pass2};

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
        require_positive("eps_normal", self.eps_normal)?;
        require_positive("eps_depth", self.eps_depth)
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
    let mut out = Image::new(color.width(), color.height(), 3);
    guided_into_isa(color, guide, params, &mut out, isa)?;
    Ok(out)
}

/// [`guided`] writing into `out` (resized when it differs).
pub fn guided_into(
    color: &Image,
    guide: &GBuffer,
    params: &GuidedParams,
    out: &mut Image,
) -> Result<(), DenoiseError> {
    guided_into_isa(color, guide, params, out, crate::simd::isa())
}

fn guided_into_isa(
    color: &Image,
    guide: &GBuffer,
    params: &GuidedParams,
    out: &mut Image,
    isa: Isa,
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
        Guidance::GreyNormal => guided_impl::<1, { k1(1) }, { k2(1) }>(color, guide, r, [en], out, isa),
        Guidance::Normal => guided_impl::<3, { k1(3) }, { k2(3) }>(color, guide, r, [en; 3], out, isa),
        Guidance::NormalDepth => {
            guided_impl::<4, { k1(4) }, { k2(4) }>(color, guide, r, [en, en, en, ed], out, isa)
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

/// `K1`, `K2`: quantity counts of the two box passes (see [`k1`], [`k2`]).
fn guided_impl<const D: usize, const K1: usize, const K2: usize>(
    color: &Image,
    g: &GBuffer,
    r: usize,
    eps: [f32; D],
    out: &mut Image,
    isa: Isa,
) {
    let (w, h) = (color.width(), color.height());
    let st = Strips::new(w, h, r);
    let inputs = Inputs::<D>::new(color, g, st, isa);
    // Pass 1: window statistics -> per-window coefficients (a_k, b_k) (eqs. 8-9), written per
    // row as `len` positions of K2 vectors.
    let coef_row = st.len * K2 * S;
    let mut coef = Buf::uninit(h * coef_row);
    let inside: Vec<V> = (0..st.len).map(|j| st.inside(j)).collect();
    let pass1 = Pass1::<D> { inputs: &inputs, eps, inside: &inside };
    strip_box_sums::<K1, _>(&st, &mut coef, coef_row, &pass1, isa);
    // Pass 2: average the coefficients over the windows covering each pixel and apply them.
    let pass2 = Pass2::<D, K2> { inputs: &inputs, coef: &coef, row: coef_row, range: inputs.fit_range() };
    strip_box_sums::<K2, _>(&st, out.data_mut(), 3 * w, &pass2, isa);
}
