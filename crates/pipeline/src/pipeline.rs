//! The frame of filtered path tracing (Bauszat et al. 2011, Figure 1), top to bottom:
//!
//! 1. **guide** — one guide ray per pixel through the pixel centre; at its hit: normal,
//!    depth, albedo, direct light (one light sample) and indirect light (1..N paths, or a
//!    per-pixel count from adaptive sampling) into the noisy indirect map (§3.1, §3.2).
//!    A source that traces single paths gets each pixel's paths in its row's task (the
//!    frame is one batch), or, with an explicit batch size, in batches (the sample-offset
//!    buffer, sample-to-pixel map and per-pixel reduction of Bauszat et al.'s
//!    adaptive-sampling paper, §4.3); every way gives the same bits as one call per pixel.
//!    The guide rays are written straight into the G-buffer layers (rows in parallel).
//! 2. **filter** — the indirect map, demodulated by the albedo, is filtered with any
//!    [`IndirectFilter`] guided by the guide rays' normal and depth (§3.3).
//! 3. **samples** — every further eye ray of the pixel (jittered in the pixel) traces its
//!    first hit and its direct light only.
//! 4. **lookup** — each further eye ray takes its indirect light from the filtered map at the
//!    most similar of its four neighbouring guide rays (§3.2, eqs. 3-5), re-modulated by its
//!    own albedo; samples are averaged with a box filter.
//!
//! Passes 3 and 4 run in passes of sample indices (1, 1, 2, 4, ... up to
//! [`SAMPLE_PASS_MAX`] further samples per pixel), and each pass over chunks of at most
//! [`SAMPLE_CHUNK`] samples whose values are added to per-pixel sums in the frame's layers,
//! so that memory is O(pixels) whatever the spp (a record per sample was 52 bytes per
//! sample: 56 GB at 512x512 and 4096 spp). The sums see the same additions in the same
//! order for any chunk size.
//!
//! Cancellation ([`FilteredRenderer::set_cancel`]): the flag is polled per row of the guide
//! rays and per sample of the further samples. Cancelled during the guide rays, the frame
//! is an error ([`PipelineError::Cancelled`]); during a pass of further samples, the pass
//! is undone (the sums are restored from a copy taken before it) and the frame is
//! completed from the whole passes done: it is then exactly the frame of
//! [`Frame::spp_done`] samples per pixel.
//!
//! The same lookup on the *unfiltered* map gives the `noisy` layer at no extra tracing cost,
//! so that `noisy = direct + indirect` and, with [`NoFilter`](crate::NoFilter),
//! `color == noisy`.

use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use filtrace_adaptive::{BatchSchedule, Slot};
use filtrace_core::rng::{splitmix64, unit_f32};
use filtrace_core::{Image, Rgb, Vec2};
use rayon::prelude::*;

use filtrace_render::memory::{try_resize, try_vec, AllocError};

use crate::filter::{GuideLayers, IndirectFilter};
use crate::lookup::{most_similar_guide, GuideGeometry, HitGeometry};
use crate::source::{EyeSample, PathSource, SampleKey};

/// Added to the albedo before demodulating (`E = L_ind / (albedo + eps)`) and after
/// re-modulating, so that the round trip is exact and black surfaces do not divide by zero.
pub const DEMODULATION_EPS: f32 = 1e-3;

/// Largest pass of further samples per pixel (sample indices traced between two checks
/// of whether a cancelled frame may stop): a cancelled frame loses at most this many
/// samples per pixel of work.
pub const SAMPLE_PASS_MAX: usize = 16;

/// Largest accepted image side and pixel count (same limits as the renderer).
pub const MAX_SIDE: u32 = 32768;
pub const MAX_PIXELS: u64 = 1 << 28;

/// Largest accepted spp: further sample `s` of a pixel is sampler index `2^24 + s`
/// ([`crate::render_source::EYE_SAMPLE_INDEX_BASE`]), which must stay within `u32`.
pub const MAX_SPP: u32 = 1 << 30;

