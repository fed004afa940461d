//! The frame of filtered path tracing (Bauszat et al. 2011, Figure 1), top to bottom:
//!
//! 1. **guide** — one guide ray per pixel through the pixel centre; at its hit: normal,
//!    depth, albedo, direct light (one light sample) and indirect light (1..N paths, or a
//!    per-pixel count from adaptive sampling) into the noisy indirect map (§3.1, §3.2).
//!    Each row's guide rays go to the source as one batch ([`PathSource::trace_batch`]),
//!    or, with an explicit batch size and a source that traces single paths, their paths
//!    go in batches (the sample-offset buffer, sample-to-pixel map and per-pixel reduction
//!    of Bauszat et al.'s adaptive-sampling paper, §4.3); every way gives the same bits as
//!    one call per pixel. The guide rays are written straight into the G-buffer layers
//!    (rows in parallel). [`crate::guide`].
//! 2. **filter** — the indirect map, demodulated by the albedo, is filtered with any
//!    [`IndirectFilter`] guided by the guide rays' normal and depth (§3.3).
//! 3. **samples** — every further eye ray of the pixel (jittered in the pixel) traces its
//!    first hit and its direct light only; blocks of them go to the source as batches.
//!    [`crate::samples`].
//! 4. **lookup** — each further eye ray takes its indirect light from the filtered map at the
//!    most similar of its four neighbouring guide rays (§3.2, eqs. 3-5), re-modulated by its
//!    own albedo; samples are averaged with a box filter.
//!
//! Passes 3 and 4 run in passes of sample indices (1, 1, 2, 4, ... up to
//! [`SAMPLE_PASS_MAX`] further samples per pixel), and each pass over chunks of at most
//! [`SAMPLE_CHUNK`] samples whose values are added to per-pixel sums in the frame's layers,
//! so that memory is O(pixels) whatever the spp (a record of 52 bytes per sample would
//! take 56 GB at 512x512 and 4096 spp). The sums see the same additions in the same
//! order for any chunk size.
//!
//! Cancellation ([`FilteredRenderer::set_cancel`]): the flag is polled per row of the guide
//! rays and per block of the further samples. Cancelled during the guide rays, the frame
//! is an error ([`PipelineError::Cancelled`]); during a pass of further samples, the pass
//! is undone (the sums are restored from a copy taken before it) and the frame is
//! completed from the whole passes done: it is then exactly the frame of
//! [`Frame::spp_done`] samples per pixel.
//!
//! The same lookup on the *unfiltered* map gives the `noisy` layer at no extra tracing cost,
//! so that `noisy = direct + indirect` and, with [`NoFilter`](crate::NoFilter),
//! `color == noisy`.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use crate::buffers::Buffers;
use crate::filter::IndirectFilter;
use crate::frame::{ms, resize_images};
use crate::guide::{self, PathCounts};
use crate::samples::supersample;
use crate::source::PathSource;

pub use crate::frame::{Frame, FrameImages, FrameTimings};
pub use crate::settings::{
    PipelineError, PipelineSettings, DEMODULATION_EPS, MAX_PIXELS, MAX_SIDE, MAX_SPP, SAMPLE_CHUNK,
    SAMPLE_PASS_MAX,
};

/// Filtered path tracing driven frame by frame (a viewer calls [`render_frame`] in its
/// loop; buffers are kept between frames).
///
/// [`render_frame`]: FilteredRenderer::render_frame
pub struct FilteredRenderer<S: PathSource, F: IndirectFilter> {
    source: S,
    filter: F,
    settings: PipelineSettings,
    /// Slots per batch of indirect paths (§4.3); `None`: one per pixel, as in the paper.
    batch_size: Option<usize>,
    /// Set (e.g. by Ctrl-C) to stop the frame early; see the module docs.
    cancel: Option<Arc<AtomicBool>>,
    /// Further samples per chunk of passes 3-4 ([`SAMPLE_CHUNK`]).
    sample_chunk: usize,
    buf: Buffers,
}

impl<S: PathSource, F: IndirectFilter> FilteredRenderer<S, F> {
    pub fn new(source: S, filter: F, settings: PipelineSettings) -> Result<Self, PipelineError> {
        check(&source, &settings)?;
        let buf = Buffers::default();
        Ok(Self { source, filter, settings, batch_size: None, cancel: None, sample_chunk: SAMPLE_CHUNK, buf })
    }

    /// A flag that, once set, stops the frames at their next check (see the module docs).
    pub fn set_cancel(&mut self, cancel: Option<Arc<AtomicBool>>) {
        self.cancel = cancel;
    }

    pub fn settings(&self) -> &PipelineSettings {
        &self.settings
    }

    /// Changes the settings (resolution, spp, seed...) for the next frame.
    pub fn set_settings(&mut self, settings: PipelineSettings) -> Result<(), PipelineError> {
        check(&self.source, &settings)?;
        self.settings = settings;
        Ok(())
    }

    /// Slots per batch when the guide rays' indirect paths are traced one at a time
    /// ([`PathSource::traces_single_paths`]); `None` (the default) is the paper's
    /// resolution-sized batch, traced without per-slot buffers (each pixel's slot range in
    /// one task, stored as it is traced). The frame does not depend on it, only memory and
    /// overhead.
    pub fn set_batch_size(&mut self, batch_size: Option<usize>) {
        self.batch_size = batch_size.map(|b| b.max(1));
    }
    pub fn batch_size(&self) -> Option<usize> {
        self.batch_size
    }

