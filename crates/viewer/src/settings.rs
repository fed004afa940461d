//! What the panel sets: how frames are rendered ([`RenderChoice`]) and how they are shown
//! ([`DisplayChoice`]). The render choice is part of every job the worker gets; a change
//! restarts the accumulation. The display choice only re-maps the last frame's layers.

use filtrace_io::{Tonemap, TonemapParams};
use filtrace_pipeline::FilterChoice;

/// The filters of the moving (1-spp) pipeline, in selector order; the first is the default.
pub const FILTERS: &[&str] = &["guided", "atrous", "bilateral", "none"];

/// The renderers of the still image (a branch each in `engine::Engine::still_frame`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StillRenderer {
    /// Progressive path tracing (`filtrace render`'s image).
    PathTracer,
    /// The many-light renderer: VPLs with the importance cache (`filtrace render
    /// --integrator vpl`), one frame of `spp_per_frame` samples.
    Vpl,
}

impl StillRenderer {
    pub const ALL: &'static [StillRenderer] = &[StillRenderer::PathTracer, StillRenderer::Vpl];
    pub fn label(self) -> &'static str {
        match self {
            StillRenderer::PathTracer => "path tracer (progressive)",
            StillRenderer::Vpl => "many-light VPL (one frame)",
        }
    }
}

/// Everything that decides the rendered frames (not their display).
#[derive(Clone, Debug, PartialEq)]
pub struct RenderChoice {
    /// Full render resolution (the still image's; moving frames scale it down).
    pub width: u32,
    pub height: u32,
    /// Mitsuba convention: 2 = direct light only, -1 = unbounded.
    pub max_depth: i32,
    pub seed: u64,
    /// Samples per pixel added per still frame.
    pub spp_per_frame: u32,
    /// Accumulation stops at this many samples per pixel.
    pub max_spp: u32,
    pub still: StillRenderer,
    /// The filter of moving frames, with preset and main parameters.
    pub filter: FilterChoice,
    /// Filter the moving frames' direct light too (at 1 spp its one light sample is noisy;
    /// the paper filters the indirect light only).
    pub filter_direct: bool,
    /// Adaptive sampling of the moving frames' indirect light (Bauszat et al.), which also
    /// gives the importance layer.
    pub adaptive: bool,
    /// Frame rate the moving frames' resolution adapts to.
    pub target_fps: f32,
}

impl RenderChoice {
    /// The defaults of `filtrace view`: the guided filter's paper preset while moving.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            max_depth: 8,
            seed: 0,
            spp_per_frame: 1,
            max_spp: 4096,
            still: StillRenderer::PathTracer,
            filter: FilterChoice::named(FILTERS[0]),
            filter_direct: false,
            adaptive: false,
            target_fps: 12.0,
        }
    }
}

/// How the frame is shown.
#[derive(Clone, Debug, PartialEq)]
pub struct DisplayChoice {
    /// Layer name (see [`crate::layers::LAYERS`]).
    pub layer: &'static str,
    /// Split view: the right part shows `split_layer`, the left `layer`.
    pub split: bool,
    pub split_layer: &'static str,
    /// Where the split is, as a fraction of the width.
    pub split_at: f32,
    pub exposure: f32,
    pub filmic: bool,
}

impl Default for DisplayChoice {
    fn default() -> Self {
        Self {
            layer: "colour",
            split: false,
            split_layer: "noisy",
            split_at: 0.5,
            exposure: 0.0,
            filmic: false,
        }
    }
}

impl DisplayChoice {
    /// The tone mapping of radiance layers (`filtrace render --exposure/--filmic`).
    pub fn tonemap(&self) -> TonemapParams {
        let curve = if self.filmic { Tonemap::Filmic } else { Tonemap::Clamp };
        TonemapParams { exposure: self.exposure, curve }
    }
}

/// The presets of filter `name` (first = default), for the panel.
pub fn filter_presets(name: &str) -> Vec<&'static str> {
    fn names<P>(p: &[(&'static str, P)]) -> Vec<&'static str> {
        p.iter().map(|(n, _)| *n).collect()
    }
    match name {
        "atrous" => names(&filtrace_denoise::AtrousParams::presets()),
        "guided" => names(&filtrace_denoise::GuidedParams::presets()),
        "bilateral" => names(&filtrace_denoise::BilateralParams::presets()),
        _ => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_filter_and_preset_builds() {
        for name in FILTERS {
            let presets = filter_presets(name);
            assert_eq!(presets.is_empty(), *name == "none", "{name}");
            let mut choices = vec![FilterChoice::named(name)];
            choices.extend(
                presets
                    .iter()
                    .map(|p| FilterChoice { preset: Some(p.to_string()), ..FilterChoice::named(name) }),
            );
            for c in choices {
                c.build(Some(1.0)).unwrap_or_else(|e| panic!("{c:?}: {e}"));
            }
        }
    }
}