/// Further samples traced before their lookup (the records kept between passes 3 and 4):
/// bounds their memory at `SAMPLE_CHUNK * 52` bytes (6.8 MB), whatever the spp and the
/// resolution. 131,072 samples are milliseconds of tracing per chunk, against two parallel
/// joins of overhead per chunk.
pub const SAMPLE_CHUNK: usize = 1 << 17;

/// Settings of the filtered pipeline.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PipelineSettings {
    pub width: u32,
    pub height: u32,
    /// Eye samples per pixel, the guide ray included (Bauszat's "pixel sampling rate").
    pub spp: u32,
    /// Paths estimating the indirect light at each guide ray's hit (Bauszat: 1).
    pub indirect_paths: u32,
    /// Frame seed; the same seed gives the same frame.
    pub seed: u64,
    /// Divide the indirect light by the albedo before filtering and multiply by each
    /// sample's albedo after the lookup, so the filter does not blur textures.
    pub demodulate_albedo: bool,
    /// Also filter the direct light (for comparison; the paper filters the indirect only).
    pub filter_direct: bool,
}

impl PipelineSettings {
    /// Bauszat et al.'s setting: 1 indirect path per guide ray, 4 eye samples per pixel.
    pub fn paper(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            spp: 4,
            indirect_paths: 1,
            seed: 0,
            demodulate_albedo: true,
            filter_direct: false,
        }
    }

    /// The interactive setting of the CPU benchmark: 1 sample per pixel (the guide ray).
    pub fn interactive(width: u32, height: u32) -> Self {
        Self { spp: 1, ..Self::paper(width, height) }
    }

    pub fn validate(&self) -> Result<(), PipelineError> {
        if self.width == 0 || self.height == 0 {
            return Err(PipelineError::Resolution(self.width, self.height));
        }
        if self.width > MAX_SIDE
            || self.height > MAX_SIDE
            || self.width as u64 * self.height as u64 > MAX_PIXELS
        {
            return Err(PipelineError::Resolution(self.width, self.height));
        }
        if self.spp == 0 {
            return Err(PipelineError::ZeroSpp);
        }
        if self.spp > MAX_SPP {
            return Err(PipelineError::TooManySamples(self.spp));
        }
        Ok(())
    }
}

/// Why a frame cannot be rendered.
#[derive(Clone, Debug, PartialEq)]
pub enum PipelineError {
    Resolution(u32, u32),
    ZeroSpp,
    TooManySamples(u32),
    CountsLength {
        expected: usize,
        got: usize,
    },
    /// The path source was built for another resolution.
    SourceResolution {
        source: (u32, u32),
        frame: (u32, u32),
    },
    /// The filter refused its input (bad parameters or buffers).
    Filter(String),
    /// The batch schedule of the indirect paths could not be built.
    Batch(String),
    /// The cancel flag was set before the guide rays were done: there is no frame.
    Cancelled,
    /// A frame buffer could not be allocated.
    OutOfMemory(AllocError),
}

impl From<AllocError> for PipelineError {
    fn from(e: AllocError) -> Self {
        Self::OutOfMemory(e)
    }
}

impl std::fmt::Display for PipelineError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Resolution(w, h) => {
                write!(
                    f,
                    "resolution {w}x{h} is not supported (1..={MAX_SIDE} per side, at most 2^28 pixels)"
                )
            }
            Self::ZeroSpp => write!(f, "samples per pixel must be at least 1"),
            Self::TooManySamples(s) => {
                write!(f, "{s} samples per pixel is too many (at most {MAX_SPP})")
            }
            Self::OutOfMemory(e) => write!(f, "{e}"),
            Self::CountsLength { expected, got } => {
                write!(f, "per-pixel indirect sample counts: expected {expected} entries, got {got}")
            }
            Self::Filter(e) => write!(f, "filter: {e}"),
            Self::Batch(e) => write!(f, "batch schedule of the indirect paths: {e}"),
            Self::Cancelled => write!(f, "cancelled before the guide rays were done: no frame"),
            Self::SourceResolution { source, frame } => write!(
                f,
                "the path source renders {}x{}, the frame is {}x{}",
                source.0, source.1, frame.0, frame.1
            ),
        }
    }
}

