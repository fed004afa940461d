//! The scene as the renderer sees it, written for the peer scripts (a debug dump, not an
//! export format): `scene.json` with the camera the renderer uses, materials, lights and
//! shapes, and one binary little-endian PLY per (mesh, material) pair in object space, with
//! the world transforms of its instances (so Mitsuba can instance it as we do, and Embree
//! gets the same world-space triangles).
//!
//! Textures are raw little-endian `f32` RGB, rows top first (`texture_K.f32`). PLY `v` is
//! written as `1 - v`: Mitsuba's bitmaps, like its OBJ loader, put `v = 0` at the top row.

use anyhow::Context;
use filtrace_core::{Affine3A, Mat4, Rgb, Vec3};
use filtrace_render::PinholeCamera;
use filtrace_scene::{Bsdf, Environment, Light, Material, Mesh, Scene, Texturable};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Writes `scene` to `dir` (created); returns the path of `scene.json`.
pub fn dump_scene(scene: &Scene, dir: &Path) -> anyhow::Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut shapes = Vec::new();
    for ((mesh, material, whole), transforms) in shape_groups(scene) {
        let file = format!("mesh{mesh}_mat{material}.ply");
        let m = &scene.meshes[mesh as usize];
        let tris: Vec<[u32; 3]> = (0..m.indices.len())
            .filter(|&i| whole || m.material_ids[i] == material)
            .map(|i| m.indices[i])
            .collect();
        let path = dir.join(&file);
        write_ply(&path, m, &tris).with_context(|| format!("cannot write {}", path.display()))?;
        shapes.push(json!({
            "file": file, "mesh": mesh, "material": material, "triangles": tris.len(),
            "normals": has_normals(m), "uvs": m.uvs.len() == m.positions.len() && !m.uvs.is_empty(),
            "instances": transforms.iter().map(row_major).collect::<Vec<_>>(),
        }));
    }
    let mut textures = Vec::new();
    for (k, t) in scene.textures.iter().enumerate() {
        let file = format!("texture_{k}.f32");
        let bytes: Vec<u8> = t.texels.iter().flat_map(|c| c.to_array()).flat_map(f32::to_le_bytes).collect();
        std::fs::write(dir.join(&file), bytes).with_context(|| format!("cannot write {file}"))?;
        textures.push(json!({"file": file, "width": t.width, "height": t.height}));
    }
    let bounds = scene.bounds();
    let cam = scene.camera.clone().unwrap_or_else(|| PinholeCamera::framing(&bounds));
    let doc = json!({
        "name": scene.name,
        "triangles": scene.triangle_count(),
        "bounds": [v3(bounds.min), v3(bounds.max)],
        "camera": {"eye": v3(cam.eye), "target": v3(cam.target), "up": v3(cam.up), "vfov_deg": cam.vfov_deg},
        "materials": scene.materials.iter().map(material).collect::<Vec<_>>(),
        "textures": textures,
        "lights": scene.lights.iter().map(light).collect::<Vec<_>>(),
        "shapes": shapes,
    });
    let path = dir.join("scene.json");
    std::fs::write(&path, serde_json::to_string_pretty(&doc)?)
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

/// Instance transforms per `(mesh, material, whole mesh)`: an instance with a material
/// override places the whole mesh under that material, otherwise each material's triangles.
type ShapeKey = (u32, u32, bool);

fn shape_groups(scene: &Scene) -> BTreeMap<ShapeKey, Vec<Affine3A>> {
    let mut groups: BTreeMap<ShapeKey, Vec<Affine3A>> = BTreeMap::new();
    for inst in &scene.instances {
        let mesh = &scene.meshes[inst.mesh as usize];
        if mesh.indices.is_empty() {
            continue;
        }
        if let Some(m) = inst.material_override {
            groups.entry((inst.mesh, m, true)).or_default().push(inst.transform);
            continue;
        }
        let mut used: Vec<u32> = mesh.material_ids.clone();
        used.sort_unstable();
        used.dedup();
        for m in used {
            groups.entry((inst.mesh, m, false)).or_default().push(inst.transform);
        }
    }
    groups
}

fn has_normals(m: &Mesh) -> bool {
    !m.normals.is_empty() && m.normals.len() == m.positions.len()
}

