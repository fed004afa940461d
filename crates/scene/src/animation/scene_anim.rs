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
#[derive(Clone, Debug, PartialEq)]
pub struct SceneAnimation {
    pub clock: Clock,
    pub camera: Option<CameraTrack>,
    pub objects: Vec<ObjectTrack>,
    pub lights: Vec<LightTrack>,
}

/// A named object (a shape, a mesh file's instances, or an area light) moved as one.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectTrack {
    pub name: String,
    /// The object's transform over time (its rest pose is the transform in the file).
    pub track: TransformTrack,
    /// Instances it places, each with its transform relative to the object (a mesh
    /// file's own node transforms; the identity for shapes).
    pub instances: Vec<(u32, Affine3A)>,
    /// Lights that came with the object's mesh file, in the file's space.
    pub lights: Vec<(u32, Light)>,
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
    /// The pose at time `t`, with `rest_lights` the scene's lights in their rest pose.
    pub fn pose(&self, rest_lights: &[Light], t: f32) -> Pose {
        let mut pose = Pose {
            time: t,
            camera: self.camera.as_ref().map(|c| c.sample(t)),
            instances: Vec::new(),
            lights: Vec::new(),
        };
        for object in &self.objects {
            let m = object.track.sample(t);
            pose.instances.extend(object.instances.iter().map(|&(i, local)| (i, m * local)));
            pose.lights.extend(object.lights.iter().map(|(i, l)| (*i, l.transformed(&m))));
        }
        for track in &self.lights {
            pose.lights.push((track.light, track.sample(&rest_lights[track.light as usize], t)));
        }
        pose
    }

    /// Earliest and latest key of every track (`None` when nothing is keyed).
    pub fn key_range(&self) -> Option<(f32, f32)> {
        let camera = self.camera.as_ref().and_then(CameraTrack::time_range);
        let objects = self.objects.iter().filter_map(|o| o.track.time_range());
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
