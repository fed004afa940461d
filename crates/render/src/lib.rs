//! # filtrace-render
//!
//! The Monte Carlo path tracer of filtrace: a pinhole [`camera`], the deterministic
//! Owen-scrambled Sobol sampler ([`filtrace_core::sampler`]), BSDFs ([`bsdf`]), lights
//! ([`lights`]), the [`integrator`]s (next-event estimation + MIS, and a BSDF-only
//! reference), and the [`film`] that keeps per-pixel means, variances and the G-buffer.
//! [`Renderer`] ties them together and renders progressive passes in parallel.
//!
//! Data flow of one sample: `Renderer::trace_sample` → `camera::PinholeCamera::sample_ray`
//! (sample 0 through the pixel centre) → `integrator::path::li` (radiance split into
//! direct and indirect, visible surface at sample 0) → `film::FilmPixel::add`.

pub mod bsdf;
pub mod camera;
mod fallible;
pub mod film;
pub mod frame;
pub mod frame_bench;
mod frame_state;
pub mod integrator;
pub mod lights;
pub mod memory;
pub mod motion;
pub mod renderer;
pub mod settings;
pub mod surface;
pub mod texture;

pub use camera::PinholeCamera;
pub use film::{Aovs, Film, VisibleSurface};
pub use frame::{FrameDesc, FrameError, FrameUpdate};
pub use integrator::lockstep::{LaneStats, RayQueries};
pub use integrator::PathParams;
pub use motion::MotionAov;
pub use renderer::{
    render_bench, BenchResult, IntegratorKind, RenderError, RenderSettings, Renderer, TraceMode,
};
