//! glTF 2.0 loader (`.gltf` and `.glb`) built on the `gltf` crate.
//!
//! - Geometry: one [`Mesh`] per glTF primitive (triangle mode only; points/lines are skipped
//!   with a warning), one [`Instance`] per primitive per node that uses the mesh, with the
//!   node's world transform (hierarchy composed). Nothing is flattened: a mesh used by ten
//!   nodes is stored once and placed ten times. Texture coordinates are flipped (`v' = 1 - v`)
//!   because glTF puts v = 0 at the top of the image and filtrace at the bottom.
//! - Materials (documented approximations):
//!   - `metallic > 0.5`: [`Bsdf::Conductor`] whose Fresnel reflectance at normal incidence equals
//!     the base colour `F0` per channel: `eta = 1`, `k = 2 sqrt(F0 / (1 - F0))` (since
//!     `F0 = ((eta-1)^2 + k^2) / ((eta+1)^2 + k^2)`), `F0` clamped to [0, 0.99]; the base colour
//!     texture is not used for metals.
//!   - otherwise `roughness < 0.9`: [`Bsdf::Plastic`] (ior 1.5) over the base colour
//!     (factor x texture); `roughness >= 0.9`: [`Bsdf::Diffuse`] (a coating that rough is close
//!     to Lambertian).
//!   - glTF and filtrace both use perceptual roughness (`alpha = r^2`): copied as is.
//!   - Emission: `emissiveFactor` x the average of the emissive texture (not per texel);
//!     `doubleSided` materials emit from both faces.
//! - `KHR_lights_punctual`: point (intensity in cd taken as W/sr), spot (inner/outer cone
//!   angles), directional (intensity in lux taken as irradiance); `range` is ignored.
//! - Camera: the first perspective camera met in a depth-first walk of the scene's nodes.

use std::collections::HashMap;
use std::path::Path;

use filtrace_core::{Affine3A, Mat4, Rgb, Vec2, Vec3};

use crate::error::SceneError;
use crate::obj::is_degenerate;
use crate::texture::srgb_to_linear;
use crate::types::{
    Bsdf, Camera, Instance, Light, Material, MaterialId, Mesh, MeshId, Scene, Texturable, Texture, TextureId,
};

/// Loads a `.gltf` or `.glb` file.
pub fn load_gltf(path: &Path) -> Result<Scene, SceneError> {
    let (doc, buffers, images) = import(path)?;
    let mut scene = Scene {
        name: path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
        ..Scene::default()
    };
    let mut ctx =
        Ctx { scene: &mut scene, images: &images, image_textures: HashMap::new(), default_mat: None };

    // Materials, in document order.
    let materials: Vec<MaterialId> = doc.materials().map(|m| ctx.material(&m)).collect();

    // Meshes: one of ours per primitive.
    let mut prims: Vec<Vec<MeshId>> = Vec::new();
    for mesh in doc.meshes() {
        let mut ids = Vec::new();
        for prim in mesh.primitives() {
            if prim.mode() != gltf::mesh::Mode::Triangles {
                ctx.scene.stats.warnings.push(format!(
                    "{}: mesh {} primitive {}: mode {:?} is not triangles, skipped",
                    path.display(),
                    mesh.index(),
                    prim.index(),
                    prim.mode()
                ));
                continue;
            }
            let mat = match prim.material().index() {
                Some(i) => materials[i],
                None => ctx.default_material(),
            };
            let name = format!("{}#{}", mesh.name().unwrap_or("mesh"), prim.index());
            let m = read_primitive(
                &prim,
                &buffers,
                mat,
                &name,
                &mut ctx.scene.stats.degenerate_triangles_skipped,
            )
            .map_err(|m| SceneError::parse(path, None, format!("mesh {}: {m}", mesh.index())))?;
            let id = ctx.scene.meshes.len() as MeshId;
            ctx.scene.meshes.push(m);
            ids.push(id);
        }
        prims.push(ids);
    }

    // Nodes of the default scene (or the first), depth first.
    let Some(gscene) = doc.default_scene().or_else(|| doc.scenes().next()) else {
        return Err(SceneError::parse(path, None, "glTF file has no scene"));
    };
    let mut stack: Vec<(gltf::Node, Mat4)> = gscene.nodes().map(|n| (n, Mat4::IDENTITY)).collect();
    stack.reverse();
    while let Some((node, parent)) = stack.pop() {
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if !world.is_finite() {
            return Err(SceneError::parse(
                path,
                None,
                format!("node {} has a non-finite transform", node.index()),
            ));
        }
        let affine = Affine3A::from_mat4(world);
        if let Some(mesh) = node.mesh() {
            for &id in &prims[mesh.index()] {
                ctx.scene.instances.push(Instance { mesh: id, transform: affine, material_override: None });
            }
        }
        if let Some(light) = node.light() {
            ctx.scene.lights.push(convert_light(&light, &affine));
        }
        if let (Some(cam), None) = (node.camera(), &ctx.scene.camera) {
            if let gltf::camera::Projection::Perspective(p) = cam.projection() {
                let eye = affine.transform_point3(Vec3::ZERO);
                let fwd = affine.transform_vector3(Vec3::NEG_Z).normalize_or_zero();
                let up = affine.transform_vector3(Vec3::Y).normalize_or_zero();
                if fwd != Vec3::ZERO && up != Vec3::ZERO {
                    ctx.scene.camera =
                        Some(Camera { eye, target: eye + fwd, up, vfov_deg: p.yfov().to_degrees() });
                }
            }
        }
        let mut children: Vec<_> = node.children().map(|c| (c, world)).collect();
        children.reverse();
        stack.extend(children);
    }
    Ok(scene)
}

