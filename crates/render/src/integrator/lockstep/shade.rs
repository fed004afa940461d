//! The shading of path vertex `vertex` in eight lanes: the body of
//! [`trace_from_hit`](crate::integrator::path::trace_from_hit)'s loop after the hit, as
//! named steps in its order: [`add_emission`], [`bsdfs`], [`VertexSamples8::draw`],
//! [`sample_lights`], [`add_light_sample`], [`sample_bsdf`], [`russian_roulette`]. The
//! lanes of a Lambert surface and of an area light, a directional light or the environment
//! run the lane versions beside the scalar code ([`Diffuse8`], [`AreaLight8`],
//! [`EnvironmentLight::sample8`](crate::lights::EnvironmentLight::sample8)); every other
//! lane calls the scalar code.

use super::surf8::{lanes_of, Surf8};
use super::tables::{LockstepTables, SmallLights, AREA_FLOATS, MAT_DIFFUSE, MAT_EMITS, MAT_TWO_SIDED};
use super::LockstepContext;
use crate::bsdf::diffuse::Diffuse8;
use crate::bsdf::SurfaceBsdf;
use crate::integrator::lanes::{
    alias_pick8, columns, from_bits, lookup, lookup8, lookup8_u32, lookup_u32, mask_of, select, F8, LANES,
    M8, U8, V8,
};
use crate::integrator::pool::PathLanes;
use crate::integrator::sampler8::Sampler8;
use crate::integrator::sampling8::{frame_from_z, power_heuristic8, to_local, to_world};
use crate::integrator::{vertex_slot, SLOT_BSDF, SLOT_CHOICES, SLOT_LIGHT, SLOT_RR};
use crate::lights::area::AreaLight8;
use crate::lights::environment::EnvSample8;
use crate::surface::SHADOW_END_FRACTION;
use filtrace_accel::RayPacket;
use filtrace_core::sampling::power_heuristic;
use filtrace_core::{Rgb, Vec2};

/// The shading at path vertex `vertex` of the lanes `act` with hit records `si`:
/// emission (MIS against light sampling), next-event estimation with one packet of shadow
/// rays, the BSDF sample and Russian roulette. Returns the lanes that go on with the next
/// ray's origin and direction.
#[inline(always)]
pub(super) fn shade<const A: bool>(
    lc: &LockstepContext,
    p: &mut PathLanes<A>,
    si: &Surf8<A>,
    act: M8<A>,
    vertex: u32,
    index: u32,
) -> (M8<A>, V8<A>, V8<A>) {
    // The path state as a local (registers), stored once at the end.
    let mut st = *p;
    let sampler = Sampler8::<A>::from_keys(p.key, index);
    let mats = MaterialLanes::lookup(lc.tables, si);
    add_emission(lc, &mut st, si, mats.emitting(act, si), vertex);

    // Stop when one more segment would exceed max_depth.
    if !lc.params.allows(vertex + 2) {
        *p = st;
        return (M8::none(), V8::default(), V8::default());
    }
    let b = bsdfs(lc, si, act, &mats);
    let frame = ShadingFrame::new(si);
    let u = VertexSamples8::draw(&sampler, vertex, b.lobe);
    let ls = sample_lights(lc, si, act, &u);
    add_light_sample(lc, &mut st, si, act, &frame, &b, &ls, vertex);
    let (cont, wi) = sample_bsdf(&mut st, si, act, &frame, &b, &u);
    let org = si.offset_origin(wi);
    let cont = russian_roulette(lc, &mut st, cont, &sampler, vertex);
    *p = st;
    (cont, org, wi)
}

/// The material flags and Lambert reflectances of the lanes by lookups in the
/// [`MaterialTable`](super::tables::MaterialTable) (without it every lane looks its
/// material up).
struct MaterialLanes<const A: bool>(Option<(U8<A>, V8<A>)>);

