//! The film: per-pixel running sums of the path tracer's samples, and the AOV images made
//! from them.
//!
//! Each pixel keeps, in `f64`, the sum and the sum of squares of the colour (for the mean
//! and the variance of the mean), the sums of the `direct` and `indirect` components, its
//! sample count, and how many samples were dropped as non-finite. The visible surface
//! (G-buffer: albedo, shading normal, position, depth) is written by sample 0, which goes
//! through the pixel centre (see [`crate::camera`]).
//!
//! Non-finite samples: a sample with any NaN or infinite value in colour/direct/indirect is
//! *dropped* (not added, not counted in `samples`) and counted in `dropped`; the estimate of
//! the pixel is then the mean of the finite samples. [`Film::dropped_samples`] reports the
//! total so that a renderer bug cannot hide.

use filtrace_core::{Image, Rgb, Vec3};

use crate::fallible::{self, AllocError};

/// The surface seen through the pixel centre. A miss is the all-zero record: albedo 0,
/// normal the zero vector (= "no surface"; filters test for it), position 0, depth 0.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VisibleSurface {
    pub albedo: Rgb,
    /// Unit shading normal, facing the camera.
    pub normal: Vec3,
    pub position: Vec3,
    /// Distance from the eye along the camera ray.
    pub depth: f32,
}

/// One sample's contribution to its pixel. `color == direct + indirect` exactly.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PixelSample {
    pub color: Rgb,
    pub direct: Rgb,
    pub indirect: Rgb,
}

impl PixelSample {
    #[inline]
    pub fn is_finite(&self) -> bool {
        // One branch-free pass over the nine values (a `&&` chain of per-component
        // `is_finite` was ~25 instructions and nine branches per sample in the render loop;
        // a `flat_map`/`fold` over them was an out-of-line call of ~80 instructions).
        let (c, d, i) = (self.color, self.direct, self.indirect);
        let mut bad = false;
        for x in [c.x, c.y, c.z, d.x, d.y, d.z, i.x, i.y, i.z] {
            bad |= (x.to_bits() & 0x7f80_0000) == 0x7f80_0000;
        }
        !bad
    }
}

/// Accumulated state of one pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FilmPixel {
    pub samples: u32,
    pub dropped: u32,
    pub sum: [f64; 3],
    pub sum_sq: [f64; 3],
    pub sum_direct: [f64; 3],
    pub sum_indirect: [f64; 3],
    pub surface: VisibleSurface,
}

impl FilmPixel {
    /// Adds a sample, or drops it when non-finite (see the module docs).
    #[inline(always)]
    pub fn add(&mut self, s: &PixelSample) {
        if !s.is_finite() {
            self.dropped += 1;
            return;
        }
        self.samples += 1;
        for c in 0..3 {
            let v = s.color[c] as f64;
            self.sum[c] += v;
            self.sum_sq[c] += v * v;
            self.sum_direct[c] += s.direct[c] as f64;
            self.sum_indirect[c] += s.indirect[c] as f64;
        }
    }

    /// Samples traced for this pixel: kept plus dropped.
    #[inline]
    pub fn traced(&self) -> u32 {
        self.samples + self.dropped
    }

    /// Mean colour (zero without samples).
    #[inline]
    pub fn mean(&self) -> [f64; 3] {
        let n = self.samples.max(1) as f64;
        self.sum.map(|s| s / n)
    }

    /// Per-channel variance of the pixel mean, `s^2 / n` with the unbiased sample variance
    /// `s^2`; zero with fewer than two samples.
    #[inline]
    pub fn variance_of_mean(&self) -> [f64; 3] {
        let n = self.samples as f64;
        if self.samples < 2 {
            return [0.0; 3];
        }
        std::array::from_fn(|c| {
            let s2 = ((self.sum_sq[c] - self.sum[c] * self.sum[c] / n) / (n - 1.0)).max(0.0);
            s2 / n
        })
    }
}

