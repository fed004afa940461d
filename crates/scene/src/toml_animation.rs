//! The `[animation]` table and `[[tracks]]` of TOML scene files (docs/scenes.md,
//! "Animation"):
//!
//! ```toml
//! [animation]
//! fps = 24
//! frames = [0, 48]                  # first and last frame, inclusive
//!
//! [[tracks]]
//! target = "camera"                 # "camera", or the `name` of an object or light
//! property = "eye"                  # see PROPERTIES
//! interpolation = "catmull-rom"     # step | linear (default) | catmull-rom
//! keys = [ { t = 0, value = [0, 1, 5] }, { frame = 48, value = [3, 1, 5] } ]
//! ```
//!
//! A key gives its time in seconds (`t`) or in frames (`frame`). Rotation keys are
//! `{ deg = 30, axis = [0, 1, 0] }` or a quaternion `[x, y, z, w]`; scale keys a number
//! or three. Errors name the file and the line of the track or key.

use std::collections::HashMap;
use std::ops::Range;
use std::path::Path;

use filtrace_core::{Affine3A, Quat, Vec3};
use serde::Deserialize;
use toml::{Spanned, Value};

use crate::animation::{
    normalized_rotations, AnimNode, CameraTrack, Clock, Interpolation, Keyable, LightTrack, SceneAnimation,
    Track, TrackError, TransformTrack,
};
use crate::error::{line_of, SceneError};
use crate::types::{Camera, Light};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct AnimationDef {
    fps: f32,
    frames: [i64; 2],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct TrackDef {
    target: String,
    property: String,
    interpolation: Option<String>,
    keys: Vec<Spanned<KeyDef>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct KeyDef {
    t: Option<f64>,
    frame: Option<f64>,
    value: Value,
}

/// The animatable properties, by target kind.
pub const PROPERTIES: &[(&str, &[&str])] = &[
    ("camera", &["eye", "target", "up", "vfov"]),
    ("object", &["translate", "rotate", "scale"]),
    ("light", &["position", "direction", "intensity"]),
];

/// A named object of the scene file, as placed at rest.
pub(crate) struct ObjectTarget {
    pub transform: Affine3A,
    /// Instances and their transforms relative to the object.
    pub instances: Vec<(u32, Affine3A)>,
    /// Lights of the object's mesh file, in the file's space.
    pub lights: Vec<(u32, Light)>,
}

/// What the scene file defined that tracks may name.
pub(crate) struct Targets<'a> {
    pub objects: &'a HashMap<String, ObjectTarget>,
    pub lights: &'a HashMap<String, u32>,
    pub scene_lights: &'a [Light],
    pub camera: Option<&'a Camera>,
}

/// Parses the tracks against `targets`; `None` when the file has no `[animation]`.
pub(crate) fn build_animation(
    src: &str,
    path: &Path,
    anim: Option<&Spanned<AnimationDef>>,
    tracks: &[Spanned<TrackDef>],
    targets: &Targets,
) -> Result<Option<SceneAnimation>, SceneError> {
    let p = Parser { src, path };
    let Some(anim) = anim else {
        return match tracks.first() {
            Some(t) => Err(p.err(t.span(), "tracks need an [animation] table (fps, frames)")),
            None => Ok(None),
        };
    };
    let def = anim.get_ref();
    let clock = Clock::new(def.fps, def.frames[0], def.frames[1])
        .map_err(|e| p.err(anim.span(), format!("animation: {e}")))?;
    let mut builder =
        AnimationBuilder { p, clock, targets, anim: SceneAnimation::new(clock), objects: HashMap::new() };
    for track in tracks {
        builder.track(track)?;
    }
    Ok(Some(builder.anim))
}

struct Parser<'a> {
    src: &'a str,
    path: &'a Path,
}

impl Parser<'_> {
    fn err(&self, span: Range<usize>, msg: impl Into<String>) -> SceneError {
        SceneError::parse(self.path, Some(line_of(self.src, span)), msg)
    }
}

struct AnimationBuilder<'a> {
    p: Parser<'a>,
    clock: Clock,
    targets: &'a Targets<'a>,
    anim: SceneAnimation,
    /// Index into `anim.nodes` by object name.
    objects: HashMap<String, usize>,
}