impl<const A: bool> MaterialLanes<A> {
    #[inline(always)]
    fn lookup(tables: &LockstepTables, si: &Surf8<A>) -> Self {
        // (A match, not `Option::map`: a closure would not inherit AVX2.)
        match tables.materials() {
            Some(t) => {
                let id = U8::from_array(si.material);
                let rho = V8::new(lookup(&t.rho[0], id), lookup(&t.rho[1], id), lookup(&t.rho[2], id));
                MaterialLanes(Some((lookup_u32(&t.flags, id), rho)))
            }
            None => MaterialLanes(None),
        }
    }

    /// The lanes of `act` that may emit towards `wo` (all of `act` without the tables).
    #[inline(always)]
    fn emitting(&self, act: M8<A>, si: &Surf8<A>) -> M8<A> {
        match &self.0 {
            Some((flags, _)) => {
                let emits = mask_of(flags.and(U8::splat(MAT_EMITS)));
                let two = mask_of(flags.and(U8::splat(MAT_TWO_SIDED)));
                act & emits & (si.front_face | two)
            }
            None => act,
        }
    }
}

/// Emitted radiance at the vertex, MIS-weighted against light sampling (per lane: few
/// lanes hit an emitter).
#[inline(always)]
fn add_emission<const A: bool>(
    lc: &LockstepContext,
    st: &mut PathLanes<A>,
    si: &Surf8<A>,
    emitting: M8<A>,
    vertex: u32,
) {
    let ctx = &lc.ctx;
    for i in lanes_of(emitting) {
        let m = &ctx.scene.materials[si.material[i] as usize];
        if !(m.is_emissive() && (si.front_face.get(i) || m.two_sided_emission)) {
            continue;
        }
        let le = m.emission;
        if le != Rgb::ZERO {
            let w_b = if vertex == 0 || st.specular.get(i) {
                1.0
            } else {
                let (inst, prim) = (si.instance[i], si.prim[i]);
                let p_l =
                    ctx.lights.pdf_area(inst, prim, st.prev_p.lane(i), si.p.lane(i), si.n_winding.lane(i));
                power_heuristic(1.0, st.p_b.lane(i), 1.0, p_l)
            };
            let l = st.beta.lane(i) * w_b * le;
            if vertex <= 1 {
                st.l_direct.set_lane(i, st.l_direct.lane(i) + l);
            } else {
                st.l_indirect.set_lane(i, st.l_indirect.lane(i) + l);
            }
        }
    }
}

/// The BSDFs of the lanes: Lambert lanes as [`Diffuse8`], the others (`glossy`) as
/// scalar BSDFs.
struct Bsdfs8<const A: bool> {
    /// `None` stores one tag byte per lane (a default BSDF copied into eight lanes was a
    /// memset/memcpy per bounce); only the glossy lanes read theirs.
    bsdf: [Option<SurfaceBsdf>; LANES],
    lambert: Diffuse8<A>,
    glossy: M8<A>,
    /// The glossy lanes whose BSDF chooses between lobes.
    lobe: M8<A>,
}

#[inline(always)]
fn bsdfs<const A: bool>(
    lc: &LockstepContext,
    si: &Surf8<A>,
    act: M8<A>,
    mats: &MaterialLanes<A>,
) -> Bsdfs8<A> {
    let ctx = &lc.ctx;
    let mut bsdf: [Option<SurfaceBsdf>; LANES] = [None; LANES];
    let mut diffuse = 0u8;
    let mut lobe = 0u8;
    let mut rho = [[0.0f32; LANES]; 3];
    let const_diffuse = match &mats.0 {
        Some((flags, _)) => act & mask_of(flags.and(U8::splat(MAT_DIFFUSE))),
        None => M8::none(),
    };
    for i in lanes_of(act & !const_diffuse) {
        // Untextured Lambert (most surfaces): its reflectance only, no BSDF record.
        if let Some(r) = ctx.geometry.constant_diffuse(si.material[i]) {
            diffuse |= 1 << i;
            (rho[0][i], rho[1][i], rho[2][i]) = (r.x, r.y, r.z);
            continue;
        }
        let b = ctx.geometry.bsdf(ctx.scene, si.material[i], Vec2::new(si.uv[0][i], si.uv[1][i]));
        match &b {
            SurfaceBsdf::Diffuse(d) => {
                diffuse |= 1 << i;
                let r = d.reflectance;
                (rho[0][i], rho[1][i], rho[2][i]) = (r.x, r.y, r.z);
            }
            b => lobe |= (b.has_lobe_choice() as u8) << i,
        }
        bsdf[i] = Some(b);
    }
    let diffuse = const_diffuse | from_bits::<A>(diffuse);
    let rho = match &mats.0 {
        Some((_, table_rho)) => V8::select(const_diffuse, *table_rho, V8::from_arrays(&rho)),
        None => V8::from_arrays(&rho),
    };
    Bsdfs8 { bsdf, lambert: Diffuse8 { rho }, glossy: act & !diffuse, lobe: from_bits::<A>(lobe) }
}

