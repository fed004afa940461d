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
//! - `KHR_lights_punctual`: point, spot (inner/outer cone angles), directional; `range` is
//!   ignored. Intensities are photometric (cd, lux) and divided by [`LUMENS_PER_WATT`].
//! - `KHR_materials_emissive_strength` multiplies the emissive factor. Other extensions in
//!   `extensionsUsed` are ignored with a warning.
//! - Nodes must form disjoint trees (no cycles, one parent at most), else an error naming
//!   the node; at most [`MAX_GLTF_INSTANCES`] instances.
//! - Accessors are checked before they are read (`gltf_accessor`): out of range, wrong
//!   type or sparse is an error naming mesh, primitive and attribute.
//! - Camera: the first perspective camera met in a depth-first walk of the scene's nodes;
//!   `yfov` must be in (0, pi).

use std::collections::HashMap;
use std::path::Path;

use filtrace_core::{Affine3A, Mat4, Rgb, Vec3};

use crate::error::SceneError;
use crate::gltf_accessor::read_primitive;
use crate::gltf_anim::{read_animation, VisitedNode};
use crate::texture::srgb_to_linear;
use crate::types::{
    Bsdf, Camera, Instance, Light, Material, MaterialId, MeshId, Scene, Texturable, Texture, TextureId,
};

/// Luminous efficacy used to turn KHR_lights_punctual's photometric units into radiometric
/// ones (lm/W): the maximum efficacy, at 555 nm, which Blender's exporter also uses
/// (`PBR_WATTS_TO_LUMENS`).
pub const LUMENS_PER_WATT: f32 = 683.0;

/// Most instances one glTF file may place. Nodes form trees (checked), so instances grow
/// only with nodes x primitives; 4M instances (about 300 MB with the top-level BVH)
/// is far above real files (2CylinderEngine: 115) and stops a hostile file early.
pub const MAX_GLTF_INSTANCES: usize = 1 << 22;

/// Extensions whose content is read; any other extension in `extensionsUsed` is ignored
/// with a warning (an unsupported one in `extensionsRequired` is refused by the `gltf` crate).
pub const GLTF_EXTENSIONS_READ: &[&str] = &["KHR_lights_punctual", "KHR_materials_emissive_strength"];

/// Loads a `.gltf` or `.glb` file.
pub fn load_gltf(path: &Path) -> Result<Scene, SceneError> {
    let (doc, buffers, images) = import(path)?;
    let mut scene = Scene {
        name: path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
        ..Scene::default()
    };
    let ignored: Vec<&str> = doc.extensions_used().filter(|e| !GLTF_EXTENSIONS_READ.contains(e)).collect();
    if !ignored.is_empty() {
        scene.stats.warnings.push(format!(
            "{}: glTF extensions not supported, ignored: {}",
            path.display(),
            ignored.join(", ")
        ));
    }
    let mut ctx =
        Ctx { scene: &mut scene, images: &images, image_textures: HashMap::new(), default_mat: None };
    let materials = doc.materials().map(|m| ctx.material(&m)).collect::<Result<Vec<_>, _>>();
    let materials = materials.map_err(|m| SceneError::parse(path, None, m))?;
    let prims = read_meshes(&doc, &buffers, &materials, &mut ctx, path)?;

    // Nodes of the default scene (or the first), depth first.
    let Some(gscene) = doc.default_scene().or_else(|| doc.scenes().next()) else {
        return Err(SceneError::parse(path, None, "glTF file has no scene"));
    };
    check_node_trees(&doc).map_err(|m| SceneError::parse(path, None, m))?;
    let visited = walk_nodes(&gscene, &prims, ctx.scene, MAX_GLTF_INSTANCES)
        .map_err(|m| SceneError::parse(path, None, m))?;
    let mut warnings = Vec::new();
    scene.animation = read_animation(&doc, &buffers, &visited, &mut warnings)
        .map_err(|m| SceneError::parse(path, None, m))?;
    scene.stats.warnings.extend(warnings.into_iter().map(|w| format!("{}: {w}", path.display())));
    Ok(scene)
}

/// One of our meshes per triangle primitive, by glTF mesh: `result[mesh][k]`.
fn read_meshes(
    doc: &gltf::Document,
    buffers: &[gltf::buffer::Data],
    materials: &[MaterialId],
    ctx: &mut Ctx,
    path: &Path,
) -> Result<Vec<Vec<MeshId>>, SceneError> {
    let mut prims = Vec::new();
    for mesh in doc.meshes() {
        let mut ids = Vec::new();
        for prim in mesh.primitives() {
            let at = format!(
                "mesh {} ({}) primitive {}",
                mesh.index(),
                mesh.name().unwrap_or("unnamed"),
                prim.index()
            );
            if prim.mode() != gltf::mesh::Mode::Triangles {
                let w = format!("{}: {at}: mode {:?} is not triangles, skipped", path.display(), prim.mode());
                ctx.scene.stats.warnings.push(w);
                continue;
            }
            let mat = match prim.material().index() {
                Some(i) => materials[i],
                None => ctx.default_material(),
            };
            let name = format!("{}#{}", mesh.name().unwrap_or("mesh"), prim.index());
            let skipped = &mut ctx.scene.stats.degenerate_triangles_skipped;
            let m = read_primitive(&prim, buffers, mat, &name, skipped)
                .map_err(|m| SceneError::parse(path, None, format!("{at}: {m}")))?;
            ids.push(ctx.scene.meshes.len() as MeshId);
            ctx.scene.meshes.push(m);
        }
        prims.push(ids);
    }
    Ok(prims)
}

