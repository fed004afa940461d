//! One VPL at one shading point: `E_VPL f(x_VPL → x0 → x−1) G(x0 ↔ x_VPL)` (thesis eq. 9),
//! and the bound of its geometry term (thesis 4.2.3).
//!
//! Per kind, with `ω` the unit direction from `x0` to the VPL at distance `r` and
//! `cos0 = |ω · n_s(x0)|` (the path tracer's convention, BSDF in the shading frame):
//! - emitter: `weight cos_l f0 cos0 / r²` with `cos_l = −ω·n` (|·| when two-sided; 0 behind);
//! - surface: `weight f_VPL(−ω, ω_in) |cos_VPL| f0 cos0 / r²` (both BSDFs);
//! - point: `weight f0 cos0 / r²`; spot: the same times the falloff;
//! - distant: `weight f0 cos0` along `n`, visibility to infinity.
//!
//! [`GeometryBound::MinDistance`] replaces `1/r²` by `1/max(r², d²)` for the *virtual*
//! lights (emitter and surface VPLs; real point and spot lights keep their exact falloff).
//! It removes the bright splotches of VPLs close to a receiver (thesis Figure 22) at the
//! price of a bias: every contribution can only shrink, so the bounded estimate is ≤ the
//! unbounded VPL sum everywhere, and light that travels less than `d` between two
//! surfaces (short-range interreflection in corners, light right next to an emitter)
//! is lost. Off, the estimator is unbiased with respect to the VPL sum.

use super::{Vpl, VplKind};
use filtrace_core::sampling::Frame;
use filtrace_core::{Ray, Rgb, Vec3};
use filtrace_render::bsdf::SurfaceBsdf;
use filtrace_render::surface::SurfaceInteraction;

/// The optional bound of the geometry term's `1/r²` singularity.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum GeometryBound {
    /// Exact `1/r²`: unbiased w.r.t. the VPL sum.
    #[default]
    Off,
    /// `1/max(r², d²)` with `d` this distance (world units) for virtual lights.
    MinDistance(f32),
}

impl GeometryBound {
    pub fn validate(&self) -> Result<(), String> {
        match *self {
            GeometryBound::MinDistance(d) if !(d.is_finite() && d > 0.0) => {
                Err(format!("geometry bound distance {d} (expected a finite value > 0)"))
            }
            _ => Ok(()),
        }
    }

    /// `1/r²`, bounded.
    #[inline]
    fn inv_dist2(&self, r2: f32) -> f32 {
        match *self {
            GeometryBound::Off => 1.0 / r2,
            GeometryBound::MinDistance(d) => 1.0 / r2.max(d * d),
        }
    }
}

/// A shading point as the VPL evaluation needs it.
#[derive(Clone, Copy, Debug)]
pub struct Receiver {
    pub si: SurfaceInteraction,
    pub bsdf: SurfaceBsdf,
    pub frame: Frame,
    /// `si.wo` in `frame`.
    pub wo: Vec3,
}

impl Receiver {
    pub fn new(si: SurfaceInteraction, bsdf: SurfaceBsdf) -> Self {
        let frame = Frame::from_z(si.n_s);
        Receiver { si, bsdf, frame, wo: frame.to_local(si.wo) }
    }

    /// `f0 cos0` for the world direction `w` towards the light.
    #[inline]
    fn reflect(&self, w: Vec3) -> Rgb {
        let wi = self.frame.to_local(w);
        self.bsdf.f(self.wo, wi) * wi.z.abs()
    }

    /// The shadow ray towards a light point at distance `dist` along `w` (∞: distant).
    #[inline]
    pub fn shadow_ray(&self, w: Vec3, dist: f32) -> Ray {
        self.si.spawn_shadow_ray(w, dist)
    }
}

/// The unoccluded contribution of `vpl` at `rx`, with the direction and distance of the
/// shadow ray that decides its visibility. Zero (and no ray needed) when it cannot light
/// the receiver.
#[inline]
pub fn contribution(vpl: &Vpl, rx: &Receiver, bound: GeometryBound) -> (Rgb, Vec3, f32) {
    let (c, w, r, _) = contribution_parts(vpl, rx, bound);
    (c, w, r)
}

/// The BSDF values [`contribution`] finds on its way, for a caller that evaluates more at
/// the same pair (the cache's bounded term needs both BSDFs in the same directions).
#[derive(Clone, Copy, Debug)]
pub struct PairParts {
    /// The direction towards the VPL in the receiver's shading frame.
    pub wi: Vec3,
    /// `f(wo, wi)` of the receiver (without the cosine).
    pub f_rx: Rgb,
    /// A surface VPL's `f(to receiver, wi_local)`; `None` where the contribution stopped
    /// before it (the receiver reflects nothing that way) and for other kinds.
    pub f_vpl: Option<Rgb>,
}

/// [`contribution`] with its [`PairParts`] (`None` for distant VPLs and degenerate
/// distances).
#[inline]
pub fn contribution_parts(
    vpl: &Vpl,
    rx: &Receiver,
    bound: GeometryBound,
) -> (Rgb, Vec3, f32, Option<PairParts>) {
    if let VplKind::Distant = vpl.kind {
        return (vpl.weight * rx.reflect(vpl.n), vpl.n, f32::INFINITY, None);
    }
    let d = vpl.p - rx.si.p;
    let r2 = d.length_squared();
    if r2.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) || !r2.is_finite() {
        return (Rgb::ZERO, Vec3::Z, 0.0, None);
    }
    let r = r2.sqrt();
    let w = d / r;
    let wi = rx.frame.to_local(w);
    let f_rx = rx.bsdf.f(rx.wo, wi);
    let mut parts = PairParts { wi, f_rx, f_vpl: None };
    let f0 = f_rx * wi.z.abs();
    if f0 == Rgb::ZERO {
        return (Rgb::ZERO, w, r, Some(parts));
    }
    let emitted = match vpl.kind {
        VplKind::Emitter { two_sided } => {
            let c = -w.dot(vpl.n);
            let c = if two_sided { c.abs() } else { c.max(0.0) };
            vpl.weight * (c * bound.inv_dist2(r2))
        }
        VplKind::Surface { bsdf, frame, wi_local } => {
            let to_rx = frame.to_local(-w);
            let f_vpl = bsdf.f(to_rx, wi_local);
            parts.f_vpl = Some(f_vpl);
            f_vpl * vpl.weight * (to_rx.z.abs() * bound.inv_dist2(r2))
        }
        VplKind::Point => vpl.weight / r2,
        VplKind::Spot { light } => vpl.weight * (light.falloff(-w.dot(light.axis)) / r2),
        VplKind::Distant => unreachable!("handled above"),
    };
    (emitted * f0, w, r, Some(parts))
}