impl std::error::Error for PipelineError {}

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

/// A further eye sample kept between the samples pass and the lookup pass.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct SampleRecord {
    film: Vec2,
    hit: Option<HitGeometry>,
    albedo: Rgb,
    direct: Rgb,
}

/// Buffers reused from frame to frame.
#[derive(Default)]
struct Buffers {
    guides: GuideGeometry,
    /// Each guide ray's direct light (the rest of its record is in the G-buffer layers).
    guide_direct: Vec<Rgb>,
    /// The guide rays as traced, before they are stored (only with explicit batches).
    guide_samples: Vec<EyeSample>,
    batch: BatchBuffers,
    /// The further samples of one chunk, between tracing and lookup.
    samples: Vec<SampleRecord>,
    /// The direct, indirect and filtered-indirect sums before the current pass of further
    /// samples, to undo a cancelled pass.
    undo: Vec<f32>,
    frame: Frame,
}

impl Buffers {
    /// Bytes held (capacities), the frame's layers included.
    fn bytes(&self) -> u64 {
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
    /// The source, to move its world to the next frame of an animation (the buffers stay).
    /// Its resolution must stay the frame's ([`FilteredRenderer::set_settings`] checks it).
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
        // Every entry is written by the pass: resize, no clearing.
        (buf.guides.width, buf.guides.height) = (w, h);
        try_resize(&mut buf.guides.hits, n, None, "the guide rays' hits")?;
        try_resize(&mut buf.guide_direct, n, Rgb::ZERO, "the guide rays' direct light")?;
        match self.batch_size {
            Some(batch) if source.traces_single_paths() => {
                // Explicit batches (§4.3): trace into per-slot buffers, then store.
                let counts: std::borrow::Cow<'_, [u32]> = match counts {
                    PathCounts::PerPixel(c) => c.into(),
                    PathCounts::Uniform(c) => vec![c; n].into(),
                };
                let schedule = BatchSchedule::from_counts(&counts, batch)
                    .map_err(|e| PipelineError::Batch(e.to_string()))?;
                try_resize(&mut buf.guide_samples, n, EyeSample::default(), "the guide rays")?;
                let bb = &mut buf.batch;
                guide_pass_batched(source, &schedule, bb, &mut buf.guide_samples, w, st.seed, cancel);
                let rows = guide_rows(&mut buf.guides.hits, &mut buf.guide_direct, &mut buf.frame.images, w);
                store_guides(&buf.guide_samples, rows, st.demodulate_albedo);
            }
            _ => {
                // The whole frame as one batch: each pixel's paths in one task, stored as
                // they are traced.
                let rows = guide_rows(&mut buf.guides.hits, &mut buf.guide_direct, &mut buf.frame.images, w);
                guide_pass(source, counts, rows, w, (st.seed, st.demodulate_albedo), cancel);
            }
        }
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

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Gives every layer the frame's size (allocated fallibly; each pass writes all of its
/// layer).
fn resize_images(im: &mut FrameImages, w: usize, h: usize, filter_direct: bool) -> Result<(), AllocError> {
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

/// Indirect path counts of the guide rays: one for every pixel, or one per pixel.
#[derive(Clone, Copy)]
enum PathCounts<'a> {
    Uniform(u32),
    PerPixel(&'a [u32]),
}

impl PathCounts<'_> {
    #[inline]
    fn of(&self, pixel: usize) -> u32 {
        match self {
            Self::Uniform(c) => *c,
            Self::PerPixel(c) => c[pixel],
        }
    }
}

/// Paths traced per [`PathSource::trace_paths`] call in [`guide_pass`]: bounds the scratch
/// buffer of a pixel with many paths (the sums do not depend on it).
const GUIDE_PATH_CHUNK: u32 = 64;

/// Pass 1 with the whole frame as one batch: rows in parallel, each pixel's paths traced in
/// one task and written straight into the G-buffer layers (no per-slot buffer, no
/// sample-to-pixel map). A source that traces single paths gets each pixel's slot range in
/// [`PathSource::trace_paths`] calls, summed from zero in path order and scaled last, as
/// [`guide_pass_batched`] does; the others get one [`PathSource::trace`] call per pixel.
/// Both give what `trace(key, film, count)` gives, bit for bit (the `trace_path` contract).
fn guide_pass<'a, S: PathSource>(
    source: &S,
    counts: PathCounts<'_>,
    rows: impl IndexedParallelIterator<Item = GuideRow<'a>>,
    w: usize,
    (seed, demod): (u64, bool),
    cancel: &AtomicBool,
) {
    let single = source.traces_single_paths();
    rows.enumerate().for_each(|(y, mut row)| {
        if cancel.load(Ordering::Relaxed) {
            return; // the frame is abandoned
        }
        let mut scratch = Vec::new();
        for x in 0..w {
            let key = SampleKey { x: x as u32, y: y as u32, sample: 0, seed };
            let count = counts.of(y * w + x);
            let e = if single && count > 0 {
                guide_paths(source, key, count, &mut scratch)
            } else {
                source.trace(key, guide_film(x, y), count)
            };
            row.store(x, &e, demod);
        }
    });
}