/// `node 3 ('Arm')`, for messages.
fn node_label(node: &gltf::Node) -> String {
    match node.name() {
        Some(n) => format!("node {} ('{n}')", node.index()),
        None => format!("node {}", node.index()),
    }
}

/// glTF 2.0 (section 3.5.3): nodes form disjoint strict trees, no cycles and at most one
/// parent each. Shared children would place a subtree once per path (exponentially many
/// instances for a chain of shared nodes), and a cycle forever, so both are errors.
fn check_node_trees(doc: &gltf::Document) -> Result<(), String> {
    let nodes: Vec<gltf::Node> = doc.nodes().collect();
    let mut parent: Vec<Option<usize>> = vec![None; nodes.len()];
    for node in &nodes {
        for child in node.children() {
            let c = child.index();
            if c == node.index() {
                return Err(format!(
                    "{} lists itself as a child (a cycle in the node hierarchy)",
                    node_label(node)
                ));
            }
            if parent[c] == Some(node.index()) {
                return Err(format!(
                    "{} is listed twice among node {}'s children",
                    node_label(&child),
                    node.index()
                ));
            }
            if let Some(p) = parent[c] {
                return Err(format!(
                    "{} is a child of both node {p} and node {}: glTF nodes must form disjoint trees",
                    node_label(&child),
                    node.index()
                ));
            }
            parent[c] = Some(node.index());
        }
    }
    // With one parent each, a cycle is a closed chain of parent links: follow each chain,
    // marking the nodes of the current walk, and stop at the first node already settled.
    let mut state = vec![0u8; nodes.len()]; // 0 new, 1 on this walk, 2 settled
    for start in 0..nodes.len() {
        let mut i = start;
        while state[i] == 0 {
            state[i] = 1;
            match parent[i] {
                Some(p) => i = p,
                None => break,
            }
        }
        if state[i] == 1 && parent[i].is_some() {
            return Err(format!(
                "{} is its own ancestor (a cycle in the node hierarchy)",
                node_label(&nodes[i])
            ));
        }
        let mut j = start;
        while state[j] == 1 {
            state[j] = 2;
            j = parent[j].unwrap_or(j);
        }
    }
    Ok(())
}

/// Places the scene's nodes depth first (instances, lights, the first perspective camera).
/// At most `max_instances` instances. Returns the nodes in walk order, for animation.
fn walk_nodes(
    gscene: &gltf::Scene,
    prims: &[Vec<MeshId>],
    scene: &mut Scene,
    max_instances: usize,
) -> Result<Vec<VisitedNode>, String> {
    let mut visited = vec![false; gscene.nodes().map(|n| n.index() + 1).max().unwrap_or(0)];
    let mut walk: Vec<VisitedNode> = Vec::new();
    let mut stack: Vec<(gltf::Node, Mat4, Option<u32>)> =
        gscene.nodes().map(|n| (n, Mat4::IDENTITY, None)).collect();
    stack.reverse();
    while let Some((node, parent, parent_walk)) = stack.pop() {
        let i = node.index();
        if i >= visited.len() {
            visited.resize(i + 1, false);
        }
        if std::mem::replace(&mut visited[i], true) {
            return Err(format!(
                "{} is reached twice from scene {}'s root nodes",
                node_label(&node),
                gscene.index()
            ));
        }
        let local = Mat4::from_cols_array_2d(&node.transform().matrix());
        let world = parent * local;
        if !world.is_finite() {
            return Err(format!("{} has a non-finite transform", node_label(&node)));
        }
        let affine = Affine3A::from_mat4(world);
        let mut here = VisitedNode {
            gltf_index: i,
            parent: parent_walk,
            local: Affine3A::from_mat4(local),
            instances: Vec::new(),
            lights: Vec::new(),
            camera: None,
        };
        if let Some(mesh) = node.mesh() {
            let ids = &prims[mesh.index()];
            if scene.instances.len() + ids.len() > max_instances {
                return Err(format!("more than {max_instances} instances (at {})", node_label(&node)));
            }
            for &id in ids {
                here.instances.push(scene.instances.len() as u32);
                scene.instances.push(Instance { mesh: id, transform: affine, material_override: None });
            }
        }
        if let Some(light) = node.light() {
            here.lights.push((scene.lights.len() as u32, convert_light(&light, &Affine3A::IDENTITY)));
            scene.lights.push(convert_light(&light, &affine));
        }
        if let (Some(cam), None) = (node.camera(), &scene.camera) {
            scene.camera = convert_camera(&cam, &affine)?;
            here.camera = convert_camera(&cam, &Affine3A::IDENTITY)?.filter(|_| scene.camera.is_some());
        }
        let me = Some(walk.len() as u32);
        walk.push(here);
        let mut children: Vec<_> = node.children().map(|c| (c, world, me)).collect();
        children.reverse();
        stack.extend(children);
    }
    Ok(walk)
}

