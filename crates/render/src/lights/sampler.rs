//! Light samplers: which light to sample from a shading point (pbrt-v4
//! `base/lightsampler.h`). [`PowerLightSampler`] picks in proportion to power, whatever
//! the point; an importance cache (the many-light renderer) picks from distributions
//! cached near the point, behind the same [`LightSampler`] interface.

use super::LightSampleContext;
use filtrace_core::sampling::AliasTable;

/// A chosen light and the probability of choosing it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampledLight {
    /// Index of the light in the sampler's list.
    pub light: usize,
    /// Probability with which [`LightSampler::sample`] chose it from this context.
    pub p: f32,
}

/// Chooses among `n` lights; `sample` and `pmf` must agree (the MIS weights use `pmf`).
pub trait LightSampler {
    /// The light that `u` in `[0, 1)` picks for `ctx`; `None` when no light can be chosen.
    fn sample(&self, ctx: &LightSampleContext, u: f32) -> Option<SampledLight>;
    /// The probability that [`LightSampler::sample`] picks `light` for `ctx`.
    fn pmf(&self, ctx: &LightSampleContext, light: usize) -> f32;
}

/// Selection in proportion to power (pbrt-v4 `PowerLightSampler`): an alias table, O(1) per
/// sample (the binary search of a CDF was 4% of the Cornell box profile with two light
/// triangles).
#[derive(Clone, Debug, Default)]
pub struct PowerLightSampler {
    table: AliasTable,
}

impl PowerLightSampler {
    /// The sampler of lights of powers `powers` (bad powers count as 0, see [`AliasTable`]).
    pub fn new(powers: &[f32]) -> Self {
        PowerLightSampler { table: AliasTable::new(powers) }
    }

    /// The light `u` picks and its probability, whatever that probability (0 for an empty
    /// sampler): the hot-loop form of [`LightSampler::sample`].
    #[inline]
    pub fn select(&self, u: f32) -> (usize, f32) {
        self.table.sample(u)
    }

    /// Probability of picking light `i`.
    #[inline]
    pub fn pmf_of(&self, i: usize) -> f32 {
        self.table.pmf(i)
    }

    /// The alias table (for the lockstep tracer's eight-lane copy of [`Self::select`]).
    #[inline]
    pub fn table(&self) -> &AliasTable {
        &self.table
    }
}

impl LightSampler for PowerLightSampler {
    #[inline]
    fn sample(&self, _ctx: &LightSampleContext, u: f32) -> Option<SampledLight> {
        let (light, p) = self.select(u);
        (p > 0.0).then_some(SampledLight { light, p })
    }

    #[inline]
    fn pmf(&self, _ctx: &LightSampleContext, light: usize) -> f32 {
        self.pmf_of(light)
    }
}