/// The shading frames (`Frame::from_z(n_s)`) and `wo` in them.
struct ShadingFrame<const A: bool> {
    x: V8<A>,
    y: V8<A>,
    n: V8<A>,
    wo: V8<A>,
}

impl<const A: bool> ShadingFrame<A> {
    #[inline(always)]
    fn new(si: &Surf8<A>) -> Self {
        let (x, y) = frame_from_z(si.n_s);
        let n = si.n_s;
        ShadingFrame { x, y, n, wo: to_local(&x, &y, &n, si.wo) }
    }
}

/// The vertex's random numbers ([`crate::integrator::VertexSamples::draw`]).
struct VertexSamples8<const A: bool> {
    u_light: (F8<A>, F8<A>),
    u_bsdf: (F8<A>, F8<A>),
    u_select: F8<A>,
    u_lobe: F8<A>,
}

impl<const A: bool> VertexSamples8<A> {
    #[inline(always)]
    fn draw(sampler: &Sampler8<A>, vertex: u32, lobe: M8<A>) -> Self {
        let base = vertex_slot(vertex);
        let u_light = sampler.next_2d(base + SLOT_LIGHT);
        let u_bsdf = sampler.next_2d(base + SLOT_BSDF);
        let (u_select, u_lobe) = if lobe.any() {
            let (cx, cy) = sampler.next_2d(base + SLOT_CHOICES);
            (cx, select(lobe, cy, F8::splat(0.0)))
        } else {
            (sampler.next_1d(base + SLOT_CHOICES), F8::splat(0.0))
        };
        VertexSamples8 { u_light, u_bsdf, u_select, u_lobe }
    }
}

/// One light sample per lane ([`crate::lights::LightSet::sample_li`]).
#[derive(Default)]
struct LightSamples8<const A: bool> {
    ok: M8<A>,
    delta: M8<A>,
    wi: V8<A>,
    li: V8<A>,
    /// Solid-angle density including the selection probability.
    pdf: F8<A>,
    dist: F8<A>,
}

/// Next-event estimation's light sample (`sample_one_light`): the light choice (in lanes
/// with at most eight lights), area, directional and environment lights sampled in lanes
/// ([`add_area_samples`]), other lights by the scalar `sample_li`.
#[inline(always)]
fn sample_lights<const A: bool>(
    lc: &LockstepContext,
    si: &Surf8<A>,
    act: M8<A>,
    u: &VertexSamples8<A>,
) -> LightSamples8<A> {
    match lc.tables.small_lights() {
        Some(sl) => choose_small(lc, sl, si, act, u),
        None => choose_per_lane(lc, si, act, u),
    }
}

/// The samples of the lanes `lanes` whose chosen light (selection probability `pmf`) is
/// the area light of that lane in `lights`, written over their entries of `ls`. Called
/// only where some lane chose an area light (no eight empty lights built per step).
#[inline(always)]
fn add_area_samples<const A: bool>(
    ls: &mut LightSamples8<A>,
    si: &Surf8<A>,
    u: &VertexSamples8<A>,
    lanes: M8<A>,
    pmf: F8<A>,
    lights: &AreaLight8<A>,
) {
    let (ok, wi, dist, pdf_a) = lights.sample(si.p, u.u_light.0, u.u_light.1);
    ls.li = V8::select(lanes, lights.le, ls.li);
    ls.ok = M8::select(lanes, lanes & ok, ls.ok);
    ls.wi = V8::select(lanes, wi, ls.wi);
    ls.pdf = select(lanes, pmf * pdf_a, ls.pdf);
    ls.dist = select(lanes, dist, ls.dist);
}

