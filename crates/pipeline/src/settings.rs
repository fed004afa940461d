//! What a frame of the filtered pipeline is asked for ([`PipelineSettings`]), its limits,
//! and why it can fail ([`PipelineError`]).

use filtrace_render::memory::AllocError;

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
