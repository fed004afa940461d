//! Light sources and next-event estimation: [`LightSet`] gathers every emitter of a scene,
//! picks one in proportion to its power and samples a direction towards it.
//!
//! Emitters: every emissive triangle of every instance, in world space ([`AreaLight`]),
//! plus the scene's explicit lights: [`PointLight`], [`SpotLight`], [`DirectionalLight`]
//! and one combined [`EnvironmentLight`] (all `Environment` entries summed).
//!
//! Selection probability ∝ power (pbrt-v4 section 12.6, `PowerLightSampler`):
//! area `π A lum(Le)` (× 2 two-sided), point `4π lum(I)`, spot
//! `2π (1 − (cos_start + cos_width)/2) lum(I)`, directional `π R² lum(E)`, environment
//! `π R² · π · mean lum(L)`, with `R` the radius of the scene's bounding sphere.
//! Lights of zero power (black, degenerate, non-finite) are dropped at build time and
//! counted in [`LightSet::skipped`].
//!
//! Densities: [`LightSample::pdf`] is in solid angle and includes the selection
//! probability; for delta lights (point, spot, directional) it is the selection
//! probability alone and `delta` is set. [`LightSet::pdf_area`] and
//! [`LightSet::pdf_environment`] give the same density for a direction found by BSDF
//! sampling, for MIS (Veach 1997, chapter 9). The emissive-triangle lookup is two array
//! reads (per-instance offset + per-triangle table), no hashing.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN, which `x <= 0.0` lets through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod area;
pub mod directional;
pub mod emission;
pub mod environment;
pub mod point;
pub mod spot;

pub use area::AreaLight;
pub use directional::DirectionalLight;
pub use emission::{EmitterKind, LeSample};
pub use environment::EnvironmentLight;
pub use point::PointLight;
pub use spot::SpotLight;

use filtrace_core::sampling::AliasTable;
use filtrace_core::{Rgb, Vec2, Vec3};
use filtrace_scene::{Environment, Light, Scene};

/// A sampled direction towards a light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightSample {
    /// Unit world direction from the shading point towards the light.
    pub wi: Vec3,
    /// Incident radiance (for delta lights: intensity / d², or irradiance).
    pub li: Rgb,
    /// Solid-angle density including the selection probability; for delta lights the
    /// selection probability alone.
    pub pdf: f32,
    /// Distance to the light point; `f32::INFINITY` for directional/environment.
    pub dist: f32,
    pub delta: bool,
}

/// One selectable light.
#[derive(Clone, Debug)]
enum LightKind {
    Area(AreaLight),
    Point(PointLight),
    Spot(SpotLight),
    Directional(DirectionalLight),
    Environment,
}

const NONE: u32 = u32::MAX;

/// All lights of a scene with a power-proportional selection distribution.
#[derive(Clone, Debug, Default)]
pub struct LightSet {
    lights: Vec<LightKind>,
    /// Power-proportional selection: an alias table, O(1) per sample (the binary search
    /// of a CDF was 4% of the Cornell box profile with two light triangles).
    selection: AliasTable,
    /// Per instance: start of its triangles in `tri_light`, or `NONE` if it has no emitter.
    instance_offset: Vec<u32>,
    /// Light index of each triangle of the instances with emitters (`NONE` if not emissive).
    tri_light: Vec<u32>,
    environment: Option<EnvironmentLight>,
    /// Index of the environment in `lights`, or `NONE`.
    env_index: u32,
    scene_radius: f32,
    /// Centre of the scene's bounding sphere (origin of distant lights' emission disks).
    scene_center: Vec3,
    skipped: usize,
    /// Per light [`AREA_FLOATS`] words for the lockstep integrator ([`LightSet::area_words`]).
    area_words: Vec<f32>,
    /// The same for scenes with at most eight lights, as eight-entry tables.
    small: Option<Box<SmallLights>>,
}

