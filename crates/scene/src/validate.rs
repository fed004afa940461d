//! The last step of every loader: make sure nothing non-finite or out of range leaves the
//! loader, so that no NaN spreads silently into the renderer.
//!
//! Repairs what has an obvious repair (each with a warning): non-finite texture coordinates
//! become (0, 0); a mesh with a non-finite or zero shading normal falls back to flat shading;
//! non-finite vertices that no triangle uses are removed. Refuses (with an error naming the
//! file) what has none: non-finite material parameters, lights or transforms, indices out of
//! range.

use std::path::Path;

use filtrace_core::{Rgb, Vec2, Vec3};

use crate::error::SceneError;
use crate::types::{Bsdf, Environment, Light, Mesh, Scene, Texturable};

/// Checks and repairs `scene` loaded from `path` (see the module docs).
pub fn sanitize(scene: &mut Scene, path: &Path) -> Result<(), SceneError> {
    let invalid = |m: String| SceneError::Invalid { message: format!("{}: {m}", path.display()) };
    let mut warnings = Vec::new();
    let materials = scene.materials.len();
    for mesh in &mut scene.meshes {
        sanitize_mesh(mesh, materials, &mut warnings).map_err(invalid)?;
    }
    check_instances(scene).map_err(invalid)?;
    check_materials(scene, &mut warnings).map_err(invalid)?;
    for t in &mut scene.textures {
        if t.texels.iter().any(|c| !colour_ok(*c)) {
            warnings.push(format!("texture '{}': non-finite texels set to 0", t.name));
            t.texels.iter_mut().filter(|c| !colour_ok(**c)).for_each(|c| *c = Rgb::ZERO);
        }
    }
    for l in &scene.lights {
        if !light_ok(l) {
            return Err(invalid(format!("light {l:?} has a non-finite or negative parameter")));
        }
    }
    if let Some(c) = &scene.camera {
        if !(c.eye.is_finite() && c.target.is_finite() && c.up.is_finite() && c.vfov_deg.is_finite()) {
            return Err(invalid("camera is not finite".into()));
        }
    }
    scene.stats.warnings.extend(warnings);
    Ok(())
}

/// A colour a material or light may hold: finite and non-negative.
fn colour_ok(c: Rgb) -> bool {
    c.is_finite() && c.min_element() >= 0.0
}

/// Refuses a mesh whose indices or material ids are out of range (`materials` materials),
/// or whose triangles use a non-finite vertex; repairs its normals, uvs and unused
/// vertices, with a warning each.
fn sanitize_mesh(mesh: &mut Mesh, materials: usize, warnings: &mut Vec<String>) -> Result<(), String> {
    let n = mesh.positions.len() as u32;
    if mesh.indices.len() != mesh.material_ids.len() {
        return Err(format!("mesh '{}': one material id per triangle expected", mesh.name));
    }
    if mesh.indices.iter().flatten().any(|&i| i >= n) {
        return Err(format!("mesh '{}': vertex index out of range", mesh.name));
    }
    if let Some(&m) = mesh.material_ids.iter().find(|&&m| m as usize >= materials) {
        return Err(format!("mesh '{}': material id {m} out of range", mesh.name));
    }
    if !mesh.normals.is_empty()
        && (mesh.normals.len() != mesh.positions.len()
            || mesh.normals.iter().any(|v| !v.is_finite() || *v == Vec3::ZERO))
    {
        warnings.push(format!("mesh '{}': invalid shading normals, using flat shading", mesh.name));
        mesh.normals.clear();
    }
    if !mesh.uvs.is_empty() && mesh.uvs.len() != mesh.positions.len() {
        warnings.push(format!("mesh '{}': uv count differs from vertex count, uvs dropped", mesh.name));
        mesh.uvs.clear();
    }
    if mesh.uvs.iter().any(|t| !t.is_finite()) {
        warnings.push(format!("mesh '{}': non-finite texture coordinates set to (0, 0)", mesh.name));
        mesh.uvs.iter_mut().filter(|t| !t.is_finite()).for_each(|t| *t = Vec2::ZERO);
    }
    if mesh.positions.iter().any(|p| !p.is_finite()) {
        remove_unreferenced(mesh);
        if mesh.positions.iter().any(|p| !p.is_finite()) {
            return Err(format!("mesh '{}': a triangle uses a non-finite vertex", mesh.name));
        }
    }
    Ok(())
}

