//! The filter slot of the pipeline: anything that turns the noisy indirect map into a
//! smooth one, guided by the guide rays' G-buffer. The pipeline sees only this trait; the
//! adapter to `filtrace-denoise`'s filters is in [`crate::denoise_filter`].

use filtrace_core::Image;

/// The guide rays' G-buffer: one entry per pixel, noise-free (one ray through the centre).
#[derive(Clone, Debug)]
pub struct GuideLayers {
    /// Unit world-space shading normal, 3 channels; zero where the guide ray escaped or
    /// (when demodulating) hit a surface of zero albedo, whose indirect map entry carries no
    /// estimate: filters treat zero-normal pixels as background.
    pub normal: Image,
    /// Distance along the guide ray, 1 channel; 0 where it escaped.
    pub depth: Image,
    /// Diffuse albedo at the hit, 3 channels; zero where the guide ray escaped.
    pub albedo: Image,
    /// World-space hit position, 3 channels; zero where the guide ray escaped.
    pub position: Image,
    /// 1 where the normal is valid (see `normal`), 0 elsewhere; 1 channel.
    pub coverage: Image,
}

impl Default for GuideLayers {
    fn default() -> Self {
        let e = |c| Image::new(0, 0, c);
        Self { normal: e(3), depth: e(1), albedo: e(3), position: e(3), coverage: e(1) }
    }
}

/// A reconstruction filter for the indirect map (3 channels in, 3 channels out, same size).
pub trait IndirectFilter: Send {
    /// Short name for reports ("none", "guided", ...).
    fn label(&self) -> String;
    /// Writes the filtered `noisy` into `out` (already of the right size and channel count).
    /// An error (bad parameters, mismatched buffers) fails the frame; `out` is then undefined.
    fn apply(&mut self, noisy: &Image, guide: &GuideLayers, out: &mut Image) -> Result<(), String>;
}

/// Filtering off: the map passes unchanged (the unfiltered baseline; the pipeline then
/// reduces to a plain path tracer that reuses the guide rays' indirect light).
#[derive(Clone, Copy, Debug, Default)]
pub struct NoFilter;

impl IndirectFilter for NoFilter {
    fn label(&self) -> String {
        "none".into()
    }
    fn apply(&mut self, noisy: &Image, _guide: &GuideLayers, out: &mut Image) -> Result<(), String> {
        out.data_mut().copy_from_slice(noisy.data());
        Ok(())
    }
}

impl<F: IndirectFilter + ?Sized> IndirectFilter for Box<F> {
    fn label(&self) -> String {
        (**self).label()
    }
    fn apply(&mut self, noisy: &Image, guide: &GuideLayers, out: &mut Image) -> Result<(), String> {
        (**self).apply(noisy, guide, out)
    }
}
