//! The exhaustive VPL estimator, the ground truth of the thesis's measurements: at every
//! pixel, every VPL with exact visibility (`L = Le + Σ_j V_j contribution_j`), and the
//! cache's view of the VPLs ([`SceneVpls`], implementing [`VplSet`]).
//!
//! Direct and indirect follow the path tracer's split: emission seen directly and direct
//! VPLs (depth 0) are `direct`, the rest `indirect`.

use super::eval::{contribution, contribution_parts, PairParts, Receiver};
use super::gbuffer::RecordReceivers;
use super::soa::{evaluate_groups, DiffuseSite, PairLanes, VplGroup, VplLanes};
use super::{Vpl, VplKind, Vpls};
use crate::cache::{
    relaxed_geometry_term_fast, CachePoint, FaintCut, RecordValues, Region, RelaxedReceiver, RgbColumns,
    VisibilityRays, VplSet,
};
use filtrace_accel::{fan_class, SceneAccel, SegmentFan, FAN_CLASSES, LANES};
use filtrace_core::cpu::{isa, Isa};
use filtrace_core::sampler::Sampler;
use filtrace_core::{luminance, Ray, Rgb, Vec3};
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
/// its receiver (the surface through the pixel's centre with its BSDF and outgoing
/// direction).
pub struct SceneVpls<'a> {
    pub ctx: PathContext<'a>,
    pub vpls: &'a Vpls,
    /// The surface seen through the centre of each record's pixel.
    pub receivers: &'a RecordReceivers,
    /// The VPLs of the eight-lane path as a structure of arrays.
    lanes: VplLanes,
}

/// Smallest `|wi.z|` [`f_folded`] keeps; at or above it a `wi` in the upper hemisphere
/// is left as it is.
const FOLD_Z: f32 = 1e-3;

/// `f(wo, wi)` with `wi` folded into the upper hemisphere: a positive stand-in where the
/// exact direction is below the horizon, for the bounded distribution only (which must
/// not vanish where a neighbour could receive light).
#[inline]
fn f_folded(bsdf: &filtrace_render::bsdf::SurfaceBsdf, wo: Vec3, wi: Vec3) -> Rgb {
    let z = wi.z.abs();
    // A unit `wi` stays unit when folded; only the clamp near the horizon needs a normalise.
    let folded =
        if z >= FOLD_Z { Vec3::new(wi.x, wi.y, z) } else { Vec3::new(wi.x, wi.y, FOLD_Z).normalize() };
    bsdf.f(wo, folded)
}

impl<'a> SceneVpls<'a> {
    /// The cache's view of `vpls` (with their structure-of-arrays copy, made once here).
    pub fn new(ctx: PathContext<'a>, vpls: &'a Vpls, receivers: &'a RecordReceivers) -> Self {
        SceneVpls { ctx, vpls, receivers, lanes: VplLanes::new(&vpls.vpls) }
    }

    fn receiver(&self, site: &CachePoint) -> Option<&Receiver> {
        self.receivers.get(site.pixel)
    }

