//! Entry points: load a scene file by extension, or a built-in scene by name.

use std::path::Path;

use filtrace_core::{Aabb, Vec3};

use crate::builtin::{builtin_names, try_builtin};
use crate::error::SceneError;
use crate::types::{Camera, Scene};

/// Choices a caller makes about what loading adds to a scene.
#[derive(Clone, Debug)]
pub struct LoadOptions {
    /// Light a bare mesh file (OBJ, PLY, glTF) that brings no light of its own by
    /// [`crate::default_light::default_lights`] (with a warning saying so). On by default;
    /// `render --no-default-light` turns it off.
    pub default_light: bool,
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions { default_light: true }
    }
}

/// Loads a scene file, choosing the loader from the extension (case-insensitive):
/// `.obj`, `.gltf`/`.glb`, `.ply`, `.toml`. The result has passed
/// [`crate::validate::sanitize`]: nothing non-finite, every index in range; exact duplicate
/// triangles are dropped ([`crate::dedup`]); a scene without light or geometry is lit by
/// default, warned about or refused ([`crate::default_light`]).
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    load_with(path, &LoadOptions::default())
}

/// [`load`] with explicit options.
pub fn load_with(path: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    let mut scene = load_part(path)?;
    let bare_mesh = !extension(path).eq("toml");
    crate::default_light::check_light_and_geometry(&mut scene, path, bare_mesh, options.default_light)?;
    for w in &mut scene.stats.warnings {
        *w = crate::error::escape_control(w);
    }
    Ok(scene)
}

use crate::mesh_file::extension;

/// Loads, sanitizes and de-duplicates one file, without the scene-level checks of
/// [`load_with`].
fn load_part(path: &Path) -> Result<Scene, SceneError> {
    if extension(path) != "toml" {
        return crate::mesh_file::load_mesh_file(path);
    }
    let mut scene = crate::toml_scene::load_toml(path)?;
    crate::mesh_file::sanitize_part(&mut scene, path)?;
    Ok(scene)
}

/// A built-in scene name (see [`builtin_names`]) or a path to a scene file.
pub fn load_scene(arg: &str) -> Result<Scene, SceneError> {
    load_scene_with(arg, &LoadOptions::default())
}

/// [`load_scene`] with explicit options (built-in scenes bring their own lights).
pub fn load_scene_with(arg: &str, options: &LoadOptions) -> Result<Scene, SceneError> {
    if let Some(r) = try_builtin(arg) {
        return r;
    }
    let path = Path::new(arg);
    if path.extension().is_none() && !path.exists() {
        return Err(SceneError::Unsupported {
            what: format!("'{arg}' is neither a built-in scene ({}) nor a file", builtin_names().join(", ")),
        });
    }
    load_with(path, options)
}

/// A camera that sees all of `bounds` from outside: it looks at the centre of the bounding
/// sphere along -z, from slightly above (direction (0, 0.25, 1) from the centre), at a distance
/// where the sphere fits the vertical field of view of 45 degrees with a 10 % margin, up +y.
/// An empty or non-finite box gives a camera at (0, 0, 5) looking at the origin.
pub fn default_camera_for(bounds: Aabb) -> Camera {
    const VFOV_DEG: f32 = 45.0;
    if bounds.is_empty() || !bounds.min.is_finite() || !bounds.max.is_finite() {
        return Camera { eye: Vec3::new(0.0, 0.0, 5.0), target: Vec3::ZERO, up: Vec3::Y, vfov_deg: VFOV_DEG };
    }
    let center = bounds.center();
    let radius = bounds.bounding_radius().max(1e-3);
    let distance = 1.1 * radius / (0.5 * VFOV_DEG.to_radians()).sin();
    let dir = Vec3::new(0.0, 0.25, 1.0).normalize();
    Camera { eye: center + distance * dir, target: center, up: Vec3::Y, vfov_deg: VFOV_DEG }
}