/// With at most eight lights the choice and the lights' data are lanes ([`SmallLights`]:
/// the alias pick and one `vpermps` per field): area and directional lights and the
/// environment are sampled in lanes; only the lanes that chose another kind of light
/// (point, spot) take the per-lane code.
#[inline(always)]
fn choose_small<const A: bool>(
    lc: &LockstepContext,
    sl: &SmallLights,
    si: &Surf8<A>,
    act: M8<A>,
    u: &VertexSamples8<A>,
) -> LightSamples8<A> {
    let (k, pmf) = alias_pick8(u.u_select, sl.n, &sl.q, &sl.alias, &sl.pmf);
    let chosen = act & pmf.gt(F8::splat(0.0));
    let is_area = mask_of(lookup8_u32(&sl.is_area, k));
    // (Tables without a sun or a sky skip their lookups: +1 % on the Cornell box.)
    let directional =
        if sl.has_directional { chosen & mask_of(lookup8_u32(&sl.is_directional, k)) } else { M8::none() };
    let environment =
        if sl.has_environment { chosen & mask_of(lookup8_u32(&sl.is_environment, k)) } else { M8::none() };
    let env = match lc.ctx.lights.environment() {
        Some(e) if environment.any() => e.sample8(environment, u.u_light.0, u.u_light.1),
        _ => EnvSample8 { scalar: environment, ..Default::default() },
    };
    let scalar = (chosen & !(is_area | directional | environment)) | env.scalar;
    let mut ls = choose_per_lane(lc, si, scalar, u);
    if directional.any() {
        // `Light::sample_li` of a directional light: a delta sample of density 1.
        macro_rules! row {
            ($t:expr) => {
                V8::new(lookup8(&$t[0], k), lookup8(&$t[1], k), lookup8(&$t[2], k))
            };
        }
        ls.ok = ls.ok | directional;
        ls.delta = ls.delta | directional;
        ls.wi = V8::select(directional, row!(sl.to_light), ls.wi);
        ls.li = V8::select(directional, row!(sl.irradiance), ls.li);
        ls.pdf = select(directional, pmf * F8::splat(1.0), ls.pdf);
        ls.dist = select(directional, F8::splat(f32::INFINITY), ls.dist);
    }
    let in_env = environment & !env.scalar;
    if in_env.any() {
        ls.ok = M8::select(in_env, env.ok, ls.ok);
        ls.wi = V8::select(in_env, env.wi, ls.wi);
        ls.li = V8::select(in_env, env.li, ls.li);
        ls.pdf = select(in_env, pmf * env.pdf, ls.pdf);
        ls.dist = select(in_env, F8::splat(f32::INFINITY), ls.dist);
    }
    let lanes = chosen & is_area;
    if !lanes.any() {
        return ls;
    }
    // A macro, not a closure (closures do not inherit AVX2).
    macro_rules! field {
        ($j:expr) => {
            lookup8(&sl.field[$j], k)
        };
    }
    let lights = AreaLight8 {
        p0: V8::new(field!(0), field!(1), field!(2)),
        e1: V8::new(field!(3), field!(4), field!(5)),
        e2: V8::new(field!(6), field!(7), field!(8)),
        n: V8::new(field!(9), field!(10), field!(11)),
        area: field!(12),
        le: V8::new(field!(13), field!(14), field!(15)),
        two_sided: mask_of(lookup8_u32(&sl.two_sided, k)),
    };
    add_area_samples(&mut ls, si, u, lanes, pmf, &lights);
    ls
}