/// The guide ray of `key` with `count > 0` indirect paths traced one path at a time
/// ([`PathSource::trace_paths`], at most [`GUIDE_PATH_CHUNK`] per call): the first path
/// names the hit, the paths are summed from zero in path order and scaled by `1 / count`
/// last, as `trace` does.
fn guide_paths<S: PathSource>(
    source: &S,
    key: SampleKey,
    count: u32,
    scratch: &mut Vec<EyeSample>,
) -> EyeSample {
    let film = guide_film(key.x as usize, key.y as usize);
    let mut acc = EyeSample::default();
    let mut first = 0;
    while first < count {
        let len = (count - first).min(GUIDE_PATH_CHUNK);
        scratch.resize(len as usize, EyeSample::default());
        source.trace_paths(key, film, first..first + len, scratch);
        if first == 0 {
            let e = scratch[0];
            // An escaped ray is final as it is (the environment in `direct`).
            if e.hit.is_none() {
                return e;
            }
            acc = EyeSample { direct: Rgb::ZERO, indirect: Rgb::ZERO, ..e };
        }
        for e in scratch.iter() {
            acc.direct += e.direct;
            acc.indirect += e.indirect;
        }
        first += len;
    }
    let inv = 1.0 / count as f32;
    acc.direct *= inv;
    acc.indirect *= inv;
    acc
}

/// The batch buffers of §4.3: the sample-to-pixel map and one result per slot.
#[derive(Default)]
struct BatchBuffers {
    slots: Vec<Slot>,
    results: Vec<EyeSample>,
}

