//! glTF 2.0 animations (spec §3.11): channels that key a node's translation, rotation or
//! scale, with `STEP`, `LINEAR` or `CUBICSPLINE` samplers. A moving node carries its
//! subtree: the instances, lights and camera below it.
//!
//! - Every animation of the file plays at once (Blender writes one per action; a channel
//!   keying a property already keyed by an earlier animation is ignored with a warning).
//! - glTF has no frame rate: frames are at [`GLTF_FPS`] (Blender's default), from frame 0 to
//!   the last key.
//! - Morph-target weights are ignored with a warning; an animated node must not carry a
//!   `matrix` (the spec forbids it), else an error.

use filtrace_core::{Affine3A, Quat, Vec3};
use gltf::animation::{Interpolation as GltfInterpolation, Property};

use crate::animation::{
    normalized_rotations, AnimNode, Clock, Interpolation, Keyable, SceneAnimation, Track, TransformTrack,
};
use crate::gltf_accessor::{check_accessor, Kind};
use crate::types::{Camera, Light};

/// Frames per second of a glTF animation's frames.
pub const GLTF_FPS: f32 = 24.0;

/// A node placed by the loader's walk, in walk order (parents before children).
#[derive(Debug)]
pub(crate) struct VisitedNode {
    pub gltf_index: usize,
    /// Walk-order index of the parent.
    pub parent: Option<u32>,
    /// The node's transform relative to its parent.
    pub local: Affine3A,
    pub instances: Vec<u32>,
    /// Lights of the node, in the node's space.
    pub lights: Vec<(u32, Light)>,
    /// The scene camera, if it is this node's, in the node's space.
    pub camera: Option<Camera>,
}

/// The file's animations over the walked nodes; `None` when it has none. Warnings are
/// appended to `warnings`.
pub(crate) fn read_animation(
    doc: &gltf::Document,
    buffers: &[gltf::buffer::Data],
    visited: &[VisitedNode],
    warnings: &mut Vec<String>,
) -> Result<Option<SceneAnimation>, String> {
    if doc.animations().next().is_none() {
        return Ok(None);
    }
    let mut walk_index = vec![None; doc.nodes().len()];
    for (i, v) in visited.iter().enumerate() {
        walk_index[v.gltf_index] = Some(i);
    }
    let mut nodes: Vec<AnimNode> = visited
        .iter()
        .map(|v| AnimNode { name: String::new(), parent: v.parent, track: TransformTrack::at_rest(&v.local) })
        .collect();
    let mut last_key = 0.0f32;
    for anim in doc.animations() {
        for channel in anim.channels() {
            let target = channel.target().node();
            let Some(walk) = walk_index.get(target.index()).copied().flatten() else { continue };
            let at =
                format!("animation {} channel {} (node {})", anim.index(), channel.index(), target.index());
            if let gltf::scene::Transform::Matrix { .. } = target.transform() {
                return Err(format!("{at}: an animated node must not have a matrix (glTF 2.0 §3.11)"));
            }
            let track = &mut nodes[walk].track;
            let keyed = read_channel(&channel, buffers, track).map_err(|m| format!("{at}: {m}"))?;
            match keyed {
                Keyed::Set(end) => last_key = last_key.max(end),
                Keyed::Twice => warnings.push(format!("{at}: property keyed twice, later one ignored")),
                Keyed::MorphWeights => {
                    warnings.push(format!("{at}: morph-target weights are not supported, ignored"))
                }
            }
        }
    }
    let last = (last_key * GLTF_FPS).ceil() as i64;
    let clock = Clock::new(GLTF_FPS, 0, last).map_err(|e| e.to_string())?;
    Ok(Some(place_on_nodes(SceneAnimation::new(clock), nodes, visited)))
}

/// Fills in what each moving node carries (a node moves when it or an ancestor is keyed).
fn place_on_nodes(mut anim: SceneAnimation, nodes: Vec<AnimNode>, visited: &[VisitedNode]) -> SceneAnimation {
    let mut moves = vec![false; nodes.len()];
    for (i, node) in nodes.iter().enumerate() {
        moves[i] = node.track.time_range().is_some() || node.parent.is_some_and(|p| moves[p as usize]);
    }
    for (i, v) in visited.iter().enumerate().filter(|(i, _)| moves[*i]) {
        let n = i as u32;
        anim.instances.extend(v.instances.iter().map(|&inst| (inst, n, Affine3A::IDENTITY)));
        anim.node_lights.extend(v.lights.iter().map(|(l, light)| (*l, n, light.clone())));
        if let Some(camera) = &v.camera {
            anim.node_camera = Some((n, camera.clone()));
        }
    }
    anim.nodes = nodes;
    anim
}