/// A film of `width x height` pixels, row-major, row 0 at the top.
#[derive(Clone, Debug)]
pub struct Film {
    width: usize,
    height: usize,
    pixels: Vec<FilmPixel>,
}

/// The images a render produces (arbitrary output variables). Every image is
/// `width x height`; `depth` has one channel, the others three.
#[derive(Clone, Debug)]
pub struct Aovs {
    pub width: usize,
    pub height: usize,
    /// Mean radiance.
    pub color: Image,
    /// Variance of the pixel mean, per channel.
    pub variance: Image,
    /// Emission seen directly plus direct light at the first hit.
    pub direct: Image,
    /// Everything after the first bounce; `direct + indirect = color`.
    pub indirect: Image,
    pub albedo: Image,
    pub normal: Image,
    pub position: Image,
    pub depth: Image,
}

impl Film {
    pub fn new(width: usize, height: usize) -> Self {
        Self { width, height, pixels: vec![FilmPixel::default(); width * height] }
    }

    /// [`Film::new`] with the pixels allocated fallibly: a film that does not fit is an
    /// error, not an abort (see [`crate::memory`]).
    pub fn try_new(width: usize, height: usize) -> Result<Self, AllocError> {
        let what = format!("the {width}x{height} film");
        let pixels = fallible::try_vec(width * height, FilmPixel::default(), &what)?;
        Ok(Self { width, height, pixels })
    }

    pub fn width(&self) -> usize {
        self.width
    }
    pub fn height(&self) -> usize {
        self.height
    }

    #[inline]
    pub fn pixel(&self, x: usize, y: usize) -> &FilmPixel {
        &self.pixels[y * self.width + x]
    }

    #[inline]
    pub fn pixel_mut(&mut self, x: usize, y: usize) -> &mut FilmPixel {
        &mut self.pixels[y * self.width + x]
    }

    /// All pixels, row-major (for parallel iteration over rows).
    pub fn pixels_mut(&mut self) -> &mut [FilmPixel] {
        &mut self.pixels
    }

    pub fn pixels(&self) -> &[FilmPixel] {
        &self.pixels
    }

    /// Total number of (kept) samples over all pixels.
    pub fn total_samples(&self) -> u64 {
        self.pixels.iter().map(|p| p.samples as u64).sum()
    }

    /// Smallest per-pixel sample count (0 for an empty film).
    pub fn min_samples(&self) -> u32 {
        self.pixels.iter().map(|p| p.samples).min().unwrap_or(0)
    }

    /// Largest per-pixel sample count (0 for an empty film).
    pub fn max_samples(&self) -> u32 {
        self.pixels.iter().map(|p| p.samples).max().unwrap_or(0)
    }

    /// Pixels for which no sample was traced yet (a render cut short before its first pass
    /// ended). Their AOVs would read as black, so such a film is not an image.
    pub fn pixels_without_samples(&self) -> usize {
        self.pixels.iter().filter(|p| p.traced() == 0).count()
    }

    /// Number of samples dropped because they were not finite.
    pub fn dropped_samples(&self) -> u64 {
        self.pixels.iter().map(|p| p.dropped as u64).sum()
    }

    /// Per-pixel sample counts as a 1-channel image (for adaptive sampling maps).
    pub fn sample_counts(&self) -> Image {
        let data = self.pixels.iter().map(|p| p.samples as f32).collect();
        Image::from_vec(self.width, self.height, 1, data).expect("size matches")
    }

    /// The AOV images of the current state.
    pub fn aovs(&self) -> Aovs {
        self.try_aovs().unwrap_or_else(|e| panic!("{e}"))
    }