/// Pass 1 with a source that traces one path per call, after Bauszat et al. 2011, §4.3:
/// the per-pixel counts are scanned into sample offsets (`schedule`); each batch fills its
/// sample-to-pixel map, traces its slots in parallel (one task per pixel's slot range in
/// the batch, which shares the pixel's first hit) into the per-slot buffer, then each
/// pixel adds its own contiguous slot range in sample order (parallel over pixels, no
/// atomics). Pixels span batches; their sums carry over in `out`. Summing from zero in
/// path order and scaling by `1 / count` last gives what `trace(key, film, count)` gives
/// (the [`PathSource::trace_path`] contract), bit for bit, whatever the batch size and
/// the thread count. Pixels with no path get `trace(key, film, 0)` (first hit, direct).
fn guide_pass_batched<S: PathSource>(
    source: &S,
    schedule: &BatchSchedule,
    bb: &mut BatchBuffers,
    out: &mut [EyeSample],
    w: usize,
    seed: u64,
    cancel: &AtomicBool,
) {
    let key_of = |p: usize| SampleKey { x: (p % w) as u32, y: (p / w) as u32, sample: 0, seed };
    // Pixels without paths: first hit and direct light (as `trace(.., 0)`). The others are
    // written by the batches (their first path resets the sum).
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, e) in row.iter_mut().enumerate() {
            if schedule.count(y * w + x) == 0 {
                *e = source.trace(key_of(y * w + x), guide_film(x, y), 0);
            }
        }
    });
    let size = schedule.batch_size().min(schedule.total_samples() as usize);
    bb.slots.resize(size, Slot::default());
    bb.results.resize(size, EyeSample::default());
    for batch in schedule.batches() {
        if cancel.load(Ordering::Relaxed) {
            return; // the frame is abandoned
        }
        let len = batch.len();
        batch.fill_sample_to_pixel(&mut bb.slots);
        // Trace the batch: each pixel's slot range is one parallel task, so a pixel's
        // first hit is traced once per batch (`trace_paths`).
        let mut rest = &mut bb.results[..len];
        let mut tasks = Vec::with_capacity(batch.pixels().len());
        for p in batch.pixels() {
            let r = batch.slots_of(p);
            let (head, tail) = rest.split_at_mut(r.len());
            rest = tail;
            if !r.is_empty() {
                tasks.push((p, bb.slots[r.start].sample, head));
            }
        }
        tasks.into_par_iter().for_each(|(p, first, out)| {
            let paths = first..first + out.len() as u32;
            source.trace_paths(key_of(p), guide_film(p % w, p / w), paths, out);
        });
        // Per-pixel reduction over each pixel's own slot range, in sample order; a pixel
        // spanning batches carries its sum over in `out`.
        let first = batch.pixels().start;
        let (slots, results) = (&bb.slots, &bb.results);
        out[batch.pixels()].par_iter_mut().enumerate().for_each(|(i, acc)| {
            let p = first + i;
            for k in batch.slots_of(p) {
                let e = &results[k];
                if slots[k].sample == 0 {
                    // The first path names the hit; an escaped ray is final as it is.
                    *acc = if e.hit.is_some() {
                        EyeSample { direct: Rgb::ZERO, indirect: Rgb::ZERO, ..*e }
                    } else {
                        *e
                    };
                }
                if acc.hit.is_some() {
                    acc.direct += e.direct;
                    acc.indirect += e.indirect;
                    // After the pixel's last path: the mean, scaled last as `trace` does.
                    let count = schedule.count(p);
                    if slots[k].sample + 1 == count {
                        let inv = 1.0 / count as f32;
                        acc.direct *= inv;
                        acc.indirect *= inv;
                    }
                }
            }
        });
    }
}

/// Film position of the guide ray of pixel `(x, y)`: the pixel centre.
fn guide_film(x: usize, y: usize) -> Vec2 {
    Vec2::new(x as f32 + 0.5, y as f32 + 0.5)
}

/// One row of the guide layers: the G-buffer, the lookup's geometry, the guide ray's direct
/// light and the (demodulated) indirect map.
struct GuideRow<'a> {
    hits: &'a mut [Option<HitGeometry>],
    direct: &'a mut [Rgb],
    normal: &'a mut [f32],
    depth: &'a mut [f32],
    albedo: &'a mut [f32],
    position: &'a mut [f32],
    coverage: &'a mut [f32],
    map: &'a mut [f32],
}

/// The rows of the guide layers (already sized `w x h`), for a parallel pass.
fn guide_rows<'a>(
    hits: &'a mut [Option<HitGeometry>],
    direct: &'a mut [Rgb],
    im: &'a mut FrameImages,
    w: usize,
) -> impl IndexedParallelIterator<Item = GuideRow<'a>> {
    let g = &mut im.guide;
    (
        hits.par_chunks_mut(w),
        direct.par_chunks_mut(w),
        g.normal.data_mut().par_chunks_mut(3 * w),
        g.depth.data_mut().par_chunks_mut(w),
        g.albedo.data_mut().par_chunks_mut(3 * w),
        g.position.data_mut().par_chunks_mut(3 * w),
        g.coverage.data_mut().par_chunks_mut(w),
        im.indirect_map.data_mut().par_chunks_mut(3 * w),
    )
        .into_par_iter()
        .map(|(hits, direct, normal, depth, albedo, position, coverage, map)| GuideRow {
            hits,
            direct,
            normal,
            depth,
            albedo,
            position,
            coverage,
            map,
        })
}

