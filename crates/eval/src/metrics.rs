//! Image error metrics against a reference, and per-pixel error maps.
//!
//! All metrics compare the RGB of two images of the same size (a 1-channel image is read
//! as grey; more than three channels: the first three are used).
//!
//! | metric | on | definition |
//! |---|---|---|
//! | [`mse`] | linear values | mean over pixels and channels of `(x - r)^2` |
//! | [`rel_mse`] | linear values | mean over pixels and channels of `(x - r)^2 / (r^2 + 0.01)` (Rousselle et al. 2011's relative MSE; ε = [`REL_MSE_EPSILON`]) |
//! | [`rel_mse_clamped`] | values clamped to [0, 1] | `Σ (x - r)^2 / Σ r^2` over pixels and channels: the relMSE of the importance-caching thesis (6.1.2), a ratio of means |
//! | [`psnr`] | values clamped to [0, 1] | `10 log10(1 / MSE_clamped)`: the peak is 1.0, the white of the PNG. A fixed peak makes numbers comparable across references (the reference maximum of a scene with a visible light is set by the light, not the image); `+inf` for identical images |
//! | [`ssim`] | luma of the displayed image | SSIM of Wang et al. 2004 (eq. 13) with an 11x11 Gaussian window, σ = 1.5, K1 = 0.01, K2 = 0.03, L = 1, on `Y' = 0.2126 R' + 0.7152 G' + 0.0722 B'` where `R'G'B'` are the clamped sRGB-encoded values (the PNG); edges are clamped (replicated), so every pixel has a window; the mean of the SSIM map |
//! | [`flip`] | the displayed image | LDR-ꟻLIP (Andersson et al. 2020) on the 8-bit sRGB images that [`filtrace_io::write_png`] would write, 67 pixels per degree (0.7 m from a 0.7 m wide 4K monitor), by NVIDIA's reference implementation through the `nv-flip` crate; the mean of the FLIP map, in [0, 1] |
//!
//! **FLIP agreement with the PyPI `flip-evaluator` 1.7** (the current reference release;
//! `nv-flip` 0.1.2 bundles an older C++ FLIP), on the same 8-bit PNGs, `evaluate(ref, test,
//! "LDR", applyMagma=False)`, 67.02 ppd in both:
//!
//! | image vs reference | flip-evaluator mean | ours | max per-pixel difference |
//! |---|---|---|---|
//! | Cornell 512², 16 spp vs Mitsuba 4096 spp | 0.0577870 | 0.0578003 | 1.7e-4 |
//! | Cornell 128², 4 spp vs 64 spp (seed 3) | 0.1097336 | 0.1097540 | 2.6e-4 |
//!
//! **Non-finite values** (NaN, ±inf) in either image are read as 0 by every metric (as
//! the PNG writer does) and counted in [`Metrics::nonfinite_image`] /
//! [`Metrics::nonfinite_reference`]: a NaN pixel is an error the metric sees (it is
//! compared as black), never a NaN that poisons the mean.

use filtrace_core::{luminance, Image, Vec3};
use filtrace_io::{srgb_eotf, srgb_oetf, tonemap_srgb8, TonemapParams};
use serde::Serialize;
use std::fmt;

/// The ε of the relative MSE denominator `r^2 + ε`.
pub const REL_MSE_EPSILON: f64 = 0.01;

/// SSIM's Gaussian window (Wang et al. 2004, section III.C).
pub const SSIM_WINDOW: usize = 11;
pub const SSIM_SIGMA: f64 = 1.5;
const SSIM_C1: f64 = 0.01 * 0.01;
const SSIM_C2: f64 = 0.03 * 0.03;

/// FLIP's observer: pixels per degree of visual angle (the FLIP paper's default).
pub const FLIP_PIXELS_PER_DEGREE: f32 = nv_flip::DEFAULT_PIXELS_PER_DEGREE;

