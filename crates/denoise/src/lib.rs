//! # filtrace-denoise
//!
//! Screen-space reconstruction filters for Monte Carlo renderings. They see only images: a
//! noisy colour (or illumination) [`Image`] and a [`GBuffer`] of guide images (normal,
//! position, depth, albedo), never a scene, so they also denoise AOVs written by other
//! renderers.
//!
//! - [`atrous`]: edge-avoiding À-Trous wavelet filter (Dammertz et al. 2010), 25 taps per
//!   pixel and iteration, the fast default;
//! - [`guided`]: guided image filter (Bauszat et al. 2011 §3.3, He et al. 2010), cost
//!   independent of the radius;
//! - [`bilateral`]: cross-bilateral filter computed directly, the quality reference;
//! - [`demodulate`]/[`remodulate`]: filter illumination, keep textures sharp.
//!
//! Inputs are validated (sizes, channel counts, parameters) into a [`DenoiseError`]. Pixels
//! whose normal is zero are background and never mixed with surface pixels; non-finite
//! colour values never spread (see [`gbuffer`]). The filters are normalised weighted
//! averages: a constant image stays constant, and the image mean is preserved up to the
//! filter's local renormalisation (tested).
//!
//! ```
//! use filtrace_core::Image;
//! use filtrace_denoise::{Filter, GBuffer, AtrousParams};
//! let color = Image::filled(32, 16, 3, 0.5);
//! let normal = Image::from_vec(32, 16, 3, [0.0, 0.0, 1.0].repeat(32 * 16)).unwrap();
//! let guide = GBuffer::new(normal);
//! let params = AtrousParams { sigma_position: None, ..AtrousParams::paper() };
//! let out = Filter::Atrous(params).apply(&color, &guide).unwrap();
//! assert!(out.data().iter().all(|v| (v - 0.5).abs() < 1e-6));
//! ```

// Index loops over small fixed dimensions read like the papers' equations.
#![allow(clippy::needless_range_loop)]

pub mod atrous;
pub mod bench_input;
pub mod bilateral;
mod chains;
pub mod demodulate;
pub mod error;
mod fused;
pub mod gbuffer;
pub mod guided;
mod kernel;
mod pool;
pub mod simd;
mod stripbox;
mod symmetric;

#[cfg(test)]
mod tests;

pub use atrous::{atrous, atrous_into, AtrousParams};
pub use bilateral::{bilateral, bilateral_into, BilateralParams};
pub use demodulate::{demodulate, remodulate, DEFAULT_ALBEDO_EPS};
pub use error::DenoiseError;
pub use filtrace_core::Image;
pub use gbuffer::GBuffer;
pub use guided::{guided, guided_into, Guidance, GuidedParams};

use serde::{Deserialize, Serialize};

/// One of the filters with its parameters, for callers that choose at run time
/// (pipeline, CLI).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Filter {
    Atrous(AtrousParams),
    Guided(GuidedParams),
    Bilateral(BilateralParams),
}

impl Filter {
    pub fn name(&self) -> &'static str {
        match self {
            Self::Atrous(_) => "atrous",
            Self::Guided(_) => "guided",
            Self::Bilateral(_) => "bilateral",
        }
    }

    /// The filter by name (`atrous`, `guided`, `bilateral`) with its paper preset.
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "atrous" | "a-trous" | "atrous-wavelet" => Some(Self::Atrous(AtrousParams::paper())),
            "guided" => Some(Self::Guided(GuidedParams::paper())),
            "bilateral" | "cross-bilateral" => Some(Self::Bilateral(BilateralParams::reference())),
            _ => None,
        }
    }

    /// Filters `color` (3 channels) guided by `guide`.
    pub fn apply(&self, color: &Image, guide: &GBuffer) -> Result<Image, DenoiseError> {
        let mut out = Image::new(color.width(), color.height(), 3);
        self.apply_into(color, guide, &mut out)?;
        Ok(out)
    }

    /// [`Filter::apply`] into a reused buffer.
    pub fn apply_into(&self, color: &Image, guide: &GBuffer, out: &mut Image) -> Result<(), DenoiseError> {
        match self {
            Self::Atrous(p) => atrous_into(color, guide, p, out),
            Self::Guided(p) => guided_into(color, guide, p, out),
            Self::Bilateral(p) => bilateral_into(color, guide, p, out),
        }
    }

    /// Filters the illumination `color / max(albedo, eps)` and multiplies the albedo back
    /// (Dammertz et al. 2010, deferred shading). Needs `guide.albedo`.
    ///
    /// Pixels whose albedo is below `eps` in every channel (black surfaces, emitters written
    /// with a black albedo) carry no usable illumination: they are left out of the filter
    /// (like non-finite values: never spread) and keep their input colour. Without this an
    /// emitter's `L / eps` would flood the geometry-only filters' neighbourhood.
    pub fn apply_demodulated(&self, color: &Image, guide: &GBuffer, eps: f32) -> Result<Image, DenoiseError> {
        let albedo = guide
            .albedo
            .as_ref()
            .ok_or(DenoiseError::MissingGuide { buffer: "albedo", needed_by: "demodulation" })?;
        let mut illum = demodulate(color, albedo, eps)?;
        let black = |a: &[f32]| !a.iter().any(|v| v.is_finite() && *v >= eps);
        for (px, a) in illum.data_mut().chunks_exact_mut(3).zip(albedo.data().chunks_exact(3)) {
            if black(a) {
                px.fill(f32::NAN);
            }
        }
        let filtered = self.apply(&illum, guide)?;
        let mut out = remodulate(&filtered, albedo, eps)?;
        for ((o, c), a) in out
            .data_mut()
            .chunks_exact_mut(3)
            .zip(color.data().chunks_exact(3))
            .zip(albedo.data().chunks_exact(3))
        {
            if black(a) {
                for (o, c) in o.iter_mut().zip(c) {
                    *o = if gbuffer::is_valid_color(*c) { *c } else { 0.0 };
                }
            }
        }
        Ok(out)
    }
}
