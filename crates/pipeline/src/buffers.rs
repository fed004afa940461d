//! The buffers a [`crate::FilteredRenderer`] keeps from frame to frame.

use filtrace_adaptive::Slot;
use filtrace_core::{Rgb, Vec2};

use crate::frame::Frame;
use crate::lookup::{GuideGeometry, HitGeometry};
use crate::source::EyeSample;

/// A further eye sample kept between the samples pass and the lookup pass.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct SampleRecord {
    pub film: Vec2,
    pub hit: Option<HitGeometry>,
    pub albedo: Rgb,
    pub direct: Rgb,
}

/// Buffers reused from frame to frame.
#[derive(Default)]
pub(crate) struct Buffers {
    pub guides: GuideGeometry,
    /// Each guide ray's direct light (the rest of its record is in the G-buffer layers).
    pub guide_direct: Vec<Rgb>,
    /// The guide rays as traced, before they are stored (only with explicit batches).
    pub guide_samples: Vec<EyeSample>,
    pub batch: BatchBuffers,
    /// The further samples of one chunk, between tracing and lookup.
    pub samples: Vec<SampleRecord>,
    /// The direct, indirect and filtered-indirect sums before the current pass of further
    /// samples, to undo a cancelled pass.
    pub undo: Vec<f32>,
    pub frame: Frame,
}

impl Buffers {
    /// Bytes held (capacities), the frame's layers included.
    pub fn bytes(&self) -> u64 {
        fn cap<T>(v: &Vec<T>) -> u64 {
            (v.capacity() * std::mem::size_of::<T>()) as u64
        }
        let im = &self.frame.images;
        let g = &im.guide;
        let images = [
            &im.color,
            &im.noisy,
            &im.direct,
            &im.indirect,
            &im.filtered_indirect,
            &im.filtered_direct,
            &im.indirect_map,
            &im.filtered_map,
            &g.normal,
            &g.depth,
            &g.albedo,
            &g.position,
            &g.coverage,
        ];
        let image_bytes: u64 = images.iter().map(|i| (i.data().len() * 4) as u64).sum();
        image_bytes
            + cap(&self.guides.hits)
            + cap(&self.guide_direct)
            + cap(&self.guide_samples)
            + cap(&self.batch.slots)
            + cap(&self.batch.results)
            + cap(&self.samples)
            + cap(&self.undo)
    }
}

/// The batch buffers of §4.3: the sample-to-pixel map and one result per slot.
#[derive(Default)]
pub(crate) struct BatchBuffers {
    pub slots: Vec<Slot>,
    pub results: Vec<EyeSample>,
}
