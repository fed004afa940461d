//! One scene file loaded on its own: the mesh formats by extension, then sanitized and
//! de-duplicated. [`crate::load`] adds the scene-level checks on top; a TOML scene uses it
//! for the mesh files it places.

use std::path::Path;

use crate::error::SceneError;
use crate::types::Scene;

/// The file's extension in lower case ("" when it has none).
pub(crate) fn extension(path: &Path) -> String {
    path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default()
}

/// Loads an OBJ, PLY or glTF file, sanitized and de-duplicated ([`sanitize_part`]); any
/// other extension is an error naming the ones accepted (TOML scenes are loaded by
/// [`crate::load`]).
pub(crate) fn load_mesh_file(path: &Path) -> Result<Scene, SceneError> {
    let ext = extension(path);
    let mut scene = match ext.as_str() {
        "obj" => crate::obj::load_obj(path),
        "ply" => crate::ply::load_ply(path),
        "gltf" | "glb" => crate::gltf_load::load_gltf(path),
        _ => Err(SceneError::Unsupported {
            what: format!(
                "{}: unknown scene file extension '{ext}' (expected obj, gltf, glb, ply or toml)",
                path.display()
            ),
        }),
    }?;
    sanitize_part(&mut scene, path)?;
    Ok(scene)
}

/// What every loaded file goes through: [`crate::validate::sanitize`] (nothing
/// non-finite, every index in range), then exact duplicate triangles dropped
/// ([`crate::dedup`]).
pub(crate) fn sanitize_part(scene: &mut Scene, path: &Path) -> Result<(), SceneError> {
    crate::validate::sanitize(scene, path)?;
    crate::dedup::remove_duplicate_triangles(scene, path);
    Ok(())
}