/// Why two images cannot be compared.
#[derive(Debug, Clone, PartialEq)]
pub enum MetricError {
    SizeMismatch { image: (usize, usize), reference: (usize, usize) },
    Channels { which: &'static str, channels: usize },
    Empty,
}

impl fmt::Display for MetricError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MetricError::SizeMismatch { image, reference } => write!(
                f,
                "image is {}x{} but the reference is {}x{}",
                image.0, image.1, reference.0, reference.1
            ),
            MetricError::Channels { which, channels } => {
                write!(f, "the {which} has {channels} channels; metrics need 1 (grey) or at least 3 (RGB)")
            }
            MetricError::Empty => write!(f, "cannot compare empty images"),
        }
    }
}

impl std::error::Error for MetricError {}

/// All metrics of one comparison.
#[derive(Clone, Debug, Serialize)]
pub struct Metrics {
    pub mse: f64,
    pub rel_mse: f64,
    /// dB; `None` (JSON `null`) when the clamped images are identical (infinite PSNR).
    pub psnr: Option<f64>,
    pub ssim: f64,
    pub flip: f64,
    /// Non-finite values in the image (read as 0).
    pub nonfinite_image: usize,
    /// Non-finite values in the reference (read as 0).
    pub nonfinite_reference: usize,
}

/// Both images as finite RGB triples, after the checks every metric shares.
struct Pair {
    width: usize,
    height: usize,
    x: Vec<Vec3>,
    r: Vec<Vec3>,
}

fn finite_rgb(im: &Image, which: &'static str) -> Result<Vec<Vec3>, MetricError> {
    let c = im.channels();
    if c == 0 || c == 2 {
        return Err(MetricError::Channels { which, channels: c });
    }
    let f = |v: f32| if v.is_finite() { v } else { 0.0 };
    Ok(im
        .data()
        .chunks_exact(c)
        .map(|p| if c == 1 { Vec3::splat(f(p[0])) } else { Vec3::new(f(p[0]), f(p[1]), f(p[2])) })
        .collect())
}

fn pair(image: &Image, reference: &Image) -> Result<Pair, MetricError> {
    if !image.same_size(reference) {
        return Err(MetricError::SizeMismatch {
            image: (image.width(), image.height()),
            reference: (reference.width(), reference.height()),
        });
    }
    if image.pixel_count() == 0 {
        return Err(MetricError::Empty);
    }
    Ok(Pair {
        width: image.width(),
        height: image.height(),
        x: finite_rgb(image, "image")?,
        r: finite_rgb(reference, "reference")?,
    })
}

fn count_nonfinite_rgb(im: &Image) -> usize {
    let c = im.channels().max(1);
    im.data().chunks_exact(c).map(|p| p.iter().take(3).filter(|v| !v.is_finite()).count()).sum()
}

/// Mean squared error over pixels and channels of linear values.
pub fn mse(image: &Image, reference: &Image) -> Result<f64, MetricError> {
    let p = pair(image, reference)?;
    let sum: f64 = p.x.iter().zip(&p.r).map(|(x, r)| (*x - *r).as_dvec3().length_squared()).sum();
    Ok(sum / (3 * p.x.len()) as f64)
}

/// Relative MSE: mean over pixels and channels of `(x - r)^2 / (r^2 + 0.01)`.
pub fn rel_mse(image: &Image, reference: &Image) -> Result<f64, MetricError> {
    let map = rel_mse_map(image, reference)?;
    Ok(map.data().iter().map(|v| *v as f64).sum::<f64>() / map.pixel_count() as f64)
}

/// Per pixel: the mean over the three channels of `(x - r)^2 / (r^2 + 0.01)` (1 channel).
pub fn rel_mse_map(image: &Image, reference: &Image) -> Result<Image, MetricError> {
    let p = pair(image, reference)?;
    let data =
        p.x.iter()
            .zip(&p.r)
            .map(|(x, r)| {
                let (x, r) = (x.as_dvec3(), r.as_dvec3());
                let e = (x - r) * (x - r) / (r * r + REL_MSE_EPSILON);
                (e.element_sum() / 3.0) as f32
            })
            .collect();
    Ok(Image::from_vec(p.width, p.height, 1, data).expect("one value per pixel"))
}

