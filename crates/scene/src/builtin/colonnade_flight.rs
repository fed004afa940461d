//! `colonnade-flight`: a camera flight through [`colonnade`] over 97 frames (0..=96 at 24
//! frames per second). The camera starts at the still scene's viewpoint, flies down the
//! front aisle, threads between two pillars of the third row under its beams, comes back
//! along the middle aisle and leaves through the second row: the pillars' thin shadows and
//! silhouettes sweep across the frame. Only the camera moves.
//!
//! Frame 0's pose is the rest pose (the still `colonnade` camera).

use filtrace_core::Vec3;

use super::colonnade::colonnade;
use crate::animation::{CameraTrack, Clock, Interpolation, SceneAnimation, Track, TrackError};
use crate::types::Scene;

pub const FLIGHT_FPS: f32 = 24.0;
pub const FLIGHT_LAST_FRAME: i64 = 96;

/// Eye and target keys every 12 frames. The crossings of a pillar row (z = 1.5 and
/// z = -1.5) are at x = +-5.6, half-way between two pillars (1.4 m apart), at heights
/// between the rail (1.1 m) and the lower beam (3.6 m).
const EYES: [[f32; 3]; 9] = [
    [-7.2, 1.7, 3.0],
    [-4.0, 1.8, 3.0],
    [0.0, 2.0, 3.0],
    [3.5, 2.2, 2.6],
    [5.6, 2.3, 1.5],
    [4.0, 2.2, 0.0],
    [0.0, 2.0, -0.2],
    [-3.5, 1.8, 0.0],
    [-5.6, 1.6, -1.5],
];
const TARGETS: [[f32; 3]; 9] = [
    [2.0, 0.8, 0.0],
    [2.0, 1.2, 2.0],
    [5.0, 1.8, 2.4],
    [6.2, 2.0, 0.8],
    [4.5, 2.0, -0.5],
    [0.0, 1.9, -0.4],
    [-4.0, 1.7, 0.0],
    [-6.0, 1.5, -2.0],
    [-6.2, 1.4, -4.0],
];

pub fn colonnade_flight() -> Scene {
    let mut s = colonnade();
    s.name = "colonnade-flight".into();
    let rest = s.camera.clone().expect("colonnade has a camera");
    debug_assert_eq!(rest.eye, Vec3::from(EYES[0]));
    debug_assert_eq!(rest.target, Vec3::from(TARGETS[0]));
    let clock = Clock::new(FLIGHT_FPS, 0, FLIGHT_LAST_FRAME).expect("a valid clock");
    let mut camera = CameraTrack::at_rest(rest);
    let tracks = (|| -> Result<_, TrackError> {
        let times: Vec<f32> = (0..EYES.len()).map(|k| (12 * k) as f32 / FLIGHT_FPS).collect();
        let keys = |v: &[[f32; 3]]| v.iter().map(|&p| Vec3::from(p)).collect();
        Ok((
            Track::new(times.clone(), keys(&EYES), Interpolation::CatmullRom)?,
            Track::new(times, keys(&TARGETS), Interpolation::CatmullRom)?,
        ))
    })();
    let (eye, target) = tracks.expect("valid built-in keys");
    camera.eye = Some(eye);
    camera.target = Some(target);
    let mut anim = SceneAnimation::new(clock);
    anim.camera = Some(camera);
    s.animation = Some(anim);
    s
}
