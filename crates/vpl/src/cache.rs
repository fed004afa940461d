//! The importance cache (Georgiev et al. 2012, "Importance caching for complex
//! illumination"; the thesis, 4.2.5 and chapter 5): records placed through the G-buffer,
//! their four distributions over the VPLs, nearest-record search, and the samplers that
//! draw VPLs from the interpolated distributions.
//!
//! One frame, in order (the thesis's listing 1):
//! 1. [`place_on_surfaces`] (the renderer: surfaces traced pixel by pixel as the
//!    placement asks) or [`place_cache_points`] (a G-buffer in memory): back-project
//!    stratified screen samples through the G-buffer;
//! 2. [`ImportanceCache::build`]: evaluate every VPL at every record (through
//!    [`VplSet`]) into the distributions full E¹, unoccluded E², bounded E³ and
//!    conservative E⁴ = uniform, with their CDFs; parameters of the `optimized` sampler
//!    are carried from the previous cache or set a priori;
//! 3. per shading point: [`ImportanceCache::neighbours`] finds the M nearest records
//!    under `d(x0, x1) = |x0 − x1| + λ √(1 − n0·n1)`, then [`ImportanceCache::sample`]
//!    returns a [`SamplePlan`]: the VPLs to evaluate (with visibility) and how to combine
//!    them, `L ≈ offset + Σ weight_i · f(vpl_i)`;
//! 4. `optimized` only: [`SamplePlan::feedback`] per evaluated draw, gathered over the
//!    frame's passes in a [`SampleHistory`]; after each pass
//!    [`ImportanceCache::optimize_history`] takes one damped Newton step per record (He and
//!    Owen 2014, thesis 3.5 and 5.2.2).
//!
//! Samplers ([`SamplerKind`]): `uniform` (one VPL, pmf 1/N), `alpha-max` (multi-sample
//! MIS, one draw per distribution, Georgiev's α-max heuristic), `balance` (one-sample
//! balance heuristic over the interpolated distributions with fixed mixture weights),
//! `balance-cv` (the same plus the distributions as control variates), `optimized`
//! (mixture and control-variate weights per record, optimised frame to frame).
//! docs/many-light-cache.md has the math as implemented and the choices the thesis
//! leaves open.

// `!(x > 0.0)` is how NaN-safe tests read here: NaN fails them.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod alpha_max;
mod faint;
mod feedback;
mod history;
mod optimize;
mod placement;
mod record;
mod sampler;
mod search;
mod vpl_set;

#[cfg(test)]
mod tests;

pub use alpha_max::{alpha_max_owner, alpha_max_weight};
pub use faint::FaintCut;
pub use feedback::SampleFeedback;
pub use history::{SampleHistory, StoredSample};
pub use optimize::{newton_step, OptimizeStats, OptimizerParams, RecordParams, StepOutcome};
pub use placement::{is_surface, place_cache_points, place_on_surfaces, GBufferView, ScreenSurfaces};
pub(crate) use record::CDF_BLOCK;
pub use record::{CacheRecord, ImportanceCache, VplCdf};
pub use sampler::{sample_uniform_vpl, SamplePlan, VplDraw, MAX_DRAWS};
pub use search::{cache_distance, KdTree, Nearest, Neighbours, MAX_NEIGHBOURS};
pub(crate) use vpl_set::RgbColumns;
pub use vpl_set::{
    evaluate_each_vpl, relaxed_geometry_term, relaxed_geometry_term_fast, relaxed_geometry_term_towards,
    RecordValues, Region, RelaxedReceiver, VisibilityRays, VplSet,
};

use filtrace_core::Vec3;

/// A cache point: the surface point seen through `pixel` (row-major index into the
/// G-buffer it was placed from), with its unit normal.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CachePoint {
    pub position: Vec3,
    pub normal: Vec3,
    pub pixel: u32,
}

