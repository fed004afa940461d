//! What to render ([`RenderSettings`]) and why settings are rejected ([`RenderError`]).

use crate::integrator::PathParams;
use std::fmt;

/// Largest accepted image side.
pub const MAX_SIDE: u32 = 32768;
/// Largest accepted pixel count (2^28).
pub const MAX_PIXELS: u64 = 1 << 28;

/// What to render.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    /// Samples per pixel of a full render ([`Renderer::render`]).
    pub spp: u32,
    /// Mitsuba convention: 1 = emitters seen directly, 2 = direct light only, 8 default,
    /// -1 = unbounded.
    pub max_depth: i32,
    pub seed: u64,
}

impl Default for RenderSettings {
    /// 512 x 512, 64 spp, max depth 8, seed 0.
    fn default() -> Self {
        Self { width: 512, height: 512, spp: 64, max_depth: 8, seed: 0 }
    }
}

/// Why settings were rejected.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RenderError {
    ZeroResolution { width: u32, height: u32 },
    ResolutionTooLarge { width: u32, height: u32 },
    ZeroSpp,
    InvalidMaxDepth(i32),
}

impl fmt::Display for RenderError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RenderError::ZeroResolution { width, height } => {
                write!(f, "resolution {width}x{height} has no pixels (both sides must be at least 1)")
            }
            RenderError::ResolutionTooLarge { width, height } => write!(
                f,
                "resolution {width}x{height} is too large (at most {MAX_SIDE} per side and {MAX_PIXELS} pixels)"
            ),
            RenderError::ZeroSpp => write!(f, "samples per pixel must be at least 1"),
            RenderError::InvalidMaxDepth(d) => {
                write!(f, "max depth {d} is invalid (use -1 for unbounded or a depth >= 1)")
            }
        }
    }
}

impl std::error::Error for RenderError {}

impl RenderSettings {
    /// Checks the settings (see [`RenderError`]).
    pub fn validate(&self) -> Result<(), RenderError> {
        let (width, height) = (self.width, self.height);
        if width == 0 || height == 0 {
            return Err(RenderError::ZeroResolution { width, height });
        }
        if width > MAX_SIDE || height > MAX_SIDE || width as u64 * height as u64 > MAX_PIXELS {
            return Err(RenderError::ResolutionTooLarge { width, height });
        }
        if self.spp == 0 {
            return Err(RenderError::ZeroSpp);
        }
        if self.max_depth == 0 || self.max_depth < -1 {
            return Err(RenderError::InvalidMaxDepth(self.max_depth));
        }
        Ok(())
    }

    /// The integrator parameters these settings imply (Russian roulette from depth 5).
    pub fn path_params(&self) -> PathParams {
        PathParams { max_depth: self.max_depth, ..PathParams::mitsuba() }
    }
}
