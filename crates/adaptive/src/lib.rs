//! # filtrace-adaptive
//!
//! Adaptive sampling for geometry-aware reconstruction filters, after
//! Bauszat, Eisemann and Magnor, *Adaptive Sampling for Geometry-aware Reconstruction
//! Filters* (2011). Before any shading ray is cast, a fixed per-frame sample budget is
//! moved towards pixels that a geometry-aware filter (À-Trous, guided,
//! cross-bilateral) cannot help much, because they have few similar neighbours.
//!
//! Three passes, one module each, all on plain images (this crate never sees a scene):
//! 1. [`importance_map`] (§4.1): `1 - W_p / |window|` from the normal and position
//!    layers of the G-buffer.
//! 2. [`apportion`] (§4.2): per-pixel counts `minSamples + ⌊s·q/t⌋`, with the rounding
//!    remainder distributed exactly by the largest-remainder method ([`Mode::Exact`],
//!    default) or dropped as in the paper ([`Mode::Paper`]).
//! 3. [`BatchSchedule`] (§4.3): exclusive scan into a sample-offset buffer, batches of
//!    a fixed size with a sample-to-pixel map, race-free per-pixel accumulation.
//!
//! When to use it: low sample counts (1-8 spp of indirect light) filtered by a
//! geometry-aware filter, on scenes with thin or detailed geometry (foliage, grass,
//! colonnades). On scenes that are complex everywhere the importance is nearly uniform
//! and the scheme falls back to uniform sampling (the paper's §6).
//!
//! ```
//! use filtrace_adaptive::{apportion, importance_map, BatchSchedule, ImportanceParams, Mode};
//! use filtrace_core::Image;
//! // G-buffer of a 4x4 frame: left half faces +z, right half faces +x (a crease).
//! let (w, h) = (4, 4);
//! let mut normal = Image::new(w, h, 3);
//! let mut position = Image::new(w, h, 3);
//! for y in 0..h {
//!     for x in 0..w {
//!         normal.pixel_mut(x, y).copy_from_slice(if x < 2 { &[0.0, 0.0, 1.0] } else { &[1.0, 0.0, 0.0] });
//!         position.pixel_mut(x, y).copy_from_slice(&[x as f32, y as f32, 0.0]);
//!     }
//! }
//! let importance = importance_map(&normal, &position, &ImportanceParams::paper()).unwrap();
//! let counts = apportion(&importance, 4 * 16, 1, Mode::Exact).unwrap();
//! assert_eq!(counts.total(), 64); // exactly the budget
//! let schedule = BatchSchedule::new(&counts, 16).unwrap();
//! let visited: usize = schedule.batches().map(|b| b.slots().count()).sum();
//! assert_eq!(visited, 64);
//! ```

pub mod apportion;
pub mod bench;
pub mod error;
pub mod importance;
pub mod schedule;
pub mod synthetic;

pub use apportion::{apportion, apportion_naive, Mode, SampleCounts};
pub use error::AdaptiveError;
pub use importance::{
    importance_map, importance_map_naive, resolve_sigma_position, ImportanceParams, PositionScale,
};
pub use schedule::{exclusive_scan, exclusive_scan_parallel, Batch, BatchSchedule, Slot};

/// All options of one adaptive frame, bundled (what `filtrace render --adaptive` sets).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AdaptiveParams {
    /// Importance map parameters (§4.1).
    pub importance: ImportanceParams,
    /// Samples per pixel on average: the frame budget is `budget_spp · pixels`.
    pub budget_spp: u32,
    /// Minimum samples of every pixel (`minSamples` of eq. 7). The paper: 1 or 2.
    pub min_spp: u32,
    /// Rounding of eq. 7.
    pub mode: Mode,
}

impl Default for AdaptiveParams {
    fn default() -> Self {
        Self::paper()
    }
}

impl AdaptiveParams {
    /// The paper's experiments: budget 4 spp, at least 1, "4x4" window; filtrace's
    /// exact rounding.
    pub fn paper() -> Self {
        Self { importance: ImportanceParams::paper(), budget_spp: 4, min_spp: 1, mode: Mode::Exact }
    }

    /// The frame budget for `pixels` pixels.
    pub fn budget(&self, pixels: usize) -> u64 {
        self.budget_spp as u64 * pixels as u64
    }
}

/// Importance map and apportionment in one call: the per-pixel counts of a frame,
/// and the importance map (to be written as an image layer).
pub fn plan_frame(
    normal: &filtrace_core::Image,
    position: &filtrace_core::Image,
    params: &AdaptiveParams,
) -> Result<(filtrace_core::Image, SampleCounts), AdaptiveError> {
    let importance = importance_map(normal, position, &params.importance)?;
    let budget = params.budget(importance.pixel_count());
    let counts = apportion(&importance, budget, params.min_spp, params.mode)?;
    Ok((importance, counts))
}
