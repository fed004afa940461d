//! The lookup tables of the lockstep tracer, owned by it and built from the scene, its
//! [`SceneGeometry`] and its [`LightSet`]: per material and per instance tables of any
//! length (read by [`lookup`](super::super::lanes::lookup): one `vpermps` per field for up
//! to eight entries, a `vgatherdps` for more), eight-entry tables for scenes with at most
//! eight lights, and the area lights as rows of words (transposed into lanes by
//! [`columns`](super::super::lanes::columns)). Every value is one the scalar code reads,
//! so a lane looks up what the scalar path computes.
//!
//! The material and instance tables depend on the scene's layout only; the light tables
//! on the lights' world-space triangles and the selection: after
//! [`LightSet::update_instances`] call [`LockstepTables::update_lights`].

use crate::lights::{EmitterKind, LightSet};
use crate::surface::{SceneGeometry, TRI_FLOATS};
use filtrace_core::Rgb;
use filtrace_scene::{MaterialId, Scene};

/// [`MaterialTable::flags`] bit: an untextured Lambert BSDF ([`SceneGeometry::
/// constant_diffuse`] is `Some`).
pub(crate) const MAT_DIFFUSE: u32 = 1;
/// Flag: the material emits (`is_emissive()` and a non-zero emission).
pub(crate) const MAT_EMITS: u32 = 2;
/// Flag: the emission is two-sided.
pub(crate) const MAT_TWO_SIDED: u32 = 4;

/// Words per light in [`LockstepTables::area_words`]: `p0`, `e1`, `e2`, `n` (xyz each) at
/// 0..12, the area at 12 and `le` (rgb) at 13..16 (zeros for a light that is not an area
/// light).
pub(crate) const AREA_FLOATS: usize = 16;

/// The materials as tables indexed by material id (entry `m` = material `m`; zeros up to
/// eight entries, so that up to eight materials take the `vpermps` lookup): flags
/// ([`MAT_DIFFUSE`], [`MAT_EMITS`], [`MAT_TWO_SIDED`]) and the reflectance of the
/// untextured Lambert ones (zero for the others). Only built when every triangle's
/// material is in range.
#[derive(Clone, Debug, Default)]
pub(crate) struct MaterialTable {
    pub(crate) flags: Vec<u32>,
    pub(crate) rho: [Vec<f32>; 3],
}

/// The selection table and the area lights of a scene with one to eight lights as
/// eight-entry tables, one per field (lane `k` = light or cell `k`). The values are those
/// `AliasTable::sample` and [`LightSet::area_light`] read.
#[derive(Clone, Debug, Default)]
pub(crate) struct SmallLights {
    /// Number of cells (= lights).
    pub(crate) n: u32,
    /// Per cell: `q`, `alias` (0 for a single cell: `sample` returns cell 0), `pmf`.
    pub(crate) q: [f32; 8],
    pub(crate) alias: [u32; 8],
    pub(crate) pmf: [f32; 8],
    /// Per light: `u32::MAX` for an area light, else 0; the same for two-sided ones, for
    /// directional lights and for the environment.
    pub(crate) is_area: [u32; 8],
    pub(crate) two_sided: [u32; 8],
    pub(crate) is_directional: [u32; 8],
    pub(crate) is_environment: [u32; 8],
    /// Some light is directional / the environment (else `choose_small` skips the lookups
    /// of `is_directional` / `is_environment`).
    pub(crate) has_directional: bool,
    pub(crate) has_environment: bool,
    /// Per directional light its unit direction towards the light and its irradiance
    /// (xyz / rgb rows; zero for the other lights).
    pub(crate) to_light: [[f32; 8]; 3],
    pub(crate) irradiance: [[f32; 8]; 3],
    /// Per field of the area words (`AREA_FLOATS` of them): its value per light.
    pub(crate) field: [[f32; 8]; AREA_FLOATS],
}

/// Per instance (entry `i` = instance `i`; zeros up to eight entries): the row of its
/// first triangle in [`SceneGeometry::tri_words`] (triangle `prim` is row `first[i] +
/// prim`, as [`SceneGeometry::row`] gives it) and `u32::MAX` when its mesh has vertex
/// normals or uvs, else 0.
#[derive(Clone, Debug, Default)]
pub(crate) struct InstanceRows {
    pub(crate) first: Vec<u32>,
    pub(crate) attributes: Vec<u32>,
}

/// Everything the lockstep tracer looks up in tables (see the module docs).
#[derive(Clone, Debug, Default)]
pub struct LockstepTables {
    materials: Option<MaterialTable>,
    instance_rows: InstanceRows,
    /// Per light [`AREA_FLOATS`] words: the values of [`LightSet::area_light`].
    area_words: Vec<f32>,
    small_lights: Option<Box<SmallLights>>,
}

impl LockstepTables {
    /// The tables of `scene` with its geometry and lights.
    pub fn new(scene: &Scene, geometry: &SceneGeometry, lights: &LightSet) -> Self {
        let mut t = LockstepTables {
            materials: material_table(scene, geometry),
            instance_rows: instance_rows(scene, geometry),
            ..Default::default()
        };
        t.update_lights(lights);
        t
    }

    /// Rebuilds the light tables from `lights` (after [`LightSet::update_instances`]):
    /// O(lights), no scene traversal.
    pub fn update_lights(&mut self, lights: &LightSet) {
        self.area_words.clear();
        self.area_words.reserve(lights.len() * AREA_FLOATS);
        for i in 0..lights.len() {
            match lights.area_light(i) {
                Some(a) => {
                    for v in [a.p0, a.e1, a.e2, a.n] {
                        self.area_words.extend_from_slice(&[v.x, v.y, v.z]);
                    }
                    self.area_words.push(a.area);
                    self.area_words.extend_from_slice(&[a.le.x, a.le.y, a.le.z]);
                }
                None => self.area_words.extend_from_slice(&[0.0; AREA_FLOATS]),
            }
        }
        self.small_lights = small_lights(lights, &self.area_words).map(Box::new);
    }

