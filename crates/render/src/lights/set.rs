//! [`LightSet`]: the lights of a scene, their power-proportional sampler and the lookup
//! from an emissive triangle to its light (two array reads: per-instance offset +
//! per-triangle table, no hashing).
//!
//! Order of the lights: the area lights of every instance (instance order, then triangle
//! order), then the scene's explicit lights, the environment last. Moving instances
//! ([`LightSet::update_instances`]) re-derives the area lights of those instances in place
//! and the explicit lights (few, and the ones an animation moves), then re-weights the
//! selection: the result equals a set built from the moved scene, bit for bit.

use super::{
    AreaLight, DirectionalLight, EmitterKind, EnvironmentLight, LeSample, Light, LightSample,
    LightSampleContext, PointLight, PowerLightSampler, SpotLight,
};
use filtrace_core::{Aabb, Rgb, Vec2, Vec3};
use filtrace_scene::{Environment, Instance, Light as SceneLight, Mesh, Scene};

const NONE: u32 = u32::MAX;

/// All lights of a scene with a power-proportional light sampler (see the module docs).
#[derive(Clone, Debug, Default)]
pub struct LightSet {
    lights: Vec<Light>,
    /// Per light its power (the sampler's weights).
    powers: Vec<f32>,
    sampler: PowerLightSampler,
    /// The first `area_count` lights are the instances' area lights.
    area_count: usize,
    /// Per instance: start of its triangles in `tri_light`, or `NONE` if it has no emitter.
    instance_offset: Vec<u32>,
    /// Light index of each triangle of the instances with emitters (`NONE` if not emissive).
    tri_light: Vec<u32>,
    /// Per instance its world bounds (`None` for a mesh id out of range): the scene radius.
    instance_bounds: Vec<Option<Aabb>>,
    /// Index of the environment in `lights`, or `NONE`.
    env_index: u32,
    scene_radius: f32,
    /// Centre of the scene's bounding sphere (origin of distant lights' emission disks).
    scene_center: Vec3,
    /// Emitters dropped among the triangles and among the explicit lights.
    skipped_area: usize,
    skipped_explicit: usize,
}

impl LightSet {
    /// Gathers the emitters of `scene` (see the module docs). Malformed references (a
    /// mesh or material id out of range) are skipped, never a panic.
    pub fn build(scene: &Scene) -> LightSet {
        let mut set = LightSet { env_index: NONE, ..Default::default() };
        set.instance_bounds = scene.instances.iter().map(|i| instance_bounds(scene, i)).collect();
        (set.scene_center, set.scene_radius) = set.bounding_sphere();

        // Emissive triangles, world space.
        set.instance_offset = vec![NONE; scene.instances.len()];
        for (ii, inst) in scene.instances.iter().enumerate() {
            let Some(mesh) = scene.meshes.get(inst.mesh as usize) else { continue };
            let emissive = |p: usize| emission_of(scene, inst, mesh, p).is_some();
            if !(0..mesh.indices.len()).any(emissive) {
                continue;
            }
            let offset = set.tri_light.len();
            set.instance_offset[ii] = offset as u32;
            set.tri_light.resize(offset + mesh.indices.len(), NONE);
            for prim in 0..mesh.indices.len() {
                if !emissive(prim) {
                    continue;
                }
                match area_light(scene, inst, mesh, prim) {
                    Some(a) => {
                        set.tri_light[offset + prim] = set.lights.len() as u32;
                        set.push(Light::Area(a));
                    }
                    None => set.skipped_area += 1,
                }
            }
        }
        set.area_count = set.lights.len();
        set.add_scene_lights(scene);
        set.sampler = PowerLightSampler::new(&set.powers);
        set
    }

    /// Brings the set up to date after the instances `moved` of `scene` changed their
    /// transforms (the scene is otherwise the one the set was built from): re-derives those
    /// instances' area lights in world space, the scene radius, the explicit lights, and
    /// re-weights the selection. Costs O(triangles of the moved instances + instances +
    /// lights), no pass over the other instances' triangles. The result equals
    /// [`LightSet::build`] of `scene` bit for bit; when it could not (an emitter became
    /// degenerate or came back, the instance or light lists changed length) it is that
    /// build.
    pub fn update_instances(&mut self, scene: &Scene, moved: &[u32]) {
        if !self.try_update(scene, moved) {
            *self = LightSet::build(scene);
        }
    }

    /// [`Self::update_instances`] in place; false when only a rebuild gives the right set.
    fn try_update(&mut self, scene: &Scene, moved: &[u32]) -> bool {
        if scene.instances.len() != self.instance_offset.len() {
            return false;
        }
        for &ii in moved {
            let ii = ii as usize;
            let Some(inst) = scene.instances.get(ii) else { return false };
            self.instance_bounds[ii] = instance_bounds(scene, inst);
            let offset = self.instance_offset[ii];
            if offset == NONE {
                continue;
            }
            let Some(mesh) = scene.meshes.get(inst.mesh as usize) else { return false };
            for prim in 0..mesh.indices.len() {
                let Some(&li) = self.tri_light.get(offset as usize + prim) else { return false };
                let light = emission_of(scene, inst, mesh, prim).and(area_light(scene, inst, mesh, prim));
                match (li, light) {
                    (NONE, None) => {}
                    (NONE, Some(_)) | (_, None) => return false,
                    (li, Some(a)) => {
                        self.powers[li as usize] = a.power();
                        self.lights[li as usize] = Light::Area(a);
                    }
                }
            }
        }
        (self.scene_center, self.scene_radius) = self.bounding_sphere();
        self.lights.truncate(self.area_count);
        self.powers.truncate(self.area_count);
        self.add_scene_lights(scene);
        self.sampler = PowerLightSampler::new(&self.powers);
        true
    }

