//! The per-frame world of a sequence: the one place where a frame number becomes what the
//! renderer traces.
//!
//! Today a frame's renderer is built anew from the scene posed at that frame
//! ([`Scene::pose_at_frame`], [`Scene::apply_pose`]): right for any animation, at the cost of
//! a copy of the scene and a full build per frame. A per-frame update of the `Renderer`
//! (refitting the top level for what moved, issue 16 item 2) replaces the body of
//! [`FrameSource::move_to`] and nothing else; the sequence loop only calls these two
//! functions.

use anyhow::Context;
use filtrace_render::Renderer;
use filtrace_scene::animation::Clock;
use filtrace_scene::Scene;

/// A scene in its rest pose and the frames of its animation.
pub struct FrameSource {
    rest: Scene,
}

impl FrameSource {
    pub fn new(rest: Scene) -> Self {
        FrameSource { rest }
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

    /// Brings `renderer` to `frame`, keeping its settings, trace mode and ray queries. A
    /// still scene's renderer is left as it is.
    pub fn move_to(
        &self,
        renderer: &mut Renderer,
        frame: i64,
        pool: &rayon::ThreadPool,
    ) -> anyhow::Result<()> {
        if self.rest.animation.is_none() {
            return Ok(());
        }
        let scene = self.scene_at(frame)?;
        let settings = renderer.settings().clone();
        let next = pool.install(|| Renderer::new(scene, settings)).map_err(|e| anyhow::anyhow!("{e}"))?;
        *renderer = next.with_trace_mode(renderer.trace_mode()).with_ray_queries(renderer.ray_queries());
        Ok(())
    }
}
