//! What moves in a scene: an object's transform, the camera and a clock that turns frame
//! numbers into times.

use super::track::Track;
use crate::types::Camera;
use filtrace_core::{Affine3A, Quat, Vec3};
use std::fmt;

/// Translation, rotation and scale over time (glTF's TRS). A missing track keeps the
/// rest pose's component, as a glTF node without that channel does.
#[derive(Clone, Debug, PartialEq)]
pub struct TransformTrack {
    pub translation: Option<Track<Vec3>>,
    pub rotation: Option<Track<Quat>>,
    pub scale: Option<Track<Vec3>>,
    /// The pose used for components without a track.
    pub rest: (Vec3, Quat, Vec3),
}

impl TransformTrack {
    /// A track that animates nothing yet, resting at `rest` (scale, rotation, translation).
    pub fn at_rest(rest: &Affine3A) -> Self {
        let (scale, rotation, translation) = rest.to_scale_rotation_translation();
        TransformTrack {
            translation: None,
            rotation: None,
            scale: None,
            rest: (translation, rotation, scale),
        }
    }

    /// Object-to-world (or to parent) transform at time `t`.
    pub fn sample(&self, t: f32) -> Affine3A {
        let (rest_t, rest_r, rest_s) = self.rest;
        let translation = self.translation.as_ref().map_or(rest_t, |k| k.sample(t));
        let rotation = self.rotation.as_ref().map_or(rest_r, |k| k.sample(t));
        let scale = self.scale.as_ref().map_or(rest_s, |k| k.sample(t));
        Affine3A::from_scale_rotation_translation(scale, rotation, translation)
    }

    /// Earliest and latest key over the tracks present (`None` when nothing is keyed).
    pub fn time_range(&self) -> Option<(f32, f32)> {
        let ranges = [
            self.translation.as_ref().map(Track::time_range),
            self.rotation.as_ref().map(Track::time_range),
            self.scale.as_ref().map(Track::time_range),
        ];
        union_ranges(ranges.into_iter().flatten())
    }
}

/// A camera over time: each of eye, target, up and field of view may be keyed.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraTrack {
    pub eye: Option<Track<Vec3>>,
    pub target: Option<Track<Vec3>>,
    pub up: Option<Track<Vec3>>,
    pub vfov_deg: Option<Track<f32>>,
    /// The camera used for components without a track.
    pub rest: Camera,
}

impl CameraTrack {
    pub fn at_rest(rest: Camera) -> Self {
        CameraTrack { eye: None, target: None, up: None, vfov_deg: None, rest }
    }

    pub fn sample(&self, t: f32) -> Camera {
        let r = &self.rest;
        Camera {
            eye: self.eye.as_ref().map_or(r.eye, |k| k.sample(t)),
            target: self.target.as_ref().map_or(r.target, |k| k.sample(t)),
            up: self.up.as_ref().map_or(r.up, |k| k.sample(t)),
            vfov_deg: self.vfov_deg.as_ref().map_or(r.vfov_deg, |k| k.sample(t)),
        }
    }

    pub fn time_range(&self) -> Option<(f32, f32)> {
        let ranges = [
            self.eye.as_ref().map(Track::time_range),
            self.target.as_ref().map(Track::time_range),
            self.up.as_ref().map(Track::time_range),
            self.vfov_deg.as_ref().map(Track::time_range),
        ];
        union_ranges(ranges.into_iter().flatten())
    }
}

fn union_ranges(ranges: impl Iterator<Item = (f32, f32)>) -> Option<(f32, f32)> {
    ranges.reduce(|(a0, a1), (b0, b1)| (a0.min(b0), a1.max(b1)))
}

/// Frame numbers to times: frame `f` is at `f / fps` seconds, and an animation covers the
/// frames `first..=last`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clock {
    pub fps: f32,
    pub first: i64,
    pub last: i64,
}

/// A frame number or clock setting that cannot be used.
#[derive(Clone, Debug, PartialEq)]
pub enum ClockError {
    BadRate { fps: f32 },
    EmptyRange { first: i64, last: i64 },
    FrameOutside { frame: i64, first: i64, last: i64 },
}

impl fmt::Display for ClockError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ClockError::BadRate { fps } => write!(f, "frame rate {fps} must be a finite number above 0"),
            ClockError::EmptyRange { first, last } => {
                write!(f, "frame range {first}..{last} is empty: the last frame comes before the first")
            }
            ClockError::FrameOutside { frame, first, last } => {
                write!(f, "frame {frame} is outside the animation's frames {first}..{last}")
            }
        }
    }
}

impl std::error::Error for ClockError {}

impl Clock {
    pub fn new(fps: f32, first: i64, last: i64) -> Result<Self, ClockError> {
        if !(fps.is_finite() && fps > 0.0) {
            return Err(ClockError::BadRate { fps });
        }
        if last < first {
            return Err(ClockError::EmptyRange { first, last });
        }
        Ok(Clock { fps, first, last })
    }

    /// The time of `frame`, refusing frames outside the range.
    pub fn time_of(&self, frame: i64) -> Result<f32, ClockError> {
        if frame < self.first || frame > self.last {
            return Err(ClockError::FrameOutside { frame, first: self.first, last: self.last });
        }
        Ok((frame as f64 / self.fps as f64) as f32)
    }

    pub fn frame_count(&self) -> u64 {
        (self.last - self.first) as u64 + 1
    }
}
