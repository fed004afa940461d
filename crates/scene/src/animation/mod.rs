//! Scenes over time: keyframe tracks and the things they move.
//!
//! A [`Track`] is a keyed value (times, values, an [`Interpolation`]); a [`TransformTrack`]
//! moves an instance, a [`CameraTrack`] the camera, and a [`Clock`] maps frame numbers to
//! times. Tracks are checked when built (times finite and strictly increasing, values
//! finite, rotations of non-zero length), so sampling never fails; loaders turn a
//! [`TrackError`] into an error naming their file and line.

mod rig;
mod scene_anim;
mod track;

pub use rig::{CameraTrack, Clock, ClockError, TransformTrack};
pub use scene_anim::{AnimNode, LightTrack, Pose, SceneAnimation};
pub use track::{hermite, normalized_rotations, Interpolation, Keyable, Track, TrackError};

#[cfg(test)]
mod tests;