    /// [`VplSet::evaluate_record`] with the lane code of `isa` (at most the detected level;
    /// the tests run every level against the per-VPL reference): the groups of
    /// [`VplLanes`] eight at a time at a diffuse receiver, every other pair per VPL.
    pub(crate) fn evaluate_record_with(
        &self,
        site: &CachePoint,
        region: &Region,
        faint_share: f32,
        out: &mut RecordValues,
        isa: Isa,
    ) {
        let n = self.vpls.len();
        let Some(rx) = self.receiver(site) else {
            out.clear(n);
            return;
        };
        // Every entry of the lists and columns is written below (the groups and `others`
        // partition the VPLs): sized, not zeroed first.
        out.resize_for_overwrite(n);
        let (mut rgb, mut visible) = (std::mem::take(&mut out.rgb), std::mem::take(&mut out.visible));
        rgb.resize_for_overwrite(n);
        visible.clear();
        visible.resize(n, false);
        let relaxed = RelaxedReceiver::new(rx.si.n_s, region.radius, region.normal_cone);
        let mut pass = RecordPass {
            rgb: &mut rgb,
            unoccluded: &mut out.unoccluded,
            bounded: &mut out.bounded,
            packets: ShadowPackets::new(self.ctx.accel, rx, n),
        };
        match DiffuseSite::new(rx, &relaxed, self.vpls.bound) {
            Some(diffuse) => {
                evaluate_groups(&self.lanes, &diffuse, isa, |g, p| {
                    if g.dense && p.valid == u8::MAX {
                        pass.store_group(g.index[0] as usize, p);
                        pass.queue_rays(g, p);
                    } else {
                        self.store_lanes(g, p, rx, region, &relaxed, &mut pass);
                    }
                });
                for &j in &self.lanes.others {
                    self.evaluate_pair(j as usize, rx, region, &relaxed, &mut pass);
                }
            }
            None => (0..n).for_each(|j| self.evaluate_pair(j, rx, region, &relaxed, &mut pass)),
        }
        let mut packets = pass.packets;
        let faint = FaintCut::new(&out.unoccluded, faint_share);
        out.rays = packets.trace_queued(&faint, &out.unoccluded, &mut visible);
        // The totals in VPL order, as the reference sums them.
        let ([cr, cg, cb], [br, bg, bb]) = (&rgb.c, &rgb.b);
        let columns = cr.iter().zip(&cg[..n]).zip(&cb[..n]).zip(&br[..n]).zip(&bg[..n]).zip(&bb[..n]);
        let luminances = out.full.iter_mut().zip(&out.unoccluded[..n]);
        for (((((((&r, &g), &b), &b_r), &b_g), &b_b), &vis), (full, &unoccluded)) in
            columns.zip(&visible[..n]).zip(luminances)
        {
            let (c, b) = (Rgb::new(r, g, b), Rgb::new(b_r, b_g, b_b));
            *full = if vis { unoccluded } else { 0.0 };
            out.totals[0] += if vis { c } else { Rgb::ZERO };
            out.totals[1] += c;
            out.totals[2] += b;
        }
        (out.rgb, out.visible) = (rgb, visible);
    }

    /// A group's lanes one by one, in order: a lane the vector code left (degenerate
    /// distance) the per-VPL way.
    fn store_lanes(
        &self,
        g: &VplGroup,
        p: &PairLanes,
        rx: &Receiver,
        region: &Region,
        relaxed: &RelaxedReceiver,
        pass: &mut RecordPass,
    ) {
        for i in 0..g.live {
            let j = g.index[i] as usize;
            if p.valid >> i & 1 == 0 {
                self.evaluate_pair(j, rx, region, relaxed, pass);
                continue;
            }
            if p.ray >> i & 1 != 0 {
                let side = p.back >> i & 1;
                pass.packets.queue_lane(j, side, p.class[i] as u8, p.w(i), p.t_max[i]);
            }
            pass.store(j, p.c(i), p.b(i), p.lum_c[i], p.lum_b[i]);
        }
    }

    /// One pair the per-VPL way: the contribution with its parts, its shadow ray queued,
    /// the bounded term from the parts.
    fn evaluate_pair(
        &self,
        j: usize,
        rx: &Receiver,
        region: &Region,
        relaxed: &RelaxedReceiver,
        pass: &mut RecordPass,
    ) {
        let v = &self.vpls.vpls[j];
        let (c, w, dist, parts) = contribution_parts(v, rx, self.vpls.bound);
        if luminance(c) > 0.0 && dist > 0.0 {
            pass.packets.queue(j, &rx.shadow_ray(w, dist));
        }
        let bounded = match parts {
            Some(parts) => bounded_towards(v, rx, w, dist, &parts, relaxed),
            None => self.bounded_at(v, rx, region, relaxed),
        };
        pass.store(j, c, bounded, luminance(c), luminance(bounded));
    }