/// A key's time and value, with its span for errors.
struct Key<'a> {
    time: f32,
    value: &'a Value,
    span: Range<usize>,
}

impl AnimationBuilder<'_> {
    fn track(&mut self, st: &Spanned<TrackDef>) -> Result<(), SceneError> {
        let (span, t) = (st.span(), st.get_ref());
        let what = format!("track '{}'.{}", t.target, t.property);
        let interpolation = match t.interpolation.as_deref().unwrap_or("linear") {
            "step" => Interpolation::Step,
            "linear" => Interpolation::Linear,
            "catmull-rom" => Interpolation::CatmullRom,
            other => {
                let msg = format!("{what}: unknown interpolation '{other}' (step, linear, catmull-rom)");
                return Err(self.p.err(span, msg));
            }
        };
        let keys = self.keys(&what, &span, &t.keys)?;
        let ctx = TrackCtx { what: &what, span: &span, keys: &keys, interpolation };
        if t.target == "camera" {
            self.camera_track(&ctx, &t.property)
        } else if let Some(object) = self.targets.objects.get(&t.target) {
            if self.targets.lights.contains_key(&t.target) {
                return Err(self
                    .p
                    .err(span, format!("{what}: '{}' names both an object and a light", t.target)));
            }
            self.object_track(&ctx, &t.target, object, &t.property)
        } else if let Some(&light) = self.targets.lights.get(&t.target) {
            self.light_track(&ctx, &t.target, light, &t.property)
        } else {
            Err(self.p.err(span, format!("{what}: no object or light is named '{}'", t.target)))
        }
    }

    fn keys<'k>(
        &self,
        what: &str,
        span: &Range<usize>,
        defs: &'k [Spanned<KeyDef>],
    ) -> Result<Vec<Key<'k>>, SceneError> {
        if defs.is_empty() {
            return Err(self.p.err(span.clone(), format!("{what}: no keys")));
        }
        let key = |k: &'k Spanned<KeyDef>| {
            let time = match (k.get_ref().t, k.get_ref().frame) {
                (Some(t), None) => t,
                (None, Some(f)) => f / self.clock.fps as f64,
                _ => {
                    return Err(self
                        .p
                        .err(k.span(), format!("{what}: a key needs exactly one of `t` or `frame`")))
                }
            };
            if !time.is_finite() {
                return Err(self.p.err(k.span(), format!("{what}: key time must be finite")));
            }
            Ok(Key { time: time as f32, value: &k.get_ref().value, span: k.span() })
        };
        defs.iter().map(key).collect()
    }

    fn camera_track(&mut self, ctx: &TrackCtx, property: &str) -> Result<(), SceneError> {
        let Some(rest) = self.targets.camera else {
            return Err(self
                .p
                .err(ctx.span.clone(), format!("{}: camera tracks need a [camera] table", ctx.what)));
        };
        let cam = self.anim.camera.get_or_insert_with(|| CameraTrack::at_rest(rest.clone()));
        let p = &self.p;
        match property {
            "eye" if cam.eye.is_none() => cam.eye = Some(ctx.vec3_track(p, finite)?),
            "target" if cam.target.is_none() => cam.target = Some(ctx.vec3_track(p, finite)?),
            "up" if cam.up.is_none() => cam.up = Some(ctx.vec3_track(p, nonzero)?),
            "vfov" if cam.vfov_deg.is_none() => cam.vfov_deg = Some(ctx.vfov_track(p)?),
            "eye" | "target" | "up" | "vfov" => return Err(ctx.duplicate(p)),
            other => return Err(ctx.unknown_property(p, other, "camera")),
        }
        Ok(())
    }

    fn object_track(
        &mut self,
        ctx: &TrackCtx,
        name: &str,
        object: &ObjectTarget,
        property: &str,
    ) -> Result<(), SceneError> {
        let index = match self.objects.get(name) {
            Some(&index) => index,
            None => self.add_object_node(name, object),
        };
        let track = &mut self.anim.nodes[index].track;
        let p = &self.p;
        match property {
            "translate" if track.translation.is_none() => {
                track.translation = Some(ctx.vec3_track(p, finite)?)
            }
            "rotate" if track.rotation.is_none() => track.rotation = Some(ctx.rotation_track(p)?),
            "scale" if track.scale.is_none() => track.scale = Some(ctx.scale_track(p)?),
            "translate" | "rotate" | "scale" => return Err(ctx.duplicate(p)),
            other => return Err(ctx.unknown_property(p, other, "object")),
        }
        Ok(())
    }

    /// A root node for a named object, carrying its instances and its mesh file's lights.
    fn add_object_node(&mut self, name: &str, object: &ObjectTarget) -> usize {
        let node = self.anim.nodes.len();
        let track = TransformTrack::at_rest(&object.transform);
        self.anim.nodes.push(AnimNode { name: name.to_string(), parent: None, track });
        let n = node as u32;
        self.anim.instances.extend(object.instances.iter().map(|&(i, local)| (i, n, local)));
        self.anim.node_lights.extend(object.lights.iter().map(|(i, l)| (*i, n, l.clone())));
        self.objects.insert(name.to_string(), node);
        node
    }

    fn light_track(
        &mut self,
        ctx: &TrackCtx,
        name: &str,
        light: u32,
        property: &str,
    ) -> Result<(), SceneError> {
        let p = &self.p;
        let rest = &self.targets.scene_lights[light as usize];
        let applies = match (rest, property) {
            (Light::Point { .. } | Light::Spot { .. }, "position") => true,
            (Light::Spot { .. } | Light::Directional { .. }, "direction") => true,
            (Light::Point { .. } | Light::Spot { .. } | Light::Directional { .. }, "intensity") => true,
            (_, "position" | "direction" | "intensity") => false,
            (_, other) => return Err(ctx.unknown_property(p, other, "light")),
        };
        if !applies {
            return Err(
                p.err(ctx.span.clone(), format!("{}: this kind of light has no {property}", ctx.what))
            );
        }
        let index = match self.anim.lights.iter().position(|l| l.light == light) {
            Some(i) => i,
            None => {
                let track = LightTrack {
                    name: name.to_string(),
                    light,
                    position: None,
                    direction: None,
                    intensity: None,
                };
                self.anim.lights.push(track);
                self.anim.lights.len() - 1
            }
        };
        let track = &mut self.anim.lights[index];
        let slot = match property {
            "position" => &mut track.position,
            "direction" => &mut track.direction,
            _ => &mut track.intensity,
        };
        if slot.is_some() {
            return Err(ctx.duplicate(p));
        }
        let check = match property {
            "position" => finite,
            "direction" => nonzero,
            _ => non_negative,
        };
        *slot = Some(ctx.vec3_track(p, check)?);
        Ok(())
    }
}