    /// [`Film::aovs`] with the images allocated fallibly.
    pub fn try_aovs(&self) -> Result<Aovs, AllocError> {
        let (w, h) = (self.width, self.height);
        let image = |c: usize| -> Result<Image, AllocError> {
            let data = fallible::try_vec(w * h * c, 0.0f32, &format!("the {w}x{h} AOV images"))?;
            Ok(Image::from_vec(w, h, c, data).expect("size matches"))
        };
        let mut a = Aovs {
            width: w,
            height: h,
            color: image(3)?,
            variance: image(3)?,
            direct: image(3)?,
            indirect: image(3)?,
            albedo: image(3)?,
            normal: image(3)?,
            position: image(3)?,
            depth: image(1)?,
        };
        let to_rgb = |v: [f64; 3]| Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32);
        for y in 0..h {
            for x in 0..w {
                let p = self.pixel(x, y);
                let n = p.samples.max(1) as f64;
                a.color.set_rgb(x, y, to_rgb(p.mean()));
                a.variance.set_rgb(x, y, to_rgb(p.variance_of_mean()));
                a.direct.set_rgb(x, y, to_rgb(p.sum_direct.map(|s| s / n)));
                a.indirect.set_rgb(x, y, to_rgb(p.sum_indirect.map(|s| s / n)));
                a.albedo.set_rgb(x, y, p.surface.albedo);
                a.normal.set_rgb(x, y, p.surface.normal);
                a.position.set_rgb(x, y, p.surface.position);
                a.depth.pixel_mut(x, y)[0] = p.surface.depth;
            }
        }
        Ok(a)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_variance_of_mean_match_the_naive_formulas() {
        let vals = [0.5f32, 2.0, 1.25, 7.0, 0.0, 3.5];
        let mut p = FilmPixel::default();
        for v in vals {
            p.add(&PixelSample { color: Rgb::splat(v), direct: Rgb::splat(v), indirect: Rgb::ZERO });
        }
        let n = vals.len() as f64;
        let mean = vals.iter().map(|&v| v as f64).sum::<f64>() / n;
        let s2 = vals.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / (n - 1.0);
        assert!((p.mean()[1] - mean).abs() < 1e-12);
        assert!((p.variance_of_mean()[2] - s2 / n).abs() < 1e-12);
    }

    #[test]
    fn non_finite_samples_are_dropped_and_counted() {
        let mut f = Film::new(2, 1);
        let good = PixelSample { color: Rgb::ONE, direct: Rgb::ONE, indirect: Rgb::ZERO };
        let bad = PixelSample { color: Rgb::new(f32::NAN, 0.0, 0.0), ..good };
        f.pixel_mut(0, 0).add(&good);
        f.pixel_mut(0, 0).add(&bad);
        f.pixel_mut(1, 0).add(&PixelSample { indirect: Rgb::splat(f32::INFINITY), ..good });
        assert_eq!(f.total_samples(), 1);
        assert_eq!(f.dropped_samples(), 2);
        assert_eq!(f.min_samples(), 0);
        assert_eq!(f.max_samples(), 1);
        assert_eq!(f.pixels_without_samples(), 0, "a pixel whose samples were all dropped was traced");
        assert_eq!(Film::new(3, 1).pixels_without_samples(), 3);
        let a = f.aovs();
        assert_eq!(a.color.count_non_finite(), 0);
        assert_eq!(a.color.rgb(0, 0), Rgb::ONE);
        assert_eq!(a.color.rgb(1, 0), Rgb::ZERO);
    }

    /// Every one of the nine values, as NaN, +-inf or the largest finite value.
    #[test]
    fn is_finite_checks_every_component() {
        let base = PixelSample { color: Rgb::ONE, direct: Rgb::splat(0.5), indirect: Rgb::splat(-0.0) };
        assert!(base.is_finite());
        for k in 0..9 {
            for (x, finite) in
                [(f32::NAN, false), (f32::INFINITY, false), (f32::NEG_INFINITY, false), (f32::MAX, true)]
            {
                let mut v = [base.color, base.direct, base.indirect].map(|c| c.to_array());
                v[k / 3][k % 3] = x;
                let s = PixelSample { color: v[0].into(), direct: v[1].into(), indirect: v[2].into() };
                assert_eq!(s.is_finite(), finite, "component {k}, value {x}");
            }
        }
    }
}