enum Keyed {
    /// Keyed, with the last key's time.
    Set(f32),
    Twice,
    MorphWeights,
}

fn read_channel(
    channel: &gltf::animation::Channel,
    buffers: &[gltf::buffer::Data],
    track: &mut TransformTrack,
) -> Result<Keyed, String> {
    let property = channel.target().property();
    let already = match property {
        Property::Translation => track.translation.is_some(),
        Property::Rotation => track.rotation.is_some(),
        Property::Scale => track.scale.is_some(),
        Property::MorphTargetWeights => return Ok(Keyed::MorphWeights),
    };
    if already {
        return Ok(Keyed::Twice);
    }
    let sampler = channel.sampler();
    check_accessor(&sampler.input(), buffers, "sampler input", Kind::ScalarF32)?;
    let output_kind = if property == Property::Rotation { Kind::Rotation } else { Kind::Vec3F32 };
    check_accessor(&sampler.output(), buffers, "sampler output", output_kind)?;
    let reader = channel.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
    let times: Vec<f32> = reader.read_inputs().ok_or("key times cannot be read")?.collect();
    let interpolation = sampler.interpolation();
    let end = times.last().copied().unwrap_or(0.0);
    use gltf::animation::util::ReadOutputs;
    match reader.read_outputs().ok_or("key values cannot be read")? {
        ReadOutputs::Translations(v) => {
            track.translation = Some(make_track(times, v.map(Vec3::from).collect(), interpolation)?)
        }
        ReadOutputs::Scales(v) => {
            track.scale = Some(make_track(times, v.map(Vec3::from).collect(), interpolation)?)
        }
        ReadOutputs::Rotations(v) => {
            let raw: Vec<Quat> = v.into_f32().map(Quat::from_array).collect();
            let unit = normalized_or_tangents(&raw, interpolation)?;
            track.rotation = Some(make_track(times, unit, interpolation)?)
        }
        ReadOutputs::MorphTargetWeights(_) => return Ok(Keyed::MorphWeights),
    }
    Ok(Keyed::Set(end))
}

/// Rotation values are normalised; cubic-spline tangents (every first and third of a
/// triple) are not unit quaternions and are kept as they are.
fn normalized_or_tangents(raw: &[Quat], interpolation: GltfInterpolation) -> Result<Vec<Quat>, String> {
    if interpolation != GltfInterpolation::CubicSpline {
        return normalized_rotations(raw).map_err(|e| e.to_string());
    }
    let mut out = raw.to_vec();
    for (k, triple) in out.chunks_mut(3).enumerate() {
        if let [_, value, _] = triple {
            *value =
                normalized_rotations(&[*value]).map_err(|_| format!("rotation key {k} has zero length"))?[0];
        }
    }
    Ok(out)
}

/// A track from glTF keys: cubic-spline outputs come as (in-tangent, value, out-tangent)
/// per key (§3.11.2, Appendix C).
fn make_track<T: Keyable>(
    times: Vec<f32>,
    values: Vec<T>,
    interpolation: GltfInterpolation,
) -> Result<Track<T>, String> {
    let track = match interpolation {
        GltfInterpolation::Step => Track::new(times, values, Interpolation::Step),
        GltfInterpolation::Linear => Track::new(times, values, Interpolation::Linear),
        GltfInterpolation::CubicSpline => {
            if values.len() != 3 * times.len() {
                let (n, v) = (times.len(), values.len());
                return Err(format!(
                    "a CUBICSPLINE sampler needs 3 outputs per key: {v} outputs for {n} keys"
                ));
            }
            let column = |c: usize| values.iter().skip(c).step_by(3).copied().collect::<Vec<T>>();
            Track::cubic_spline(times, column(0), column(1), column(2))
        }
    };
    track.map_err(|e| e.to_string())
}