/// The selection table and the area lights of a scene with one to eight lights as
/// eight-entry tables, one per field (lane `k` = light or cell `k`): the lockstep
/// integrator looks them up with one `vpermps` per field ([`crate::integrator::lanes::
/// lookup8`]), no per-lane code. The values are those [`AliasTable::sample`] and
/// [`LightSet::area_light`] read.
#[derive(Clone, Debug, Default)]
pub(crate) struct SmallLights {
    /// Number of cells (= lights).
    pub(crate) n: u32,
    /// Per cell: `q`, `alias` (0 for a single cell: `sample` returns cell 0), `pmf`.
    pub(crate) q: [f32; 8],
    pub(crate) alias: [u32; 8],
    pub(crate) pmf: [f32; 8],
    /// Per light: `u32::MAX` for an area light, else 0; the same for two-sided ones.
    pub(crate) is_area: [u32; 8],
    pub(crate) two_sided: [u32; 8],
    /// Per field of [`LightSet::area_words`] (`AREA_FLOATS` of them): its value per light.
    pub(crate) field: [[f32; 8]; AREA_FLOATS],
}

impl SmallLights {
    fn new(set: &LightSet) -> Option<SmallLights> {
        let n = set.selection.count();
        if !(1..=8).contains(&n) || set.lights.len() != n {
            return None;
        }
        let mut t = SmallLights { n: n as u32, ..Default::default() };
        for i in 0..n {
            let (q, alias) = set.selection.bin(i)?;
            if alias as usize >= n {
                return None;
            }
            t.q[i] = q;
            t.alias[i] = if n == 1 { 0 } else { alias };
            t.pmf[i] = set.selection.pmf(i);
            if let LightKind::Area(a) = &set.lights[i] {
                t.is_area[i] = u32::MAX;
                t.two_sided[i] = if a.two_sided { u32::MAX } else { 0 };
            }
            for (f, w) in t.field.iter_mut().zip(&set.area_words[i * AREA_FLOATS..(i + 1) * AREA_FLOATS]) {
                f[i] = *w;
            }
        }
        Some(t)
    }
}

/// Words per light in [`LightSet::area_words`]: `p0`, `e1`, `e2`, `n` (xyz each) at 0..12,
/// the area at 12 and `le` (rgb) at 13..16 (zeros for a light that is not an area light).
pub(crate) const AREA_FLOATS: usize = 16;