/// `gltf::import`, with a panic inside it turned into an error: gltf-json 1.4's validation
/// indexes `accessors` with the POSITION attribute's index before checking it is in range.
fn import(
    path: &Path,
) -> Result<(gltf::Document, Vec<gltf::buffer::Data>, Vec<gltf::image::Data>), SceneError> {
    check_glb_length(path)?;
    match std::panic::catch_unwind(|| gltf::import(path)) {
        Ok(r) => r.map_err(|e| gltf_error(path, e)),
        Err(_) => Err(SceneError::parse(
            path,
            None,
            "malformed glTF (the validator failed on it; is an accessor index out of range?)",
        )),
    }
}

/// A binary glTF whose header claims more bytes than the file holds is an error: gltf 1.4
/// allocates the claimed length (up to 4 GiB) before reading.
fn check_glb_length(path: &Path) -> Result<(), SceneError> {
    use std::io::Read;
    let io = |source| SceneError::Io { path: path.to_path_buf(), source };
    let mut file = std::fs::File::open(path).map_err(io)?;
    let mut header = [0u8; 12];
    if file.read_exact(&mut header).is_err() || &header[..4] != b"glTF" {
        return Ok(()); // Not binary glTF, or too short: gltf reports it.
    }
    let claimed = u32::from_le_bytes([header[8], header[9], header[10], header[11]]) as u64;
    let actual = file.metadata().map_err(io)?.len();
    if claimed > actual {
        let msg = format!("GLB header claims {claimed} bytes, the file has {actual} (truncated or corrupt)");
        return Err(SceneError::parse(path, None, msg));
    }
    Ok(())
}

fn gltf_error(path: &Path, e: gltf::Error) -> SceneError {
    match e {
        gltf::Error::Io(source) => SceneError::Io { path: path.to_path_buf(), source },
        gltf::Error::Deserialize(d) => {
            SceneError::parse(path, Some(d.line()), format!("invalid glTF JSON: {d}"))
        }
        other => SceneError::parse(path, None, other.to_string()),
    }
}

struct Ctx<'a> {
    scene: &'a mut Scene,
    images: &'a [gltf::image::Data],
    image_textures: HashMap<usize, Option<TextureId>>,
    default_mat: Option<MaterialId>,
}

impl Ctx<'_> {
    fn default_material(&mut self) -> MaterialId {
        if let Some(m) = self.default_mat {
            return m;
        }
        let id = self.scene.add_material(Material::default_grey());
        self.default_mat = Some(id);
        id
    }

    /// The texture of glTF image `index` (converted once), or `None` for unsupported formats.
    fn texture(&mut self, index: usize) -> Option<TextureId> {
        if let Some(&t) = self.image_textures.get(&index) {
            return t;
        }
        let t = match image_to_texture(&self.images[index], index) {
            Ok(t) => {
                self.scene.textures.push(t);
                Some((self.scene.textures.len() - 1) as TextureId)
            }
            Err(m) => {
                self.scene.stats.warnings.push(m);
                None
            }
        };
        self.image_textures.insert(index, t);
        t
    }

    fn material(&mut self, m: &gltf::Material) -> MaterialId {
        let pbr = m.pbr_metallic_roughness();
        let [r, g, b, _] = pbr.base_color_factor();
        let base = Rgb::new(r, g, b);
        let roughness = pbr.roughness_factor().clamp(0.0, 1.0);
        let bsdf = if pbr.metallic_factor() > 0.5 {
            let f0 = base.clamp(Rgb::ZERO, Rgb::splat(0.99));
            let k = Rgb::new(
                2.0 * (f0.x / (1.0 - f0.x)).sqrt(),
                2.0 * (f0.y / (1.0 - f0.y)).sqrt(),
                2.0 * (f0.z / (1.0 - f0.z)).sqrt(),
            );
            Bsdf::Conductor { eta: Rgb::ONE, k, roughness }
        } else {
            let tex = pbr.base_color_texture().and_then(|t| self.texture(t.texture().source().index()));
            let diffuse = match tex {
                Some(texture) => Texturable::Texture { texture, factor: base },
                None => Texturable::Constant(base),
            };
            if roughness < 0.9 {
                Bsdf::Plastic { diffuse, roughness, ior: 1.5 }
            } else {
                Bsdf::Diffuse { reflectance: diffuse }
            }
        };
        let mut emission = Rgb::from(m.emissive_factor());
        if let Some(t) = m.emissive_texture() {
            if let Some(id) = self.texture(t.texture().source().index()) {
                let tex = &self.scene.textures[id as usize];
                let avg = tex.texels.iter().copied().sum::<Rgb>() / tex.texels.len().max(1) as f32;
                emission *= avg;
            }
        }
        let name =
            m.name().map(str::to_string).unwrap_or_else(|| format!("material{}", m.index().unwrap_or(0)));
        self.scene.add_material(Material { name, bsdf, emission, two_sided_emission: m.double_sided() })
    }
}