/// The relative MSE of the thesis (6.1.2): `E[(x − r)²] / E[r²]` over pixels and
/// channels, on values clamped to [0, 1] (the thesis's stand-in for the display's
/// tonemapping, which keeps a few fireflies from dominating an l² error). Unlike
/// [`rel_mse`] it is one ratio of means, not a mean of ratios. A black reference gives 0
/// for a black image and `+inf` otherwise.
pub fn rel_mse_clamped(image: &Image, reference: &Image) -> Result<f64, MetricError> {
    let p = pair(image, reference)?;
    let clamp = |v: Vec3| v.clamp(Vec3::ZERO, Vec3::ONE).as_dvec3();
    let (mut err, mut energy) = (0.0, 0.0);
    for (x, r) in p.x.iter().zip(&p.r) {
        let (x, r) = (clamp(*x), clamp(*r));
        err += (x - r).length_squared();
        energy += r.length_squared();
    }
    Ok(if energy > 0.0 {
        err / energy
    } else if err == 0.0 {
        0.0
    } else {
        f64::INFINITY
    })
}

/// PSNR in dB on values clamped to [0, 1] with peak 1.0; `+inf` for identical images.
pub fn psnr(image: &Image, reference: &Image) -> Result<f64, MetricError> {
    let p = pair(image, reference)?;
    let clamp = |v: Vec3| v.clamp(Vec3::ZERO, Vec3::ONE).as_dvec3();
    let sum: f64 = p.x.iter().zip(&p.r).map(|(x, r)| (clamp(*x) - clamp(*r)).length_squared()).sum();
    let mse = sum / (3 * p.x.len()) as f64;
    Ok(if mse == 0.0 { f64::INFINITY } else { -10.0 * mse.log10() })
}

/// The luma SSIM works on: Rec. 709 weights on clamped, sRGB-encoded values.
fn display_luma(rgb: &[Vec3]) -> Vec<f64> {
    let params = TonemapParams::srgb_clamp();
    rgb.iter()
        .map(|c| {
            let enc = Vec3::new(
                srgb_oetf(params.display(c.x)),
                srgb_oetf(params.display(c.y)),
                srgb_oetf(params.display(c.z)),
            );
            luminance(enc) as f64
        })
        .collect()
}

/// The normalised 1D Gaussian of SSIM's window.
fn gaussian_1d() -> [f64; SSIM_WINDOW] {
    let mut g = [0.0; SSIM_WINDOW];
    let h = (SSIM_WINDOW / 2) as f64;
    for (i, w) in g.iter_mut().enumerate() {
        let d = i as f64 - h;
        *w = (-d * d / (2.0 * SSIM_SIGMA * SSIM_SIGMA)).exp();
    }
    let s: f64 = g.iter().sum();
    g.map(|w| w / s)
}

/// Separable Gaussian blur with clamped (replicated) edges.
fn blur(v: &[f64], w: usize, h: usize, g: &[f64; SSIM_WINDOW]) -> Vec<f64> {
    let r = (SSIM_WINDOW / 2) as isize;
    let clampi = |i: isize, n: usize| i.clamp(0, n as isize - 1) as usize;
    let mut tmp = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            tmp[y * w + x] =
                (-r..=r).map(|d| g[(d + r) as usize] * v[y * w + clampi(x as isize + d, w)]).sum();
        }
    }
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            out[y * w + x] =
                (-r..=r).map(|d| g[(d + r) as usize] * tmp[clampi(y as isize + d, h) * w + x]).sum();
        }
    }
    out
}