    /// `E f_VPL f0` at folded directions times the relaxed geometry term (the cache's
    /// [`RelaxedReceiver`]); distant VPLs have no distance to relax.
    fn bounded_at(&self, v: &Vpl, rx: &Receiver, region: &Region, relaxed: &RelaxedReceiver) -> Rgb {
        if let VplKind::Distant = v.kind {
            return v.weight * f_folded(&rx.bsdf, rx.wo, rx.frame.to_local(v.n));
        }
        let d = v.p - rx.si.p;
        let r = d.length();
        if !(r > 0.0 && r.is_finite()) {
            let (n_vpl, Region { radius, normal_cone }) = (v.surface_normal(), *region);
            let f0 = f_folded(&rx.bsdf, rx.wo, Vec3::Z);
            let g = relaxed_geometry_term_fast(rx.si.p, rx.si.n_s, v.p, n_vpl, radius, normal_cone);
            return v.weight * f0 * g;
        }
        let w = d / r;
        let wi = rx.frame.to_local(w);
        let parts = PairParts { wi, f_rx: f_folded(&rx.bsdf, rx.wo, wi), f_vpl: None };
        bounded_towards(v, rx, w, r, &parts, relaxed)
    }
}

/// The bounded contribution of a VPL at distance `r > 0` along `w` from the receiver,
/// from the BSDF values [`contribution_parts`] found (`f(wo, wi)` is the folded value
/// wherever `wi` is above the horizon, where folding changes nothing); a receiver that
/// reflects nothing towards the camera (seen from behind) gets 0 without the rest.
#[inline]
fn bounded_towards(
    v: &Vpl,
    rx: &Receiver,
    w: Vec3,
    r: f32,
    parts: &PairParts,
    relaxed: &RelaxedReceiver,
) -> Rgb {
    let f0 = if parts.wi.z >= FOLD_Z { parts.f_rx } else { f_folded(&rx.bsdf, rx.wo, parts.wi) };
    if f0 == Rgb::ZERO {
        return Rgb::ZERO;
    }
    let (emit, n_vpl) = match v.kind {
        // A two-sided emitter lights the receiver's side with the face towards it.
        VplKind::Emitter { two_sided } => {
            (v.weight, Some(if two_sided && v.n.dot(w) > 0.0 { -v.n } else { v.n }))
        }
        VplKind::Surface { bsdf, frame, wi_local } => {
            let f_vpl = match parts.f_vpl {
                Some(f) if wi_local.z >= FOLD_Z => f,
                _ => f_folded(&bsdf, frame.to_local(-w), wi_local),
            };
            (f_vpl * v.weight, Some(v.n))
        }
        VplKind::Point | VplKind::Spot { .. } | VplKind::Distant => (v.weight, None),
    };
    emit * f0 * relaxed.towards(w, r, n_vpl)
}

/// The visibility rays of one record as [`SegmentFan`]s: they leave the record's point
/// (offset to one side of the surface or the other: two origins), and are gathered by
/// side and [`fan_class`] (octant and dominant axis of the direction, the classes the
/// packet kernels take as one) into fans of eight, each traced with
/// [`SceneAccel::occluded_fan`] once full, whose answer per lane is that of the
/// single-ray query. The rays are queued while the record's VPLs are evaluated and
/// traced afterwards, when the [`FaintCut`] (which needs every contribution) is known.
struct ShadowPackets<'a> {
    accel: &'a SceneAccel,
    /// The record's two ray origins (`offset_origin` towards and away from `n_g`).
    origins: [Vec3; 2],
    /// Per side and class: the fan, the VPLs of its lanes and how many lanes are set.
    fans: [[(SegmentFan, [u32; LANES], usize); FAN_CLASSES]; 2],
    /// Rays from one of the origins, in the order they were queued.
    queued: Vec<QueuedLane>,
    /// Rays from neither origin (not shadow rays of the record), traced alone.
    alone: Vec<(u32, Ray)>,
}