impl GuideRow<'_> {
    /// Writes guide ray `e` of column `x` into the G-buffer and the (demodulated) indirect map.
    #[inline]
    fn store(&mut self, x: usize, e: &EyeSample, demod: bool) {
        let set = |dst: &mut [f32], c: Rgb| dst[3 * x..3 * x + 3].copy_from_slice(&c.to_array());
        self.hits[x] = e.hit;
        self.direct[x] = e.direct;
        let (n, d) = e.hit.map_or((Rgb::ZERO, 0.0), |h| (h.normal, h.depth));
        // A surface that reflects nothing (a pure emitter, like the Cornell light) has no
        // irradiance estimate: its map entry is 0 by construction, not a sample. Its normal
        // is zeroed in the filter's G-buffer so that filters treat it as background and do
        // not blend that 0 into coplanar neighbours (the ceiling around the light).
        let reflects = !demod || e.albedo.max_element() > 0.0;
        set(self.normal, if reflects { n } else { Rgb::ZERO });
        self.depth[x] = d;
        set(self.albedo, e.albedo);
        set(self.position, e.position);
        self.coverage[x] = if e.hit.is_some() && reflects { 1.0 } else { 0.0 };
        let ind = if demod { e.indirect / (e.albedo + DEMODULATION_EPS) } else { e.indirect };
        debug_assert!(ind.is_finite(), "non-finite indirect light at guide column {x}: {ind}");
        set(self.map, ind);
    }
}

/// Writes the guide rays traced by [`guide_pass_batched`] into the guide layers, rows in
/// parallel.
fn store_guides<'a>(g: &[EyeSample], rows: impl IndexedParallelIterator<Item = GuideRow<'a>>, demod: bool) {
    let w = g.len() / rows.len().max(1);
    rows.zip(g.par_chunks(w.max(1))).for_each(|(mut row, src)| {
        for (x, e) in src.iter().enumerate() {
            row.store(x, e, demod);
        }
    });
}

/// Jitter of further sample `key` inside its pixel, in `[0, 1)^2`: a hash of the key.
fn jitter(key: SampleKey) -> Vec2 {
    let mut h = key.seed ^ 0x243f_6a88_85a3_08d3;
    for v in [key.x as u64, key.y as u64, key.sample as u64] {
        h = splitmix64(h ^ v.wrapping_mul(0x9e37_79b9_7f4a_7c15));
    }
    Vec2::new(unit_f32(h), unit_f32(splitmix64(h)))
}

/// Passes 3 and 4: further samples `1..=extra` of every pixel in passes of sample indices
/// (1, 1, 2, 4, ... up to [`SAMPLE_PASS_MAX`] per pixel), each pass over chunks of at most
/// `chunk` samples: trace a chunk into `buf.samples` ([`trace_samples`]), then add each
/// sample to its pixel's sums ([`lookup_samples`]). The guide ray's own terms start the sums
/// ([`start_sums`]); the box mean is taken last ([`finish_sums`]). Every pixel's sums get
/// its samples in index order whatever the chunk and pass sizes, so the frame is the same
/// bit for bit. A pass cut by `cancel` is undone from a copy of the sums. Returns the
/// milliseconds of tracing and of lookup, the lookup failures and the further samples done.
fn supersample<S: PathSource>(
    source: &S,
    buf: &mut Buffers,
    st: &PipelineSettings,
    chunk: usize,
    cancel: &AtomicBool,
) -> Result<(f64, f64, u64, usize), AllocError> {
    let (w, demod) = (st.width as usize, st.demodulate_albedo);
    let pixels = w * st.height as usize;
    let extra = st.spp as usize - 1;
    let chunk = chunk.clamp(1, (pixels * extra.min(SAMPLE_PASS_MAX)).max(1));
    try_resize(&mut buf.samples, chunk, SampleRecord::default(), "the further samples")?;
    let undo_len = if extra > 0 { pixels * 9 } else { 0 };
    try_resize(&mut buf.undo, undo_len, 0.0, "the copy of the sums for a cancelled pass")?;
    let t = Instant::now();
    start_sums(buf, demod);
    let (mut samples_ms, mut lookup_ms) = (0.0, ms(t));
    let (mut failures, mut done) = (0, 0);
    'passes: while done < extra && !cancel.load(Ordering::Relaxed) {
        let pass = SamplePass { first: done, count: done.clamp(1, SAMPLE_PASS_MAX).min(extra - done) };
        save_sums(buf);
        let total = pixels * pass.count;
        let (mut at, mut pass_failures) = (0, 0);
        while at < total {
            let len = chunk.min(total - at);
            let t = Instant::now();
            let traced = trace_samples(source, &mut buf.samples[..len], at, pass, w, st.seed, cancel);
            samples_ms += ms(t);
            if !traced {
                restore_sums(buf);
                break 'passes;
            }
            let t = Instant::now();
            pass_failures += lookup_samples(buf, at..at + len, pass.count, demod);
            lookup_ms += ms(t);
            at += len;
        }
        failures += pass_failures;
        done += pass.count;
    }
    let t = Instant::now();
    finish_sums(&mut buf.frame.images, done);
    Ok((samples_ms, lookup_ms + ms(t), failures, done))
}