/// The light choice per lane of `lanes`: area lights sampled in lanes (their rows of the
/// area words transposed), the others by the scalar `sample_li`.
#[inline(always)]
fn choose_per_lane<const A: bool>(
    lc: &LockstepContext,
    si: &Surf8<A>,
    lanes: M8<A>,
    u: &VertexSamples8<A>,
) -> LightSamples8<A> {
    let lights = lc.ctx.lights;
    // Per-lane values go to plain arrays first (one vector load each afterwards).
    let (mut area, mut a_two, mut ok, mut delta) = (0u8, 0u8, 0u8, 0u8);
    let (mut wi, mut li) = ([[0.0f32; LANES]; 3], [[0.0f32; LANES]; 3]);
    let (mut pdf, mut dist, mut pmf) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
    // Rows of the chosen area lights in `area_words` (row 0 for the other lanes).
    let mut a_start = [0usize; LANES];
    let (u_sel, ulx, uly) = (u.u_select.to_array(), u.u_light.0, u.u_light.1);
    for i in lanes_of(lanes) {
        let (l, pm) = lights.select(u_sel[i]);
        if pm > 0.0 {
            if let Some(a) = lights.area_light(l) {
                area |= 1 << i;
                pmf[i] = pm;
                a_start[i] = l * AREA_FLOATS;
                a_two |= (a.two_sided as u8) << i;
                continue;
            }
        }
        if let Some(ls) = lights.sample_li(si.p.lane(i), u_sel[i], Vec2::new(ulx.lane(i), uly.lane(i))) {
            ok |= 1 << i;
            (wi[0][i], wi[1][i], wi[2][i]) = (ls.wi.x, ls.wi.y, ls.wi.z);
            (li[0][i], li[1][i], li[2][i]) = (ls.li.x, ls.li.y, ls.li.z);
            (pdf[i], dist[i]) = (ls.pdf, ls.dist);
            delta |= (ls.delta as u8) << i;
        }
    }
    let mut ls = LightSamples8 {
        ok: from_bits(ok),
        delta: from_bits(delta),
        wi: V8::from_arrays(&wi),
        li: V8::from_arrays(&li),
        pdf: F8::from_array(pdf),
        dist: F8::from_array(dist),
    };
    if area != 0 {
        // The chosen lights' rows as lanes (words 0..8 and 8..16, transposed; the rows
        // exist: `area_light` found the lights).
        let words = lc.tables.area_words();
        let a = columns::<A>(words, &a_start).expect("area light rows in the table");
        let b = columns::<A>(words, &a_start.map(|s| s + 8)).expect("area light rows in the table");
        let area_lights = AreaLight8 {
            p0: V8::new(a[0], a[1], a[2]),
            e1: V8::new(a[3], a[4], a[5]),
            e2: V8::new(a[6], a[7], b[0]),
            n: V8::new(b[1], b[2], b[3]),
            area: b[4],
            le: V8::new(b[5], b[6], b[7]),
            two_sided: from_bits(a_two),
        };
        add_area_samples(&mut ls, si, u, from_bits(area), F8::from_array(pmf), &area_lights);
    }
    ls
}

