//! filtrace's TOML scene files. The format reference is `docs/scenes.md`; in short:
//!
//! ```toml
//! name = "example"
//! [camera]                      # optional; without it `camera` is None
//! eye = [0, 1, 5]
//! target = [0, 1, 0]
//! up = [0, 1, 0]                # default +y
//! vfov = 40                     # degrees, default 45
//!
//! [[materials]]
//! name = "red"
//! type = "diffuse"              # diffuse | conductor | plastic
//! color = [0.6, 0.05, 0.05]
//!
//! [[objects]]
//! shape = "cube"                # quad | cube | sphere, or `mesh = "file.obj"`
//! material = "red"
//! transform = { scale = 2, rotate = { deg = 30, axis = [0, 1, 0] }, translate = [0, 1, 0] }
//!
//! [[lights]]
//! type = "point"
//! position = [0, 4, 0]
//! intensity = [10, 10, 10]
//! ```
//!
//! Unknown keys are errors; every error names the file and line (from `toml`'s spans).
//! Mesh files are loaded once per path and placed once per object (instancing).

use std::collections::HashMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

use filtrace_core::{Affine3A, Mat4, Quat, Rgb, Vec3};
use serde::Deserialize;
use toml::Spanned;

use crate::error::{line_of, SceneError};
use crate::shapes;
use crate::toml_animation::{build_animation, AnimationDef, ObjectTarget, Targets, TrackDef};
use crate::types::{
    Bsdf, Camera, Environment, Instance, Light, Material, MaterialId, MeshId, Scene, Texturable, TextureId,
};