/// The shadow ray of VPL `vpl` from `origins[side]` along `dir` to `t_max`, `class`
/// its [`fan_class`].
#[derive(Clone, Copy)]
pub(crate) struct QueuedLane {
    vpl: u32,
    side: u8,
    class: u8,
    dir: Vec3,
    t_max: f32,
}

impl<'a> ShadowPackets<'a> {
    /// The packets of a record at `rx` with room for `vpl_count` queued rays.
    fn new(accel: &'a SceneAccel, rx: &Receiver, vpl_count: usize) -> Self {
        let n_g = rx.si.n_g;
        let origins = [rx.si.offset_origin(n_g), rx.si.offset_origin(-n_g)];
        let fans = origins.map(|o| [(SegmentFan::new(o, 0.0), [0; LANES], 0); FAN_CLASSES]);
        ShadowPackets { accel, origins, fans, queued: Vec::with_capacity(vpl_count), alone: Vec::new() }
    }

    /// Queues the ray deciding VPL `j`'s visibility.
    #[inline]
    fn queue(&mut self, j: usize, ray: &Ray) {
        let side = (ray.origin != self.origins[0]) as usize;
        if ray.origin != self.origins[side] || ray.t_min != 0.0 {
            self.alone.push((j as u32, *ray));
            return;
        }
        self.queue_lane(j, side as u8, fan_class(ray.dir) as u8, ray.dir, ray.t_max);
    }

    /// Queues the shadow ray of VPL `j` from `origins[side]` along `dir` to `t_max` (the
    /// ray [`Receiver::shadow_ray`] makes, given by its parts; `class` is
    /// [`fan_class`]`(dir)`).
    #[inline]
    fn queue_lane(&mut self, j: usize, side: u8, class: u8, dir: Vec3, t_max: f32) {
        self.queued.push(QueuedLane { vpl: j as u32, side, class, dir, t_max });
    }

    /// Decides every queued VPL's visibility: faint ones (by their unoccluded luminance)
    /// are visible without a ray, the others are traced in fans.
    fn trace_queued(&mut self, faint: &FaintCut, unoccluded: &[f32], visible: &mut [bool]) -> VisibilityRays {
        let queued = self.queued.len() + self.alone.len();
        let mut faint_vpls = 0;
        for q in std::mem::take(&mut self.queued) {
            let j = q.vpl as usize;
            if faint.is_faint(unoccluded[j]) {
                visible[j] = true;
                faint_vpls += 1;
            } else {
                self.push_lane(j, q.side as usize, q.class as usize, q.dir, q.t_max, visible);
            }
        }
        for (j, ray) in std::mem::take(&mut self.alone) {
            let j = j as usize;
            let is_faint = faint.is_faint(unoccluded[j]);
            faint_vpls += is_faint as usize;
            visible[j] = is_faint || !self.accel.occluded(&ray);
        }
        self.flush(visible);
        VisibilityRays { traced: (queued - faint_vpls) as u64, faint: faint_vpls as u64 }
    }

    /// Adds a ray to its fan; a full fan is traced at once.
    #[inline]
    fn push_lane(
        &mut self,
        j: usize,
        side: usize,
        class: usize,
        dir: Vec3,
        t_max: f32,
        visible: &mut [bool],
    ) {
        let (fan, ids, len) = &mut self.fans[side][class];
        fan.set_lane(*len, dir, t_max);
        ids[*len] = j as u32;
        *len += 1;
        if *len == LANES {
            self.trace(side, class, visible);
        }
    }

    /// Traces the queued rays of one fan and writes their VPLs' visibility.
    fn trace(&mut self, side: usize, class: usize, visible: &mut [bool]) {
        let (fan, ids, len) = &mut self.fans[side][class];
        let active = ((1u32 << *len) - 1) as u8;
        let occluded = super::rays::occluded_fan(self.accel, fan, active);
        for (i, &j) in ids[..*len].iter().enumerate() {
            visible[j as usize] = occluded & (1 << i) == 0;
        }
        *len = 0;
    }