/// The light sample's contribution `f |cos| L_i w_l / p_l` where unoccluded (one packet
/// of shadow rays), added to the component of vertex `vertex + 1`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn add_light_sample<const A: bool>(
    lc: &LockstepContext,
    st: &mut PathLanes<A>,
    si: &Surf8<A>,
    act: M8<A>,
    frame: &ShadingFrame<A>,
    b: &Bsdfs8<A>,
    ls: &LightSamples8<A>,
    vertex: u32,
) {
    let zero = F8::<A>::splat(0.0);
    let p_l = ls.pdf;
    let usable = (ls.ok & !(p_l.is_nan() | p_l.le(zero))) & !ls.li.is_zero();
    let wi_l = to_local(&frame.x, &frame.y, &frame.n, ls.wi);
    let (f_d, mut pdf_b) = b.lambert.f_pdf(frame.wo.z, wi_l.z);
    let mut f = f_d * wi_l.z.abs();
    for i in lanes_of(b.glossy & usable) {
        if let Some(bsdf) = &b.bsdf[i] {
            let (wo_i, wi_i) = (frame.wo.lane(i), wi_l.lane(i));
            f.set_lane(i, bsdf.f(wo_i, wi_i) * wi_i.z.abs());
            pdf_b.set_lane(i, bsdf.pdf(wo_i, wi_i));
        }
    }
    let shadow = usable & !f.is_zero();
    let s_org = si.offset_origin(ls.wi);
    let far =
        select(ls.dist.is_finite(), ls.dist * F8::splat(1.0 - SHADOW_END_FRACTION), F8::splat(f32::INFINITY));
    let srays = RayPacket {
        origin: s_org.to_arrays(),
        dir: ls.wi.to_arrays(),
        t_min: [0.0; LANES],
        t_max: far.to_array(),
    };
    let lit = shadow & !lc.occluded(&srays, shadow);
    let w_l = select(ls.delta, F8::splat(1.0), power_heuristic8(p_l, pdf_b));
    let contrib = V8::select(lit, f * ls.li * (w_l / p_l), V8::default());
    // The light reaches the eye over vertices 0..=vertex: component of vertex + 1.
    let add = st.beta * contrib;
    if vertex < 1 {
        st.l_direct = V8::select(act, st.l_direct + add, st.l_direct);
    } else {
        st.l_indirect = V8::select(act, st.l_indirect + add, st.l_indirect);
    }
}

/// BSDF sampling for the next direction (cosine hemisphere in lanes for Lambert): updates
/// the throughput and the MIS state; returns the lanes that go on and their direction.
#[inline(always)]
fn sample_bsdf<const A: bool>(
    st: &mut PathLanes<A>,
    si: &Surf8<A>,
    act: M8<A>,
    frame: &ShadingFrame<A>,
    b: &Bsdfs8<A>,
    u: &VertexSamples8<A>,
) -> (M8<A>, V8<A>) {
    let (ubx, uby) = u.u_bsdf;
    let (mut bs_ok, mut bs_wi, mut bs_f, mut bs_pdf) = b.lambert.sample(frame.wo.z, ubx, uby);
    let mut bs_spec = M8::none();
    for i in lanes_of(b.glossy) {
        let sample = b.bsdf[i]
            .as_ref()
            .and_then(|b| b.sample(frame.wo.lane(i), Vec2::new(ubx.lane(i), uby.lane(i)), u.u_lobe.lane(i)));
        match sample {
            Some(bs) => {
                bs_ok.set(i, true);
                bs_wi.set_lane(i, bs.wi);
                bs_f.set_lane(i, bs.f);
                bs_pdf.set_lane(i, bs.pdf);
                bs_spec.set(i, bs.specular);
            }
            None => bs_ok.set(i, false),
        }
    }
    let cont = act & bs_ok;
    let wi = to_world(&frame.x, &frame.y, &frame.n, bs_wi);
    let new_beta = st.beta * (bs_f * (bs_wi.z.abs() / bs_pdf));
    st.beta = V8::select(cont, new_beta, st.beta);
    st.p_b = select(cont, bs_pdf, st.p_b);
    st.specular = M8::select(cont, bs_spec, st.specular);
    st.prev_p = V8::select(cont, si.p, st.prev_p);
    (cont & (!st.beta.is_zero() & st.beta.is_finite()), wi)
}

/// Russian roulette once the path has `rr_depth` segments (survival `min(max(beta),
/// 0.95)`); returns the lanes that survive.
#[inline(always)]
fn russian_roulette<const A: bool>(
    lc: &LockstepContext,
    st: &mut PathLanes<A>,
    cont: M8<A>,
    sampler: &Sampler8<A>,
    vertex: u32,
) -> M8<A> {
    if vertex + 2 < lc.params.rr_depth {
        return cont;
    }
    let q = st.beta.max_element().min(F8::splat(0.95));
    let u_rr = sampler.next_1d(vertex_slot(vertex) + SLOT_RR);
    let cont = cont & !u_rr.ge(q);
    st.beta = V8::select(cont, st.beta / q, st.beta);
    cont
}
