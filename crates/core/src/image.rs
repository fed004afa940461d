//! Plain float images: `width x height` pixels of `channels` interleaved `f32` values,
//! row-major with row 0 at the top. Filters, film and I/O exchange these.

use glam::Vec3;

#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    width: usize,
    height: usize,
    channels: usize,
    data: Vec<f32>,
}

impl Image {
    /// A zero-filled image. Zero-sized images are allowed (and empty).
    pub fn new(width: usize, height: usize, channels: usize) -> Self {
        Self { width, height, channels, data: vec![0.0; width * height * channels] }
    }

    /// An image filled with `value` in every channel.
    pub fn filled(width: usize, height: usize, channels: usize, value: f32) -> Self {
        Self { width, height, channels, data: vec![value; width * height * channels] }
    }

    /// Wraps existing interleaved data. Returns `None` when the length does not match.
    pub fn from_vec(width: usize, height: usize, channels: usize, data: Vec<f32>) -> Option<Self> {
        (data.len() == width * height * channels).then_some(Self { width, height, channels, data })
    }

    /// A 3-channel image from RGB pixels.
    pub fn from_rgb(width: usize, height: usize, pixels: &[Vec3]) -> Option<Self> {
        if pixels.len() != width * height {
            return None;
        }
        let data = pixels.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
        Some(Self { width, height, channels: 3, data })
    }

    #[inline]
    pub fn width(&self) -> usize {
        self.width
    }
    #[inline]
    pub fn height(&self) -> usize {
        self.height
    }
    #[inline]
    pub fn channels(&self) -> usize {
        self.channels
    }
    #[inline]
    pub fn pixel_count(&self) -> usize {
        self.width * self.height
    }
    #[inline]
    pub fn data(&self) -> &[f32] {
        &self.data
    }
    #[inline]
    pub fn data_mut(&mut self) -> &mut [f32] {
        &mut self.data
    }
    pub fn into_vec(self) -> Vec<f32> {
        self.data
    }

    #[inline]
    pub fn same_size(&self, other: &Image) -> bool {
        self.width == other.width && self.height == other.height
    }

    /// Channel values of pixel `(x, y)`.
    #[inline]
    pub fn pixel(&self, x: usize, y: usize) -> &[f32] {
        let i = (y * self.width + x) * self.channels;
        &self.data[i..i + self.channels]
    }

    #[inline]
    pub fn pixel_mut(&mut self, x: usize, y: usize) -> &mut [f32] {
        let i = (y * self.width + x) * self.channels;
        &mut self.data[i..i + self.channels]
    }

    /// The first three channels of pixel `(x, y)` as a vector (missing channels read 0).
    #[inline]
    pub fn rgb(&self, x: usize, y: usize) -> Vec3 {
        let p = self.pixel(x, y);
        Vec3::new(p[0], *p.get(1).unwrap_or(&0.0), *p.get(2).unwrap_or(&0.0))
    }

    /// Writes the first three channels of pixel `(x, y)`.
    #[inline]
    pub fn set_rgb(&mut self, x: usize, y: usize, c: Vec3) {
        let p = self.pixel_mut(x, y);
        for (k, v) in p.iter_mut().take(3).enumerate() {
            *v = c[k];
        }
    }

    /// Rows of interleaved values, for parallel iteration.
    pub fn rows_mut(&mut self) -> std::slice::ChunksExactMut<'_, f32> {
        let stride = (self.width * self.channels).max(1);
        self.data.chunks_exact_mut(stride)
    }

    /// Per-channel mean over all pixels (non-finite values included as they are).
    pub fn mean(&self) -> Vec<f64> {
        let mut sum = vec![0.0f64; self.channels];
        for px in self.data.chunks_exact(self.channels.max(1)) {
            for (s, v) in sum.iter_mut().zip(px) {
                *s += *v as f64;
            }
        }
        let n = self.pixel_count().max(1) as f64;
        sum.iter().map(|s| s / n).collect()
    }

    /// Number of non-finite (NaN or infinite) values.
    pub fn count_non_finite(&self) -> usize {
        self.data.iter().filter(|v| !v.is_finite()).count()
    }

    /// A new image holding channels `range` of this one.
    pub fn channels_range(&self, range: std::ops::Range<usize>) -> Image {
        let c = range.len();
        let mut out = Image::new(self.width, self.height, c);
        for (dst, src) in
            out.data.chunks_exact_mut(c.max(1)).zip(self.data.chunks_exact(self.channels.max(1)))
        {
            dst.copy_from_slice(&src[range.clone()]);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_addressing_is_row_major() {
        let mut im = Image::new(3, 2, 3);
        im.set_rgb(2, 1, Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(&im.data()[15..18], &[1.0, 2.0, 3.0]);
        assert_eq!(im.rgb(2, 1), Vec3::new(1.0, 2.0, 3.0));
    }

    #[test]
    fn from_vec_checks_length() {
        assert!(Image::from_vec(2, 2, 3, vec![0.0; 11]).is_none());
        assert!(Image::from_vec(0, 0, 3, vec![]).is_some());
    }

    #[test]
    fn channel_subset_and_mean() {
        let im = Image::from_vec(2, 1, 4, vec![1.0, 2.0, 3.0, 4.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        let s = im.channels_range(1..3);
        assert_eq!(s.data(), &[2.0, 3.0, 4.0, 5.0]);
        assert_eq!(s.mean(), vec![3.0, 4.0]);
    }
}
