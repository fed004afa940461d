//! The timeline of an animated scene: which frame is shown, playback at the animation's
//! frame rate, and whether the camera follows the animation's camera track.
//!
//! Playback follows the wall clock (frame = start frame + elapsed seconds x fps, wrapping
//! at the end): when rendering is slower than the animation, frames are skipped rather than
//! the animation slowed down. Stepping or scrubbing pauses it.

use std::time::Instant;

use filtrace_scene::animation::{Clock, SceneAnimation};
use filtrace_scene::{Camera, Light, Scene};

pub struct Timeline {
    pub clock: Clock,
    animation: SceneAnimation,
    /// The scene's lights at rest (the pose of a frame is computed from them).
    rest_lights: Vec<Light>,
    frame: i64,
    /// Playing since: (frame, instant) playback started from.
    playing: Option<(i64, Instant)>,
    /// The camera is the animation's camera track's (until the user moves it).
    pub follow_camera: bool,
}

impl Timeline {
    /// The timeline of `scene` at frame `start` (the animation's first frame when `None`);
    /// `Ok(None)` for a scene without animation. Error: `start` outside the animation.
    pub fn new(scene: &Scene, start: Option<i64>) -> Result<Option<Self>, String> {
        let Some(animation) = scene.animation.clone() else { return Ok(None) };
        let clock = animation.clock;
        let frame = start.unwrap_or(clock.first);
        if clock.time_of(frame).is_err() {
            return Err(format!(
                "frame {frame} is outside the animation of scene '{}', which has frames {}..{}",
                scene.name, clock.first, clock.last
            ));
        }
        let follow_camera = animation.camera.is_some();
        Ok(Some(Self {
            clock,
            animation,
            rest_lights: scene.lights.clone(),
            frame,
            playing: None,
            follow_camera,
        }))
    }

    pub fn frame(&self) -> i64 {
        self.frame
    }

    /// Seconds of the shown frame on the animation's clock.
    pub fn time(&self) -> f64 {
        self.frame as f64 / self.clock.fps as f64
    }

    pub fn playing(&self) -> bool {
        self.playing.is_some()
    }

    pub fn has_camera_track(&self) -> bool {
        self.animation.camera.is_some()
    }

    /// The camera the animation gives the shown frame (`None` without a camera track).
    pub fn animated_camera(&self) -> Option<Camera> {
        let t = self.clock.time_of(self.frame).ok()?;
        self.animation.pose(&self.rest_lights, t).camera
    }

    /// Shows `frame` (clamped to the animation) and pauses.
    pub fn set_frame(&mut self, frame: i64) {
        self.playing = None;
        self.frame = frame.clamp(self.clock.first, self.clock.last);
    }

    /// One frame on (`delta` 1) or back (-1), wrapping around; pauses.
    pub fn step(&mut self, delta: i64) {
        let n = self.clock.frame_count() as i64;
        self.set_frame(self.clock.first + (self.frame - self.clock.first + delta).rem_euclid(n));
    }

    pub fn toggle_play(&mut self, now: Instant) {
        self.playing = match self.playing {
            Some(_) => None,
            None => Some((self.frame, now)),
        };
    }

    /// A playing timeline moves to the frame of the wall clock `now`; true when the shown
    /// frame changed.
    pub fn tick(&mut self, now: Instant) -> bool {
        let Some((from, since)) = self.playing else { return false };
        let elapsed = (now.saturating_duration_since(since).as_secs_f64() * self.clock.fps as f64) as i64;
        let n = self.clock.frame_count() as i64;
        let frame = self.clock.first + (from - self.clock.first + elapsed).rem_euclid(n);
        let changed = frame != self.frame;
        self.frame = frame;
        changed
    }

    /// Seconds between two frames of the animation.
    pub fn frame_seconds(&self) -> f64 {
        1.0 / self.clock.fps.max(1e-3) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn steps_wrap_playback_follows_the_clock_and_the_camera_is_the_tracks() {
        let scene = filtrace_scene::builtin("cornell-anim").unwrap();
        let clock = scene.animation.as_ref().unwrap().clock;
        assert!(Timeline::new(&filtrace_scene::builtin("cornell").unwrap(), None).unwrap().is_none());
        assert!(Timeline::new(&scene, Some(clock.last + 1)).is_err());
        let mut t = Timeline::new(&scene, Some(clock.last)).unwrap().unwrap();
        t.step(1);
        assert_eq!(t.frame(), clock.first, "wraps to the first frame");
        t.step(-1);
        assert_eq!(t.frame(), clock.last);
        let start = Instant::now();
        t.set_frame(clock.first);
        t.toggle_play(start);
        assert!(t.tick(start + Duration::from_secs_f64(2.5 / clock.fps as f64)));
        assert_eq!(t.frame(), clock.first + 2);
        t.step(1);
        assert!(!t.playing(), "stepping pauses");
        // The camera of frame n is the pose's, as `filtrace render --frame n` takes it.
        let want = scene.pose_at_frame(t.frame()).unwrap().camera;
        assert!(t.has_camera_track());
        assert_eq!(t.animated_camera(), want);
    }
}
