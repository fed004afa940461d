//! What the VPL integrator carries from one frame to the next, as data that can be written
//! and read back (serde): a sequence resumed after frame k renders frame k + 1 exactly as
//! an uninterrupted one would (docs/many-light.md, "Sequences").
//!
//! The next frame's `prepare` reads one thing of the frame before: its importance cache,
//! and of that only what interpolates the `optimized` parameters at the new records
//! (thesis 5.2.2): each record's point (position, normal) with its learnt α' and β, and
//! the search's λ and M (the same M and weights as shading). The VPLs, the G-buffer and the
//! records' distributions are made anew every frame and the sample history starts empty,
//! so they are not state. The region of each record (radius, normal cone) is kept too, so
//! that a restored record is the record without its distributions.
//!
//! Exact: every `f32` is stored as the `f64` holding it (a JSON writer prints it
//! shortest-exact, and the nearest `f32` of anything read back within an `f64` ulp is the
//! value itself), so a restored integrator renders the next frame bit for bit.
//! [`VplState::settings`] is the integrator's settings as text: a state is only restored
//! into an integrator of the same settings.

use super::integrator::{VplIntegrator, VplSettings};
use crate::cache::{CachePoint, CacheRecord, ImportanceCache, KdTree, RecordParams, RecordValues};
use crate::cache::{SamplerKind, TECHNIQUES};
use filtrace_core::Vec3;
use serde::{Deserialize, Serialize};

/// The format of [`VplState`]; a state of another version is refused.
pub const STATE_VERSION: u32 = 1;

/// Most records a state may hold (the CLI's `--cache-points` limit).
const MAX_RECORDS: usize = 1_000_000;

/// What a VPL integrator carries into its next frame (see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VplState {
    /// [`STATE_VERSION`].
    pub version: u32,
    /// The integrator's settings (`{:?}`), which a restoring integrator must have.
    pub settings: String,
    /// λ of the cache's search distance.
    pub lambda: f64,
    pub records: Vec<CarriedRecord>,
}

/// One record of the last frame's cache, as the next frame reads it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CarriedRecord {
    /// The G-buffer pixel the record was placed through (row-major).
    pub pixel: u32,
    pub position: [f64; 3],
    pub normal: [f64; 3],
    /// Radius and normal cone of the record's region (E³'s neighbourhood).
    pub radius: f64,
    pub normal_cone: f64,
    /// The `optimized` parameters α' and β.
    pub alpha: [f64; TECHNIQUES],
    pub beta: [f64; TECHNIQUES],
}

/// Whether an integrator of `settings` carries anything from frame to frame: only the
/// `optimized` sampler learns (the ground truth samples nothing).
pub fn carries_state(settings: &VplSettings) -> bool {
    settings.sampler == SamplerKind::Optimized && !settings.ground_truth
}

impl VplIntegrator {
    /// What the next frame's `prepare` would read, after the frame rendered so far; `None`
    /// for settings that carry nothing ([`carries_state`]).
    pub fn state(&self) -> Option<VplState> {
        if !carries_state(self.settings()) {
            return None;
        }
        self.with_cache(|cache| {
            let (lambda, records) = cache.map_or((0.0, Vec::new()), |c| (c.lambda(), carried_records(c)));
            Some(VplState {
                version: STATE_VERSION,
                settings: settings_text(self.settings()),
                lambda: lambda as f64,
                records,
            })
        })
    }

    /// Continues from `state` (written by [`VplIntegrator::state`] of an integrator of the
    /// same settings): the next `prepare` carries its parameters over as after the frame it
    /// was taken from. Errors say why the state does not fit.
    pub fn restore(&mut self, state: &VplState) -> Result<(), String> {
        state.check()?;
        if state.settings != settings_text(self.settings()) {
            return Err(format!("written with other VPL settings ({})", state.settings));
        }
        let cache = restored_cache(state, &self.settings().cache);
        self.set_previous_cache(Some(cache));
        Ok(())
    }
}

impl VplState {
    /// `Ok` for a state of this version with finite values and at most `MAX_RECORDS`
    /// records; else what is wrong, naming the record.
    pub fn check(&self) -> Result<(), String> {
        if self.version != STATE_VERSION {
            return Err(format!(
                "state version {} (this filtrace reads version {STATE_VERSION})",
                self.version
            ));
        }
        if !(self.lambda.is_finite() && self.lambda >= 0.0) {
            return Err(format!("search distance lambda {} (expected finite and >= 0)", self.lambda));
        }
        if self.records.len() > MAX_RECORDS {
            return Err(format!("{} records (at most {MAX_RECORDS})", self.records.len()));
        }
        for (i, r) in self.records.iter().enumerate() {
            let values = r.position.iter().chain(&r.normal).chain(&r.alpha).chain(&r.beta);
            if !values.chain([&r.radius, &r.normal_cone]).all(|v| v.is_finite() && v.abs() <= f32::MAX as f64)
            {
                return Err(format!("record {i} has a value that is not a finite f32"));
            }
        }
        Ok(())
    }
}

fn settings_text(settings: &VplSettings) -> String {
    format!("{settings:?}")
}

fn carried_records(cache: &ImportanceCache) -> Vec<CarriedRecord> {
    let widen = |v: Vec3| [v.x as f64, v.y as f64, v.z as f64];
    let f64s = |a: [f32; TECHNIQUES]| a.map(|x| x as f64);
    cache
        .records()
        .iter()
        .zip(cache.params())
        .map(|(r, p)| CarriedRecord {
            pixel: r.point.pixel,
            position: widen(r.point.position),
            normal: widen(r.point.normal),
            radius: r.radius as f64,
            normal_cone: r.normal_cone as f64,
            alpha: f64s(p.alpha),
            beta: f64s(p.beta),
        })
        .collect()
}

/// The cache `state` was taken from, without distributions (over no VPLs: sampling from
/// it draws nothing), which is all the next frame's build reads of it.
fn restored_cache(state: &VplState, config: &crate::cache::CacheParams) -> ImportanceCache {
    let narrow = |v: [f64; 3]| Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32);
    let f32s = |a: [f64; TECHNIQUES]| a.map(|x| x as f32);
    let none = RecordValues::default();
    let mut records = Vec::with_capacity(state.records.len());
    let mut params = Vec::with_capacity(state.records.len());
    for r in &state.records {
        let point = CachePoint { position: narrow(r.position), normal: narrow(r.normal), pixel: r.pixel };
        records.push(CacheRecord::new(point, r.radius as f32, r.normal_cone as f32, &none));
        params.push(RecordParams { alpha: f32s(r.alpha), beta: f32s(r.beta) });
    }
    let positions: Vec<Vec3> = records.iter().map(|r| r.point.position).collect();
    let normals: Vec<Vec3> = records.iter().map(|r| r.point.normal).collect();
    let tree = KdTree::new(&positions, &normals, state.lambda as f32);
    ImportanceCache::from_parts(records, params, tree, config, 0)
}
