//! One frame of the filtered pipeline: its layers ([`FrameImages`]) and what each stage
//! cost ([`FrameTimings`]).

use std::time::Instant;

use filtrace_core::Image;
use filtrace_render::memory::{try_vec, AllocError};

use crate::filter::GuideLayers;

/// Milliseconds per stage of one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrameTimings {
    /// Guide rays: first hit, direct light, indirect paths.
    pub guide_ms: f64,
    /// Filtering the indirect map (and the direct layer when asked).
    pub filter_ms: f64,
    /// Further eye samples: first hit and direct light.
    pub samples_ms: f64,
    /// Geometry-aware lookup and box reconstruction.
    pub lookup_ms: f64,
    pub total_ms: f64,
}

impl FrameTimings {
    /// Tracing time (guide rays and further samples).
    pub fn trace_ms(&self) -> f64 {
        self.guide_ms + self.samples_ms
    }
    /// `(stage, ms)` pairs in frame order, for tables.
    pub fn stages(&self) -> [(&'static str, f64); 4] {
        [
            ("guide", self.guide_ms),
            ("filter", self.filter_ms),
            ("samples", self.samples_ms),
            ("lookup", self.lookup_ms),
        ]
    }
}

/// The layers of a frame (all `width x height`, linear radiance unless noted).
#[derive(Clone, Debug)]
pub struct FrameImages {
    /// The final image: direct + filtered indirect (3 channels).
    pub color: Image,
    /// Direct + unfiltered indirect, same samples and lookup (3 channels).
    pub noisy: Image,
    /// Box mean of the samples' direct light (3 channels).
    pub direct: Image,
    /// Box mean of the samples' unfiltered indirect light (3 channels).
    pub indirect: Image,
    /// Box mean of the samples' filtered indirect light (3 channels).
    pub filtered_indirect: Image,
    /// The filtered direct layer when `filter_direct` is on (else empty).
    pub filtered_direct: Image,
    /// The guide rays' indirect map as filtered (demodulated when `demodulate_albedo`).
    pub indirect_map: Image,
    /// The map after the filter.
    pub filtered_map: Image,
    /// The guide rays' G-buffer (normal, depth, albedo, position, coverage).
    pub guide: GuideLayers,
}

impl Default for FrameImages {
    fn default() -> Self {
        let e = || Image::new(0, 0, 3);
        Self {
            color: e(),
            noisy: e(),
            direct: e(),
            indirect: e(),
            filtered_indirect: e(),
            filtered_direct: e(),
            indirect_map: e(),
            filtered_map: e(),
            guide: GuideLayers::default(),
        }
    }
}

/// One rendered frame: its layers and what each stage cost.
#[derive(Clone, Debug, Default)]
pub struct Frame {
    pub images: FrameImages,
    pub timings: FrameTimings,
    /// Further samples whose four neighbouring guide rays all escaped (no indirect light).
    pub lookup_failures: u64,
    /// Eye samples per pixel in the images, the guide ray included: the settings' `spp`,
    /// or fewer when the frame was cancelled.
    pub spp_done: u32,
}

pub(crate) fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Gives every layer the frame's size (allocated fallibly; each pass writes all of its
/// layer).
pub(crate) fn resize_images(
    im: &mut FrameImages,
    w: usize,
    h: usize,
    filter_direct: bool,
) -> Result<(), AllocError> {
    let fit = |img: &mut Image, c: usize| -> Result<(), AllocError> {
        if img.width() != w || img.height() != h || img.channels() != c {
            *img = Image::new(0, 0, c); // free the old layer first
            let data = try_vec(w * h * c, 0.0, &format!("the {w}x{h} frame layers"))?;
            *img = Image::from_vec(w, h, c, data).expect("w * h * c values");
        }
        Ok(())
    };
    for img in [&mut im.color, &mut im.noisy, &mut im.direct, &mut im.indirect, &mut im.filtered_indirect] {
        fit(img, 3)?;
    }
    fit(&mut im.indirect_map, 3)?;
    fit(&mut im.filtered_map, 3)?;
    fit(&mut im.guide.normal, 3)?;
    fit(&mut im.guide.albedo, 3)?;
    fit(&mut im.guide.position, 3)?;
    fit(&mut im.guide.depth, 1)?;
    fit(&mut im.guide.coverage, 1)?;
    if filter_direct {
        fit(&mut im.filtered_direct, 3)?;
    } else {
        im.filtered_direct = Image::new(0, 0, 3);
    }
    Ok(())
}