/// Every instance names an existing mesh (and override material) with a finite transform.
fn check_instances(scene: &Scene) -> Result<(), String> {
    for i in &scene.instances {
        if i.mesh as usize >= scene.meshes.len() || !i.transform.is_finite() {
            return Err("instance with a bad mesh id or a non-finite transform".into());
        }
        if i.material_override.is_some_and(|m| m as usize >= scene.materials.len()) {
            return Err("instance material override out of range".into());
        }
    }
    Ok(())
}

/// Every material parameter finite and in range (textures existing); a constant albedo
/// above 1 is allowed with a warning.
fn check_materials(scene: &Scene, warnings: &mut Vec<String>) -> Result<(), String> {
    let tex_ok = |t: &Texturable| match t {
        Texturable::Constant(c) => colour_ok(*c),
        Texturable::Texture { texture, factor } => {
            (*texture as usize) < scene.textures.len() && colour_ok(*factor)
        }
    };
    for m in &scene.materials {
        let ok = colour_ok(m.emission)
            && match &m.bsdf {
                Bsdf::Diffuse { reflectance } => tex_ok(reflectance),
                Bsdf::Conductor { eta, k, roughness } => {
                    colour_ok(*eta) && colour_ok(*k) && (0.0..=1.0).contains(roughness)
                }
                Bsdf::Plastic { diffuse, roughness, ior } => {
                    tex_ok(diffuse) && (0.0..=1.0).contains(roughness) && ior.is_finite() && *ior > 0.0
                }
            };
        if !ok {
            return Err(format!("material '{}' has a non-finite or out-of-range parameter", m.name));
        }
        if let Bsdf::Diffuse { reflectance: Texturable::Constant(c) }
        | Bsdf::Plastic { diffuse: Texturable::Constant(c), .. } = &m.bsdf
        {
            if c.max_element() > 1.0 {
                warnings.push(format!(
                    "material '{}': albedo {} above 1 reflects more light than it receives",
                    m.name,
                    c.max_element()
                ));
            }
        }
    }
    Ok(())
}

/// A light's positions and directions finite (directions non-zero), its colours finite
/// and non-negative.
fn light_ok(l: &Light) -> bool {
    match l {
        Light::Point { position, intensity } => position.is_finite() && colour_ok(*intensity),
        Light::Spot { position, direction, intensity, cos_total_width, cos_falloff_start } => {
            position.is_finite()
                && direction.is_finite()
                && *direction != Vec3::ZERO
                && colour_ok(*intensity)
                && cos_total_width.is_finite()
                && cos_falloff_start.is_finite()
        }
        Light::Directional { direction, irradiance } => {
            direction.is_finite() && *direction != Vec3::ZERO && colour_ok(*irradiance)
        }
        Light::Environment(Environment::Constant { radiance }) => colour_ok(*radiance),
        Light::Environment(Environment::Sky { zenith, horizon, ground }) => {
            colour_ok(*zenith) && colour_ok(*horizon) && colour_ok(*ground)
        }
    }
}

/// Drops vertices that no triangle uses, renumbering the triangles.
fn remove_unreferenced(mesh: &mut Mesh) {
    let mut remap = vec![u32::MAX; mesh.positions.len()];
    let mut keep = Vec::new();
    for t in &mut mesh.indices {
        for i in t.iter_mut() {
            if remap[*i as usize] == u32::MAX {
                remap[*i as usize] = keep.len() as u32;
                keep.push(*i as usize);
            }
            *i = remap[*i as usize];
        }
    }
    mesh.positions = keep.iter().map(|&i| mesh.positions[i]).collect();
    if !mesh.normals.is_empty() {
        mesh.normals = keep.iter().map(|&i| mesh.normals[i]).collect();
    }
    if !mesh.uvs.is_empty() {
        mesh.uvs = keep.iter().map(|&i| mesh.uvs[i]).collect();
    }
}
