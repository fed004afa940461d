//! The cache's evaluation of eight (record, VPL) pairs at a time: the VPLs of the common
//! case as a structure of arrays, built once per frame with the cache's VPL set
//! ([`super::SceneVpls::new`]), and the three values the cache stores per pair
//! (thesis 4.2.5) in eight lanes.
//!
//! The common case is a diffuse receiver lit by emitter VPLs and diffuse surface VPLs;
//! glossy ones, point, spot and distant lights, and pairs at a degenerate distance keep the
//! per-VPL path ([`super::eval::contribution_parts`], `bounded_towards`). For the common
//! case the scalar code reduces to a few lanes of arithmetic (a diffuse `f` is `ρ/π` or
//! zero; the folding of the bounded term changes nothing for it), which this module does
//! with the operations of the scalar code in the same order, on the lane types of
//! `filtrace_render::integrator::lanes` (each lane operation the IEEE operation of the
//! scalar one; AVX2 after run-time detection, a portable build otherwise). So every
//! pair's values are those of the per-VPL reference bit for bit
//! (`vector_evaluation_equals_the_per_vpl_reference`, both instruction sets).

use super::eval::{GeometryBound, Receiver};
use super::{Vpl, VplKind};
use crate::cache::RelaxedReceiver;
use filtrace_core::cpu::Isa;
use filtrace_core::{Rgb, Vec3};
use filtrace_render::bsdf::SurfaceBsdf;
use filtrace_render::integrator::lanes::{bits, from_bits, mask_words, select, F8, LANES, M8, U8, V8};
use filtrace_render::surface::SHADOW_END_FRACTION;
use std::f32::consts::FRAC_1_PI;

/// Eight VPLs of the vector path, one per lane, in VPL order.
#[derive(Clone, Copy, Debug, Default)]
pub struct VplGroup {
    /// VPL index of each lane; lanes `live..` are padding (the last group).
    pub index: [u32; LANES],
    pub live: usize,
    /// Eight VPLs in a row (`index[i] = index[0] + i`): the lanes are stored as blocks.
    pub dense: bool,
    p: [[f32; LANES]; 3],
    /// The VPL's geometric normal (`Vpl::n`), which the bounded term relaxes.
    n: [[f32; LANES]; 3],
    /// Surface VPLs: the shading normal (their frame's z), which the contribution uses.
    n_s: [[f32; LANES]; 3],
    weight: [[f32; LANES]; 3],
    /// Surface VPLs: `ρ/π` of their diffuse BSDF; emitters: 1, so that `f · weight` is
    /// the weight bit for bit and one expression serves both kinds.
    f: [[f32; LANES]; 3],
    /// Bits per lane: surface VPL, lit from above its surface (`wi_local.z > 0`, always
    /// for emitters), two-sided emitter.
    surface: u8,
    lit: u8,
    two_sided: u8,
}

/// The VPLs of a frame split for the cache: groups of eight for the vector path, the rest
/// (by index) for the per-VPL path.
#[derive(Clone, Debug, Default)]
pub struct VplLanes {
    pub groups: Vec<VplGroup>,
    pub others: Vec<u32>,
}

impl VplLanes {
    /// The split of `vpls` (emitters and diffuse surface VPLs in groups, in order).
    pub fn new(vpls: &[Vpl]) -> Self {
        let mut lanes = VplLanes::default();
        for (j, v) in vpls.iter().enumerate() {
            let (f, surface, lit, two_sided) = match v.kind {
                VplKind::Emitter { two_sided } => (Rgb::ONE, false, true, two_sided),
                VplKind::Surface { bsdf: SurfaceBsdf::Diffuse(d), wi_local, .. } => {
                    // `Diffuse::f` is zero for `wi.z <= 0` (and not for NaN).
                    let below = wi_local.z <= 0.0;
                    (d.reflectance * FRAC_1_PI, true, !below, false)
                }
                _ => {
                    lanes.others.push(j as u32);
                    continue;
                }
            };
            if lanes.groups.last().is_none_or(|g| g.live == LANES) {
                lanes.groups.push(VplGroup::default());
            }
            let g = lanes.groups.last_mut().expect("just pushed");
            let i = g.live;
            let n_s = match v.kind {
                VplKind::Surface { frame, .. } => frame.z,
                _ => v.n,
            };
            for k in 0..3 {
                (g.p[k][i], g.n[k][i], g.n_s[k][i]) = (v.p[k], v.n[k], n_s[k]);
                (g.weight[k][i], g.f[k][i]) = (v.weight[k], f[k]);
            }
            g.index[i] = j as u32;
            g.surface |= (surface as u8) << i;
            g.lit |= (lit as u8) << i;
            g.two_sided |= (two_sided as u8) << i;
            g.live += 1;
        }
        for g in &mut lanes.groups {
            g.dense = g.live == LANES && g.index[LANES - 1] - g.index[0] == (LANES - 1) as u32;
        }
        lanes
    }
}