    /// Further samples traced per chunk before their lookup (default [`SAMPLE_CHUNK`]); the
    /// frame does not depend on it, only memory and overhead (`usize::MAX`: every sample
    /// of the frame at once, the two-pass frame without chunks).
    pub fn set_sample_chunk(&mut self, samples: usize) {
        self.sample_chunk = samples.max(1);
    }
    pub fn sample_chunk(&self) -> usize {
        self.sample_chunk
    }

    /// Bytes of the pipeline's own buffers and layers now (their capacities; the filter's
    /// scratch is not included): what [`crate::memory::frame_bytes`] estimates.
    pub fn buffer_bytes(&self) -> u64 {
        self.buf.bytes()
    }

    pub fn source(&self) -> &S {
        &self.source
    }
    /// The source, to change it between frames (the viewer moves the renderer's camera);
    /// a source whose resolution then differs from the settings' fails the next frame with
    /// [`PipelineError::SourceResolution`] until [`FilteredRenderer::set_settings`] follows.
    pub fn source_mut(&mut self) -> &mut S {
        &mut self.source
    }
    pub fn filter_mut(&mut self) -> &mut F {
        &mut self.filter
    }
    /// Replaces the filter for the next frame.
    pub fn set_filter(&mut self, filter: F) {
        self.filter = filter;
    }

    /// The last frame rendered (empty before the first).
    pub fn last_frame(&self) -> &Frame {
        &self.buf.frame
    }

    /// Renders a frame with `settings.indirect_paths` indirect paths at every guide ray.
    pub fn render_frame(&mut self) -> Result<&Frame, PipelineError> {
        self.render_frame_with_counts(None)
    }

    /// Renders a frame; `indirect_counts` (row-major, one per pixel) replaces
    /// `indirect_paths` per pixel, e.g. from adaptive sampling. 0 leaves a pixel's indirect
    /// map entry at zero for the filter to fill from its neighbours.
    pub fn render_frame_with_counts(
        &mut self,
        indirect_counts: Option<&[u32]>,
    ) -> Result<&Frame, PipelineError> {
        let st = self.settings.clone();
        check(&self.source, &st)?;
        let (w, h) = (st.width as usize, st.height as usize);
        let n = w * h;
        if let Some(c) = indirect_counts {
            if c.len() != n {
                return Err(PipelineError::CountsLength { expected: n, got: c.len() });
            }
        }
        let start = Instant::now();
        let source = &self.source;
        let buf = &mut self.buf;
        let (never, flag) = (AtomicBool::new(false), self.cancel.clone());
        let cancel = flag.as_deref().unwrap_or(&never);
        resize_images(&mut buf.frame.images, w, h, st.filter_direct)?;

        // 1. Guide rays through the pixel centres (§3.2): first hit, direct, indirect.
        let t0 = Instant::now();
        let counts = match indirect_counts {
            Some(c) => PathCounts::PerPixel(c),
            None => PathCounts::Uniform(st.indirect_paths),
        };
        guide::trace_guides(source, buf, &st, counts, self.batch_size, cancel)?;
        let guide_ms = ms(t0);
        if cancel.load(Ordering::Relaxed) {
            return Err(PipelineError::Cancelled);
        }

        // 2. Filter the indirect map guided by the guide rays' normal and depth (§3.3).
        let t1 = Instant::now();
        {
            let im = &mut buf.frame.images;
            self.filter
                .apply(&im.indirect_map, &im.guide, &mut im.filtered_map)
                .map_err(PipelineError::Filter)?;
        }
        let mut filter_ms = ms(t1);

        // 3. Further eye samples, jittered in the pixel: first hit and direct light only;
        // 4. their geometry-aware lookup (eqs. 3-5) and box reconstruction. In passes of
        // sample indices (a cancelled frame keeps whole passes), a chunk of samples at a
        // time (memory independent of spp).
        let (samples_ms, lookup_ms, failures, done) =
            supersample(source, buf, &st, self.sample_chunk, cancel)?;

        // Optional: the direct light filtered too (comparison only).
        if st.filter_direct {
            let t4 = Instant::now();
            let im = &mut buf.frame.images;
            self.filter
                .apply(&im.direct, &im.guide, &mut im.filtered_direct)
                .map_err(PipelineError::Filter)?;
            let (c, fd, fi) = (&mut im.color, &im.filtered_direct, &im.filtered_indirect);
            for ((c, d), i) in c.data_mut().iter_mut().zip(fd.data()).zip(fi.data()) {
                *c = d + i;
            }
            filter_ms += ms(t4);
        }

        buf.frame.lookup_failures = failures;
        buf.frame.spp_done = done as u32 + 1;
        buf.frame.timings = FrameTimings { guide_ms, filter_ms, samples_ms, lookup_ms, total_ms: ms(start) };
        Ok(&buf.frame)
    }
}

fn check<S: PathSource>(source: &S, settings: &PipelineSettings) -> Result<(), PipelineError> {
    settings.validate()?;
    match source.resolution() {
        Some(r) if r != (settings.width, settings.height) => {
            Err(PipelineError::SourceResolution { source: r, frame: (settings.width, settings.height) })
        }
        _ => Ok(()),
    }
}