impl LightSet {
    /// Gathers the emitters of `scene` (see the module docs). Malformed references (a
    /// mesh or material id out of range) are skipped, never a panic.
    pub fn build(scene: &Scene) -> LightSet {
        // Scene::bounds() indexes meshes unchecked; skip instances of unknown meshes here.
        let bounds = scene
            .instances
            .iter()
            .filter_map(|i| scene.meshes.get(i.mesh as usize).map(|m| m.bounds().transformed(&i.transform)))
            .fold(filtrace_core::Aabb::EMPTY, filtrace_core::Aabb::union);
        let r = if bounds.is_empty() { 0.0 } else { bounds.bounding_radius() };
        let scene_radius = if r.is_finite() && r > 0.0 { r } else { 1.0 };
        let c = bounds.center();
        let scene_center = if !bounds.is_empty() && c.is_finite() { c } else { Vec3::ZERO };
        let mut set = LightSet { env_index: NONE, scene_radius, scene_center, ..Default::default() };
        let mut powers = Vec::new();

        // Emissive triangles, world space.
        set.instance_offset = vec![NONE; scene.instances.len()];
        for (ii, inst) in scene.instances.iter().enumerate() {
            let Some(mesh) = scene.meshes.get(inst.mesh as usize) else { continue };
            let material = |prim: usize| {
                let id = inst.material_override.or_else(|| mesh.material_ids.get(prim).copied())?;
                scene.materials.get(id as usize)
            };
            let any = (0..mesh.indices.len()).any(|p| material(p).is_some_and(|m| m.is_emissive()));
            if !any {
                continue;
            }
            let offset = set.tri_light.len();
            set.instance_offset[ii] = offset as u32;
            set.tri_light.resize(offset + mesh.indices.len(), NONE);
            for (prim, idx) in mesh.indices.iter().enumerate() {
                let Some(m) = material(prim).filter(|m| m.is_emissive()) else { continue };
                let Some(tri) = idx
                    .iter()
                    .map(|&v| mesh.positions.get(v as usize).map(|&p| inst.transform.transform_point3(p)))
                    .collect::<Option<Vec<Vec3>>>()
                else {
                    set.skipped += 1;
                    continue;
                };
                match AreaLight::new([tri[0], tri[1], tri[2]], m.emission, m.two_sided_emission) {
                    Some(a) if a.power() > 0.0 && a.power().is_finite() => {
                        set.tri_light[offset + prim] = set.lights.len() as u32;
                        powers.push(a.power());
                        set.lights.push(LightKind::Area(a));
                    }
                    _ => set.skipped += 1,
                }
            }
        }

        // Explicit lights.
        let mut envs: Vec<&Environment> = Vec::new();
        for l in &scene.lights {
            let (kind, power) = match l {
                Light::Point { position, intensity } => {
                    let p = PointLight { position: *position, intensity: *intensity };
                    (Some(LightKind::Point(p)), p.power())
                }
                Light::Spot { position, direction, intensity, cos_total_width, cos_falloff_start } => {
                    match SpotLight::new(
                        *position,
                        *direction,
                        *intensity,
                        *cos_total_width,
                        *cos_falloff_start,
                    ) {
                        Some(s) => (Some(LightKind::Spot(s)), s.power()),
                        None => (None, 0.0),
                    }
                }
                Light::Directional { direction, irradiance } => {
                    match DirectionalLight::new(*direction, *irradiance) {
                        Some(d) => (Some(LightKind::Directional(d)), d.power(scene_radius)),
                        None => (None, 0.0),
                    }
                }
                Light::Environment(e) => {
                    envs.push(e);
                    continue;
                }
            };
            match kind {
                Some(k) if power > 0.0 && power.is_finite() && position_ok(l) => {
                    powers.push(power);
                    set.lights.push(k);
                }
                _ => set.skipped += 1,
            }
        }
        if !envs.is_empty() {
            let env = EnvironmentLight::new(&envs);
            let power = env.power(scene_radius);
            if power > 0.0 && power.is_finite() {
                set.env_index = set.lights.len() as u32;
                powers.push(power);
                set.lights.push(LightKind::Environment);
                set.environment = Some(env);
            } else {
                set.skipped += envs.len();
            }
        }
        set.selection = AliasTable::new(&powers);
        for l in &set.lights {
            match l {
                LightKind::Area(a) => {
                    for v in [a.p0, a.e1, a.e2, a.n] {
                        set.area_words.extend_from_slice(&[v.x, v.y, v.z]);
                    }
                    set.area_words.push(a.area);
                    set.area_words.extend_from_slice(&[a.le.x, a.le.y, a.le.z]);
                }
                _ => set.area_words.extend_from_slice(&[0.0; AREA_FLOATS]),
            }
        }
        set.small = SmallLights::new(&set).map(Box::new);
        set
    }

    /// [`SmallLights`] of scenes with one to eight lights.
    #[inline]
    pub(crate) fn small_lights(&self) -> Option<&SmallLights> {
        self.small.as_deref()
    }

    /// The area lights as rows of [`AREA_FLOATS`] words (row `i` = light `i`), read as
    /// lanes by the lockstep integrator: the values of [`LightSet::area_light`].
    #[inline]
    pub(crate) fn area_words(&self) -> &[f32] {
        &self.area_words
    }