/// One track being built: its name for messages, span, keys and interpolation.
struct TrackCtx<'a> {
    what: &'a str,
    span: &'a Range<usize>,
    keys: &'a [Key<'a>],
    interpolation: Interpolation,
}

type Check = fn(Vec3) -> Result<(), &'static str>;

fn finite(v: Vec3) -> Result<(), &'static str> {
    if v.is_finite() {
        Ok(())
    } else {
        Err("values must be finite")
    }
}

fn nonzero(v: Vec3) -> Result<(), &'static str> {
    finite(v)?;
    if v.length_squared() > 0.0 {
        Ok(())
    } else {
        Err("directions must be non-zero")
    }
}

fn non_negative(v: Vec3) -> Result<(), &'static str> {
    finite(v)?;
    if v.min_element() >= 0.0 {
        Ok(())
    } else {
        Err("intensities must be non-negative")
    }
}

fn scale_factor(v: Vec3) -> Result<(), &'static str> {
    finite(v)?;
    if v.x * v.y * v.z != 0.0 {
        Ok(())
    } else {
        Err("scale factors must be non-zero")
    }
}

impl TrackCtx<'_> {
    fn duplicate(&self, p: &Parser) -> SceneError {
        p.err(self.span.clone(), format!("{}: this property is keyed by an earlier track too", self.what))
    }

    fn unknown_property(&self, p: &Parser, property: &str, kind: &str) -> SceneError {
        let known = PROPERTIES.iter().find(|(k, _)| *k == kind).map_or(&[][..], |(_, v)| *v);
        let msg =
            format!("{}: a {kind} has no property '{property}' (known: {})", self.what, known.join(", "));
        p.err(self.span.clone(), msg)
    }

    fn key_err(&self, p: &Parser, key: &Key, msg: impl std::fmt::Display) -> SceneError {
        p.err(key.span.clone(), format!("{}: {msg}", self.what))
    }

    fn vec3_track(&self, p: &Parser, check: Check) -> Result<Track<Vec3>, SceneError> {
        let values = self.values(p, |v| {
            let v = numbers::<3>(v).map(Vec3::from).ok_or("expected [x, y, z]")?;
            check(v).map(|_| v)
        })?;
        self.finish(p, values)
    }

    /// Scale keys: three factors, or one for a uniform scale.
    fn scale_track(&self, p: &Parser) -> Result<Track<Vec3>, SceneError> {
        let values = self.values(p, |v| {
            let v = number(v).map(Vec3::splat).or_else(|| numbers::<3>(v).map(Vec3::from));
            let v = v.ok_or("expected a number or [x, y, z]")?;
            scale_factor(v).map(|_| v)
        })?;
        self.finish(p, values)
    }

    fn vfov_track(&self, p: &Parser) -> Result<Track<f32>, SceneError> {
        let values = self.values(p, |v| match number(v) {
            Some(deg) if deg > 0.0 && deg < 180.0 => Ok(deg),
            _ => Err("vfov keys must be numbers in (0, 180) degrees"),
        })?;
        self.finish(p, values)
    }

    fn rotation_track(&self, p: &Parser) -> Result<Track<Quat>, SceneError> {
        let values = self.values(p, |v| {
            rotation_value(v).ok_or("expected { deg = .., axis = [x, y, z] } or [x, y, z, w]")
        })?;
        let unit = normalized_rotations(&values).map_err(|e| self.track_err(p, e))?;
        self.finish(p, unit)
    }

    fn values<T>(
        &self,
        p: &Parser,
        parse: impl Fn(&Value) -> Result<T, &'static str>,
    ) -> Result<Vec<T>, SceneError> {
        self.keys.iter().map(|k| parse(k.value).map_err(|m| self.key_err(p, k, m))).collect()
    }

    fn finish<T: Keyable>(&self, p: &Parser, values: Vec<T>) -> Result<Track<T>, SceneError> {
        let times = self.keys.iter().map(|k| k.time).collect();
        Track::new(times, values, self.interpolation).map_err(|e| self.track_err(p, e))
    }

    /// A track error reported at the line of the key it names.
    fn track_err(&self, p: &Parser, e: TrackError) -> SceneError {
        let index = match &e {
            TrackError::TimesOutOfOrder { index, .. }
            | TrackError::NonFiniteTime { index }
            | TrackError::NonFiniteValue { index, .. }
            | TrackError::ZeroQuaternion { index } => Some(*index),
            TrackError::Empty | TrackError::LengthMismatch { .. } => None,
        };
        match index.and_then(|i| self.keys.get(i)) {
            Some(key) => self.key_err(p, key, e),
            None => p.err(self.span.clone(), format!("{}: {e}", self.what)),
        }
    }
}

fn number(v: &Value) -> Option<f32> {
    match v {
        Value::Integer(i) => Some(*i as f32),
        Value::Float(f) => Some(*f as f32),
        _ => None,
    }
}

fn numbers<const N: usize>(v: &Value) -> Option<[f32; N]> {
    let a = v.as_array().filter(|a| a.len() == N)?;
    let mut out = [0.0; N];
    for (o, x) in out.iter_mut().zip(a) {
        *o = number(x)?;
    }
    Some(out)
}

fn rotation_value(v: &Value) -> Option<Quat> {
    if let Some([x, y, z, w]) = numbers::<4>(v) {
        return Some(Quat::from_xyzw(x, y, z, w));
    }
    let table = v.as_table().filter(|t| t.len() == 2)?;
    let deg = number(table.get("deg")?)?;
    let axis = Vec3::from(numbers::<3>(table.get("axis")?)?).try_normalize()?;
    Some(Quat::from_axis_angle(axis, deg.to_radians()))
}