fn image_to_texture(img: &gltf::image::Data, index: usize) -> Result<Texture, String> {
    use gltf::image::Format;
    let (w, h) = (img.width, img.height);
    let name = format!("image{index}");
    let eight_bit = |channels: usize| crate::texture::texture_from_srgb8(&name, w, h, &img.pixels, channels);
    let sixteen_bit = |channels: usize| {
        let texels = img
            .pixels
            .chunks_exact(2 * channels)
            .map(|p| {
                let c =
                    |i: usize| srgb_to_linear(u16::from_le_bytes([p[2 * i], p[2 * i + 1]]) as f32 / 65535.0);
                if channels < 3 {
                    Rgb::splat(c(0))
                } else {
                    Rgb::new(c(0), c(1), c(2))
                }
            })
            .collect();
        Texture { name: name.clone(), width: w, height: h, texels }
    };
    let t = match img.format {
        Format::R8 => eight_bit(1),
        Format::R8G8 => eight_bit(2),
        Format::R8G8B8 => eight_bit(3),
        Format::R8G8B8A8 => eight_bit(4),
        Format::R16 => sixteen_bit(1),
        Format::R16G16 => sixteen_bit(2),
        Format::R16G16B16 => sixteen_bit(3),
        Format::R16G16B16A16 => sixteen_bit(4),
        f => return Err(format!("glTF image {index}: pixel format {f:?} not supported, texture ignored")),
    };
    if t.texels.len() != (w as usize) * (h as usize) || t.texels.is_empty() {
        return Err(format!("glTF image {index}: size mismatch, texture ignored"));
    }
    Ok(t)
}

fn read_primitive(
    prim: &gltf::Primitive,
    buffers: &[gltf::buffer::Data],
    material: MaterialId,
    name: &str,
    skipped: &mut usize,
) -> Result<Mesh, String> {
    let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
    let positions: Vec<Vec3> =
        reader.read_positions().ok_or("primitive without POSITION")?.map(Vec3::from).collect();
    let n = positions.len();
    let flat: Vec<u32> = match reader.read_indices() {
        Some(i) => i.into_u32().collect(),
        None => (0..n as u32).collect(),
    };
    if !flat.chunks_exact(3).remainder().is_empty() {
        return Err(format!("index count {} is not a multiple of 3", flat.len()));
    }
    let mut mesh = Mesh { name: name.to_string(), ..Mesh::default() };
    for t in flat.chunks_exact(3) {
        let t = [t[0], t[1], t[2]];
        if let Some(&bad) = t.iter().find(|&&i| i as usize >= n) {
            return Err(format!("vertex index {bad} out of range ({n} vertices)"));
        }
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || is_degenerate(t.map(|i| positions[i as usize])) {
            *skipped += 1;
            continue;
        }
        mesh.indices.push(t);
        mesh.material_ids.push(material);
    }
    if let Some(ns) = reader.read_normals() {
        let ns: Vec<Vec3> = ns.map(|v| Vec3::from(v).normalize_or_zero()).collect();
        if ns.len() == n && ns.iter().all(|v| v.is_finite() && *v != Vec3::ZERO) {
            mesh.normals = ns;
        }
    }
    if let Some(uv) = reader.read_tex_coords(0) {
        let uv: Vec<Vec2> = uv.into_f32().map(|[u, v]| Vec2::new(u, 1.0 - v)).collect();
        if uv.len() == n {
            mesh.uvs = uv;
        }
    }
    mesh.positions = positions;
    Ok(mesh)
}

fn convert_light(light: &gltf::khr_lights_punctual::Light, m: &Affine3A) -> Light {
    use gltf::khr_lights_punctual::Kind;
    let power = Rgb::from(light.color()) * light.intensity();
    let position = m.transform_point3(Vec3::ZERO);
    // glTF lights shine along the node's -Z.
    let forward = m.transform_vector3(Vec3::NEG_Z).normalize_or(Vec3::NEG_Z);
    match light.kind() {
        Kind::Point => Light::Point { position, intensity: power },
        Kind::Directional => Light::Directional { direction: -forward, irradiance: power },
        Kind::Spot { inner_cone_angle, outer_cone_angle } => Light::Spot {
            position,
            direction: forward,
            intensity: power,
            cos_total_width: outer_cone_angle.cos(),
            cos_falloff_start: inner_cone_angle.cos(),
        },
    }
}