    fn push(&mut self, light: Light) {
        self.powers.push(light.power(self.scene_radius));
        self.lights.push(light);
    }

    /// Centre and radius of the bounding sphere of the instances (origin and radius 1 for
    /// an empty or degenerate scene).
    fn bounding_sphere(&self) -> (Vec3, f32) {
        let bounds = self.instance_bounds.iter().flatten().fold(Aabb::EMPTY, |a, b| a.union(*b));
        let r = if bounds.is_empty() { 0.0 } else { bounds.bounding_radius() };
        let c = bounds.center();
        let center = if !bounds.is_empty() && c.is_finite() { c } else { Vec3::ZERO };
        (center, if r.is_finite() && r > 0.0 { r } else { 1.0 })
    }

    /// Appends the scene's explicit lights (after the area lights), the environments
    /// combined into one light at the end.
    fn add_scene_lights(&mut self, scene: &Scene) {
        self.env_index = NONE;
        self.skipped_explicit = 0;
        let mut envs: Vec<&Environment> = Vec::new();
        for l in &scene.lights {
            if let SceneLight::Environment(e) = l {
                envs.push(e);
                continue;
            }
            match explicit_light(l) {
                Some(light) if usable(light.power(self.scene_radius)) => self.push(light),
                _ => self.skipped_explicit += 1,
            }
        }
        if !envs.is_empty() {
            let env = Light::Environment(EnvironmentLight::new(&envs));
            if usable(env.power(self.scene_radius)) {
                self.env_index = self.lights.len() as u32;
                self.push(env);
            } else {
                self.skipped_explicit += envs.len();
            }
        }
    }

    /// The light sampler (power-proportional).
    #[inline]
    pub fn sampler(&self) -> &PowerLightSampler {
        &self.sampler
    }

    /// Light `i`.
    #[inline]
    pub fn light(&self, i: usize) -> Option<&Light> {
        self.lights.get(i)
    }

    /// Every light, in the order of the module docs.
    pub fn lights(&self) -> &[Light] {
        &self.lights
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
        self.skipped_area + self.skipped_explicit
    }

    /// Probability of selecting light `i`.
    pub fn selection_pmf(&self, i: usize) -> f32 {
        self.sampler.pmf_of(i)
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
        self.sampler.select(u_select)
    }

    /// Light `i` when it is an area light.
    #[inline]
    pub fn area_light(&self, i: usize) -> Option<&AreaLight> {
        self.lights.get(i)?.as_area()
    }

    /// The environment light, if the scene has one.
    #[inline]
    pub fn environment(&self) -> Option<&EnvironmentLight> {
        match self.lights.get(self.env_index as usize) {
            Some(Light::Environment(e)) => Some(e),
            _ => None,
        }
    }

    /// True when the scene has an environment light.
    #[inline]
    pub fn has_environment(&self) -> bool {
        self.env_index != NONE
    }

    /// Picks a light with `u_select` and samples a direction towards it from `p`; the
    /// density includes the selection probability.
    #[inline]
    pub fn sample_li(&self, p: Vec3, u_select: f32, u: Vec2) -> Option<LightSample> {
        let (i, pmf) = self.sampler.select(u_select);
        if !(pmf > 0.0) {
            return None;
        }
        let s = self.lights.get(i)?.sample_li(&LightSampleContext { p }, u)?;
        Some(LightSample { pdf: pmf * s.pdf, ..s })
    }

    /// Solid-angle density (incl. selection) with which [`Self::sample_li`] from `p`
    /// produces the direction towards `hit_point` on emissive triangle (`instance`,
    /// `prim`). 0 for non-emissive triangles and for the back face of one-sided emitters.
    /// The light's own stored normal decides the face; `n_geom` is accepted for the
    /// interface and only checked in debug builds.
    #[inline]
    pub fn pdf_area(&self, instance: u32, prim: u32, p: Vec3, hit_point: Vec3, n_geom: Vec3) -> f32 {
        let Some(i) = self.area_light_index(instance, prim) else { return 0.0 };
        let Light::Area(a) = &self.lights[i] else { return 0.0 };
        debug_assert!(
            !n_geom.is_finite()
                || n_geom.length_squared() == 0.0
                || a.n.dot(n_geom).abs() > 0.9 * n_geom.length(),
            "pdf_area: n_geom {n_geom} is not the light triangle's normal {}",
            a.n
        );
        self.sampler.pmf_of(i) * a.pdf(p, hit_point)
    }

