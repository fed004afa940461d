//! A scene that would render black must not pass silently.
//!
//! - No triangles: a mesh file is refused; a TOML scene is refused unless an environment
//!   light makes the background visible (then a warning).
//! - No light (no light source of non-zero power and no emissive material that any
//!   instance uses): a bare mesh file (OBJ, PLY, glTF) is lit by [`default_lights`], as mesh
//!   viewers do, with a warning saying so; with [`crate::LoadOptions::default_light`] off, and for
//!   TOML scenes (written on purpose), a warning that the image will be black.

use std::path::Path;

use filtrace_core::{Rgb, Vec3};

use crate::error::SceneError;
use crate::types::{Environment, Light, Scene};

/// The light a bare mesh file gets: a neutral sky (zenith 1, horizon 0.8, ground 0.3) and
/// a sun of irradiance 2 from the upper right, in front (direction towards it
/// (0.5, 1, 0.8), normalised), so that shapes read under the default camera (which looks
/// along -z from +z, y up). A grey (0.5) surface facing the sun comes out at roughly 0.7.
pub fn default_lights() -> Vec<Light> {
    vec![
        Light::Environment(Environment::Sky {
            zenith: Rgb::splat(1.0),
            horizon: Rgb::splat(0.8),
            ground: Rgb::splat(0.3),
        }),
        Light::Directional { direction: Vec3::new(0.5, 1.0, 0.8).normalize(), irradiance: Rgb::splat(2.0) },
    ]
}

/// Whether anything in `scene` emits light.
pub fn has_light(scene: &Scene) -> bool {
    let positive = |c: &Rgb| c.max_element() > 0.0;
    let light_emits = |l: &Light| match l {
        Light::Point { intensity, .. } | Light::Spot { intensity, .. } => positive(intensity),
        Light::Directional { irradiance, .. } => positive(irradiance),
        Light::Environment(Environment::Constant { radiance }) => positive(radiance),
        Light::Environment(Environment::Sky { zenith, horizon, ground }) => {
            positive(zenith) || positive(horizon) || positive(ground)
        }
    };
    if scene.lights.iter().any(light_emits) {
        return true;
    }
    let emissive = |m: u32| scene.materials.get(m as usize).is_some_and(|m| m.is_emissive());
    let mut mesh_seen = vec![false; scene.meshes.len()];
    for inst in &scene.instances {
        let mesh = &scene.meshes[inst.mesh as usize];
        if mesh.indices.is_empty() {
            continue;
        }
        if let Some(m) = inst.material_override {
            if emissive(m) {
                return true;
            }
        } else if !std::mem::replace(&mut mesh_seen[inst.mesh as usize], true)
            && mesh.material_ids.iter().any(|&m| emissive(m))
        {
            return true;
        }
    }
    false
}

/// Applies the rules of the module docs to `scene`, loaded from `path`; `default_light`:
/// [`crate::LoadOptions::default_light`].
pub(crate) fn check_light_and_geometry(
    scene: &mut Scene,
    path: &Path,
    bare_mesh: bool,
    default_light: bool,
) -> Result<(), SceneError> {
    let has_env = scene.lights.iter().any(|l| matches!(l, Light::Environment(_)));
    if scene.triangle_count() == 0 {
        if bare_mesh || !has_env {
            return Err(SceneError::Invalid {
                message: format!("{}: no triangles: nothing to render", path.display()),
            });
        }
        scene
            .stats
            .warnings
            .push(format!("{}: no triangles: the image shows only the environment light", path.display()));
    }
    if has_light(scene) {
        return Ok(());
    }
    if bare_mesh && default_light {
        scene.lights.extend(default_lights());
        scene.stats.warnings.push(format!(
            "{}: no lights in the file: lit by the default sky and sun (render --no-default-light turns this off)",
            path.display()
        ));
    } else {
        scene.stats.warnings.push(format!(
            "{}: the scene has no lights (no light source, no emissive material in use): the image will be black",
            path.display()
        ));
    }
    Ok(())
}
