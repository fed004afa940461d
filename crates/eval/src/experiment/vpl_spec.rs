//! The many-light part of an experiment spec (issue 14, the thesis's 6.4-6.5): the VPL
//! ground truth, the `[vpl]` defaults and the per-method sampler settings. Plain data:
//! the crate never sees a renderer, the CLI's backend maps these onto `filtrace-vpl`
//! (and its tests check that the names and ranges here match that crate's).

use serde::{Deserialize, Deserializer, Serialize};

/// Most cache records interpolated per shading point (`filtrace_vpl::cache::MAX_NEIGHBOURS`).
pub const MAX_NEIGHBOURS: u32 = 4;
/// Most distributions of a record: full, unoccluded, bounded, uniform.
pub const MAX_DISTRIBUTIONS: u32 = 4;
/// Upper bound of VPL and cache-point counts (as the CLI's `--vpls` / `--cache-points`).
pub const MAX_COUNT: u32 = 1_000_000;

/// What the methods are judged against, besides a path-traced reference.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GroundTruth {
    /// The exhaustive VPL sum (`filtrace render --integrator vpl --ground-truth`).
    Vpl,
}

/// An image error ([`crate::metrics`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Metric {
    /// Mean of per-pixel `(x − r)² / (r² + 0.01)` (Rousselle et al. 2011).
    #[serde(rename = "relmse")]
    RelMse,
    /// The thesis's relMSE (6.1.2): values clamped to [0, 1], `Σ (x − r)² / Σ r²`.
    #[serde(rename = "relmse-clamped")]
    RelMseClamped,
}

impl Metric {
    pub fn label(self) -> &'static str {
        match self {
            Metric::RelMse => "relMSE",
            Metric::RelMseClamped => "relMSE (clamped)",
        }
    }
}

/// The VPL samplers (`--vpl-sampler`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum VplSampler {
    Uniform,
    AlphaMax,
    Balance,
    BalanceCv,
    Optimized,
}

impl VplSampler {
    pub const ALL: [VplSampler; 5] = [
        VplSampler::Uniform,
        VplSampler::AlphaMax,
        VplSampler::Balance,
        VplSampler::BalanceCv,
        VplSampler::Optimized,
    ];

    /// The CLI name.
    pub fn name(self) -> &'static str {
        match self {
            VplSampler::Uniform => "uniform",
            VplSampler::AlphaMax => "alpha-max",
            VplSampler::Balance => "balance",
            VplSampler::BalanceCv => "balance-cv",
            VplSampler::Optimized => "optimized",
        }
    }
}

/// `[vpl]`: the VPL set (shared by every method and the ground truth) and the defaults
/// of the methods' cache settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VplSpec {
    /// VPLs per frame, one eighth on the lights (the thesis: 2048).
    #[serde(default = "default_vpls", deserialize_with = "de_vpls")]
    pub vpls: u32,
    /// Bound of the geometry term below this fraction of the scene radius (`--vpl-clamp`);
    /// none by default (unbiased with respect to the VPL sum).
    #[serde(default, deserialize_with = "de_clamp")]
    pub clamp: Option<f32>,
    #[serde(default, deserialize_with = "de_count")]
    pub cache_points: Option<u32>,
    #[serde(default, deserialize_with = "de_neighbours")]
    pub neighbours: Option<u32>,
    #[serde(default, deserialize_with = "de_distributions")]
    pub distributions: Option<u32>,
    #[serde(default, deserialize_with = "de_faint_share")]
    pub faint_share: Option<f32>,
}

impl Default for VplSpec {
    fn default() -> Self {
        VplSpec {
            vpls: default_vpls(),
            clamp: None,
            cache_points: None,
            neighbours: None,
            distributions: None,
            faint_share: None,
        }
    }
}

fn default_vpls() -> u32 {
    2048
}

/// A many-light method with every default filled in.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct VplMethod {
    pub sampler: VplSampler,
    pub vpls: u32,
    pub clamp: Option<f32>,
    pub cache_points: u32,
    /// M.
    pub neighbours: u32,
    /// Uniform included, 1..=4.
    pub distributions: u32,
    /// Share of a record's light its faint VPLs may carry without a visibility ray
    /// (`--cache-faint-share`).
    pub faint_share: f32,
}

/// A method's own cache settings, each over `[vpl]`'s and the renderer's defaults.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VplOverrides {
    pub neighbours: Option<u32>,
    pub distributions: Option<u32>,
    pub cache_points: Option<u32>,
    pub faint_share: Option<f32>,
}

/// Defaults of `filtrace render --integrator vpl` (`CacheParams::default()`).
pub const DEFAULT_CACHE_POINTS: u32 = 2048;
pub const DEFAULT_NEIGHBOURS: u32 = 2;
pub const DEFAULT_DISTRIBUTIONS: u32 = 4;
pub const DEFAULT_FAINT_SHARE: f32 = 0.02;

impl VplSpec {
    /// A method's settings: its own, else these defaults, else the renderer's.
    pub fn resolve(&self, sampler: VplSampler, own: &VplOverrides) -> VplMethod {
        VplMethod {
            sampler,
            vpls: self.vpls,
            clamp: self.clamp,
            cache_points: own.cache_points.or(self.cache_points).unwrap_or(DEFAULT_CACHE_POINTS),
            neighbours: own.neighbours.or(self.neighbours).unwrap_or(DEFAULT_NEIGHBOURS),
            distributions: own.distributions.or(self.distributions).unwrap_or(DEFAULT_DISTRIBUTIONS),
            faint_share: own.faint_share.or(self.faint_share).unwrap_or(DEFAULT_FAINT_SHARE),
        }
    }
}

pub(super) fn de_neighbours<'de, D: Deserializer<'de>>(d: D) -> Result<Option<u32>, D::Error> {
    de_range(d, "neighbours", 1, MAX_NEIGHBOURS)
}

pub(super) fn de_distributions<'de, D: Deserializer<'de>>(d: D) -> Result<Option<u32>, D::Error> {
    de_range(d, "distributions", 1, MAX_DISTRIBUTIONS)
}

pub(super) fn de_count<'de, D: Deserializer<'de>>(d: D) -> Result<Option<u32>, D::Error> {
    de_range(d, "cache_points", 1, MAX_COUNT)
}

pub(super) fn de_faint_share<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f32>, D::Error> {
    let v = f64::deserialize(d)?;
    if !(v.is_finite() && (0.0..1.0).contains(&v)) {
        return Err(serde::de::Error::custom(format!("faint_share = {v} (expected in [0, 1))")));
    }
    Ok(Some(v as f32))
}

fn de_vpls<'de, D: Deserializer<'de>>(d: D) -> Result<u32, D::Error> {
    Ok(de_range(d, "vpls", 1, MAX_COUNT)?.unwrap_or(default_vpls()))
}

fn de_clamp<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f32>, D::Error> {
    let v = f64::deserialize(d)?;
    if !(v.is_finite() && v > 0.0 && v < 1.0) {
        return Err(serde::de::Error::custom(format!(
            "clamp = {v} (expected a fraction of the scene radius in (0, 1))"
        )));
    }
    Ok(Some(v as f32))
}

/// `Option<u32>` in `lo..=hi`, for `deserialize_with`: the error carries the value's span.
fn de_range<'de, D: Deserializer<'de>>(d: D, what: &str, lo: u32, hi: u32) -> Result<Option<u32>, D::Error> {
    let v = i64::deserialize(d)?;
    if v < lo as i64 || v > hi as i64 {
        return Err(serde::de::Error::custom(format!("{what} = {v} (expected {lo}..={hi})")));
    }
    Ok(Some(v as u32))
}
