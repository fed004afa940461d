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

mod lights;
mod materials;
mod objects;

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

    /// Errors when `name` already names an object, a light or the camera: animation tracks
    /// address them by name.
    fn check_name_is_new(&self, span: &Range<usize>, name: &str) -> Result<(), SceneError> {
        if self.anim_objects.contains_key(name) || self.anim_lights.contains_key(name) || name == "camera" {
            return Err(self.err(span.clone(), format!("the name '{name}' is used twice")));
        }
        Ok(())
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
}