/// SSIM index map (Wang et al. 2004, eq. 13) from the five blurred moments.
fn ssim_from_moments(mx: &[f64], my: &[f64], sxx: &[f64], syy: &[f64], sxy: &[f64]) -> Vec<f64> {
    (0..mx.len())
        .map(|i| {
            let (ux, uy) = (mx[i], my[i]);
            let vx = (sxx[i] - ux * ux).max(0.0);
            let vy = (syy[i] - uy * uy).max(0.0);
            let cxy = sxy[i] - ux * uy;
            ((2.0 * ux * uy + SSIM_C1) * (2.0 * cxy + SSIM_C2))
                / ((ux * ux + uy * uy + SSIM_C1) * (vx + vy + SSIM_C2))
        })
        .collect()
}

/// Per-pixel SSIM (1 channel); its mean is [`ssim`].
pub fn ssim_map(image: &Image, reference: &Image) -> Result<Image, MetricError> {
    let p = pair(image, reference)?;
    let (w, h) = (p.width, p.height);
    let (x, y) = (display_luma(&p.x), display_luma(&p.r));
    let g = gaussian_1d();
    let prod = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(a, b)| a * b).collect::<Vec<_>>();
    let mx = blur(&x, w, h, &g);
    let my = blur(&y, w, h, &g);
    let sxx = blur(&prod(&x, &x), w, h, &g);
    let syy = blur(&prod(&y, &y), w, h, &g);
    let sxy = blur(&prod(&x, &y), w, h, &g);
    let map = ssim_from_moments(&mx, &my, &sxx, &syy, &sxy);
    Ok(Image::from_vec(w, h, 1, map.iter().map(|v| *v as f32).collect()).expect("one per pixel"))
}

/// Mean SSIM (1 for identical images).
pub fn ssim(image: &Image, reference: &Image) -> Result<f64, MetricError> {
    let map = ssim_map(image, reference)?;
    Ok(map.data().iter().map(|v| *v as f64).sum::<f64>() / map.pixel_count() as f64)
}

/// The LDR-FLIP error map (1 channel, values in [0, 1]).
pub fn flip_map(image: &Image, reference: &Image) -> Result<Image, MetricError> {
    let p = pair(image, reference)?;
    let to8 = |rgb: &[Vec3]| {
        let im = Image::from_rgb(p.width, p.height, rgb).expect("sizes checked");
        let (bytes, _) = tonemap_srgb8(&im, &TonemapParams::srgb_clamp());
        nv_flip::FlipImageRgb8::with_data(p.width as u32, p.height as u32, &bytes)
    };
    let err = nv_flip::flip(to8(&p.r), to8(&p.x), FLIP_PIXELS_PER_DEGREE);
    Ok(Image::from_vec(p.width, p.height, 1, err.to_vec()).expect("one per pixel"))
}

/// Mean LDR-FLIP (0 for identical images).
pub fn flip(image: &Image, reference: &Image) -> Result<f64, MetricError> {
    let map = flip_map(image, reference)?;
    Ok(map.data().iter().map(|v| *v as f64).sum::<f64>() / map.pixel_count() as f64)
}

/// A scalar map (values expected in [0, 1], clamped) in FLIP's "magma" false colour,
/// as LINEAR RGB, so that [`filtrace_io::write_png`] reproduces the colour map exactly.
pub fn false_color(map: &Image) -> Image {
    let lut = nv_flip::magma_lut().to_vec();
    let entries = lut.len() / 3;
    let mut out = Image::new(map.width(), map.height(), 3);
    let c = map.channels().max(1);
    for (dst, src) in out.data_mut().chunks_exact_mut(3).zip(map.data().chunks_exact(c)) {
        let v = if src[0].is_finite() { src[0].clamp(0.0, 1.0) } else { 0.0 };
        let i = ((v * (entries - 1) as f32).round() as usize).min(entries - 1);
        for k in 0..3 {
            dst[k] = srgb_eotf(lut[3 * i + k] as f32 / 255.0);
        }
    }
    out
}