/// One group's pairs with a record, lane by lane.
#[derive(Clone, Copy, Debug, Default)]
pub struct PairLanes {
    /// Lanes evaluated here; the others (padding, degenerate distances) are not.
    pub valid: u8,
    /// The unoccluded contribution E² and the bounded one E³ (RGB), and their luminances.
    pub c: [[f32; LANES]; 3],
    pub b: [[f32; LANES]; 3],
    pub lum_c: [f32; LANES],
    pub lum_b: [f32; LANES],
    /// Lanes whose visibility decides E¹ (`luminance(c) > 0`), the side of the record's
    /// surface their shadow rays leave from (set: against `n_g`), direction and `t_max`.
    pub ray: u8,
    pub back: u8,
    pub w: [[f32; LANES]; 3],
    pub t_max: [f32; LANES],
    /// `filtrace_accel::fan_class` of each lane's direction.
    pub class: [u32; LANES],
}

impl PairLanes {
    #[inline]
    pub fn c(&self, i: usize) -> Rgb {
        Rgb::new(self.c[0][i], self.c[1][i], self.c[2][i])
    }
    #[inline]
    pub fn b(&self, i: usize) -> Rgb {
        Rgb::new(self.b[0][i], self.b[1][i], self.b[2][i])
    }
    #[inline]
    pub fn w(&self, i: usize) -> Vec3 {
        Vec3::new(self.w[0][i], self.w[1][i], self.w[2][i])
    }
}

/// What the vector path needs of a record: a diffuse receiver, its relaxed term's radius
/// and normal cone, and the bound of the geometry term.
#[derive(Clone, Copy, Debug)]
pub struct DiffuseSite {
    p: Vec3,
    n_s: Vec3,
    n_g: Vec3,
    /// `f(wo, ·)` above the horizon: `ρ/π`, zero when the camera sees the back.
    f: Rgb,
    radius: f32,
    cone: Option<(f32, f32)>,
    /// `d²` of [`GeometryBound::MinDistance`].
    min_r2: Option<f32>,
}

impl DiffuseSite {
    /// `None` unless the receiver is diffuse.
    pub fn new(rx: &Receiver, relaxed: &RelaxedReceiver, bound: GeometryBound) -> Option<Self> {
        let SurfaceBsdf::Diffuse(d) = rx.bsdf else { return None };
        // `Diffuse::f`: zero unless `wo.z > 0` (and `wi.z > 0`, per lane).
        let f = if rx.wo.z <= 0.0 { Rgb::ZERO } else { d.reflectance * FRAC_1_PI };
        let min_r2 = match bound {
            GeometryBound::Off => None,
            GeometryBound::MinDistance(d) => Some(d * d),
        };
        let (radius, cone) = relaxed.radius_and_cone();
        Some(DiffuseSite { p: rx.si.p, n_s: rx.si.n_s, n_g: rx.si.n_g, f, radius, cone, min_r2 })
    }
}

/// Calls `each` with every group of `lanes` evaluated at `site`, in order, with the widest
/// lane code `isa` allows (AVX2, else the portable build of the same source).
pub fn evaluate_groups(
    lanes: &VplLanes,
    site: &DiffuseSite,
    isa: Isa,
    mut each: impl FnMut(&VplGroup, &PairLanes),
) {
    #[cfg(target_arch = "x86_64")]
    if isa.has_avx2() {
        // SAFETY: the caller's `isa` is at most the detected level: AVX2 and FMA run.
        unsafe { evaluate_groups_avx2(lanes, site, &mut each) };
        return;
    }
    let _ = isa;
    groups::<false>(lanes, site, &mut each);
}

