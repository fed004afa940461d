//! VPL generation (Keller 1997; the thesis, 4.2.1): direct VPLs on the emitters, indirect
//! VPLs at the vertices of light paths.
//!
//! Direct: point, spot and directional lights become one VPL each, as they are (exact, no
//! variance). The `direct` budget minus those goes to the area lights and the
//! environment, chosen with the light set's power-proportional probabilities renormalised
//! over them: an area sample is a point `x` with normal `n`, weight `Le / (p_sel pdf_pos
//! n)`; an environment sample is a distant VPL from direction `ω` with weight
//! `L(ω) / (p_sel pdf(ω) n)`.
//!
//! Indirect: light paths from `LightSet::sample_le` (power-proportional choice) carry the
//! flux `Le |cos| / (p_sel pdf_pos pdf_dir)`; every surface vertex where the BSDF can
//! reflect becomes a VPL holding the path's flux, then the path continues by BSDF sampling
//! with Russian roulette on the per-bounce factor `max(f |cos| / pdf)` (survival at most
//! 0.95). Paths are traced until the indirect budget is reached; the last path is kept
//! whole (so there can be a few more VPLs than asked), and every indirect weight is divided
//! by the number of paths K. K is a stopping time, which makes Σ/K a ratio estimator:
//! consistent, with an O(1/K) bias (K ≈ 1000 for the defaults); a fixed K would be
//! unbiased but gives no control over the VPL count the cache's cost depends on.
//!
//! Path depth follows the renderer's `max_depth` (Mitsuba convention): a VPL `d` bounces
//! from the light lights a shading point over `d + 2` segments, so it is kept only when
//! the depth allows them.
//!
//! Determinism: one sequential stream of `SplitMix64(seed)`; same seed, same VPLs, bit
//! for bit, whatever the thread count.

// `!(x > 0.0)` rejects NaN too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::{GeometryBound, Vpl, VplKind, Vpls};
use filtrace_core::rng::SplitMix64;
use filtrace_core::sampling::{AliasTable, Frame};
use filtrace_core::{Rgb, Vec2};
use filtrace_render::integrator::{PathContext, PathParams};
use filtrace_render::lights::{EmitterKind, LightSet};

/// What to generate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VplParams {
    /// Total VPLs (`--vpls`); the thesis's default 2048.
    pub count: usize,
    /// Of which on the lights; the thesis's default 256 (one eighth).
    pub direct: usize,
    pub seed: u64,
    /// Bound of the geometry term's singularity (off by default: unbiased w.r.t. the sum).
    pub bound: GeometryBound,
    /// Longest light path in bounces cap, a guard for closed mirror boxes.
    pub max_bounces: u32,
}

impl VplParams {
    /// The thesis's setting: 2048 VPLs, 256 of them direct.
    pub fn thesis() -> Self {
        VplParams { count: 2048, direct: 256, seed: 0, bound: GeometryBound::Off, max_bounces: 64 }
    }

    /// `count` VPLs split as the thesis does (one eighth direct).
    pub fn with_count(count: usize) -> Self {
        VplParams { count, direct: count.div_ceil(8), ..Self::thesis() }
    }

    pub fn validate(&self) -> Result<(), String> {
        if self.count == 0 {
            return Err("VPL count 0 (expected at least 1)".into());
        }
        if self.direct > self.count {
            return Err(format!(
                "{} direct VPLs out of {} (expected at most the total)",
                self.direct, self.count
            ));
        }
        self.bound.validate()
    }
}

impl Default for VplParams {
    fn default() -> Self {
        Self::thesis()
    }
}

/// Uniform numbers from one sequential stream.
struct Stream(SplitMix64);

impl Stream {
    fn f32(&mut self) -> f32 {
        self.0.next_f32()
    }
    fn vec2(&mut self) -> Vec2 {
        Vec2::new(self.f32(), self.f32())
    }
}

/// The VPLs of a scene (see the module docs). Light paths that can hold no VPL (max
/// depth 2: direct light only) are not traced; max depth 1 (emission only) has no VPLs.
pub fn generate_vpls(ctx: &PathContext, path: &PathParams, params: &VplParams) -> Vpls {
    let mut rng = Stream(SplitMix64::new(params.seed ^ 0x7670_6c5f_6765_6e21));
    let mut vpls = Vec::with_capacity(params.count + 16);
    // A direct VPL lights a shading point over two segments (light, point, camera): at
    // max depth 1 only the emitters seen directly remain, and there are no VPLs.
    if path.allows(2) {
        direct_vpls(ctx.lights, params.direct, &mut rng, &mut vpls);
    }
    let mut out = Vpls { vpls, light_paths: 0, bound: params.bound };
    let indirect = params.count.saturating_sub(out.vpls.len().max(params.direct));
    if indirect > 0 && path.allows(3) {
        indirect_vpls(ctx, path, params, indirect, &mut rng, &mut out);
    }
    out
}

