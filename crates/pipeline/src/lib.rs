//! # filtrace-pipeline
//!
//! Filtered path tracing after Bauszat, Eisemann and Magnor, *Guided Image Filtering for
//! Interactive High-quality Global Illumination* (EGSR 2011), Figure 1: direct and indirect
//! light are estimated separately; one guide ray per pixel estimates the indirect light,
//! which is filtered with a geometry-aware filter; every further sample of the pixel takes
//! its indirect light from the filtered map by a geometry-aware lookup (§3.2, eqs. 3-5) and
//! samples its direct light as usual; box reconstruction.
//!
//! - [`pipeline`]: the frame, pass by pass ([`FilteredRenderer::render_frame`]);
//!   [`guide`] (pass 1) and [`samples`] (passes 3 and 4) trace it, [`settings`] and
//!   [`frame`] say what is asked for and what comes out.
//! - [`lookup`]: the geometry-aware lookup (eqs. 3-5).
//! - [`memory`]: the bytes a frame will need, known before it is rendered.
//! - [`source`]: what the pipeline asks of a path tracer ([`PathSource`]).
//! - [`filter`]: the filter slot ([`IndirectFilter`]); [`denoise_filter`] puts
//!   `filtrace-denoise`'s filters in it.
//! - [`render_source`]: [`PathSource`] on filtrace's path tracer.
//!
//! ```
//! use filtrace_core::{Rgb, Vec2, Vec3};
//! use filtrace_pipeline::*;
//!
//! /// A wall facing the camera at depth 1: direct light 0.5, indirect light 0.25.
//! struct Wall;
//! impl PathSource for Wall {
//!     fn trace(&self, _key: SampleKey, _film: Vec2, paths: u32) -> EyeSample {
//!         let hit = Some(HitGeometry { normal: Vec3::Z, depth: 1.0 });
//!         let indirect = if paths > 0 { Rgb::splat(0.25) } else { Rgb::ZERO };
//!         EyeSample { hit, albedo: Rgb::splat(0.5), direct: Rgb::splat(0.5), indirect, ..Default::default() }
//!     }
//! }
//! let mut r = FilteredRenderer::new(Wall, NoFilter, PipelineSettings::paper(8, 8)).unwrap();
//! let frame = r.render_frame().unwrap();
//! assert!((frame.images.color.rgb(3, 4) - Rgb::splat(0.75)).abs().max_element() < 1e-6);
//! ```

pub mod adaptive;
mod buffers;
pub mod denoise_filter;
pub mod filter;
pub mod frame;
pub mod guide;
pub mod lookup;
pub mod memory;
pub mod pipeline;
pub mod render_source;
pub mod samples;
pub mod settings;
pub mod source;

pub use denoise_filter::{filter_by_name, DenoiseFilter, FilterChoice};
pub use filter::{GuideLayers, IndirectFilter, NoFilter};
pub use lookup::{most_similar_guide, neighbour_guides, GuideGeometry, HitGeometry};
pub use pipeline::{
    FilteredRenderer, Frame, FrameImages, FrameTimings, PipelineError, PipelineSettings, MAX_SPP,
    SAMPLE_CHUNK,
};
pub use render_source::RenderSource;
pub use source::{EyeRay, EyeSample, PathSlot, PathSource, SampleKey};