/// The four distributions of a record (thesis 4.2.5), in the α-max order: earlier ones
/// are trusted first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Technique {
    /// E¹: the full contribution, with visibility.
    Full = 0,
    /// E²: the contribution without visibility.
    Unoccluded = 1,
    /// E³: the contribution with the relaxed geometry term over the record's neighbourhood.
    Bounded = 2,
    /// E⁴ = 1: conservative, uniform over the VPLs.
    Uniform = 3,
}

/// Number of [`Technique`]s; arrays indexed by technique have this length.
pub const TECHNIQUES: usize = 4;

impl Technique {
    pub const ALL: [Technique; TECHNIQUES] =
        [Technique::Full, Technique::Unoccluded, Technique::Bounded, Technique::Uniform];

    pub fn name(self) -> &'static str {
        match self {
            Technique::Full => "full",
            Technique::Unoccluded => "unoccluded",
            Technique::Bounded => "bounded",
            Technique::Uniform => "uniform",
        }
    }
}

/// Which distributions the samplers use. The uniform one is always on: it is the
/// fallback that keeps every VPL's pmf positive, which every estimator here needs to be
/// unbiased (thesis 3.5). The thesis's GPU setting found 3 best (full, unoccluded,
/// uniform; its Figure 37); Georgiev uses all four.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DistributionSet {
    pub full: bool,
    pub unoccluded: bool,
    pub bounded: bool,
}

impl DistributionSet {
    /// All four (Georgiev et al.).
    pub fn all() -> Self {
        DistributionSet { full: true, unoccluded: true, bounded: true }
    }

    /// Full, unoccluded and uniform (the thesis's choice, 6.4).
    pub fn thesis() -> Self {
        DistributionSet { full: true, unoccluded: true, bounded: false }
    }

    /// The first `n` of full, unoccluded, bounded, plus uniform: `n + 1` distributions
    /// (`n` clamped to 0..=3), for the "number of distributions" experiment.
    pub fn first(n: usize) -> Self {
        DistributionSet { full: n >= 1, unoccluded: n >= 2, bounded: n >= 3 }
    }

    /// Whether `t` is used.
    #[inline]
    pub fn contains(&self, t: Technique) -> bool {
        match t {
            Technique::Full => self.full,
            Technique::Unoccluded => self.unoccluded,
            Technique::Bounded => self.bounded,
            Technique::Uniform => true,
        }
    }

    /// The enabled techniques in α-max order.
    pub fn techniques(&self) -> impl Iterator<Item = Technique> + '_ {
        Technique::ALL.into_iter().filter(|&t| self.contains(t))
    }

    /// Number of enabled distributions (uniform included).
    pub fn count(&self) -> usize {
        self.techniques().count()
    }
}

/// The VPL samplers (`--vpl-sampler`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SamplerKind {
    Uniform,
    AlphaMax,
    Balance,
    BalanceCv,
    Optimized,
}

impl SamplerKind {
    pub const ALL: [SamplerKind; 5] = [
        SamplerKind::Uniform,
        SamplerKind::AlphaMax,
        SamplerKind::Balance,
        SamplerKind::BalanceCv,
        SamplerKind::Optimized,
    ];

    /// The CLI name.
    pub fn name(self) -> &'static str {
        match self {
            SamplerKind::Uniform => "uniform",
            SamplerKind::AlphaMax => "alpha-max",
            SamplerKind::Balance => "balance",
            SamplerKind::BalanceCv => "balance-cv",
            SamplerKind::Optimized => "optimized",
        }
    }

    /// Whether the sampler reads the cache (all but `uniform`).
    pub fn needs_cache(self) -> bool {
        self != SamplerKind::Uniform
    }
}

impl std::str::FromStr for SamplerKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        SamplerKind::ALL.into_iter().find(|k| k.name() == s).ok_or_else(|| {
            let names: Vec<_> = SamplerKind::ALL.iter().map(|k| k.name()).collect();
            format!("unknown VPL sampler '{s}' (expected one of: {})", names.join(", "))
        })
    }
}

/// Default [`CacheParams::faint_share`]: see docs/many-light-cache.md, "Faint VPLs without
/// a ray", for the measurement that chose it.
pub const DEFAULT_FAINT_SHARE: f32 = 0.02;