/// The lane code compiled for AVX2 + FMA (the same source; Rust never contracts into FMAs).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn evaluate_groups_avx2(
    lanes: &VplLanes,
    site: &DiffuseSite,
    each: &mut impl FnMut(&VplGroup, &PairLanes),
) {
    groups::<true>(lanes, site, each);
}

#[inline(always)]
fn groups<const A: bool>(lanes: &VplLanes, site: &DiffuseSite, each: &mut impl FnMut(&VplGroup, &PairLanes)) {
    let s = SiteLanes::<A>::new(site);
    for g in &lanes.groups {
        let out = pairs8(g, &s);
        each(g, &out);
    }
}

/// [`DiffuseSite`] splatted.
struct SiteLanes<const A: bool> {
    p: V8<A>,
    n_s: V8<A>,
    n_g: V8<A>,
    f: V8<A>,
    f_zero: bool,
    radius: F8<A>,
    cone: Option<(F8<A>, F8<A>)>,
    min_r2: Option<F8<A>>,
}

impl<const A: bool> SiteLanes<A> {
    #[allow(clippy::manual_map)]
    #[inline(always)]
    fn new(s: &DiffuseSite) -> Self {
        SiteLanes {
            p: V8::splat(s.p),
            n_s: V8::splat(s.n_s),
            n_g: V8::splat(s.n_g),
            f: V8::splat(s.f),
            f_zero: s.f == Rgb::ZERO,
            radius: F8::splat(s.radius),
            // `match`, not `Option::map`: a closure is compiled without the AVX2 feature.
            cone: match s.cone {
                Some((sin, cos)) => Some((F8::splat(sin), F8::splat(cos))),
                None => None,
            },
            min_r2: match s.min_r2 {
                Some(min_r2) => Some(F8::splat(min_r2)),
                None => None,
            },
        }
    }
}

/// `luminance(c)`: `0.2126 r + 0.7152 g + 0.0722 b`.
#[inline(always)]
fn luminance8<const A: bool>(c: V8<A>) -> F8<A> {
    F8::splat(0.2126) * c.x + F8::splat(0.7152) * c.y + F8::splat(0.0722) * c.z
}

/// `Slack::relax`: `max(cos(max(θ − s, 0)), 0)` for `θ = acos(cos_theta)` and the slack
/// `s` as its cosine, sine and "at least π".
#[inline(always)]
fn relax8<const A: bool>(cos_theta: F8<A>, cos_s: F8<A>, sin_s: F8<A>, at_least_pi: M8<A>) -> F8<A> {
    let (zero, one) = (F8::splat(0.0), F8::splat(1.0));
    // `f32::clamp(-1, 1)`.
    let c = select(cos_theta.lt(-one), -one, cos_theta);
    let c = select(c.gt(one), one, c);
    let relaxed = (c * cos_s + (one - c * c).max(zero).sqrt() * sin_s).max(zero);
    select(at_least_pi | c.ge(cos_s), one, relaxed)
}