/// Further samples `first + 1 ..= first + count` of every pixel. Sample `r` of a pass is
/// sample `first + r % count + 1` of row-major pixel `r / count`.
#[derive(Clone, Copy)]
struct SamplePass {
    first: usize,
    count: usize,
}

/// The sums a pass adds to (direct, indirect, filtered indirect), copied before it.
fn save_sums(buf: &mut Buffers) {
    let im = &buf.frame.images;
    let n = im.direct.data().len();
    for (k, layer) in [&im.direct, &im.indirect, &im.filtered_indirect].into_iter().enumerate() {
        buf.undo[k * n..(k + 1) * n].copy_from_slice(layer.data());
    }
}

fn restore_sums(buf: &mut Buffers) {
    let im = &mut buf.frame.images;
    let n = im.direct.data().len();
    for (k, layer) in [&mut im.direct, &mut im.indirect, &mut im.filtered_indirect].into_iter().enumerate() {
        layer.data_mut().copy_from_slice(&buf.undo[k * n..(k + 1) * n]);
    }
}

/// Pass 3 on samples `first..first + out.len()` of `pass`: first hit and direct light of
/// each further eye ray, jittered in its pixel. Returns false, with `out` incomplete, when
/// `cancel` was set.
fn trace_samples<S: PathSource>(
    source: &S,
    out: &mut [SampleRecord],
    first: usize,
    pass: SamplePass,
    w: usize,
    seed: u64,
    cancel: &AtomicBool,
) -> bool {
    out.par_iter_mut()
        .enumerate()
        .try_for_each(|(k, rec)| {
            if cancel.load(Ordering::Relaxed) {
                return Err(());
            }
            let (p, s) = ((first + k) / pass.count, (pass.first + (first + k) % pass.count) as u32 + 1);
            let key = SampleKey { x: (p % w) as u32, y: (p / w) as u32, sample: s, seed };
            let film = Vec2::new(key.x as f32, key.y as f32) + jitter(key);
            let e = source.trace(key, film, 0);
            *rec = SampleRecord { film, hit: e.hit, albedo: e.albedo, direct: e.direct };
            Ok(())
        })
        .is_ok()
}

/// Factor that re-modulates a demodulated map entry at a sample of albedo `albedo`.
#[inline]
fn remodulation(albedo: Rgb, demod: bool) -> Rgb {
    if demod {
        albedo + DEMODULATION_EPS
    } else {
        Rgb::ONE
    }
}

/// The RGB value of one pixel's 3 values.
#[inline]
fn load(layer: &[f32]) -> Rgb {
    Rgb::new(layer[0], layer[1], layer[2])
}