    /// The [`MaterialTable`] (`None` when a triangle's material is out of range).
    #[inline]
    pub(crate) fn materials(&self) -> Option<&MaterialTable> {
        self.materials.as_ref()
    }

    /// The [`InstanceRows`].
    #[inline]
    pub(crate) fn instance_rows(&self) -> &InstanceRows {
        &self.instance_rows
    }

    /// The area lights as rows of [`AREA_FLOATS`] words (row `i` = light `i`).
    #[inline]
    pub(crate) fn area_words(&self) -> &[f32] {
        &self.area_words
    }

    /// [`SmallLights`] of scenes with one to eight lights.
    #[inline]
    pub(crate) fn small_lights(&self) -> Option<&SmallLights> {
        self.small_lights.as_deref()
    }
}

/// Entries per table: at least eight (the `vpermps` lookup reads eight words).
fn table_len(n: usize) -> usize {
    n.max(8)
}

fn instance_rows(scene: &Scene, geometry: &SceneGeometry) -> InstanceRows {
    let n = scene.instances.len();
    let mut t = InstanceRows { first: vec![0; table_len(n)], attributes: vec![0; table_len(n)] };
    for i in 0..n {
        let (row, attributes) = geometry.row(i as u32, 0);
        t.first[i] = row as u32;
        t.attributes[i] = if attributes { u32::MAX } else { 0 };
    }
    t
}

fn material_table(scene: &Scene, geometry: &SceneGeometry) -> Option<MaterialTable> {
    let n = scene.materials.len();
    let in_range = |row: &[f32]| (row[TRI_FLOATS - 1].to_bits() as usize) < n;
    if n == 0 || !geometry.tri_words().chunks_exact(TRI_FLOATS).all(in_range) {
        return None;
    }
    let len = table_len(n);
    let mut t = MaterialTable { flags: vec![0; len], rho: [vec![0.0; len], vec![0.0; len], vec![0.0; len]] };
    for (i, m) in scene.materials.iter().enumerate() {
        let rho = geometry.constant_diffuse(i as MaterialId);
        let emits = m.is_emissive() && m.emission != Rgb::ZERO;
        t.flags[i] = if rho.is_some() { MAT_DIFFUSE } else { 0 }
            | if emits { MAT_EMITS } else { 0 }
            | if m.two_sided_emission { MAT_TWO_SIDED } else { 0 };
        let r = rho.unwrap_or(Rgb::ZERO);
        (t.rho[0][i], t.rho[1][i], t.rho[2][i]) = (r.x, r.y, r.z);
    }
    Some(t)
}

fn small_lights(lights: &LightSet, area_words: &[f32]) -> Option<SmallLights> {
    let table = lights.sampler().table();
    let n = table.count();
    if !(1..=8).contains(&n) || lights.len() != n {
        return None;
    }
    let mut t = SmallLights { n: n as u32, ..Default::default() };
    for i in 0..n {
        let (q, alias) = table.bin(i)?;
        if alias as usize >= n {
            return None;
        }
        t.q[i] = q;
        t.alias[i] = if n == 1 { 0 } else { alias };
        t.pmf[i] = table.pmf(i);
        if let Some(a) = lights.area_light(i) {
            t.is_area[i] = u32::MAX;
            t.two_sided[i] = if a.two_sided { u32::MAX } else { 0 };
        }
        if let Some(d) = lights.directional_light(i) {
            t.is_directional[i] = u32::MAX;
            t.has_directional = true;
            for c in 0..3 {
                (t.to_light[c][i], t.irradiance[c][i]) = (d.to_light[c], d.irradiance[c]);
            }
        }
        if lights.emitter_kind(i) == Some(EmitterKind::Environment) {
            t.is_environment[i] = u32::MAX;
            t.has_environment = true;
        }
        for (f, w) in t.field.iter_mut().zip(&area_words[i * AREA_FLOATS..(i + 1) * AREA_FLOATS]) {
            f[i] = *w;
        }
    }
    Some(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use filtrace_core::{Affine3A, Vec3};

    /// After moving an instance, `LightSet::update_instances` + `update_lights` give the
    /// tables a build from the moved scene gives (the Cornell box: at most eight lights, so
    /// `SmallLights` too; its light moved).
    #[test]
    fn updated_light_tables_equal_rebuilt_ones() {
        let mut scene = filtrace_scene::builtin("cornell").unwrap();
        let geometry = SceneGeometry::new(&scene);
        let mut lights = LightSet::build(&scene);
        let mut tables = LockstepTables::new(&scene, &geometry, &lights);
        assert!(tables.small_lights().is_some() && tables.materials().is_some());
        let light = (0..scene.instances.len() as u32)
            .find(|&i| lights.area_light_index(i, 0).is_some() || lights.area_light_index(i, 1).is_some())
            .expect("the Cornell box has an emissive instance");
        scene.instances[light as usize].transform = Affine3A::from_translation(Vec3::new(30.0, -20.0, 10.0))
            * scene.instances[light as usize].transform;
        lights.update_instances(&scene, &[light]);
        tables.update_lights(&lights);
        let rebuilt = LockstepTables::new(&scene, &SceneGeometry::new(&scene), &LightSet::build(&scene));
        assert_eq!(format!("{tables:?}"), format!("{rebuilt:?}"));
    }
}