/// Eight pairs: `contribution_parts` and `bounded_towards` of `exhaustive.rs` for a
/// diffuse receiver, term by term.
#[inline(always)]
fn pairs8<const A: bool>(g: &VplGroup, s: &SiteLanes<A>) -> PairLanes {
    let (zero, one) = (F8::<A>::splat(0.0), F8::<A>::splat(1.0));
    let live = from_bits::<A>(((1u32 << g.live) - 1) as u8);
    // Distance and direction.
    let d = V8::from_arrays(&g.p) - s.p;
    let r2 = d.dot(d);
    let valid = live & r2.gt(zero) & r2.is_finite();
    let r = r2.sqrt();
    let w = d / r;
    // The receiver's side: `f(wo, wi) |wi.z|`, `wi.z = w · n_s` (the frame's z).
    let wi_z = w.dot(s.n_s);
    let f0 = V8::select(wi_z.le(zero), V8::default(), s.f) * wi_z.abs();
    // The VPL's side: an emitter's cosine, or a surface VPL's `f` and cosine.
    let neg_w = -w;
    let n = V8::from_arrays(&g.n);
    let w_n = w.dot(n);
    let neg_w_n = neg_w.dot(n);
    let t = neg_w.dot(V8::from_arrays(&g.n_s));
    let (surface, lit, two_sided) =
        (from_bits::<A>(g.surface), from_bits::<A>(g.lit), from_bits::<A>(g.two_sided));
    let cos_e = -w_n;
    let cos_e = select(two_sided, cos_e.abs(), cos_e.max(zero));
    let cos_v = select(surface, t.abs(), cos_e);
    let f = V8::from_arrays(&g.f);
    let f_vpl = V8::select(surface & (t.le(zero) | !lit), V8::default(), f);
    let inv_r2 = match s.min_r2 {
        None => one / r2,
        Some(min_r2) => one / r2.max(min_r2),
    };
    let weight = V8::from_arrays(&g.weight);
    let emitted = (f_vpl * weight) * (cos_v * inv_r2);
    let c = V8::select(f0.is_zero(), V8::default(), emitted * f0);
    let lum_c = luminance8(c);
    // The bounded term: folded `f`s (a surface VPL's is zero only towards its back).
    let b = if s.f_zero {
        V8::default()
    } else {
        let f_b = V8::select(surface & t.le(zero), V8::default(), f);
        let cos_vpl = select(two_sided & w_n.gt(zero), w_n, neg_w_n);
        ((f_b * weight) * s.f) * relaxed8(s, wi_z, cos_vpl, r)
    };
    let t_max = r * F8::splat(1.0 - SHADOW_END_FRACTION);
    PairLanes {
        valid: bits(valid),
        c: c.to_arrays(),
        b: b.to_arrays(),
        lum_c: lum_c.to_array(),
        lum_b: luminance8(b).to_array(),
        ray: bits(valid & lum_c.gt(zero)),
        back: bits(w.dot(s.n_g).lt(zero)),
        w: w.to_arrays(),
        t_max: t_max.to_array(),
        class: fan_class8(w).to_array(),
    }
}

/// `filtrace_accel::fan_class` in eight lanes: the sign bits of `w` (the octant) plus 8
/// times the axis of its largest magnitude (x on ties, then y).
#[inline(always)]
fn fan_class8<const A: bool>(w: V8<A>) -> U8<A> {
    let sign = |c: F8<A>| c.to_bits().shr::<31>();
    let octant = sign(w.x).xor(sign(w.y).shl::<1>()).xor(sign(w.z).shl::<2>());
    let a = w.abs();
    let x_max = a.x.ge(a.y) & a.x.ge(a.z);
    let eight = U8::splat(8);
    // `kz = !x_max · (1 + (a.y < a.z))`, times 8.
    let kz8 = mask_words(!x_max).and(eight.wrapping_add(mask_words(a.y.lt(a.z)).and(eight)));
    octant.xor(kz8)
}