type V3 = [f32; 3];

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    name: Option<String>,
    camera: Option<CameraDef>,
    #[serde(default)]
    materials: Vec<Spanned<MaterialDef>>,
    #[serde(default)]
    objects: Vec<Spanned<ObjectDef>>,
    #[serde(default)]
    lights: Vec<Spanned<LightDef>>,
    animation: Option<Spanned<AnimationDef>>,
    #[serde(default)]
    tracks: Vec<Spanned<TrackDef>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraDef {
    eye: V3,
    target: V3,
    up: Option<V3>,
    vfov: Option<f32>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct MaterialDef {
    name: String,
    #[serde(rename = "type")]
    kind: String,
    color: Option<V3>,
    texture: Option<String>,
    metal: Option<String>,
    eta: Option<V3>,
    k: Option<V3>,
    roughness: Option<f32>,
    ior: Option<f32>,
    emission: Option<V3>,
    two_sided: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjectDef {
    name: Option<String>,
    mesh: Option<String>,
    shape: Option<String>,
    segments: Option<u32>,
    material: Option<String>,
    transform: Option<TransformDef>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TransformDef {
    translate: Option<V3>,
    rotate: Option<RotateDef>,
    scale: Option<ScaleDef>,
    /// Row-major 4x4 matrix (rows as written); the last row must be (0, 0, 0, 1).
    matrix: Option<[[f32; 4]; 4]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RotateDef {
    deg: f32,
    axis: V3,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum ScaleDef {
    Uniform(f32),
    PerAxis(V3),
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct LightDef {
    /// Names the light for animation tracks.
    name: Option<String>,
    #[serde(rename = "type")]
    kind: String,
    position: Option<V3>,
    direction: Option<V3>,
    target: Option<V3>,
    intensity: Option<V3>,
    irradiance: Option<V3>,
    radiance: Option<V3>,
    cone_angle: Option<f32>,
    falloff_start: Option<f32>,
    zenith: Option<V3>,
    horizon: Option<V3>,
    ground: Option<V3>,
    corner: Option<V3>,
    edge1: Option<V3>,
    edge2: Option<V3>,
    two_sided: Option<bool>,
}

/// Complex index of refraction (eta, k) of named metals in linear RGB (approximately the
/// measured values near 650, 550 and 450 nm, as tabulated in common renderers' presets).
pub fn named_metal(name: &str) -> Option<(Rgb, Rgb)> {
    let (eta, k) = match name {
        "gold" | "Au" => ([0.143_119, 0.374_957, 1.442_48], [3.983_16, 2.385_72, 1.603_22]),
        "copper" | "Cu" => ([0.200_438, 0.924_033, 1.102_21], [3.912_95, 2.452_85, 2.142_19]),
        "aluminium" | "aluminum" | "Al" => ([1.657_46, 0.880_369, 0.521_229], [9.223_87, 6.269_52, 4.837]),
        "silver" | "Ag" => ([0.155_265, 0.116_723, 0.138_342], [4.828_35, 3.122_25, 2.146_96]),
        _ => return None,
    };
    Some((Rgb::from(eta), Rgb::from(k)))
}

/// Names accepted by `metal = "..."`.
pub const METAL_NAMES: &[&str] = &["gold", "copper", "aluminium", "silver"];

/// Loads a TOML scene file.
pub fn load_toml(path: &Path) -> Result<Scene, SceneError> {
    let src = crate::obj::read_text(path)?;
    parse_toml(&src, path)
}

/// Parses a TOML scene; paths inside are relative to `path`'s folder.
pub fn parse_toml(src: &str, path: &Path) -> Result<Scene, SceneError> {
    let file: SceneFile = toml::from_str(src).map_err(|e| {
        let line = e.span().map(|s| line_of(src, s));
        SceneError::parse(path, line, e.message().trim().to_string())
    })?;
    let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut b = Builder {
        src,
        path,
        base,
        scene: Scene::default(),
        by_name: HashMap::new(),
        textures: HashMap::new(),
        files: HashMap::new(),
        default_mat: None,
        anim_objects: HashMap::new(),
        anim_lights: HashMap::new(),
    };
    b.scene.name = file
        .name
        .clone()
        .unwrap_or_else(|| path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default());
    if let Some(c) = &file.camera {
        b.scene.camera = Some(b.camera(c)?);
    }
    for m in &file.materials {
        b.material(m)?;
    }
    for o in &file.objects {
        b.object(o)?;
    }
    for l in &file.lights {
        b.light(l)?;
    }
    let targets = Targets {
        objects: &b.anim_objects,
        lights: &b.anim_lights,
        scene_lights: &b.scene.lights,
        camera: b.scene.camera.as_ref(),
    };
    let animation = build_animation(src, path, file.animation.as_ref(), &file.tracks, &targets)?;
    b.scene.animation = animation;
    Ok(b.scene)
}

/// A mesh file loaded once: where its meshes/materials start in our scene, and its instances.
struct LoadedFile {
    instances: Vec<Instance>,
    lights: Vec<Light>,
}

struct Builder<'a> {
    src: &'a str,
    path: &'a Path,
    base: PathBuf,
    scene: Scene,
    by_name: HashMap<String, MaterialId>,
    textures: HashMap<PathBuf, TextureId>,
    files: HashMap<PathBuf, LoadedFile>,
    default_mat: Option<MaterialId>,
    /// Named objects and lights, for animation tracks.
    anim_objects: HashMap<String, ObjectTarget>,
    anim_lights: HashMap<String, u32>,
}

fn finite3(v: V3) -> bool {
    v.iter().all(|x| x.is_finite())
}

impl Builder<'_> {
    fn err(&self, span: Range<usize>, msg: impl Into<String>) -> SceneError {
        SceneError::parse(self.path, Some(line_of(self.src, span)), msg)
    }

    fn camera(&self, c: &CameraDef) -> Result<Camera, SceneError> {
        let cam = Camera {
            eye: Vec3::from(c.eye),
            target: Vec3::from(c.target),
            up: Vec3::from(c.up.unwrap_or([0.0, 1.0, 0.0])),
            vfov_deg: c.vfov.unwrap_or(45.0),
        };
        let line = self.src.lines().position(|l| l.trim() == "[camera]").map(|i| i + 1);
        let bad = |m: &str| SceneError::parse(self.path, line, format!("camera: {m}"));
        if !(cam.eye.is_finite() && cam.target.is_finite() && cam.up.is_finite()) {
            return Err(bad("non-finite vector"));
        }
        if (cam.target - cam.eye).length_squared() == 0.0 {
            return Err(bad("eye and target coincide"));
        }
        if (cam.target - cam.eye).cross(cam.up).length_squared() == 0.0 {
            return Err(bad("up is parallel to the view direction"));
        }
        if !(cam.vfov_deg > 0.0 && cam.vfov_deg < 180.0) {
            return Err(bad("vfov must be in (0, 180) degrees"));
        }
        Ok(cam)
    }

    /// Rejects keys that `kind` does not use.
    fn only(
        &self,
        span: &Range<usize>,
        what: &str,
        set: &[(&str, bool)],
        allowed: &[&str],
    ) -> Result<(), SceneError> {
        for (key, present) in set {
            if *present && !allowed.contains(key) {
                return Err(self.err(span.clone(), format!("{what}: key '{key}' does not apply")));
            }
        }
        Ok(())
    }

    fn colour(
        &self,
        span: &Range<usize>,
        what: &str,
        v: Option<V3>,
        default: Rgb,
    ) -> Result<Rgb, SceneError> {
        let Some(v) = v else { return Ok(default) };
        if !finite3(v) || v.iter().any(|&x| x < 0.0) {
            return Err(self.err(span.clone(), format!("{what}: colours must be finite and non-negative")));
        }
        Ok(Rgb::from(v))
    }

    fn texture(&mut self, span: &Range<usize>, file: &str) -> Result<TextureId, SceneError> {
        let p = self.base.join(file);
        if let Some(&id) = self.textures.get(&p) {
            return Ok(id);
        }
        let t =
            crate::texture::load_texture(&p).map_err(|e| self.err(span.clone(), format!("texture: {e}")))?;
        self.scene.textures.push(t);
        let id = (self.scene.textures.len() - 1) as TextureId;
        self.textures.insert(p, id);
        Ok(id)
    }

    fn material(&mut self, sm: &Spanned<MaterialDef>) -> Result<(), SceneError> {
        let span = sm.span();
        let m = sm.get_ref();
        let what = format!("material '{}'", m.name);
        if self.by_name.contains_key(&m.name) {
            return Err(self.err(span, format!("{what} defined twice")));
        }
        let set = [
            ("color", m.color.is_some()),
            ("texture", m.texture.is_some()),
            ("metal", m.metal.is_some()),
            ("eta", m.eta.is_some()),
            ("k", m.k.is_some()),
            ("roughness", m.roughness.is_some()),
            ("ior", m.ior.is_some()),
        ];
        let roughness = m.roughness.unwrap_or(0.0);
        if !(0.0..=1.0).contains(&roughness) {
            return Err(self.err(span, format!("{what}: roughness must be in [0, 1]")));
        }
        let diffuse = |b: &mut Self| -> Result<Texturable, SceneError> {
            let c = b.colour(&span, &what, m.color, Rgb::splat(0.5))?;
            Ok(match &m.texture {
                Some(f) => Texturable::Texture {
                    texture: b.texture(&span, f)?,
                    factor: if m.color.is_some() { c } else { Rgb::ONE },
                },
                None => Texturable::Constant(c),
            })
        };
        let bsdf = match m.kind.as_str() {
            "diffuse" => {
                self.only(&span, &what, &set, &["color", "texture"])?;
                Bsdf::Diffuse { reflectance: diffuse(self)? }
            }
            "plastic" => {
                self.only(&span, &what, &set, &["color", "texture", "roughness", "ior"])?;
                let ior = m.ior.unwrap_or(1.5);
                if !(ior > 1.0 && ior < 4.0) {
                    return Err(self.err(span, format!("{what}: ior must be in (1, 4)")));
                }
                Bsdf::Plastic { diffuse: diffuse(self)?, roughness: m.roughness.unwrap_or(0.1), ior }
            }
            "conductor" => {
                self.only(&span, &what, &set, &["metal", "eta", "k", "roughness"])?;
                let (eta, k) = match (&m.metal, m.eta, m.k) {
                    (Some(name), None, None) => named_metal(name).ok_or_else(|| {
                        self.err(
                            span.clone(),
                            format!("{what}: unknown metal '{name}' (known: {})", METAL_NAMES.join(", ")),
                        )
                    })?,
                    (None, Some(eta), Some(k)) => {
                        let (eta, k) = (
                            self.colour(&span, &what, Some(eta), Rgb::ONE)?,
                            self.colour(&span, &what, Some(k), Rgb::ZERO)?,
                        );
                        if eta.min_element() <= 0.0 {
                            return Err(self.err(span, format!("{what}: eta must be positive")));
                        }
                        (eta, k)
                    }
                    _ => {
                        return Err(
                            self.err(span, format!("{what}: give either `metal` or both `eta` and `k`"))
                        )
                    }
                };
                Bsdf::Conductor { eta, k, roughness }
            }
            other => {
                return Err(
                    self.err(span, format!("{what}: unknown type '{other}' (diffuse, conductor, plastic)"))
                )
            }
        };
        let emission = self.colour(&span, &what, m.emission, Rgb::ZERO)?;
        let id = self.scene.add_material(Material {
            name: m.name.clone(),
            bsdf,
            emission,
            two_sided_emission: m.two_sided.unwrap_or(false),
        });
        self.by_name.insert(m.name.clone(), id);
        Ok(())
    }

    fn transform(&self, span: &Range<usize>, t: Option<&TransformDef>) -> Result<Affine3A, SceneError> {
        let Some(t) = t else { return Ok(Affine3A::IDENTITY) };
        let m = if let Some(rows) = t.matrix {
            if t.translate.is_some() || t.rotate.is_some() || t.scale.is_some() {
                return Err(self.err(span.clone(), "transform: `matrix` excludes translate/rotate/scale"));
            }
            if rows[3] != [0.0, 0.0, 0.0, 1.0] {
                return Err(self.err(span.clone(), "transform: the matrix's last row must be [0, 0, 0, 1]"));
            }
            Affine3A::from_mat4(Mat4::from_cols_array_2d(&rows).transpose())
        } else {
            let s = match &t.scale {
                None => Vec3::ONE,
                Some(ScaleDef::Uniform(s)) => Vec3::splat(*s),
                Some(ScaleDef::PerAxis(v)) => Vec3::from(*v),
            };
            let r = match &t.rotate {
                None => Quat::IDENTITY,
                Some(r) => {
                    let axis = Vec3::from(r.axis);
                    if !(axis.is_finite() && axis.length_squared() > 0.0) {
                        return Err(self.err(span.clone(), "transform: rotation axis must be non-zero"));
                    }
                    Quat::from_axis_angle(axis.normalize(), r.deg.to_radians())
                }
            };
            Affine3A::from_scale_rotation_translation(s, r, Vec3::from(t.translate.unwrap_or([0.0; 3])))
        };
        let det = m.matrix3.determinant();
        if !m.is_finite() || det == 0.0 || !det.is_finite() {
            return Err(self.err(span.clone(), "transform: must be finite and invertible"));
        }
        Ok(m)
    }

    fn default_material(&mut self) -> MaterialId {
        if let Some(m) = self.default_mat {
            return m;
        }
        let id = self.scene.add_material(Material::default_grey());
        self.default_mat = Some(id);
        id
    }

    fn object(&mut self, so: &Spanned<ObjectDef>) -> Result<(), SceneError> {
        let span = so.span();
        let o = so.get_ref();
        let transform = self.transform(&span, o.transform.as_ref())?;
        let material = match &o.material {
            Some(name) => Some(
                *self
                    .by_name
                    .get(name)
                    .ok_or_else(|| self.err(span.clone(), format!("unknown material '{name}'")))?,
            ),
            None => None,
        };
        if o.segments.is_some() && o.shape.as_deref() != Some("sphere") {
            return Err(self.err(span, "`segments` applies only to shape = \"sphere\""));
        }
        match (&o.mesh, &o.shape) {
            (Some(file), None) => {
                let first = (self.scene.instances.len(), self.scene.lights.len());
                self.mesh_file(&span, file, transform, material)?;
                self.name_object(&span, o.name.as_deref(), transform, first)
            }
            (None, Some(shape)) => {
                let mat = match material {
                    Some(m) => m,
                    None => self.default_material(),
                };
                let mut mesh = match shape.as_str() {
                    "quad" => shapes::quad(mat),
                    "cube" => shapes::cube(mat),
                    "sphere" => {
                        let seg = o.segments.unwrap_or(48);
                        if !(3..=4096).contains(&seg) {
                            return Err(self.err(span, "sphere segments must be in [3, 4096]"));
                        }
                        shapes::sphere(seg, mat)
                    }
                    other => {
                        return Err(self.err(span, format!("unknown shape '{other}' (quad, cube, sphere)")));
                    }
                };
                if let Some(n) = &o.name {
                    mesh.name = n.clone();
                }
                let first = (self.scene.instances.len(), self.scene.lights.len());
                let id = self.scene.meshes.len() as MeshId;
                self.scene.meshes.push(mesh);
                self.scene.instances.push(Instance { mesh: id, transform, material_override: None });
                self.name_object(&span, o.name.as_deref(), transform, first)
            }
            _ => Err(self.err(span, "an object needs exactly one of `mesh` (a file) or `shape`")),
        }
    }

    /// Records a named object (its instances and lights from index `first` on) so that
    /// animation tracks can move it.
    fn name_object(
        &mut self,
        span: &Range<usize>,
        name: Option<&str>,
        transform: Affine3A,
        first: (usize, usize),
    ) -> Result<(), SceneError> {
        let Some(name) = name else { return Ok(()) };
        if self.anim_objects.contains_key(name) || self.anim_lights.contains_key(name) || name == "camera" {
            return Err(self.err(span.clone(), format!("the name '{name}' is used twice")));
        }
        let to_object = transform.inverse();
        let instances = (first.0..self.scene.instances.len())
            .map(|i| (i as u32, to_object * self.scene.instances[i].transform))
            .collect();
        let lights = (first.1..self.scene.lights.len())
            .map(|i| (i as u32, self.scene.lights[i].transformed(&to_object)))
            .collect();
        self.anim_objects.insert(name.to_string(), ObjectTarget { transform, instances, lights });
        Ok(())
    }

    fn mesh_file(
        &mut self,
        span: &Range<usize>,
        file: &str,
        transform: Affine3A,
        material: Option<MaterialId>,
    ) -> Result<(), SceneError> {
        let p = self.base.join(file);
        if p.extension().is_some_and(|e| e.eq_ignore_ascii_case("toml")) {
            return Err(self.err(span.clone(), "a mesh file cannot be another TOML scene"));
        }
        if !self.files.contains_key(&p) {
            let sub = crate::mesh_file::load_mesh_file(&p)
                .map_err(|e| self.err(span.clone(), format!("cannot load mesh '{file}': {e}")))?;
            let loaded = self.merge(sub);
            self.files.insert(p.clone(), loaded);
        }
        let f = &self.files[&p];
        let insts: Vec<Instance> = f
            .instances
            .iter()
            .map(|i| Instance {
                mesh: i.mesh,
                transform: transform * i.transform,
                material_override: material.or(i.material_override),
            })
            .collect();
        let lights: Vec<Light> = f.lights.iter().map(|l| l.transformed(&transform)).collect();
        self.scene.instances.extend(insts);
        self.scene.lights.extend(lights);
        Ok(())
    }

    /// Appends a loaded file's meshes, materials and textures; returns its instances and
    /// lights with ids remapped to this scene (transforms still in the file's space).
    fn merge(&mut self, sub: Scene) -> LoadedFile {
        let mesh_off = self.scene.meshes.len() as u32;
        let mat_off = self.scene.materials.len() as u32;
        let tex_off = self.scene.textures.len() as u32;
        let shift = |t: &mut Texturable| {
            if let Texturable::Texture { texture, .. } = t {
                *texture += tex_off;
            }
        };
        for mut m in sub.materials {
            match &mut m.bsdf {
                Bsdf::Diffuse { reflectance } => shift(reflectance),
                Bsdf::Plastic { diffuse, .. } => shift(diffuse),
                Bsdf::Conductor { .. } => {}
            }
            self.scene.materials.push(m);
        }
        self.scene.textures.extend(sub.textures);
        for mut m in sub.meshes {
            m.material_ids.iter_mut().for_each(|id| *id += mat_off);
            self.scene.meshes.push(m);
        }
        self.scene.stats.degenerate_triangles_skipped += sub.stats.degenerate_triangles_skipped;
        self.scene.stats.warnings.extend(sub.stats.warnings);
        if sub.animation.is_some() {
            let w = format!(
                "{}: the mesh file's animation is ignored (animate the object with [[tracks]])",
                sub.name
            );
            self.scene.stats.warnings.push(w);
        }
        let instances = sub
            .instances
            .into_iter()
            .map(|i| Instance {
                mesh: i.mesh + mesh_off,
                transform: i.transform,
                material_override: i.material_override.map(|m| m + mat_off),
            })
            .collect();
        LoadedFile { instances, lights: sub.lights }
    }

    fn light(&mut self, sl: &Spanned<LightDef>) -> Result<(), SceneError> {
        let span = sl.span();
        let l = sl.get_ref();
        let what = format!("light '{}'", l.kind);
        let set = [
            ("position", l.position.is_some()),
            ("direction", l.direction.is_some()),
            ("target", l.target.is_some()),
            ("intensity", l.intensity.is_some()),
            ("irradiance", l.irradiance.is_some()),
            ("radiance", l.radiance.is_some()),
            ("cone_angle", l.cone_angle.is_some()),
            ("falloff_start", l.falloff_start.is_some()),
            ("zenith", l.zenith.is_some()),
            ("horizon", l.horizon.is_some()),
            ("ground", l.ground.is_some()),
            ("corner", l.corner.is_some()),
            ("edge1", l.edge1.is_some()),
            ("edge2", l.edge2.is_some()),
            ("two_sided", l.two_sided.is_some()),
        ];
        let need = |v: Option<V3>, key: &str| -> Result<Vec3, SceneError> {
            match v {
                Some(v) if finite3(v) => Ok(Vec3::from(v)),
                Some(_) => Err(self.err(span.clone(), format!("{what}: '{key}' must be finite"))),
                None => Err(self.err(span.clone(), format!("{what}: missing '{key}'"))),
            }
        };
        let dir = |v: Vec3, key: &str| -> Result<Vec3, SceneError> {
            v.try_normalize()
                .ok_or_else(|| self.err(span.clone(), format!("{what}: '{key}' must be non-zero")))
        };
        let light = match l.kind.as_str() {
            "point" => {
                self.only(&span, &what, &set, &["position", "intensity"])?;
                Light::Point {
                    position: need(l.position, "position")?,
                    intensity: self.colour(
                        &span,
                        &what,
                        Some(need(l.intensity, "intensity")?.into()),
                        Rgb::ZERO,
                    )?,
                }
            }
            "spot" => {
                self.only(
                    &span,
                    &what,
                    &set,
                    &["position", "direction", "target", "intensity", "cone_angle", "falloff_start"],
                )?;
                let position = need(l.position, "position")?;
                let direction = match (l.direction, l.target) {
                    (Some(_), None) => dir(need(l.direction, "direction")?, "direction")?,
                    (None, Some(_)) => dir(need(l.target, "target")? - position, "target - position")?,
                    _ => {
                        return Err(
                            self.err(span, format!("{what}: give exactly one of `direction` or `target`"))
                        )
                    }
                };
                let cone = l.cone_angle.unwrap_or(30.0);
                let start = l.falloff_start.unwrap_or(0.75 * cone);
                if !(cone > 0.0 && cone <= 90.0 && start >= 0.0 && start <= cone) {
                    return Err(
                        self.err(span, format!("{what}: need 0 < falloff_start <= cone_angle <= 90 degrees"))
                    );
                }
                Light::Spot {
                    position,
                    direction,
                    intensity: self.colour(
                        &span,
                        &what,
                        Some(need(l.intensity, "intensity")?.into()),
                        Rgb::ZERO,
                    )?,
                    cos_total_width: cone.to_radians().cos(),
                    cos_falloff_start: start.to_radians().cos(),
                }
            }
            "directional" | "sun" => {
                self.only(&span, &what, &set, &["direction", "irradiance"])?;
                Light::Directional {
                    direction: dir(need(l.direction, "direction")?, "direction")?,
                    irradiance: self.colour(
                        &span,
                        &what,
                        Some(need(l.irradiance, "irradiance")?.into()),
                        Rgb::ZERO,
                    )?,
                }
            }
            "environment" => {
                self.only(&span, &what, &set, &["radiance"])?;
                let radiance =
                    self.colour(&span, &what, Some(need(l.radiance, "radiance")?.into()), Rgb::ZERO)?;
                Light::Environment(Environment::Constant { radiance })
            }
            "sky" => {
                self.only(&span, &what, &set, &["zenith", "horizon", "ground"])?;
                Light::Environment(Environment::Sky {
                    zenith: self.colour(&span, &what, l.zenith, Rgb::new(0.25, 0.45, 1.0))?,
                    horizon: self.colour(&span, &what, l.horizon, Rgb::new(0.9, 0.95, 1.0))?,
                    ground: self.colour(&span, &what, l.ground, Rgb::splat(0.2))?,
                })
            }
            "quad" => {
                self.only(&span, &what, &set, &["corner", "edge1", "edge2", "radiance", "two_sided"])?;
                let (c, e1, e2) =
                    (need(l.corner, "corner")?, need(l.edge1, "edge1")?, need(l.edge2, "edge2")?);
                if e1.cross(e2).length_squared() == 0.0 {
                    return Err(self.err(span, format!("{what}: edges must not be parallel")));
                }
                let radiance =
                    self.colour(&span, &what, Some(need(l.radiance, "radiance")?.into()), Rgb::ZERO)?;
                let mut mat = Material::diffuse(&format!("light{}", self.scene.lights.len()), Rgb::ZERO);
                mat.emission = radiance;
                mat.two_sided_emission = l.two_sided.unwrap_or(false);
                let mat = self.scene.add_material(mat);
                let mut mesh = shapes::parallelogram(c, e1, e2, mat);
                mesh.name = "quad_light".into();
                let first = (self.scene.instances.len(), self.scene.lights.len());
                self.scene.add_mesh(mesh);
                return self.name_object(&span, l.name.as_deref(), Affine3A::IDENTITY, first);
            }
            other => {
                return Err(self.err(
                    span,
                    format!(
                    "unknown light type '{other}' (point, spot, directional, sun, environment, sky, quad)"
                ),
                ))
            }
        };
        if let Some(name) = &l.name {
            if self.anim_objects.contains_key(name) || self.anim_lights.contains_key(name) || name == "camera"
            {
                return Err(self.err(span, format!("the name '{name}' is used twice")));
            }
            self.anim_lights.insert(name.clone(), self.scene.lights.len() as u32);
        }
        self.scene.lights.push(light);
        Ok(())
    }
}