    /// Traces what is left in every fan.
    fn flush(&mut self, visible: &mut [bool]) {
        for side in 0..2 {
            for class in 0..FAN_CLASSES {
                if self.fans[side][class].2 > 0 {
                    self.trace(side, class, visible);
                }
            }
        }
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

    /// See `bounded_at`.
    fn bounded(&self, vpl: usize, site: &CachePoint, region: &Region) -> Rgb {
        let Some(rx) = self.receiver(site) else { return Rgb::ZERO };
        let relaxed = RelaxedReceiver::new(rx.si.n_s, region.radius, region.normal_cone);
        self.bounded_at(&self.vpls.vpls[vpl], rx, region, &relaxed)
    }

    /// The same values as [`crate::cache::evaluate_each_vpl`], bit for bit, with one evaluation of each
    /// VPL's contribution (the per-VPL methods find it twice), eight VPLs at a time for a
    /// diffuse receiver and emitter or diffuse VPLs (`vpls/soa.rs`), the bounded term from
    /// the BSDF values the contribution found (`contribution_parts`; the reference
    /// evaluates both BSDFs again), and the visibility rays traced as fans of eight from
    /// the record's point (`ShadowPackets`; VPLs that cannot light the record, e.g.
    /// behind its surface, get no ray). The RGB totals are summed in VPL order
    /// afterwards, as the reference does.
    fn evaluate_record(&self, site: &CachePoint, region: &Region, faint_share: f32, out: &mut RecordValues) {
        self.evaluate_record_with(site, region, faint_share, out, isa());
    }
}

/// One record's evaluation in progress: per VPL the RGB unoccluded and bounded
/// contributions and their luminances, and the queued visibility rays.
struct RecordPass<'s, 'a> {
    rgb: &'s mut RgbColumns,
    unoccluded: &'s mut [f32],
    bounded: &'s mut [f32],
    packets: ShadowPackets<'a>,
}

impl RecordPass<'_, '_> {
    /// VPL `j`'s E² and E³, and their luminances as `RecordValues::set` keeps them.
    #[inline]
    fn store(&mut self, j: usize, c: Rgb, b: Rgb, lum_c: f32, lum_b: f32) {
        self.rgb.set(j, c, b);
        self.unoccluded[j] = lum_c.max(0.0);
        self.bounded[j] = lum_b.max(0.0);
    }

    /// [`RecordPass::store`] of eight evaluated lanes of VPLs `j0..j0 + 8`, as blocks.
    #[inline]
    fn store_group(&mut self, j0: usize, p: &PairLanes) {
        let block = j0..j0 + LANES;
        for k in 0..3 {
            self.rgb.c[k][block.clone()].copy_from_slice(&p.c[k]);
            self.rgb.b[k][block.clone()].copy_from_slice(&p.b[k]);
        }
        for (dst, src) in
            [(&mut self.unoccluded[block.clone()], &p.lum_c), (&mut self.bounded[block], &p.lum_b)]
        {
            for (d, s) in dst.iter_mut().zip(src) {
                *d = s.max(0.0);
            }
        }
    }

    /// Queues the shadow rays of a group's lanes, in lane order.
    #[inline]
    fn queue_rays(&mut self, g: &VplGroup, p: &PairLanes) {
        let mut rays = p.ray;
        while rays != 0 {
            let i = rays.trailing_zeros() as usize;
            rays &= rays - 1;
            let side = p.back >> i & 1;
            self.packets.queue_lane(g.index[i] as usize, side, p.class[i] as u8, p.w(i), p.t_max[i]);
        }
    }
}

#[cfg(test)]
mod packet_tests {
    use super::*;
    use crate::cache::evaluate_each_vpl;
    use crate::vpls::{generate_vpls, VplParams};
    use filtrace_accel::BuildParams;
    use filtrace_core::Vec2;
    use filtrace_render::{RenderSettings, Renderer};