/// Starts each pixel's sums with its guide ray: its direct light, and its own map entry
/// (unfiltered and filtered) re-modulated by its albedo.
fn start_sums(buf: &mut Buffers, demod: bool) {
    let im = &mut buf.frame.images;
    let (map, fmap, albedo) = (&im.indirect_map, &im.filtered_map, &im.guide.albedo);
    let guide_direct = &buf.guide_direct;
    im.direct
        .data_mut()
        .par_chunks_mut(3)
        .zip(im.indirect.data_mut().par_chunks_mut(3))
        .zip(im.filtered_indirect.data_mut().par_chunks_mut(3))
        .enumerate()
        .for_each(|(own, ((d, ind), find))| {
            let m = remodulation(map_rgb(albedo, own), demod);
            d.copy_from_slice(&guide_direct[own].to_array());
            ind.copy_from_slice(&(m * map_rgb(map, own)).to_array());
            find.copy_from_slice(&(m * map_rgb(fmap, own)).to_array());
        });
}

/// Pass 4 on samples `range` of a pass of `per_pixel` samples per pixel (traced into `buf.samples[..range.len()]`): each
/// sample's direct light, and its indirect light from the unfiltered and the filtered map
/// at the most similar neighbouring guide ray, added to its pixel's sums in sample order.
/// Returns the number of samples whose lookup found no guide that hit.
fn lookup_samples(buf: &mut Buffers, range: Range<usize>, per_pixel: usize, demod: bool) -> u64 {
    let Buffers { guides, samples, frame, .. } = buf;
    let im = &mut frame.images;
    let (map, fmap) = (&im.indirect_map, &im.filtered_map);
    let pixels = range.start / per_pixel..(range.end - 1) / per_pixel + 1;
    let values = pixels.start * 3..pixels.end * 3;
    im.direct.data_mut()[values.clone()]
        .par_chunks_mut(3)
        .zip(im.indirect.data_mut()[values.clone()].par_chunks_mut(3))
        .zip(im.filtered_indirect.data_mut()[values].par_chunks_mut(3))
        .enumerate()
        .map(|(i, ((d, ind), find))| {
            let p = pixels.start + i;
            let own = range.start.max(p * per_pixel)..range.end.min((p + 1) * per_pixel);
            let (mut sd, mut si, mut sf) = (load(d), load(ind), load(find));
            let mut fails = 0u64;
            for rec in &samples[own.start - range.start..own.end - range.start] {
                sd += rec.direct;
                let Some(hit) = &rec.hit else { continue };
                match most_similar_guide(guides, rec.film, hit) {
                    Some(g) => {
                        let m = remodulation(rec.albedo, demod);
                        si += m * map_rgb(map, g);
                        sf += m * map_rgb(fmap, g);
                    }
                    None => fails += 1,
                }
            }
            d.copy_from_slice(&sd.to_array());
            ind.copy_from_slice(&si.to_array());
            find.copy_from_slice(&sf.to_array());
            fails
        })
        .sum()
}

/// Box reconstruction: the sums of `done + 1` samples become means; `noisy` and `color`
/// are direct + unfiltered and direct + filtered indirect.
fn finish_sums(im: &mut FrameImages, done: usize) {
    let inv = 1.0 / (done + 1) as f32;
    im.color
        .data_mut()
        .par_chunks_mut(3)
        .zip(im.noisy.data_mut().par_chunks_mut(3))
        .zip(im.direct.data_mut().par_chunks_mut(3))
        .zip(im.indirect.data_mut().par_chunks_mut(3))
        .zip(im.filtered_indirect.data_mut().par_chunks_mut(3))
        .for_each(|((((color, noisy), direct), indirect), filtered)| {
            let (d, ind, find) = (load(direct) * inv, load(indirect) * inv, load(filtered) * inv);
            direct.copy_from_slice(&d.to_array());
            indirect.copy_from_slice(&ind.to_array());
            filtered.copy_from_slice(&find.to_array());
            noisy.copy_from_slice(&(d + ind).to_array());
            color.copy_from_slice(&(d + find).to_array());
        });
}

#[inline]
fn map_rgb(map: &Image, i: usize) -> Rgb {
    let p = &map.data()[i * 3..i * 3 + 3];
    Rgb::new(p[0], p[1], p[2])
}