/// Binary PLY of triangles `tris` of `m`, with only the vertices they use.
fn write_ply(path: &Path, m: &Mesh, tris: &[[u32; 3]]) -> std::io::Result<()> {
    let mut remap = vec![u32::MAX; m.positions.len()];
    let mut order = Vec::new();
    let faces: Vec<[u32; 3]> = tris
        .iter()
        .map(|t| {
            t.map(|i| {
                if remap[i as usize] == u32::MAX {
                    remap[i as usize] = order.len() as u32;
                    order.push(i as usize);
                }
                remap[i as usize]
            })
        })
        .collect();
    let (normals, uvs) = (has_normals(m), !m.uvs.is_empty() && m.uvs.len() == m.positions.len());
    let mut w = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n",
        order.len()
    );
    if normals {
        header += "property float nx\nproperty float ny\nproperty float nz\n";
    }
    if uvs {
        header += "property float u\nproperty float v\n";
    }
    header += &format!("element face {}\nproperty list uchar int vertex_indices\nend_header\n", faces.len());
    w.write_all(header.as_bytes())?;
    for &i in &order {
        let mut values = m.positions[i].to_array().to_vec();
        if normals {
            values.extend(m.normals[i].to_array());
        }
        if uvs {
            values.extend([m.uvs[i].x, 1.0 - m.uvs[i].y]);
        }
        for v in values {
            w.write_all(&v.to_le_bytes())?;
        }
    }
    for f in &faces {
        w.write_all(&[3u8])?;
        for &i in f {
            w.write_all(&(i as i32).to_le_bytes())?;
        }
    }
    w.flush()
}

fn v3(v: Vec3) -> [f32; 3] {
    v.to_array()
}

fn rgb(c: Rgb) -> [f32; 3] {
    c.to_array()
}

fn row_major(t: &Affine3A) -> [f32; 16] {
    Mat4::from(*t).transpose().to_cols_array()
}

fn texturable(t: &Texturable) -> Value {
    match t {
        Texturable::Constant(c) => json!({"rgb": rgb(*c)}),
        Texturable::Texture { texture, factor } => json!({"texture": texture, "factor": rgb(*factor)}),
    }
}

fn material(m: &Material) -> Value {
    let bsdf = match &m.bsdf {
        Bsdf::Diffuse { reflectance } => json!({"type": "diffuse", "reflectance": texturable(reflectance)}),
        Bsdf::Conductor { eta, k, roughness } => {
            json!({"type": "conductor", "eta": rgb(*eta), "k": rgb(*k), "roughness": roughness})
        }
        Bsdf::Plastic { diffuse, roughness, ior } => {
            json!({"type": "plastic", "diffuse": texturable(diffuse), "roughness": roughness, "ior": ior})
        }
    };
    json!({"name": m.name, "bsdf": bsdf, "emission": rgb(m.emission), "two_sided_emission": m.two_sided_emission})
}

fn light(l: &Light) -> Value {
    match l {
        Light::Point { position, intensity } => {
            json!({"type": "point", "position": v3(*position), "intensity": rgb(*intensity)})
        }
        Light::Spot { position, direction, intensity, cos_total_width, cos_falloff_start } => json!({
            "type": "spot", "position": v3(*position), "direction": v3(*direction), "intensity": rgb(*intensity),
            "cos_total_width": cos_total_width, "cos_falloff_start": cos_falloff_start,
        }),
        Light::Directional { direction, irradiance } => {
            json!({"type": "directional", "direction": v3(*direction), "irradiance": rgb(*irradiance)})
        }
        Light::Environment(Environment::Constant { radiance }) => {
            json!({"type": "constant", "radiance": rgb(*radiance)})
        }
        Light::Environment(Environment::Sky { zenith, horizon, ground }) => json!({
            "type": "sky", "zenith": rgb(*zenith), "horizon": rgb(*horizon), "ground": rgb(*ground),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The PLY holds exactly the selected triangles over compacted vertices, and the JSON
    /// names every shape with its instance transforms.
    #[test]
    fn cornell_dump_has_every_triangle_once() {
        let scene = filtrace_scene::builtin("cornell").expect("built-in");
        let dir = std::env::temp_dir().join(format!("filtrace-dump-{}", std::process::id()));
        let path = dump_scene(&scene, &dir).unwrap();
        let doc: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        let shapes = doc["shapes"].as_array().unwrap();
        let total: u64 = shapes
            .iter()
            .map(|s| s["triangles"].as_u64().unwrap() * s["instances"].as_array().unwrap().len() as u64)
            .sum();
        assert_eq!(total as usize, scene.triangle_count());
        let first = dir.join(shapes[0]["file"].as_str().unwrap());
        let bytes = std::fs::read(first).unwrap();
        let text = String::from_utf8_lossy(&bytes);
        let faces = format!("element face {}\n", shapes[0]["triangles"]);
        assert!(
            text.starts_with("ply\nformat binary_little_endian 1.0\n") && text.contains(&faces),
            "{text:.300}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