    /// Every 7th pixel of a `width`² Cornell view as a cache point, with the receivers.
    fn cornell_sites(r: &Renderer, width: u32) -> (Vec<Option<Receiver>>, Vec<CachePoint>) {
        let ctx = r.context();
        let receivers: Vec<Option<Receiver>> = (0..width * width)
            .map(|i| {
                let ray = r.camera().generate_ray(i % width, i / width, Vec2::splat(0.5));
                ctx.intersect(&ray).map(|si| Receiver::new(si, ctx.bsdf(&si)))
            })
            .collect();
        let sites = (0..receivers.len())
            .step_by(7)
            .map(|i| {
                let (position, normal) =
                    receivers[i].map_or((Vec3::ZERO, Vec3::Z), |rx| (rx.si.p, rx.si.n_s));
                CachePoint { position, normal, pixel: i as u32 }
            })
            .collect();
        (receivers, sites)
    }

    /// The packet evaluation of a record gives the per-VPL reference's values bit for
    /// bit (so the same visibility bits: E¹ is E² where visible, 0 where not), on the
    /// Cornell box with its flat bottom level (any packet traced as one) and with an
    /// 8-wide BVH (packets of mixed directions fall back to one query per lane), with
    /// every ray traced and with the faint VPLs taken as visible.
    #[test]
    fn packet_visibility_equals_one_ray_per_vpl() {
        let scene = filtrace_scene::builtin("cornell").expect("built-in Cornell box");
        let settings = RenderSettings { width: 24, height: 24, spp: 1, max_depth: 8, seed: 1 };
        let r = Renderer::new(scene.clone(), settings).expect("settings");
        let vpls = generate_vpls(
            &r.context(),
            &r.path_params(),
            &VplParams { seed: 3, ..VplParams::with_count(512) },
        );
        let (receivers, sites) = cornell_sites(&r, 24);
        let bvh =
            SceneAccel::build_with(&scene, &BuildParams { max_flat_triangles: 0, ..BuildParams::default() });
        for accel in [r.context().accel, &bvh] {
            let receivers = RecordReceivers::from_pixels(&receivers);
            let set = SceneVpls::new(PathContext { accel, ..r.context() }, &vpls, &receivers);
            let mut occluded_by_share = Vec::new();
            for faint_share in [0.0, 0.05] {
                let (mut packet, mut reference) = (RecordValues::default(), RecordValues::default());
                let (mut visible, mut occluded) = (0, 0);
                for site in &sites {
                    let region = Region { radius: 0.1, normal_cone: 0.2 };
                    let base = filtrace_core::cpu::Isa::Base;
                    set.evaluate_record_with(site, &region, faint_share, &mut packet, base);
                    let mut widest = RecordValues::default();
                    set.evaluate_record(site, &region, faint_share, &mut widest);
                    let what = format!("pixel {}, faint share {faint_share}", site.pixel);
                    assert_eq!(widest.full, packet.full, "widest lane code vs portable at {what}");
                    evaluate_each_vpl(&set, site, &region, faint_share, &mut reference);
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&packet.full), bits(&reference.full), "E1 at {what}");
                    assert_eq!(bits(&packet.unoccluded), bits(&reference.unoccluded), "E2 at {what}");
                    assert_eq!(bits(&packet.bounded), bits(&reference.bounded), "E3 at {what}");
                    assert_eq!(packet.totals, reference.totals, "totals at {what}");
                    for (f, u) in packet.full.iter().zip(&packet.unoccluded) {
                        visible += (*u > 0.0 && f == u) as usize;
                        occluded += (*u > 0.0 && *f == 0.0) as usize;
                    }
                }
                assert!(
                    visible > 1000 && occluded > 100,
                    "{visible} visible, {occluded} occluded: the test has power"
                );
                occluded_by_share.push(occluded);
            }
            assert!(
                occluded_by_share[1] < occluded_by_share[0],
                "the faint share takes some occluded VPLs as visible: {occluded_by_share:?}"
            );
        }
    }
}