/// `RelaxedReceiver::towards` with the receiver's cosine `cos0_in = n0 · w` and the
/// VPL's `cos_vpl_in = n_vpl · (−w)`.
#[inline(always)]
fn relaxed8<const A: bool>(s: &SiteLanes<A>, cos0_in: F8<A>, cos_vpl_in: F8<A>, r: F8<A>) -> F8<A> {
    let (zero, one) = (F8::<A>::splat(0.0), F8::<A>::splat(1.0));
    let sin_d = (s.radius / r).min(one);
    let cos_d = (one - sin_d * sin_d).max(zero).sqrt();
    let (cos_s, sin_s, at_least_pi) = match s.cone {
        Some((sin_c, cos_c)) => {
            (cos_d * cos_c - sin_d * sin_c, sin_d * cos_c + cos_d * sin_c, cos_c.le(-cos_d))
        }
        None => (cos_d, sin_d, M8::none()),
    };
    let cos0 = relax8(cos0_in, cos_s, sin_s, at_least_pi);
    let cos_vpl = relax8(cos_vpl_in, cos_d, sin_d, M8::none());
    let r_min = (r - s.radius).max(s.radius).max(F8::splat(f32::MIN_POSITIVE.sqrt()));
    cos0 * cos_vpl / (r_min * r_min)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::{evaluate_each_vpl, CachePoint, RecordValues, Region};
    use crate::vpls::{generate_vpls, SceneVpls, VplParams};
    use filtrace_accel::fan_class;
    use filtrace_core::Vec2;
    use filtrace_render::{RenderSettings, Renderer};
    use filtrace_scene::{Bsdf, Light, Texturable};

    /// The Cornell box with glossy walls (plastic, conductor), a two-sided light, a point,
    /// a spot and a directional light: every VPL kind, diffuse and glossy receivers.
    fn mixed_cornell() -> Renderer {
        let mut scene = filtrace_scene::builtin("cornell").expect("built-in Cornell box");
        let red = Texturable::Constant(Rgb::new(0.6, 0.1, 0.1));
        scene.materials[1].bsdf = Bsdf::Plastic { diffuse: red, roughness: 0.3, ior: 1.5 };
        scene.materials[2].bsdf =
            Bsdf::Conductor { eta: Rgb::splat(0.2), k: Rgb::splat(3.0), roughness: 0.2 };
        scene.materials[4].two_sided_emission = true;
        let (position, intensity) = (Vec3::new(278.0, 400.0, 278.0), Rgb::splat(2e4));
        scene.lights.push(Light::Point { position, intensity });
        scene.lights.push(Light::Spot {
            position: Vec3::new(100.0, 500.0, 100.0),
            direction: Vec3::new(0.3, -1.0, 0.2).normalize(),
            intensity,
            cos_total_width: 0.5,
            cos_falloff_start: 0.8,
        });
        let (direction, irradiance) = (Vec3::new(0.2, 1.0, -0.3).normalize(), Rgb::splat(0.5));
        scene.lights.push(Light::Directional { direction, irradiance });
        let settings = RenderSettings { width: 20, height: 20, spp: 1, max_depth: 8, seed: 1 };
        Renderer::new(scene, settings).expect("settings")
    }

    /// Every pair evaluated eight at a time (at every instruction set this CPU runs) has
    /// the per-VPL reference's values bit for bit: E¹, E², E³ and the RGB totals, on
    /// diffuse and glossy receivers, with and without the geometry bound, radii and
    /// normal cones from 0 to beyond the scene, VPLs exactly at a record's point
    /// (degenerate distance, evaluated per VPL), surface VPLs lit from below, faint shares
    /// from 0 (every ray traced) to 0.3.
    #[test]
    fn vector_evaluation_equals_the_per_vpl_reference() {
        let r = mixed_cornell();
        let ctx = r.context();
        let receivers: Vec<Option<Receiver>> = (0..400u32)
            .map(|i| {
                let ray = r.camera().generate_ray(i % 20, i / 20, Vec2::splat(0.5));
                ctx.intersect(&ray).map(|si| Receiver::new(si, ctx.bsdf(&si)))
            })
            .collect();
        let sites: Vec<CachePoint> = (0..400)
            .step_by(3)
            .filter_map(|i| {
                receivers[i].map(|rx| CachePoint { position: rx.si.p, normal: rx.si.n_s, pixel: i as u32 })
            })
            .collect();
        let diffuse_sites = sites
            .iter()
            .filter(|s| matches!(receivers[s.pixel as usize].unwrap().bsdf, SurfaceBsdf::Diffuse(_)))
            .count();
        assert!(diffuse_sites > 20 && diffuse_sites + 10 < sites.len(), "{diffuse_sites} of {}", sites.len());
        let regions = [
            Region { radius: 0.0, normal_cone: 0.0 },
            Region { radius: 0.1, normal_cone: 0.2 },
            Region { radius: 40.0, normal_cone: 1.0 },
            Region { radius: 2000.0, normal_cone: std::f32::consts::PI },
        ];
        for bound in [GeometryBound::Off, GeometryBound::MinDistance(30.0)] {
            let params = VplParams { seed: 5, bound, ..VplParams::with_count(300) };
            let mut vpls = generate_vpls(&ctx, &r.path_params(), &params);
            // Diffuse VPLs exactly at two records, one lit from below.
            let diffuse: Vec<usize> = (0..vpls.len())
                .filter(|&j| {
                    matches!(vpls.vpls[j].kind, VplKind::Surface { bsdf: SurfaceBsdf::Diffuse(_), .. })
                })
                .collect();
            vpls.vpls[diffuse[0]].p = sites[0].position;
            vpls.vpls[diffuse[9]].p = sites[1].position;
            if let Some(v) = vpls.vpls.iter_mut().rev().find(|v| matches!(v.kind, VplKind::Surface { .. })) {
                if let VplKind::Surface { wi_local, .. } = &mut v.kind {
                    wi_local.z = -wi_local.z.abs();
                }
            }
            let receivers = crate::vpls::RecordReceivers::from_pixels(&receivers);
            let set = SceneVpls::new(r.context(), &vpls, &receivers);
            let lanes = VplLanes::new(&vpls.vpls);
            assert!(lanes.groups.len() > 20 && lanes.others.len() > 20, "both paths are tested");
            let dense = lanes.groups.iter().filter(|g| g.dense).count();
            assert!(dense > 0 && dense < lanes.groups.len(), "groups stored as blocks and lane by lane");
            let (mut fast, mut reference) = (RecordValues::default(), RecordValues::default());
            for isa in Isa::supported() {
                for (k, site) in sites.iter().enumerate() {
                    let region = regions[k % regions.len()];
                    let faint_share = [0.0, 0.02, 0.3][k % 3];
                    set.evaluate_record_with(site, &region, faint_share, &mut fast, isa);
                    evaluate_each_vpl(&set, site, &region, faint_share, &mut reference);
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    let what =
                        format!("{isa:?}, {bound:?}, pixel {}, {region:?}, faint {faint_share}", site.pixel);
                    assert_eq!(bits(&fast.full), bits(&reference.full), "E1: {what}");
                    assert_eq!(bits(&fast.unoccluded), bits(&reference.unoccluded), "E2: {what}");
                    assert_eq!(bits(&fast.bounded), bits(&reference.bounded), "E3: {what}");
                    let totals = |v: &RecordValues| v.totals.map(|t| t.to_array().map(f32::to_bits));
                    assert_eq!(totals(&fast), totals(&reference), "totals: {what}");
                }
            }
        }
    }

    /// The fan class computed in the lanes is `filtrace_accel::fan_class` of each lane's
    /// direction, at every instruction set; signed zeros and ties (rare towards VPLs) on
    /// a grid of directions in the portable lanes.
    #[test]
    fn lane_fan_classes_equal_fan_class() {
        let r = mixed_cornell();
        let ctx = r.context();
        let vpls =
            generate_vpls(&ctx, &r.path_params(), &VplParams { seed: 7, ..VplParams::with_count(300) });
        let lanes = VplLanes::new(&vpls.vpls);
        let mut checked = 0;
        for i in (0..400).step_by(7) {
            let ray = r.camera().generate_ray(i % 20, i / 20, Vec2::splat(0.5));
            let Some(si) = ctx.intersect(&ray) else { continue };
            let rx = Receiver::new(si, ctx.bsdf(&si));
            let relaxed = RelaxedReceiver::new(rx.si.n_s, 0.1, 0.2);
            let Some(site) = DiffuseSite::new(&rx, &relaxed, vpls.bound) else { continue };
            for isa in Isa::supported() {
                evaluate_groups(&lanes, &site, isa, |g, p| {
                    for i in (0..g.live).filter(|&i| p.valid >> i & 1 != 0) {
                        assert_eq!(p.class[i] as usize, fan_class(p.w(i)), "{isa:?}, {:?}", p.w(i));
                        checked += 1;
                    }
                });
            }
        }
        assert!(checked > 1000, "{checked} lanes checked");
        let values = [0.0f32, -0.0, 0.5, -0.5, 1.0, -1.0, f32::MIN_POSITIVE, -2.0];
        for (x, y) in values.iter().flat_map(|&x| values.map(|y| (x, y))) {
            let w = V8::<false>::from_arrays(&[[x; LANES], [y; LANES], values]);
            let classes = fan_class8(w).to_array();
            for (i, &z) in values.iter().enumerate() {
                assert_eq!(classes[i] as usize, fan_class(Vec3::new(x, y, z)), "({x}, {y}, {z})");
            }
        }
    }
}
