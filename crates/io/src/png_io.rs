//! Tonemapped 8-bit sRGB PNG output.
//!
//! `value → value · 2^exposure → tone curve → clamp to [0,1] → sRGB OETF (IEC 61966-2-1)
//! → round to 8 bits`. The default curve is a plain clamp, so that a linear value of 1.0
//! is white and the PNG looks as every other viewer shows the EXR. Non-finite values are
//! written as 0 and counted in [`PngReport::nonfinite`] (the caller warns).

use crate::error::IoError;
use filtrace_core::Image;
use std::path::Path;

/// The tone curve applied after exposure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tonemap {
    /// Clamp to [0, 1]: what users expect from "show me the EXR".
    Clamp,
    /// Narkowicz's fit of the ACES filmic curve (2015): `x(2.51x+0.03) / (x(2.43x+0.59)+0.14)`;
    /// compresses highlights instead of clipping them.
    Filmic,
}

/// How a linear HDR image becomes an 8-bit sRGB PNG.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TonemapParams {
    /// Exposure in stops: values are multiplied by `2^exposure` first.
    pub exposure: f32,
    /// Tone curve applied after exposure.
    pub curve: Tonemap,
}

impl TonemapParams {
    /// Plain sRGB with clamping at 1.0, no exposure change (the default).
    pub fn srgb_clamp() -> Self {
        Self { exposure: 0.0, curve: Tonemap::Clamp }
    }
    /// The filmic curve, no exposure change.
    pub fn filmic() -> Self {
        Self { exposure: 0.0, curve: Tonemap::Filmic }
    }
    /// All named presets (tests loop over them).
    pub fn presets() -> [(&'static str, Self); 2] {
        [("srgb_clamp", Self::srgb_clamp()), ("filmic", Self::filmic())]
    }

    /// Maps one linear value to display-referred [0, 1] (before the OETF). Non-finite → 0.
    #[inline]
    pub fn display(&self, v: f32) -> f32 {
        if !v.is_finite() {
            return 0.0;
        }
        let x = (v * self.exposure.exp2()).max(0.0);
        let y = match self.curve {
            Tonemap::Clamp => x,
            Tonemap::Filmic => (x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14),
        };
        y.clamp(0.0, 1.0)
    }
}

impl Default for TonemapParams {
    fn default() -> Self {
        Self::srgb_clamp()
    }
}

/// The sRGB opto-electronic transfer function (IEC 61966-2-1), for `x` in [0, 1].
#[inline]
pub fn srgb_oetf(x: f32) -> f32 {
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// The inverse of [`srgb_oetf`]: an sRGB-encoded value in [0, 1] back to linear.
#[inline]
pub fn srgb_eotf(v: f32) -> f32 {
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// What happened while writing a PNG.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PngReport {
    /// Number of non-finite channel values, written as 0.
    pub nonfinite: usize,
}

/// Tonemaps to interleaved 8-bit sRGB RGB. One channel is shown as grey, two as (c0, c1, 0),
/// more than three use the first three. Returns the bytes and the count of non-finite values.
pub fn tonemap_srgb8(image: &Image, params: &TonemapParams) -> (Vec<u8>, usize) {
    let c = image.channels();
    let mut out = Vec::with_capacity(image.pixel_count() * 3);
    let mut nonfinite = 0;
    let to8 = |v: f32| (srgb_oetf(params.display(v)) * 255.0 + 0.5) as u8;
    if c == 0 {
        return (vec![0; image.pixel_count() * 3], 0);
    }
    for px in image.data().chunks_exact(c) {
        let rgb = match c {
            1 => [px[0]; 3],
            2 => [px[0], px[1], 0.0],
            _ => [px[0], px[1], px[2]],
        };
        nonfinite += px.iter().take(3).filter(|v| !v.is_finite()).count();
        out.extend(rgb.map(to8));
    }
    (out, nonfinite)
}

/// Writes `image` as a tonemapped 8-bit sRGB PNG (encoded in memory, then written by
/// [`crate::write_atomic`]: a failed write leaves what was at `path` as it was).
pub fn write_png(
    path: impl AsRef<Path>,
    image: &Image,
    params: &TonemapParams,
) -> Result<PngReport, IoError> {
    let path = path.as_ref();
    if image.width() == 0 || image.height() == 0 {
        return Err(IoError::InvalidImage(format!(
            "{}: cannot write an empty {}x{} PNG",
            path.display(),
            image.width(),
            image.height()
        )));
    }
    let (bytes, nonfinite) = tonemap_srgb8(image, params);
    let buf = image::RgbImage::from_raw(image.width() as u32, image.height() as u32, bytes)
        .expect("3 bytes per pixel");
    let mut encoded = std::io::Cursor::new(Vec::new());
    buf.write_to(&mut encoded, image::ImageFormat::Png)
        .map_err(|source| IoError::Png { path: path.to_path_buf(), source })?;
    crate::write_atomic(path, |w| w.write_all(encoded.get_ref()))?;
    Ok(PngReport { nonfinite })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn oetf_matches_the_standard_at_known_points() {
        assert_eq!(srgb_oetf(0.0), 0.0);
        assert!((srgb_oetf(1.0) - 1.0).abs() < 1e-6);
        // 18% grey → 0.4614 (IEC 61966-2-1).
        assert!((srgb_oetf(0.18) - 0.4614).abs() < 1e-3);
        // The two pieces meet at the break point.
        let b = 0.003_130_8f32;
        assert!((12.92 * b - (1.055 * b.powf(1.0 / 2.4) - 0.055)).abs() < 1e-5);
        for i in 0..=100 {
            let x = i as f32 / 100.0;
            assert!((srgb_eotf(srgb_oetf(x)) - x).abs() < 1e-5, "{x}");
        }
    }

    #[test]
    fn every_preset_is_monotone_bounded_and_zeroes_nonfinite() {
        for (name, p) in TonemapParams::presets() {
            let mut last = -1.0;
            for i in 0..1000 {
                let y = p.display(i as f32 * 0.01);
                assert!((0.0..=1.0).contains(&y), "{name}");
                assert!(y >= last, "{name} not monotone");
                last = y;
            }
            assert_eq!(p.display(f32::NAN), 0.0, "{name}");
            assert_eq!(p.display(f32::INFINITY), 0.0, "{name}");
            assert_eq!(p.display(-3.0), 0.0, "{name}");
        }
    }

    #[test]
    fn tonemap_counts_nonfinite_and_maps_white_and_grey() {
        let im =
            Image::from_vec(3, 1, 3, vec![1.0, 1.0, 1.0, 0.18, 0.18, 0.18, f32::NAN, 0.0, f32::INFINITY])
                .unwrap();
        let (bytes, bad) = tonemap_srgb8(&im, &TonemapParams::default());
        assert_eq!(bad, 2);
        assert_eq!(&bytes[0..3], &[255, 255, 255]);
        assert_eq!(bytes[3], 118); // 0.4614 * 255 = 117.7
        assert_eq!(&bytes[6..9], &[0, 0, 0]);
        // One stop up doubles the linear value.
        let p = TonemapParams { exposure: 1.0, curve: Tonemap::Clamp };
        assert!((p.display(0.25) - 0.5).abs() < 1e-6);
    }
}