/// The direct VPLs: one per delta light, `budget` minus those on area lights and the
/// environment.
fn direct_vpls(lights: &LightSet, budget: usize, rng: &mut Stream, out: &mut Vec<Vpl>) {
    let mut sampled = vec![0.0f32; lights.len()];
    for (i, weight) in sampled.iter_mut().enumerate() {
        match lights.emitter_kind(i) {
            Some(EmitterKind::Point) => {
                let l = lights.point_light(i).expect("point light");
                out.push(Vpl {
                    p: l.position,
                    n: filtrace_core::Vec3::ZERO,
                    weight: l.intensity,
                    kind: VplKind::Point,
                    depth: 0,
                });
            }
            Some(EmitterKind::Spot) => {
                let l = *lights.spot_light(i).expect("spot light");
                let kind = VplKind::Spot { light: l };
                out.push(Vpl {
                    p: l.position,
                    n: filtrace_core::Vec3::ZERO,
                    weight: l.intensity,
                    kind,
                    depth: 0,
                });
            }
            Some(EmitterKind::Directional) => {
                let l = lights.directional_light(i).expect("directional light");
                let p = filtrace_core::Vec3::ZERO;
                out.push(Vpl { p, n: l.to_light, weight: l.irradiance, kind: VplKind::Distant, depth: 0 });
            }
            Some(EmitterKind::Area | EmitterKind::Environment) => *weight = lights.selection_pmf(i),
            None => {}
        }
    }
    let n = budget.saturating_sub(out.len());
    if n == 0 || sampled.iter().all(|&w| !(w > 0.0)) {
        return;
    }
    let table = AliasTable::new(&sampled);
    for _ in 0..n {
        let (i, p_sel) = table.sample(rng.f32());
        let (u_pos, u_dir) = (rng.vec2(), rng.vec2());
        let Some(s) = lights.sample_le_of(i, u_pos, u_dir) else { continue };
        if !(p_sel > 0.0) {
            continue;
        }
        let vpl = match s.kind {
            EmitterKind::Area => {
                let two_sided = lights.area_light(i).is_some_and(|a| a.two_sided);
                let weight = s.le / (p_sel * s.pdf_pos * n as f32);
                // The face the sample left from: the VPL emits from that face (both when
                // two-sided), whatever side the cosine sample picked.
                let n_face = lights.area_light(i).map_or(s.n, |a| a.n);
                Vpl { p: s.p, n: n_face, weight, kind: VplKind::Emitter { two_sided }, depth: 0 }
            }
            _ => {
                let weight = s.le / (p_sel * s.pdf_dir * n as f32);
                Vpl { p: s.p, n: -s.dir, weight, kind: VplKind::Distant, depth: 0 }
            }
        };
        if vpl.weight.is_finite() {
            out.push(vpl);
        }
    }
}

/// Traces light paths until `budget` indirect VPLs exist; divides their weights by the
/// number of paths.
fn indirect_vpls(
    ctx: &PathContext,
    path: &PathParams,
    params: &VplParams,
    budget: usize,
    rng: &mut Stream,
    out: &mut Vpls,
) {
    let first = out.vpls.len();
    // Guard: a scene whose light paths never hit anything reflective ends after this many.
    let max_paths = budget.saturating_mul(64).max(1024);
    let mut paths = 0usize;
    while out.vpls.len() - first < budget && paths < max_paths {
        paths += 1;
        trace_light_path(ctx, path, params, rng, &mut out.vpls);
    }
    out.light_paths = paths;
    let inv = 1.0 / paths as f32;
    for v in &mut out.vpls[first..] {
        v.weight *= inv;
    }
}

/// One light path: a VPL at each surface vertex the depth allows.
fn trace_light_path(
    ctx: &PathContext,
    path: &PathParams,
    params: &VplParams,
    rng: &mut Stream,
    out: &mut Vec<Vpl>,
) {
    let (u_sel, u_pos, u_dir) = (rng.f32(), rng.vec2(), rng.vec2());
    let Some(s) = ctx.lights.sample_le(u_sel, u_pos, u_dir) else { return };
    let mut beta: Rgb = s.flux();
    if !beta.is_finite() || beta.max_element() <= 0.0 {
        return;
    }
    // Leave the emitter's surface: offset along its normal by a scale-aware epsilon, or
    // the ray finds the emitting triangle itself at t ≈ 0 (and the path dies on it).
    let eps = 1e-4 * s.p.abs().max_element().max(1.0);
    let mut ray = filtrace_core::Ray::new(s.p + s.n * eps, s.dir);
    for depth in 1..=params.max_bounces {
        let Some(si) = ctx.intersect(&ray) else { return };
        let bsdf = ctx.bsdf(&si);
        let frame = Frame::from_z(si.n_s);
        let wi_local = frame.to_local(si.wo);
        if path.allows(depth + 2) {
            let kind = VplKind::Surface { bsdf, frame, wi_local };
            out.push(Vpl { p: si.p, n: si.n_g, weight: beta, kind, depth });
        }
        if !path.allows(depth + 3) {
            return;
        }
        // Continue by BSDF sampling (the BSDFs are reciprocal, so sampling f(wo = the way
        // back, ·) is the adjoint walk), Russian roulette on the per-bounce factor.
        let (u, uc, u_rr) = (rng.vec2(), rng.f32(), rng.f32());
        let Some(bs) = bsdf.sample(wi_local, u, uc) else { return };
        let factor = bs.f * (bs.wi.z.abs() / bs.pdf);
        let q = factor.max_element().min(0.95);
        if !(q > 0.0) || u_rr >= q {
            return;
        }
        beta *= factor / q;
        if !beta.is_finite() {
            return;
        }
        ray = si.spawn_ray(frame.to_world(bs.wi));
    }
}
