//! `cornell-anim`: the Cornell box ([`cornell`]) over 49 frames (0..=48 at 24 frames per
//! second): the ceiling light slides around the ceiling on a closed loop and the camera
//! dollies in from the classic viewpoint while panning across the box and back. The light
//! is its own named instance (`light`) moved by its transform; the room is still.
//!
//! Frame 0's pose is the scene's rest pose, so a still render of `cornell-anim` is frame 0.

use filtrace_core::Vec3;

use super::cornell::cornell;
use crate::animation::{
    AnimNode, CameraTrack, Clock, Interpolation, SceneAnimation, Track, TrackError, TransformTrack,
};
use crate::types::{Camera, Scene};

/// Frame rate and last frame (the first is 0).
pub const CORNELL_ANIM_FPS: f32 = 24.0;
pub const CORNELL_ANIM_LAST_FRAME: i64 = 48;

/// Offsets of the light quad from its place in `cornell`, at frames 0, 12, 24, 36, 48: a
/// loop over the ceiling that keeps the quad inside it (x 213..343, z 227..332 at rest).
const LIGHT_LOOP: [[f32; 3]; 5] =
    [[0.0, 0.0, 0.0], [150.0, 0.0, 90.0], [0.0, 0.0, 160.0], [-150.0, 0.0, 90.0], [0.0, 0.0, 0.0]];

/// Camera eyes at frames 0, 16, 32, 48 (a dolly in and a pan) and the point looked at.
const CAMERA_EYES: [[f32; 3]; 4] =
    [[278.0, 273.0, -800.0], [180.0, 330.0, -520.0], [390.0, 220.0, -480.0], [278.0, 273.0, -800.0]];
const CAMERA_TARGET: [f32; 3] = [278.0, 273.0, 280.0];

pub fn cornell_anim() -> Scene {
    let mut s = cornell();
    s.name = "cornell-anim".into();
    let rest = Camera { target: Vec3::from(CAMERA_TARGET), ..Camera::cornell() };
    s.camera = Some(rest.clone());
    let light = s.meshes.iter().position(|m| m.name == "light").expect("cornell has a light") as u32;
    let light_instance =
        s.instances.iter().position(|i| i.mesh == light).expect("the light is placed") as u32;
    let clock = Clock::new(CORNELL_ANIM_FPS, 0, CORNELL_ANIM_LAST_FRAME).expect("a valid clock");
    s.animation = Some(animation(clock, rest, light_instance).expect("valid built-in keys"));
    s
}

fn animation(clock: Clock, rest: Camera, light_instance: u32) -> Result<SceneAnimation, TrackError> {
    let at = |frames: &[i64]| frames.iter().map(|&f| f as f32 / clock.fps).collect::<Vec<_>>();
    let mut anim = SceneAnimation::new(clock);
    let mut light = TransformTrack::at_rest(&filtrace_core::Affine3A::IDENTITY);
    light.translation = Some(Track::new(
        at(&[0, 12, 24, 36, 48]),
        LIGHT_LOOP.iter().map(|&p| Vec3::from(p)).collect(),
        Interpolation::CatmullRom,
    )?);
    anim.nodes.push(AnimNode { name: "light".into(), parent: None, track: light });
    anim.instances.push((light_instance, 0, filtrace_core::Affine3A::IDENTITY));
    let mut camera = CameraTrack::at_rest(rest);
    camera.eye = Some(Track::new(
        at(&[0, 16, 32, 48]),
        CAMERA_EYES.iter().map(|&p| Vec3::from(p)).collect(),
        Interpolation::CatmullRom,
    )?);
    anim.camera = Some(camera);
    Ok(anim)
}