    /// Picks a light in proportion to power with `u_select` and samples a ray leaving it
    /// ([`super::emission`]); the sample's `pmf` is the selection probability.
    #[inline]
    pub fn sample_le(&self, u_select: f32, u_pos: Vec2, u_dir: Vec2) -> Option<LeSample> {
        let (i, pmf) = self.sampler.select(u_select);
        if !(pmf > 0.0) {
            return None;
        }
        let s = self.sample_le_of(i, u_pos, u_dir)?;
        Some(LeSample { pmf, ..s })
    }

    /// A ray leaving light `i` (`pmf` 1: no selection).
    #[inline]
    pub fn sample_le_of(&self, i: usize, u_pos: Vec2, u_dir: Vec2) -> Option<LeSample> {
        self.lights.get(i)?.sample_le(u_pos, u_dir, self.scene_center, self.scene_radius)
    }

    /// The kind of light `i`.
    pub fn emitter_kind(&self, i: usize) -> Option<EmitterKind> {
        Some(self.lights.get(i)?.kind())
    }

    /// Light `i` when it is a point light.
    pub fn point_light(&self, i: usize) -> Option<&PointLight> {
        match self.lights.get(i) {
            Some(Light::Point(l)) => Some(l),
            _ => None,
        }
    }

    /// Light `i` when it is a spot light.
    pub fn spot_light(&self, i: usize) -> Option<&SpotLight> {
        match self.lights.get(i) {
            Some(Light::Spot(l)) => Some(l),
            _ => None,
        }
    }

    /// Light `i` when it is a directional light.
    pub fn directional_light(&self, i: usize) -> Option<&DirectionalLight> {
        match self.lights.get(i) {
            Some(Light::Directional(l)) => Some(l),
            _ => None,
        }
    }

    /// Centre of the scene's bounding sphere (see [`Self::scene_radius`]).
    pub fn scene_center(&self) -> Vec3 {
        self.scene_center
    }

    /// Environment radiance arriving from `dir` (zero without an environment).
    #[inline]
    pub fn environment_radiance(&self, dir: Vec3) -> Rgb {
        match self.environment() {
            Some(e) => e.radiance(dir),
            None => Rgb::ZERO,
        }
    }

    /// Selection probability of the environment (0 without one).
    #[inline]
    pub fn environment_pmf(&self) -> f32 {
        if self.has_environment() {
            self.sampler.pmf_of(self.env_index as usize)
        } else {
            0.0
        }
    }

    /// Solid-angle density (incl. selection) of sampling the environment direction `dir`.
    #[inline]
    pub fn pdf_environment(&self, dir: Vec3) -> f32 {
        match self.environment() {
            Some(e) => self.sampler.pmf_of(self.env_index as usize) * e.pdf(dir),
            None => 0.0,
        }
    }
}

/// Power that a selectable light needs.
fn usable(power: f32) -> bool {
    power > 0.0 && power.is_finite()
}

/// World bounds of an instance; `None` for a mesh id out of range (`Scene::bounds`
/// indexes meshes unchecked, so it is not used here).
fn instance_bounds(scene: &Scene, inst: &Instance) -> Option<Aabb> {
    scene.meshes.get(inst.mesh as usize).map(|m| m.bounds().transformed(&inst.transform))
}

/// The material emission of triangle `prim` (overrides applied) when it is emissive.
fn emission_of(scene: &Scene, inst: &Instance, mesh: &Mesh, prim: usize) -> Option<(Rgb, bool)> {
    let id = inst.material_override.or_else(|| mesh.material_ids.get(prim).copied())?;
    let m = scene.materials.get(id as usize).filter(|m| m.is_emissive())?;
    Some((m.emission, m.two_sided_emission))
}

/// The area light of emissive triangle `prim` in world space; `None` when it is not
/// emissive, has a vertex index out of range or no usable power.
fn area_light(scene: &Scene, inst: &Instance, mesh: &Mesh, prim: usize) -> Option<AreaLight> {
    let (le, two_sided) = emission_of(scene, inst, mesh, prim)?;
    let idx = mesh.indices.get(prim)?;
    let corner = |k: usize| mesh.positions.get(idx[k] as usize).map(|&p| inst.transform.transform_point3(p));
    let a = AreaLight::new([corner(0)?, corner(1)?, corner(2)?], le, two_sided)?;
    usable(a.power()).then_some(a)
}

/// The light of an explicit scene light (not an environment); `None` when malformed
/// (zero axis or direction, non-finite position).
fn explicit_light(l: &SceneLight) -> Option<Light> {
    match l {
        SceneLight::Point { position, intensity } => position
            .is_finite()
            .then_some(Light::Point(PointLight { position: *position, intensity: *intensity })),
        SceneLight::Spot { position, direction, intensity, cos_total_width, cos_falloff_start } => {
            if !position.is_finite() {
                return None;
            }
            SpotLight::new(*position, *direction, *intensity, *cos_total_width, *cos_falloff_start)
                .map(Light::Spot)
        }
        SceneLight::Directional { direction, irradiance } => {
            DirectionalLight::new(*direction, *irradiance).map(Light::Directional)
        }
        SceneLight::Environment(_) => None,
    }
}