    /// No light can be sampled.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.lights.is_empty()
    }

    /// Number of selectable lights (each emissive triangle counts once).
    pub fn len(&self) -> usize {
        self.lights.len()
    }

    /// Emitters dropped at build time (zero power, degenerate, non-finite, bad indices).
    pub fn skipped(&self) -> usize {
        self.skipped
    }

    /// Probability of selecting light `i`.
    pub fn selection_pmf(&self, i: usize) -> f32 {
        self.selection.pmf(i)
    }

    /// Radius of the scene bounding sphere used for distant-light power.
    pub fn scene_radius(&self) -> f32 {
        self.scene_radius
    }

    /// Index of the selectable light for triangle `prim` of `instance`, if emissive.
    #[inline]
    pub fn area_light_index(&self, instance: u32, prim: u32) -> Option<usize> {
        let off = *self.instance_offset.get(instance as usize)?;
        if off == NONE {
            return None;
        }
        let l = *self.tri_light.get(off as usize + prim as usize)?;
        (l != NONE).then_some(l as usize)
    }

    /// The light `u_select` picks and its selection probability (the first step of
    /// [`Self::sample_li`]).
    #[inline]
    pub fn select(&self, u_select: f32) -> (usize, f32) {
        self.selection.sample(u_select)
    }

    /// Light `i` when it is an area light.
    #[inline]
    pub fn area_light(&self, i: usize) -> Option<&AreaLight> {
        match self.lights.get(i) {
            Some(LightKind::Area(a)) => Some(a),
            _ => None,
        }
    }

    /// True when the scene has an environment light.
    #[inline]
    pub fn has_environment(&self) -> bool {
        self.environment.is_some()
    }

    /// Picks a light with `u_select` and samples a direction towards it from `p`.
    #[inline]
    pub fn sample_li(&self, p: Vec3, u_select: f32, u: Vec2) -> Option<LightSample> {
        let (i, pmf) = self.selection.sample(u_select);
        if !(pmf > 0.0) {
            return None;
        }
        match self.lights.get(i)? {
            LightKind::Area(a) => {
                let s = a.sample(p, u)?;
                Some(LightSample { wi: s.wi, li: a.le, pdf: pmf * s.pdf, dist: s.dist, delta: false })
            }
            LightKind::Point(l) => {
                let (wi, li, dist) = l.sample(p)?;
                Some(LightSample { wi, li, pdf: pmf, dist, delta: true })
            }
            LightKind::Spot(l) => {
                let (wi, li, dist) = l.sample(p)?;
                Some(LightSample { wi, li, pdf: pmf, dist, delta: true })
            }
            LightKind::Directional(l) => Some(LightSample {
                wi: l.to_light,
                li: l.irradiance,
                pdf: pmf,
                dist: f32::INFINITY,
                delta: true,
            }),
            LightKind::Environment => {
                let env = self.environment.as_ref()?;
                let (wi, pdf) = env.sample(u)?;
                Some(LightSample {
                    wi,
                    li: env.radiance(wi),
                    pdf: pmf * pdf,
                    dist: f32::INFINITY,
                    delta: false,
                })
            }
        }
    }

    /// Solid-angle density (incl. selection) with which [`Self::sample_li`] from `p`
    /// produces the direction towards `hit_point` on emissive triangle (`instance`,
    /// `prim`). 0 for non-emissive triangles and for the back face of one-sided emitters.
    /// The light's own stored normal decides the face; `n_geom` is accepted for the
    /// interface and only checked in debug builds.
    #[inline]
    pub fn pdf_area(&self, instance: u32, prim: u32, p: Vec3, hit_point: Vec3, n_geom: Vec3) -> f32 {
        let Some(i) = self.area_light_index(instance, prim) else { return 0.0 };
        let LightKind::Area(a) = &self.lights[i] else { return 0.0 };
        debug_assert!(
            !n_geom.is_finite()
                || n_geom.length_squared() == 0.0
                || a.n.dot(n_geom).abs() > 0.9 * n_geom.length(),
            "pdf_area: n_geom {n_geom} is not the light triangle's normal {}",
            a.n
        );
        self.selection.pmf(i) * a.pdf(p, hit_point)
    }

    /// Picks a light in proportion to power with `u_select` and samples a ray leaving it
    /// ([`emission`]); the sample's `pmf` is the selection probability.
    #[inline]
    pub fn sample_le(&self, u_select: f32, u_pos: Vec2, u_dir: Vec2) -> Option<LeSample> {
        let (i, pmf) = self.selection.sample(u_select);
        if !(pmf > 0.0) {
            return None;
        }
        let s = self.sample_le_of(i, u_pos, u_dir)?;
        Some(LeSample { pmf, ..s })
    }

    /// A ray leaving light `i` (`pmf` 1: no selection).
    #[inline]
    pub fn sample_le_of(&self, i: usize, u_pos: Vec2, u_dir: Vec2) -> Option<LeSample> {
        let (c, r) = (self.scene_center, self.scene_radius);
        match self.lights.get(i)? {
            LightKind::Area(a) => a.sample_le(u_pos, u_dir),
            LightKind::Point(l) => l.sample_le(u_dir),
            LightKind::Spot(l) => l.sample_le(u_dir),
            LightKind::Directional(l) => l.sample_le(u_pos, c, r),
            LightKind::Environment => self.environment.as_ref()?.sample_le(u_pos, u_dir, c, r),
        }
    }

    /// The kind of light `i`.
    pub fn emitter_kind(&self, i: usize) -> Option<EmitterKind> {
        Some(match self.lights.get(i)? {
            LightKind::Area(_) => EmitterKind::Area,
            LightKind::Point(_) => EmitterKind::Point,
            LightKind::Spot(_) => EmitterKind::Spot,
            LightKind::Directional(_) => EmitterKind::Directional,
            LightKind::Environment => EmitterKind::Environment,
        })
    }

    /// Light `i` when it is a point light.
    pub fn point_light(&self, i: usize) -> Option<&PointLight> {
        match self.lights.get(i) {
            Some(LightKind::Point(l)) => Some(l),
            _ => None,
        }
    }

    /// Light `i` when it is a spot light.
    pub fn spot_light(&self, i: usize) -> Option<&SpotLight> {
        match self.lights.get(i) {
            Some(LightKind::Spot(l)) => Some(l),
            _ => None,
        }
    }

    /// Light `i` when it is a directional light.
    pub fn directional_light(&self, i: usize) -> Option<&DirectionalLight> {
        match self.lights.get(i) {
            Some(LightKind::Directional(l)) => Some(l),
            _ => None,
        }
    }

    /// The scene's environment light, if any.
    pub fn environment(&self) -> Option<&EnvironmentLight> {
        self.environment.as_ref()
    }

    /// Centre of the scene's bounding sphere (see [`Self::scene_radius`]).
    pub fn scene_center(&self) -> Vec3 {
        self.scene_center
    }

    /// Environment radiance arriving from `dir` (zero without an environment).
    #[inline]
    pub fn environment_radiance(&self, dir: Vec3) -> Rgb {
        match &self.environment {
            Some(e) => e.radiance(dir),
            None => Rgb::ZERO,
        }
    }

    /// Solid-angle density (incl. selection) of sampling the environment direction `dir`.
    #[inline]
    pub fn pdf_environment(&self, dir: Vec3) -> f32 {
        match &self.environment {
            Some(e) => self.selection.pmf(self.env_index as usize) * e.pdf(dir),
            None => 0.0,
        }
    }
}

/// Delta lights need a finite position.
fn position_ok(l: &Light) -> bool {
    match l {
        Light::Point { position, .. } | Light::Spot { position, .. } => position.is_finite(),
        _ => true,
    }
}

#[cfg(test)]
mod tests;