/// A perspective camera at the node (looking along its -Z, up +Y); `None` for orthographic
/// cameras and degenerate transforms. `yfov` outside (0, π) is an error.
fn convert_camera(cam: &gltf::Camera, affine: &Affine3A) -> Result<Option<Camera>, String> {
    let gltf::camera::Projection::Perspective(p) = cam.projection() else { return Ok(None) };
    let yfov = p.yfov();
    if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
        return Err(format!("camera {}: yfov {yfov} rad is outside (0, pi)", cam.index()));
    }
    let eye = affine.transform_point3(Vec3::ZERO);
    let fwd = affine.transform_vector3(Vec3::NEG_Z).normalize_or_zero();
    let up = affine.transform_vector3(Vec3::Y).normalize_or_zero();
    if fwd == Vec3::ZERO || up == Vec3::ZERO {
        return Ok(None);
    }
    Ok(Some(Camera { eye, target: eye + fwd, up, vfov_deg: yfov.to_degrees() }))
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

    /// Our material for a glTF material (approximations in the module docs). A base colour
    /// outside [0, 1] (the specification's range; above 1 a surface would create energy) is
    /// an error naming the material.
    fn material(&mut self, m: &gltf::Material) -> Result<MaterialId, String> {
        let name =
            m.name().map(str::to_string).unwrap_or_else(|| format!("material{}", m.index().unwrap_or(0)));
        let pbr = m.pbr_metallic_roughness();
        let [r, g, b, _] = pbr.base_color_factor();
        let base = Rgb::new(r, g, b);
        if !(base.min_element() >= 0.0 && base.max_element() <= 1.0) {
            return Err(format!(
                "material {} ('{name}'): baseColorFactor [{r}, {g}, {b}] is outside [0, 1]",
                m.index().unwrap_or(0)
            ));
        }
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
        // KHR_materials_emissive_strength scales the (0..1) emissive factor: Blender writes
        // a strength-5 emitter as factor 1, strength 5.
        let mut emission = Rgb::from(m.emissive_factor()) * m.emissive_strength().unwrap_or(1.0);
        if let Some(t) = m.emissive_texture() {
            if let Some(id) = self.texture(t.texture().source().index()) {
                let tex = &self.scene.textures[id as usize];
                let avg = tex.texels.iter().copied().sum::<Rgb>() / tex.texels.len().max(1) as f32;
                emission *= avg;
            }
        }
        Ok(self.scene.add_material(Material { name, bsdf, emission, two_sided_emission: m.double_sided() }))
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

/// KHR_lights_punctual intensities are photometric: candela (lm/sr) for point and spot
/// lights, lux (lm/m^2) for directional ones. Dividing by [`LUMENS_PER_WATT`] gives W/sr and
/// W/m^2, which undoes Blender's exporter (a P-watt point light is written as
/// P / (4 pi) x 683 cd, a sun of S W/m^2 as S x 683 lux).
fn convert_light(light: &gltf::khr_lights_punctual::Light, m: &Affine3A) -> Light {
    use gltf::khr_lights_punctual::Kind;
    let power = Rgb::from(light.color()) * (light.intensity() / LUMENS_PER_WATT);
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn instance_count_is_bounded() {
        // One mesh of one primitive placed by 5 nodes; a limit of 3 stops the walk.
        let json = r#"{"asset": {"version": "2.0"},
            "meshes": [{"primitives": [{"attributes": {}}]}],
            "nodes": [{"mesh": 0}, {"mesh": 0}, {"mesh": 0}, {"mesh": 0}, {"mesh": 0}],
            "scenes": [{"nodes": [0, 1, 2, 3, 4]}]}"#;
        let doc = gltf::Gltf::from_slice_without_validation(json.as_bytes()).map(|g| g.document);
        let doc = doc.unwrap_or_else(|e| panic!("{e}"));
        let gscene = doc.scenes().next().unwrap_or_else(|| panic!("no scene"));
        let mut scene = Scene::default();
        let err = walk_nodes(&gscene, &[vec![0]], &mut scene, 3).unwrap_err();
        assert!(err.contains("more than 3 instances") && err.contains("node 3"), "{err}");
        let mut scene = Scene::default();
        walk_nodes(&gscene, &[vec![0]], &mut scene, 5).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(scene.instances.len(), 5);
    }
}
