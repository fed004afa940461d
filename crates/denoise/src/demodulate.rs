//! Albedo demodulation (Dammertz et al. 2010, §3 "Deferred Shading"): filter the illumination
//! `L / max(albedo, eps)` instead of the colour and multiply the albedo back afterwards, so
//! texture and material detail, which the filters would blur, stay sharp.
//!
//! The same `max(albedo, eps)` is used both ways, so demodulation followed by remodulation
//! returns the input exactly (up to rounding) for any albedo, black included.

use crate::error::{require_positive, DenoiseError};
use filtrace_core::Image;

/// Default `eps`: albedos below 1% are clamped (keeps black surfaces from blowing up).
pub const DEFAULT_ALBEDO_EPS: f32 = 0.01;

fn check(color: &Image, albedo: &Image, eps: f32) -> Result<(), DenoiseError> {
    if color.channels() != 3 {
        return Err(DenoiseError::ChannelCount { buffer: "colour", expected: "3", found: color.channels() });
    }
    if albedo.channels() != 3 {
        return Err(DenoiseError::ChannelCount { buffer: "albedo", expected: "3", found: albedo.channels() });
    }
    if !albedo.same_size(color) {
        return Err(DenoiseError::SizeMismatch {
            buffer: "albedo",
            expected: (color.width(), color.height()),
            found: (albedo.width(), albedo.height()),
        });
    }
    require_positive("albedo_eps", eps)
}

/// The divisor for one albedo value; non-finite albedo counts as `eps`... as 1 (no change).
#[inline]
fn safe(a: f32, eps: f32) -> f32 {
    if a.is_finite() {
        a.max(eps)
    } else {
        1.0
    }
}

/// Illumination `color / max(albedo, eps)` per channel.
pub fn demodulate(color: &Image, albedo: &Image, eps: f32) -> Result<Image, DenoiseError> {
    check(color, albedo, eps)?;
    let mut out = color.clone();
    for (o, a) in out.data_mut().iter_mut().zip(albedo.data()) {
        *o /= safe(*a, eps);
    }
    Ok(out)
}

/// Colour `illumination * max(albedo, eps)` per channel (inverse of [`demodulate`]).
pub fn remodulate(illumination: &Image, albedo: &Image, eps: f32) -> Result<Image, DenoiseError> {
    check(illumination, albedo, eps)?;
    let mut out = illumination.clone();
    for (o, a) in out.data_mut().iter_mut().zip(albedo.data()) {
        *o *= safe(*a, eps);
    }
    Ok(out)
}
