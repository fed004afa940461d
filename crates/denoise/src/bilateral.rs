//! Cross-bilateral filter, computed directly: the quality reference of Bauszat et al. 2011
//! (§4, after Petschnigg et al. 2004 and Eisemann & Durand 2004).
//!
//! `c_out(p) = sum_q G_s(|p - q|) w_rt w_n w_x c(q) / sum_q G_s w_rt w_n w_x` over the full
//! `(2r+1)^2` window, with a Gaussian spatial kernel `G_s` and the same edge-stopping terms as
//! the À-Trous filter (without the step-width scaling). Cost `O(r^2)` per pixel: a reference
//! to judge the fast filters against, not an interactive filter.

use crate::error::{invalid, require_positive, require_positive_sigmas, DenoiseError};
use crate::gbuffer::{check_color, from_planes, to_planes, GBuffer, Guides, Planes3};
use crate::kernel::{edge_avoiding_pass, RangeTerms, Tap};
use crate::pool::Buf;
use filtrace_core::Image;
use serde::{Deserialize, Serialize};

/// Parameters of [`bilateral`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BilateralParams {
    /// Window radius `r` in pixels, 1..=64 (Bauszat's Table 2: 16, 24, 32).
    pub radius: u32,
    /// Standard deviation of the Gaussian spatial kernel, in pixels.
    pub sigma_spatial: f32,
    /// Colour range term (`None`: geometry-only cross-bilateral).
    pub sigma_color: Option<f32>,
    /// Normal range term (unit normals).
    pub sigma_normal: Option<f32>,
    /// Position range term, in units of the scene scale.
    pub sigma_position: Option<f32>,
}

impl BilateralParams {
    /// Bauszat et al.'s reference: radius 16, spatial sigma r/2, geometry-only range terms
    /// (normal and position, the values of [`crate::AtrousParams::paper`]).
    pub fn reference() -> Self {
        Self {
            radius: 16,
            sigma_spatial: 8.0,
            sigma_color: None,
            sigma_normal: Some(0.3),
            sigma_position: Some(0.05),
        }
    }
    /// Radius 32 (the widest in Bauszat's Table 2).
    pub fn reference_wide() -> Self {
        Self { radius: 32, sigma_spatial: 16.0, ..Self::reference() }
    }
    /// A small window for tests and previews.
    pub fn small() -> Self {
        Self { radius: 4, sigma_spatial: 2.0, ..Self::reference() }
    }
    pub fn presets() -> [(&'static str, Self); 3] {
        [
            ("reference", Self::reference()),
            ("reference_wide", Self::reference_wide()),
            ("small", Self::small()),
        ]
    }

    pub fn validate(&self) -> Result<(), DenoiseError> {
        if !(1..=64).contains(&self.radius) {
            return Err(invalid("radius", format!("must be 1..=64, got {}", self.radius)));
        }
        require_positive("sigma_spatial", self.sigma_spatial)?;
        require_positive_sigmas(self.sigma_color, self.sigma_normal, self.sigma_position)
    }
}

impl Default for BilateralParams {
    fn default() -> Self {
        Self::reference()
    }
}

pub(crate) fn bilateral_taps(p: &BilateralParams) -> Vec<Tap> {
    let r = p.radius as isize;
    let k = -0.5 / (p.sigma_spatial * p.sigma_spatial);
    let mut taps = Vec::with_capacity(((2 * r + 1) * (2 * r + 1)) as usize);
    for dy in -r..=r {
        for dx in -r..=r {
            taps.push(Tap { dx, dy, h: ((dx * dx + dy * dy) as f32 * k).exp() });
        }
    }
    taps
}

/// Filters `color` (3 channels) guided by `guide`. See the module docs.
pub fn bilateral(color: &Image, guide: &GBuffer, params: &BilateralParams) -> Result<Image, DenoiseError> {
    let mut out = Image::new(color.width(), color.height(), 3);
    bilateral_into(color, guide, params, &mut out)?;
    Ok(out)
}

/// [`bilateral`] writing into `out` (resized when it differs).
pub fn bilateral_into(
    color: &Image,
    guide: &GBuffer,
    params: &BilateralParams,
    out: &mut Image,
) -> Result<(), DenoiseError> {
    check_color(color)?;
    params.validate()?;
    let g = Guides::new(guide, color.width(), color.height())?;
    g.require_position(params.sigma_position)?;
    let (src, valid) = to_planes(color);
    let src = if valid.contains(&0.0) {
        crate::atrous::inpaint_invalid(&src, &valid, color.width(), color.height(), color.width())
    } else {
        src
    };
    let n = color.pixel_count();
    let mut dst: Planes3 = [Buf::zeros(n), Buf::zeros(n), Buf::zeros(n)];
    let terms = RangeTerms {
        inv_color: params.sigma_color.map(|s| 1.0 / (s * s)),
        inv_normal: params.sigma_normal.map(|s| 1.0 / (s * s)),
        inv_position: params.sigma_position.map(|s| 1.0 / (s * s)),
    };
    edge_avoiding_pass(&src, Some(&valid), &g, &bilateral_taps(params), terms, &mut dst);
    if out.width() != color.width() || out.height() != color.height() || out.channels() != 3 {
        *out = Image::new(color.width(), color.height(), 3);
    }
    from_planes(&dst, out);
    Ok(())
}
