//! The exhaustive VPL estimator, the ground truth of the thesis's measurements: at every
//! pixel, every VPL with exact visibility (`L = Le + Σ_j V_j contribution_j`), and the
//! cache's view of the VPLs ([`SceneVpls`], implementing [`VplSet`]).
//!
//! Direct and indirect follow the path tracer's split: emission seen directly and direct
//! VPLs (depth 0) are `direct`, the rest `indirect`.

use super::eval::{contribution, Receiver};
use super::{Vpl, VplKind, Vpls};
use crate::cache::{relaxed_geometry_term, CachePoint, VplSet};
use filtrace_core::sampler::Sampler;
use filtrace_core::{Rgb, Vec3};
use filtrace_render::film::{Film, VisibleSurface};
use filtrace_render::integrator::path::visible_surface;
use filtrace_render::integrator::{PathContext, Split, SLOT_PIXEL};
use filtrace_render::PinholeCamera;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// The full contribution of `vpl` at `rx`: unoccluded contribution times visibility.
#[inline]
pub fn full_contribution(ctx: &PathContext, vpl: &Vpl, rx: &Receiver, vpls: &Vpls) -> Rgb {
    let (c, w, dist) = contribution(vpl, rx, vpls.bound);
    if c == Rgb::ZERO || super::rays::occluded(ctx.accel, &rx.shadow_ray(w, dist)) {
        Rgb::ZERO
    } else {
        c
    }
}

/// Every VPL at the surface `rx` (emission of the surface itself excluded).
pub fn gather_all(ctx: &PathContext, vpls: &Vpls, rx: &Receiver) -> Split {
    let mut l = Split::default();
    for v in &vpls.vpls {
        let c = full_contribution(ctx, v, rx, vpls);
        if v.is_direct() {
            l.direct += c;
        } else {
            l.indirect += c;
        }
    }
    l
}

/// The exhaustive estimate along a camera ray, with the visible surface.
pub fn exhaustive_pixel(ctx: &PathContext, vpls: &Vpls, ray: &filtrace_core::Ray) -> (Split, VisibleSurface) {
    match ctx.intersect(ray) {
        None => {
            let direct = ctx.lights.environment_radiance(ray.dir);
            (Split { direct, indirect: Rgb::ZERO }, VisibleSurface::default())
        }
        Some(si) => {
            let rx = Receiver::new(si, ctx.bsdf(&si));
            let mut l = gather_all(ctx, vpls, &rx);
            l.direct += ctx.emitted(&si);
            (l, visible_surface(ctx, &si))
        }
    }
}

/// A film of the exhaustive estimator, camera samples `first..first + spp` of each pixel
/// (sample 0 through the pixel centre, the others jittered as the path tracer's). Rows in parallel; every
/// pixel is a function of its own samples only, so the film is the same whatever the
/// thread count. Returns `None` when `cancel` stopped it.
pub fn render_exhaustive(
    ctx: &PathContext,
    camera: &PinholeCamera,
    vpls: &Vpls,
    first: u32,
    spp: u32,
    seed: u64,
    cancel: &AtomicBool,
) -> Option<Film> {
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let mut film = Film::new(w, h);
    film.pixels_mut().par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, px) in row.iter_mut().enumerate() {
            for index in first..first.saturating_add(spp) {
                if cancel.load(Ordering::Relaxed) {
                    return;
                }
                let mut sampler = Sampler::new(x as u32, y as u32, index, seed);
                sampler.set_slot(SLOT_PIXEL);
                let ray = camera.sample_ray(x as u32, y as u32, index, sampler.next_2d());
                let (l, surface) = exhaustive_pixel(ctx, vpls, &ray);
                if index == 0 {
                    px.surface = surface;
                }
                px.add(&l.to_pixel_sample());
            }
        }
    });
    (!cancel.load(Ordering::Relaxed)).then_some(film)
}

/// The image of [`render_exhaustive`] with the VPLs it used.
pub struct ExhaustiveImage {
    pub film: Film,
    pub vpls: Vpls,
}

/// The VPLs of a frame as the importance cache sees them: each cache point's pixel has
/// its receiver (the G-buffer's surface with its BSDF and outgoing direction).
pub struct SceneVpls<'a> {
    pub ctx: PathContext<'a>,
    pub vpls: &'a Vpls,
    /// Per pixel (row-major), the surface seen through its centre.
    pub receivers: &'a [Option<Receiver>],
}

/// `f(wo, wi)` with `wi` folded into the upper hemisphere: a positive stand-in where the
/// exact direction is below the horizon, for the bounded distribution only (which must
/// not vanish where a neighbour could receive light).
#[inline]
fn f_folded(bsdf: &filtrace_render::bsdf::SurfaceBsdf, wo: Vec3, wi: Vec3) -> Rgb {
    bsdf.f(wo, Vec3::new(wi.x, wi.y, wi.z.abs().max(1e-3)).normalize())
}

impl SceneVpls<'_> {
    fn receiver(&self, site: &CachePoint) -> Option<&Receiver> {
        self.receivers.get(site.pixel as usize)?.as_ref()
    }
}

impl VplSet for SceneVpls<'_> {
    fn vpl_count(&self) -> usize {
        self.vpls.len()
    }

    fn unoccluded(&self, vpl: usize, site: &CachePoint) -> Rgb {
        match self.receiver(site) {
            Some(rx) => contribution(&self.vpls.vpls[vpl], rx, self.vpls.bound).0,
            None => Rgb::ZERO,
        }
    }

    fn visible(&self, vpl: usize, site: &CachePoint) -> bool {
        let Some(rx) = self.receiver(site) else { return false };
        let (_, w, dist) = contribution(&self.vpls.vpls[vpl], rx, self.vpls.bound);
        dist > 0.0 && !super::rays::occluded(self.ctx.accel, &rx.shadow_ray(w, dist))
    }

    /// `E f_VPL f0` at folded directions times the relaxed geometry term (the cache's
    /// [`relaxed_geometry_term`]); distant VPLs have no distance to relax.
    fn bounded(&self, vpl: usize, site: &CachePoint, radius: f32) -> Rgb {
        let Some(rx) = self.receiver(site) else { return Rgb::ZERO };
        let v = &self.vpls.vpls[vpl];
        let w = match v.kind {
            VplKind::Distant => v.n,
            _ => (v.p - rx.si.p).normalize_or_zero(),
        };
        let f0 = f_folded(&rx.bsdf, rx.wo, rx.frame.to_local(w));
        let (emit, n_vpl) = match v.kind {
            // A two-sided emitter lights the receiver's side with the face towards it.
            VplKind::Emitter { two_sided } => {
                (v.weight, Some(if two_sided && v.n.dot(w) > 0.0 { -v.n } else { v.n }))
            }
            VplKind::Surface { bsdf, frame, wi_local } => {
                (f_folded(&bsdf, frame.to_local(-w), wi_local) * v.weight, Some(v.n))
            }
            VplKind::Point | VplKind::Spot { .. } => (v.weight, None),
            VplKind::Distant => return v.weight * f0,
        };
        emit * f0 * relaxed_geometry_term(rx.si.p, rx.si.n_s, v.p, n_vpl, radius, 0.0)
    }
}
