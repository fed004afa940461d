//! A scene's animation and the pose it gives at one time.
//!
//! The scene description keeps its rest pose; [`SceneAnimation::pose`] returns, for a time,
//! only what moves: the camera, the transforms of animated instances and the animated
//! lights (kajiya's per-frame `WorldFrameDesc` in spirit). Applying a pose touches
//! instances and lights, never a triangle, so a per-frame renderer can refit its top level
//! from it.

use super::rig::{CameraTrack, Clock, ClockError, TransformTrack};
use super::track::Track;
use crate::types::{Camera, Light, Scene};
use filtrace_core::{Affine3A, Rgb, Vec3};

/// Everything that moves in a scene, over the frames of its clock.
///
/// Moving things hang from a forest of [`AnimNode`]s (a TOML object is a root node; glTF
/// nodes keep their hierarchy), each instance, light or camera placed relative to its node.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneAnimation {
    pub clock: Clock,
    /// A camera keyed directly (TOML).
    pub camera: Option<CameraTrack>,
    /// Transform nodes, parents before children.
    pub nodes: Vec<AnimNode>,
    /// Instances moved by a node: (instance, node, transform relative to the node).
    pub instances: Vec<(u32, u32, Affine3A)>,
    /// Lights moved by a node: (light, node, the light in the node's space).
    pub node_lights: Vec<(u32, u32, Light)>,
    /// A camera carried by a node (glTF): (node, the camera in the node's space).
    pub node_camera: Option<(u32, Camera)>,
    /// Lights whose own parameters are keyed (TOML).
    pub lights: Vec<LightTrack>,
}

/// A transform node: its transform relative to its parent (or the world) over time.
#[derive(Clone, Debug, PartialEq)]
pub struct AnimNode {
    pub name: String,
    /// Index into [`SceneAnimation::nodes`], always smaller than this node's own.
    pub parent: Option<u32>,
    pub track: TransformTrack,
}

/// A point, spot or directional light whose parameters are keyed.
#[derive(Clone, Debug, PartialEq)]
pub struct LightTrack {
    pub name: String,
    /// Index into [`Scene::lights`].
    pub light: u32,
    pub position: Option<Track<Vec3>>,
    /// Unit direction keys (a spot's axis, or towards a directional light's source).
    pub direction: Option<Track<Vec3>>,
    /// Radiant intensity of a point or spot light, or the irradiance of a directional one.
    pub intensity: Option<Track<Vec3>>,
}

/// What moves at one time: the camera and the new state of every animated instance and
/// light (indices into the scene's lists).
#[derive(Clone, Debug, PartialEq)]
pub struct Pose {
    pub time: f32,
    pub camera: Option<Camera>,
    pub instances: Vec<(u32, Affine3A)>,
    pub lights: Vec<(u32, Light)>,
}

impl SceneAnimation {
    /// An animation of `clock` that moves nothing yet.
    pub fn new(clock: Clock) -> Self {
        SceneAnimation {
            clock,
            camera: None,
            nodes: Vec::new(),
            instances: Vec::new(),
            node_lights: Vec::new(),
            node_camera: None,
            lights: Vec::new(),
        }
    }

    /// World transforms of the nodes at time `t` (parents come first, so one pass).
    pub fn node_transforms(&self, t: f32) -> Vec<Affine3A> {
        let mut world: Vec<Affine3A> = Vec::with_capacity(self.nodes.len());
        for node in &self.nodes {
            let local = node.track.sample(t);
            world.push(match node.parent {
                Some(p) => world[p as usize] * local,
                None => local,
            });
        }
        world
    }

    /// The pose at time `t`, with `rest_lights` the scene's lights in their rest pose.
    pub fn pose(&self, rest_lights: &[Light], t: f32) -> Pose {
        let world = self.node_transforms(t);
        let mut camera = self.camera.as_ref().map(|c| c.sample(t));
        if let Some((node, local)) = &self.node_camera {
            camera = Some(local.transformed(&world[*node as usize]));
        }
        let instances =
            self.instances.iter().map(|&(i, node, local)| (i, world[node as usize] * local)).collect();
        let mut lights: Vec<(u32, Light)> =
            self.node_lights.iter().map(|(i, node, l)| (*i, l.transformed(&world[*node as usize]))).collect();
        for track in &self.lights {
            lights.push((track.light, track.sample(&rest_lights[track.light as usize], t)));
        }
        Pose { time: t, camera, instances, lights }
    }

    /// Earliest and latest key of every track (`None` when nothing is keyed).
    pub fn key_range(&self) -> Option<(f32, f32)> {
        let camera = self.camera.as_ref().and_then(CameraTrack::time_range);
        let objects = self.nodes.iter().filter_map(|n| n.track.time_range());
        let lights = self.lights.iter().filter_map(LightTrack::time_range);
        camera.into_iter().chain(objects).chain(lights).reduce(|(a0, a1), (b0, b1)| (a0.min(b0), a1.max(b1)))
    }
}

impl LightTrack {
    /// `rest` with the keyed parameters at time `t`.
    pub fn sample(&self, rest: &Light, t: f32) -> Light {
        let pos = |p: Vec3| self.position.as_ref().map_or(p, |k| k.sample(t));
        let dir = |d: Vec3| self.direction.as_ref().map_or(d, |k| k.sample(t).normalize_or(d));
        let power = |i: Rgb| self.intensity.as_ref().map_or(i, |k| Rgb::from(k.sample(t).max(Vec3::ZERO)));
        match rest.clone() {
            Light::Point { position, intensity } => {
                Light::Point { position: pos(position), intensity: power(intensity) }
            }
            Light::Spot { position, direction, intensity, cos_total_width, cos_falloff_start } => {
                Light::Spot {
                    position: pos(position),
                    direction: dir(direction),
                    intensity: power(intensity),
                    cos_total_width,
                    cos_falloff_start,
                }
            }
            Light::Directional { direction, irradiance } => {
                Light::Directional { direction: dir(direction), irradiance: power(irradiance) }
            }
            env @ Light::Environment(_) => env,
        }
    }

    fn time_range(&self) -> Option<(f32, f32)> {
        let ranges = [&self.position, &self.direction, &self.intensity];
        ranges
            .into_iter()
            .flatten()
            .map(Track::time_range)
            .reduce(|(a0, a1), (b0, b1)| (a0.min(b0), a1.max(b1)))
    }
}

impl Scene {
    /// The pose of frame `frame` of the scene's animation; a still scene has one pose, its
    /// own, at every frame (so a still scene renders identically as any frame).
    pub fn pose_at_frame(&self, frame: i64) -> Result<Pose, ClockError> {
        match &self.animation {
            Some(anim) => Ok(anim.pose(&self.lights, anim.clock.time_of(frame)?)),
            None => Ok(Pose { time: 0.0, camera: None, instances: Vec::new(), lights: Vec::new() }),
        }
    }

    /// Moves the camera, instances and lights to `pose`. Costs one write per moved
    /// instance and light; meshes are untouched.
    pub fn apply_pose(&mut self, pose: &Pose) {
        if let Some(camera) = &pose.camera {
            self.camera = Some(camera.clone());
        }
        for &(i, transform) in &pose.instances {
            self.instances[i as usize].transform = transform;
        }
        for (i, light) in &pose.lights {
            self.lights[*i as usize] = light.clone();
        }
    }
}
