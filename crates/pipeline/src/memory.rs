//! Memory of a filtered frame, known before the frame is rendered: the bytes of the
//! pipeline's layers and buffers ([`frame_bytes`]), of the filter's scratch
//! ([`filter_bytes`]) and of adaptive sampling's plan ([`adaptive_bytes`]), in the terms of
//! [`filtrace_render::memory`]. None of them grows with the spp: the further samples are
//! traced and looked up a chunk at a time ([`crate::pipeline::SAMPLE_CHUNK`]).
//!
//! The per-pixel factors of the filters and of the plan were measured by counting the
//! allocator's peak (`tests/memory.rs`, which checks every estimate against it).

use filtrace_core::Rgb;
use filtrace_render::memory::{bytes_of, image_bytes, output_bytes, MemoryEstimate};

use crate::buffers::SampleRecord;
use crate::lookup::HitGeometry;
use crate::settings::PipelineSettings;
use crate::source::EyeSample;

/// f32 channels of a frame's layers ([`crate::FrameImages`]): colour, noisy, direct,
/// indirect, filtered indirect, indirect map, filtered map, guide normal, albedo and
/// position (3 each), guide depth and coverage (1 each); `filtered_direct` adds 3.
pub const FRAME_CHANNELS: u32 = 10 * 3 + 2;

/// The pipeline's own layers and buffers for a frame of `st` (what
/// [`crate::FilteredRenderer::buffer_bytes`] counts after the frame): the layers, the guide
/// rays' hits and direct light (with an explicit `batch_size`, also the traced guide rays
/// and the batch buffers), one chunk of `sample_chunk` further-sample records (at most one
/// pass's) and the copy of the sums that undoes a cancelled pass.
pub fn frame_bytes(st: &PipelineSettings, batch_size: Option<usize>, sample_chunk: usize) -> MemoryEstimate {
    let (w, h) = (st.width, st.height);
    let n = w as u64 * h as u64;
    let channels = FRAME_CHANNELS + if st.filter_direct { 3 } else { 0 };
    let mut guide = bytes_of::<Option<HitGeometry>>(n) + bytes_of::<Rgb>(n);
    if let Some(batch) = batch_size {
        let slots = (batch as u64).min(n.saturating_mul(st.indirect_paths.max(1) as u64));
        guide += bytes_of::<EyeSample>(n) + slots * (8 + std::mem::size_of::<EyeSample>() as u64);
    }
    let pass = st.spp.saturating_sub(1).min(crate::settings::SAMPLE_PASS_MAX as u32) as u64;
    let records = (sample_chunk as u64).min(n.saturating_mul(pass)).max(1);
    let undo = if st.spp > 1 { image_bytes(w, h, 9) } else { 0 };
    MemoryEstimate::new(format!("a {w}x{h} filtered frame"))
        .with("frame layers", image_bytes(w, h, channels))
        .with("guide buffers", guide)
        .with("further samples", bytes_of::<SampleRecord>(records))
        .with("copy of the sums (cancelled pass)", undo)
}

/// The scratch of filter `name` (`none`, `atrous`, `guided`, `bilateral`) on a `w x h`
/// frame: f32 values per pixel plus a fixed part (measured peaks, `tests/memory.rs`; the
/// guided filter's fixed part is its strip buffers, the replayed column sums of its
/// sub-bands and the pool's right-sized buffers; 2 threads).
pub fn filter_bytes(name: &str, w: u32, h: u32) -> u64 {
    let (values_per_pixel, fixed) = match name {
        "none" => (0, 0),
        "atrous" => (22, 64 << 10),
        "guided" => (57, 2048 << 10),
        _ => (21, 8 << 10),
    };
    image_bytes(w, h, values_per_pixel) + fixed
}

/// Adaptive sampling's plan on a `w x h` frame while the frame is rendered and written:
/// the importance map, the per-pixel path counts and their image, 3 values per pixel (its
/// pre-pass G-buffer is freed before the frame's buffers are made; measured).
pub fn adaptive_bytes(w: u32, h: u32) -> u64 {
    image_bytes(w, h, 3)
}

/// Channels of the motion AOV (`motion.X/Y`, `prev_depth.Z`, `prev_normal.X/Y/Z`).
pub const MOTION_CHANNELS: u32 = 6;

/// Channels `filtrace render --filter` writes: every frame layer but the guide's coverage
/// (`filtered_direct` when on), adaptive sampling's importance and path counts, and the
/// motion AOV.
pub fn written_channels(st: &PipelineSettings, adaptive: bool) -> u32 {
    FRAME_CHANNELS - 1 + if st.filter_direct { 3 } else { 0 } + if adaptive { 2 } else { 0 } + MOTION_CHANNELS
}

/// Everything a filtered render of `st` with filter `filter` keeps alive while its EXR is
/// written: the pipeline's layers and buffers, the filter's scratch, adaptive sampling's
/// plan, and the EXR + PNG output ([`filtrace_render::memory::output_bytes`]).
pub fn render_bytes(st: &PipelineSettings, filter: &str, adaptive: bool) -> MemoryEstimate {
    let (w, h) = (st.width, st.height);
    frame_bytes(st, None, crate::settings::SAMPLE_CHUNK)
        .with("filter", filter_bytes(filter, w, h))
        .with("adaptive plan", if adaptive { adaptive_bytes(w, h) } else { 0 })
        .with("EXR and PNG output", output_bytes(w, h, written_channels(st, adaptive)))
}