/// Maps a non-negative scalar map logarithmically to [0, 1]: `lo` and below → 0, `hi` and
/// above → 1 (for showing relMSE maps, whose values span decades, with [`false_color`]).
/// Non-finite values → 0.
pub fn log_scale(map: &Image, lo: f32, hi: f32) -> Image {
    let (l0, l1) = (lo.max(f32::MIN_POSITIVE).log10(), hi.max(f32::MIN_POSITIVE).log10());
    let span = (l1 - l0).max(f32::EPSILON);
    let data = map
        .data()
        .iter()
        .map(|v| if v.is_finite() && *v > 0.0 { ((v.log10() - l0) / span).clamp(0.0, 1.0) } else { 0.0 })
        .collect();
    Image::from_vec(map.width(), map.height(), map.channels(), data).expect("same size")
}

/// Every metric at once.
pub fn compare(image: &Image, reference: &Image) -> Result<Metrics, MetricError> {
    let psnr = psnr(image, reference)?;
    Ok(Metrics {
        mse: mse(image, reference)?,
        rel_mse: rel_mse(image, reference)?,
        psnr: psnr.is_finite().then_some(psnr),
        ssim: ssim(image, reference)?,
        flip: flip(image, reference)?,
        nonfinite_image: count_nonfinite_rgb(image),
        nonfinite_reference: count_nonfinite_rgb(reference),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(w: usize, h: usize, data: &[f32]) -> Image {
        Image::from_vec(w, h, 3, data.to_vec()).unwrap()
    }

    /// The thesis's relMSE by hand: clamp to [0, 1], then Σ(x − r)² / Σ r².
    #[test]
    fn rel_mse_clamped_matches_a_hand_computed_value() {
        let x = img(2, 1, &[0.5, 2.0, -1.0, 0.2, 0.2, 0.2]);
        let r = img(2, 1, &[0.25, 0.5, 0.0, 0.1, 0.3, 1.5]);
        // Clamped x = (0.5, 1, 0), (0.2, 0.2, 0.2); clamped r = (0.25, 0.5, 0), (0.1, 0.3, 1).
        // Σ(x − r)² = 0.0625 + 0.25 + 0 + 0.01 + 0.01 + 0.64 = 0.9725;
        // Σ r² = 0.0625 + 0.25 + 0 + 0.01 + 0.09 + 1 = 1.4125.
        let want = 0.9725 / 1.4125;
        let got = rel_mse_clamped(&x, &r).unwrap();
        assert!((got - want).abs() < 1e-7, "{got} vs {want}");
        // Without the clamp it would differ (the 2.0, -1.0 and 1.5 count in full).
        assert!((rel_mse(&x, &r).unwrap() - got).abs() > 0.1);
        // Identical images: 0; a black reference: 0 for black, +inf otherwise.
        assert_eq!(rel_mse_clamped(&x, &x).unwrap(), 0.0);
        let black = img(2, 1, &[0.0; 6]);
        assert_eq!(rel_mse_clamped(&black, &black).unwrap(), 0.0);
        assert_eq!(rel_mse_clamped(&x, &black).unwrap(), f64::INFINITY);
        // Scale-free on values inside [0, 1]: both images times 0.5, same error.
        let (xs, rs) = (img(1, 1, &[0.2, 0.4, 0.6]), img(1, 1, &[0.3, 0.3, 0.3]));
        let (xh, rh) = (img(1, 1, &[0.1, 0.2, 0.3]), img(1, 1, &[0.15, 0.15, 0.15]));
        assert!((rel_mse_clamped(&xs, &rs).unwrap() - rel_mse_clamped(&xh, &rh).unwrap()).abs() < 1e-7);
    }

    /// A deterministic noisy image (xorshift), values in [0, scale).
    fn noise(w: usize, h: usize, seed: u32, scale: f32) -> Image {
        let mut s = seed.max(1);
        let data = (0..w * h * 3)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                (s as f32 / u32::MAX as f32) * scale
            })
            .collect();
        Image::from_vec(w, h, 3, data).unwrap()
    }

    #[test]
    fn hand_computed_values_on_two_pixels() {
        let x = img(2, 1, &[1.0, 2.0, 3.0, 0.0, 0.0, 0.0]);
        let r = img(2, 1, &[1.0, 1.0, 1.0, 0.0, 0.0, 1.0]);
        // Squared differences 0, 1, 4, 0, 0, 1 → 6 / 6.
        assert!((mse(&x, &r).unwrap() - 1.0).abs() < 1e-12);
        // (0 + 1 + 4 + 1) / 1.01 / 6, the zero-reference channels contribute 0 / 0.01.
        assert!((rel_mse(&x, &r).unwrap() - 1.0 / 1.01).abs() < 1e-7);
        // Clamped: x = (1,1,1, 0,0,0) vs r = (1,1,1, 0,0,1): MSE 1/6 → 10 log10 6.
        assert!((psnr(&x, &r).unwrap() - 10.0 * 6f64.log10()).abs() < 1e-9);
        let map = rel_mse_map(&x, &r).unwrap();
        assert!((map.data()[0] as f64 - 5.0 / 1.01 / 3.0).abs() < 1e-6);
        assert!((map.data()[1] as f64 - 1.0 / 1.01 / 3.0).abs() < 1e-6);
    }

    #[test]
    fn identical_images_have_zero_error_and_unit_ssim() {
        let a = noise(23, 17, 7, 2.0);
        let m = compare(&a, &a).unwrap();
        assert_eq!(m.mse, 0.0);
        assert_eq!(m.rel_mse, 0.0);
        assert_eq!(m.psnr, None);
        assert!((m.ssim - 1.0).abs() < 1e-12, "{}", m.ssim);
        assert_eq!(m.flip, 0.0);
    }

    #[test]
    fn ssim_of_constant_images_is_the_luminance_term() {
        // σ = 0 everywhere, so SSIM = (2 μx μy + C1) / (μx² + μy² + C1) exactly.
        let (a, b) = (0.2f32, 0.6f32);
        let x = Image::filled(15, 12, 3, a);
        let r = Image::filled(15, 12, 3, b);
        let (ea, eb) = (srgb_oetf(a) as f64, srgb_oetf(b) as f64);
        // Luma of a grey: weights sum to 1 (in f32).
        let want = (2.0 * ea * eb + SSIM_C1) / (ea * ea + eb * eb + SSIM_C1);
        assert!((ssim(&x, &r).unwrap() - want).abs() < 1e-5, "{want}");
    }

    /// The O(w·h·121) direct 2D window against the separable blur.
    #[test]
    fn separable_ssim_matches_the_direct_window() {
        let (w, h) = (19, 14);
        let x = noise(w, h, 3, 1.2);
        let r = noise(w, h, 11, 1.0);
        let fast = ssim_map(&x, &r).unwrap();
        let (lx, ly) = (
            display_luma(&finite_rgb(&x, "image").unwrap()),
            display_luma(&finite_rgb(&r, "reference").unwrap()),
        );
        let g = gaussian_1d();
        let rad = (SSIM_WINDOW / 2) as isize;
        for py in 0..h {
            for px in 0..w {
                let mut m = [0.0f64; 5];
                for dy in -rad..=rad {
                    for dx in -rad..=rad {
                        let qx = (px as isize + dx).clamp(0, w as isize - 1) as usize;
                        let qy = (py as isize + dy).clamp(0, h as isize - 1) as usize;
                        let wt = g[(dx + rad) as usize] * g[(dy + rad) as usize];
                        let (a, b) = (lx[qy * w + qx], ly[qy * w + qx]);
                        m[0] += wt * a;
                        m[1] += wt * b;
                        m[2] += wt * a * a;
                        m[3] += wt * b * b;
                        m[4] += wt * a * b;
                    }
                }
                let naive = ssim_from_moments(&[m[0]], &[m[1]], &[m[2]], &[m[3]], &[m[4]])[0];
                let got = fast.pixel(px, py)[0] as f64;
                assert!((naive - got).abs() < 1e-5, "({px},{py}) {naive} vs {got}");
            }
        }
    }

    #[test]
    fn more_noise_means_worse_scores() {
        let r = Image::filled(32, 32, 3, 0.4);
        let mut small = r.clone();
        let mut large = r.clone();
        let n = noise(32, 32, 5, 1.0);
        for ((s, l), e) in small.data_mut().iter_mut().zip(large.data_mut()).zip(n.data()) {
            *s += 0.05 * (e - 0.5);
            *l += 0.4 * (e - 0.5);
        }
        let (a, b) = (compare(&small, &r).unwrap(), compare(&large, &r).unwrap());
        assert!(a.mse < b.mse && a.rel_mse < b.rel_mse);
        assert!(a.psnr.unwrap() > b.psnr.unwrap());
        assert!(a.ssim > b.ssim && b.ssim < 0.9);
        assert!(a.flip < b.flip && a.flip > 0.0 && b.flip <= 1.0);
    }

    #[test]
    fn black_against_white_is_the_largest_flip_and_mse() {
        let black = Image::filled(16, 16, 3, 0.0);
        let white = Image::filled(16, 16, 3, 1.0);
        let f = flip(&black, &white).unwrap();
        assert!(f > 0.5 && f <= 1.0, "{f}");
        assert_eq!(mse(&black, &white).unwrap(), 1.0);
        assert_eq!(psnr(&black, &white).unwrap(), 0.0);
    }

    #[test]
    fn nonfinite_values_are_compared_as_black_and_counted() {
        let r = Image::filled(8, 8, 3, 0.5);
        let mut bad = r.clone();
        bad.data_mut()[0] = f32::NAN;
        bad.data_mut()[4] = f32::INFINITY;
        let mut zeroed = r.clone();
        zeroed.data_mut()[0] = 0.0;
        zeroed.data_mut()[4] = 0.0;
        let m = compare(&bad, &r).unwrap();
        let z = compare(&zeroed, &r).unwrap();
        assert!(m.mse.is_finite() && m.ssim.is_finite() && m.flip.is_finite());
        assert_eq!(m.mse, z.mse);
        assert_eq!(m.rel_mse, z.rel_mse);
        assert_eq!(m.ssim, z.ssim);
        assert_eq!(m.flip, z.flip);
        assert_eq!((m.nonfinite_image, m.nonfinite_reference), (2, 0));
    }

    #[test]
    fn bad_input_is_an_error() {
        let a = Image::filled(4, 4, 3, 0.0);
        assert!(matches!(compare(&a, &Image::filled(4, 5, 3, 0.0)), Err(MetricError::SizeMismatch { .. })));
        assert!(matches!(compare(&a, &Image::filled(4, 4, 2, 0.0)), Err(MetricError::Channels { .. })));
        assert!(matches!(compare(&Image::new(0, 0, 3), &Image::new(0, 0, 3)), Err(MetricError::Empty)));
        // Grey images are read as grey RGB.
        let g = Image::filled(4, 4, 1, 0.5);
        assert_eq!(mse(&g, &Image::filled(4, 4, 3, 0.5)).unwrap(), 0.0);
    }

    #[test]
    fn log_scale_maps_decades_linearly() {
        let m = Image::from_vec(5, 1, 1, vec![1e-5, 1e-4, 1e-2, 1.0, f32::NAN]).unwrap();
        let s = log_scale(&m, 1e-4, 1.0);
        let want = [0.0, 0.0, 0.5, 1.0, 0.0];
        for (g, w) in s.data().iter().zip(want) {
            assert!((g - w).abs() < 1e-6, "{:?}", s.data());
        }
    }

    #[test]
    fn false_color_ends_are_magma_black_and_yellow() {
        let m = Image::from_vec(3, 1, 1, vec![0.0, 1.0, f32::NAN]).unwrap();
        let fc = false_color(&m);
        let (lo, hi) = (fc.rgb(0, 0), fc.rgb(1, 0));
        assert!(luminance(lo) < 0.01 && luminance(hi) > 0.5, "{lo} {hi}");
        assert_eq!(fc.rgb(2, 0), lo);
    }
}