/// Parameters of the cache and its samplers.
#[derive(Clone, Debug, PartialEq)]
pub struct CacheParams {
    /// Number of cache points placed per frame (`--cache-points`; Georgiev and the
    /// thesis: 2048 at 1080p... tied to the image, not the scene).
    pub cache_points: usize,
    /// M, records interpolated per shading point (`--cache-neighbours`; the thesis uses 2,
    /// Georgiev 3), 1..=[`MAX_NEIGHBOURS`].
    pub neighbours: usize,
    /// λ = `lambda_scale` · D with D the scene's bounding-box diagonal (the thesis: the
    /// paper's 0.5/D is a typo for a length proportional to D; we keep the 0.5).
    pub lambda_scale: f32,
    /// Which distributions the samplers use.
    pub distributions: DistributionSet,
    /// α-max confidences (full, unoccluded, bounded, uniform); Georgiev's (1, 0.5, 0.5, 0.3).
    pub confidences: [f32; TECHNIQUES],
    /// Fixed mixture weights of `balance` and `balance-cv`, and the a priori start of
    /// `optimized` (normalised over the enabled distributions).
    pub prior_alpha: [f32; TECHNIQUES],
    /// The per-record optimisation of `optimized`.
    pub optimizer: OptimizerParams,
    /// At most this share of a record's unoccluded light may come from VPLs taken as
    /// visible without a shadow ray, the faintest ones (`--cache-faint-share`; 0: every
    /// VPL gets its ray, as in the thesis). Shapes only the full distribution E¹, so it
    /// biases nothing ([`FaintCut`]).
    pub faint_share: f32,
}

impl Default for CacheParams {
    fn default() -> Self {
        CacheParams {
            cache_points: 2048,
            neighbours: 2,
            lambda_scale: 0.5,
            distributions: DistributionSet::all(),
            confidences: [1.0, 0.5, 0.5, 0.3],
            // The α-max confidences, normalised: the same trust order without a second
            // set of magic numbers.
            prior_alpha: [1.0 / 2.3, 0.5 / 2.3, 0.5 / 2.3, 0.3 / 2.3],
            optimizer: OptimizerParams::default(),
            faint_share: DEFAULT_FAINT_SHARE,
        }
    }
}

impl CacheParams {
    /// Checks the parameters; the message names the bad value.
    pub fn validate(&self) -> Result<(), String> {
        if !(1..=MAX_NEIGHBOURS).contains(&self.neighbours) {
            return Err(format!("cache neighbours M = {} (expected 1..={MAX_NEIGHBOURS})", self.neighbours));
        }
        if !(self.lambda_scale.is_finite() && self.lambda_scale >= 0.0) {
            return Err(format!("cache lambda scale {} (expected a finite value >= 0)", self.lambda_scale));
        }
        for (t, &c) in Technique::ALL.iter().zip(&self.confidences) {
            if !(c > 0.0 && c <= 1.0) {
                return Err(format!("alpha-max confidence of {} = {c} (expected in (0, 1])", t.name()));
            }
        }
        for (t, &a) in Technique::ALL.iter().zip(&self.prior_alpha) {
            if self.distributions.contains(*t) && !(a.is_finite() && a > 0.0) {
                return Err(format!("prior mixture weight of {} = {a} (expected > 0)", t.name()));
            }
        }
        if !(0.0..1.0).contains(&self.faint_share) {
            return Err(format!("cache faint share {} (expected in [0, 1))", self.faint_share));
        }
        self.optimizer.validate(&self.distributions)
    }

    /// The fixed mixture `prior_alpha`, zero for disabled distributions, normalised.
    pub fn prior_mixture(&self) -> [f32; TECHNIQUES] {
        let mut a = [0.0; TECHNIQUES];
        for t in self.distributions.techniques() {
            a[t as usize] = self.prior_alpha[t as usize].max(0.0);
        }
        let sum: f32 = a.iter().sum();
        a.map(|x| x / sum)
    }
}
