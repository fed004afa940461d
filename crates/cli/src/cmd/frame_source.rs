//! The per-frame world of a sequence: the one place where a frame number becomes what the
//! renderer traces.
//!
//! The first frame's renderer is built from the scene posed at that frame
//! ([`Scene::pose_at_frame`], [`Scene::apply_pose`]); every frame then moves it with the
//! renderer's per-frame update ([`Renderer::prepare_frame`]), which touches only what moved.
//! The sequence loop only calls these two functions.

use anyhow::Context;
use filtrace_render::Renderer;
use filtrace_scene::animation::Clock;
use filtrace_scene::Scene;
use std::cell::Cell;

/// A scene in its rest pose and the frames of its animation.
pub struct FrameSource {
    rest: Scene,
    /// The frame the renderer was last moved to by [`FrameSource::move_to`].
    current: Cell<Option<i64>>,
}

impl FrameSource {
    pub fn new(rest: Scene) -> Self {
        FrameSource { rest, current: Cell::new(None) }
    }

    /// The animation's frames; `None` for a still scene (every frame is the same world).
    pub fn clock(&self) -> Option<Clock> {
        self.rest.animation.as_ref().map(|a| a.clock)
    }

    /// Seconds of `frame` on the animation's clock (0 for a still scene).
    pub fn time_of(&self, frame: i64) -> f64 {
        self.clock().map_or(0.0, |c| frame as f64 / c.fps as f64)
    }

    /// The scene posed at `frame`, for the renderer of a sequence's first frame.
    pub fn scene_at(&self, frame: i64) -> anyhow::Result<Scene> {
        let mut scene = self.rest.clone();
        let pose = scene.pose_at_frame(frame).with_context(|| format!("scene '{}'", self.rest.name))?;
        scene.apply_pose(&pose);
        Ok(scene)
    }

    /// Brings `renderer` to `frame` by the renderer's per-frame update (only what moved is
    /// updated: the top level refit, the moved instances' records and emitters). The
    /// renderer is first brought to `frame - 1` when it is not there (the first frame of a
    /// sequence, or after frames skipped by `--resume`), so that every frame's motion
    /// vectors point to the frame before it. A still scene's renderer is left as it is.
    pub fn move_to(&self, renderer: &mut Renderer, frame: i64) -> anyhow::Result<()> {
        if self.rest.animation.is_none() {
            return Ok(());
        }
        let inside = |f: i64| self.clock().is_some_and(|c| c.time_of(f).is_ok());
        if self.current.get() != Some(frame - 1) && inside(frame - 1) {
            renderer.prepare_frame(frame - 1).with_context(|| format!("scene '{}'", self.rest.name))?;
        }
        renderer.prepare_frame(frame).with_context(|| format!("scene '{}'", self.rest.name))?;
        self.current.set(Some(frame));
        Ok(())
    }
}
