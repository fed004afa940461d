//! Virtual point lights (Keller 1997, "Instant radiosity"; the thesis, 4.2.1-4.2.3):
//! global illumination as direct light from a few thousand point lights.
//!
//! - [`generate`]: direct VPLs on the emitters and indirect VPLs from light paths, drawn
//!   with the lights' emission sampling (`LightSet::sample_le`), deterministic per seed;
//!   defaults as the thesis: 2048 VPLs, 256 on the lights, 1792 indirect.
//! - [`eval`]: the contribution of one VPL at a shading point, `E_VPL f G` (thesis eq. 9),
//!   with the BSDFs of both ends, and the optional bound of the geometry term's
//!   singularity (thesis 4.2.3, [`GeometryBound`]).
//! - [`exhaustive`]: the ground truth the importance cache is measured against, every VPL
//!   with exact visibility at every pixel, and the cache's [`crate::cache::VplSet`] view.
//! - [`gbuffer`]: the surfaces through the pixel centres, traced only where the cache
//!   placement and the records read them.
//! - [`integrator`]: the many-light integrator of the per-frame renderer: VPLs, G-buffer
//!   and importance cache in its `prepare`, shading with a sampler per camera sample, the
//!   optimisation step after each pass; the d-distance layer of the thesis's Figure 27.
//! - [`seam`]: plugging it into a [`filtrace_render::Renderer`] and rendering a frame in
//!   progressive passes ([`render_vpl_frame`], [`render_vpl_passes`]).
//! - `soa`: the cache's evaluation of eight VPLs at a time (structure of arrays).
//! - [`state`]: what the integrator carries from frame to frame ([`VplState`], serde),
//!   so that a sequence resumed after a frame continues exactly.
//! - [`rays`]: shadow rays counted (and sampled for replay) for the experiments' clocks.
//!
//! A VPL's `weight` already holds every Monte Carlo normalisation (selection probability,
//! densities, number of samples or light paths), so the VPL estimate of the reflected
//! radiance at `x0` is the plain sum `Σ_j contribution_j(x0)` (thesis eq. 9 with the 1/N
//! folded in).

pub mod eval;
pub mod exhaustive;
pub mod gbuffer;
pub mod generate;
pub mod integrator;
pub mod rays;
pub mod seam;
mod soa;
pub mod state;

#[cfg(test)]
mod tests;

pub use eval::{GeometryBound, Receiver};
pub use exhaustive::{exhaustive_pixel, render_exhaustive, ExhaustiveImage, SceneVpls};
pub use gbuffer::{CameraSurfaces, RecordReceivers};
pub use generate::{generate_vpls, VplParams};
pub use integrator::{frame_vpl_seed, StageTimes, VplIntegrator, VplReport, VplSettings};
pub use seam::{collect_frame, render_vpl_frame, render_vpl_passes, use_vpl_integrator, VplFrame};
pub use state::{carries_state, VplState, STATE_VERSION};

use filtrace_core::sampling::Frame;
use filtrace_core::{Rgb, Vec3};
use filtrace_render::bsdf::SurfaceBsdf;
use filtrace_render::lights::SpotLight;

/// How a VPL emits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum VplKind {
    /// A point on an emitter: radiance `weight` (normalised) leaving the face of `n`
    /// (both faces when `two_sided`) with cosine falloff.
    Emitter { two_sided: bool },
    /// A light path's vertex on a reflecting surface: the flux `weight` arrived from
    /// `wi_local` (in `frame`, pointing back along the path) and leaves by the BSDF.
    Surface { bsdf: SurfaceBsdf, frame: Frame, wi_local: Vec3 },
    /// An isotropic point light of intensity `weight`, as it is.
    Point,
    /// A spot light of intensity `weight` times its falloff, as it is.
    Spot { light: SpotLight },
    /// Light from infinitely far along `n` (towards the light): irradiance `weight`
    /// (a directional light, or one sample of the environment).
    Distant,
}

/// One virtual point light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vpl {
    /// Position (unused for [`VplKind::Distant`]).
    pub p: Vec3,
    /// Unit geometric normal on the lit side (surface and emitter VPLs); the direction
    /// towards the light for distant ones; zero for point and spot lights.
    pub n: Vec3,
    /// Radiance, flux or intensity with every Monte Carlo normalisation folded in.
    pub weight: Rgb,
    pub kind: VplKind,
    /// Bounces from the light: 0 for direct VPLs, k for the k-th vertex of a light path.
    pub depth: u32,
}

impl Vpl {
    /// True for VPLs on the light sources themselves (direct light).
    #[inline]
    pub fn is_direct(&self) -> bool {
        self.depth == 0
    }

    /// The surface normal the cache's bounded distribution relaxes (`None` for VPLs
    /// without a surface).
    #[inline]
    pub fn surface_normal(&self) -> Option<Vec3> {
        match self.kind {
            VplKind::Emitter { .. } | VplKind::Surface { .. } => Some(self.n),
            _ => None,
        }
    }
}

/// The VPLs of one frame with how they were made.
#[derive(Clone, Debug, Default)]
pub struct Vpls {
    pub vpls: Vec<Vpl>,
    /// Light paths traced for the indirect VPLs (their weights are divided by this).
    pub light_paths: usize,
    /// The bound applied when evaluating them.
    pub bound: GeometryBound,
}

impl Vpls {
    pub fn len(&self) -> usize {
        self.vpls.len()
    }
    pub fn is_empty(&self) -> bool {
        self.vpls.is_empty()
    }
    /// Number of direct VPLs (they come first).
    pub fn direct_count(&self) -> usize {
        self.vpls.iter().take_while(|v| v.is_direct()).count()
    }
}
