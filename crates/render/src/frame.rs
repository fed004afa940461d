//! A per-frame world: one [`FrameDesc`] per frame (index, time, camera, resolution) and an
//! update whose cost follows what moved (kajiya's `WorldFrameDesc` and
//! `set_instance_transform`; STYLE.md, "Seams for a world that moves").
//!
//! [`Renderer::set_pose`] (or [`Renderer::prepare_frame`] for frame `n` of the scene's own
//! animation) moves the instances, lights and camera of a [`Pose`]:
//! - geometry stays in object space; for each instance whose transform changed, the top
//!   level's record is recomputed and the 4-wide top level refit, or rebuilt when the refit
//!   would let its SAH cost grow too far ([`SceneAccel::update_instances`]); the moved
//!   instance's per-triangle shading records are rewritten
//!   ([`SceneGeometry::update_instance`]). Instances that did not move cost nothing.
//! - instances animated by the scene are never merged into the identity instances' bottom
//!   level at build time, so moving them never rebuilds a bottom level;
//! - the light set is updated only when an emitting instance or a light moved, or the
//!   scene's bounding sphere (the power of distant lights) changed
//!   ([`crate::lights::LightSet::update_instances`] re-derives only the moved instances'
//!   area lights); the lockstep tables made from it follow;
//! - a camera change touches no geometry.
//!
//! The image of a frame reached by updates is the image of a renderer built from scratch
//! on the posed scene with the same animation data, bit for bit (`tests/frames.rs`): hits
//! do not depend on the BVH's shape (`filtrace_accel`'s tie rule), and every record is
//! recomputed as a fresh build computes it. A build without the animation data merges
//! every instance into world space, which changes the last bits of the hits.
//!
//! Every update ([`Renderer::set_pose`], [`Renderer::prepare_frame`],
//! [`Renderer::set_camera`]) begins a new frame: the state before it becomes the previous
//! frame, which the [`crate::motion`] AOV reprojects into. Every update, a new resolution
//! included, ends with the integrator's per-frame `prepare` (a VPL renderer makes its lights
//! and cache there); the update's `seconds` do not include it.

use crate::camera::PinholeCamera;
use crate::renderer::Renderer;
use filtrace_core::{Aabb, Affine3A};
use filtrace_scene::animation::Pose;
use filtrace_scene::{Camera, Light};
use std::time::Instant;

pub use crate::frame_state::{animated_instances, FrameDesc, FrameError, FrameUpdate};

impl Renderer {
    /// The frame currently shown.
    pub fn frame(&self) -> &FrameDesc {
        &self.frame.desc
    }

    /// Moves the scene to frame `index` of its animation ([`Scene::pose_at_frame`]; a
    /// scene without animation is the same at every frame) and updates what moved.
    pub fn prepare_frame(&mut self, index: i64) -> Result<FrameUpdate, FrameError> {
        let pose = self.scene.pose_at_frame(index).map_err(FrameError::Clock)?;
        let update = self.apply_pose(&pose)?;
        self.frame.desc.index = index;
        self.prepare_integrator();
        Ok(update)
    }

    /// Applies `pose` (instances, lights, camera; a new frame, see the module docs) and
    /// updates what moved. A pose naming unknown instances or lights is rejected whole.
    pub fn set_pose(&mut self, pose: &Pose) -> Result<FrameUpdate, FrameError> {
        let update = self.apply_pose(pose)?;
        self.prepare_integrator();
        Ok(update)
    }

    /// [`Renderer::set_pose`] without the integrator's `prepare`.
    fn apply_pose(&mut self, pose: &Pose) -> Result<FrameUpdate, FrameError> {
        if let Some(&(i, _)) = pose.instances.iter().find(|(i, _)| *i as usize >= self.scene.instances.len())
        {
            return Err(FrameError::UnknownInstance(i));
        }
        if let Some((i, _)) = pose.lights.iter().find(|(i, _)| *i as usize >= self.scene.lights.len()) {
            return Err(FrameError::UnknownLight(*i));
        }
        let start = Instant::now();
        self.begin_frame();
        let moved = self.move_instances(&pose.instances);
        let top_level = self.accel.update_instances(&self.scene, &moved);
        let mut triangle_records = 0;
        for &i in &moved {
            self.geometry.update_instance(&self.scene, i);
            triangle_records +=
                self.scene.meshes[self.scene.instances[i as usize].mesh as usize].triangle_count();
        }
        let lights_moved = self.move_lights(&pose.lights);
        let lights_updated = self.update_lights(&moved, lights_moved);
        let camera_moved = pose.camera.as_ref().is_some_and(|c| self.move_camera(c));
        self.frame.desc.time = pose.time;
        self.frame.moved_last = moved;
        Ok(FrameUpdate {
            moved_instances: self.frame.moved_last.len(),
            top_level,
            triangle_records,
            lights_updated,
            camera_moved,
            seconds: start.elapsed().as_secs_f64(),
        })
    }

    /// Moves the camera only (a new frame; no geometry is touched). The image is that of
    /// a renderer built with `camera`, bit for bit.
    pub fn set_camera(&mut self, camera: &Camera) {
        self.begin_frame();
        self.frame.moved_last.clear();
        self.move_camera(camera);
        self.prepare_integrator();
    }

    /// Changes the image size (films of the old size no longer fit); the previous frame's
    /// camera is resized with it, so motion vectors stay in pixels of the new size.
    pub fn set_resolution(&mut self, width: u32, height: u32) -> Result<(), FrameError> {
        let settings = crate::RenderSettings { width, height, ..self.settings.clone() };
        settings.validate().map_err(FrameError::Resolution)?;
        self.apply_size(settings);
        self.prepare_integrator();
        Ok(())
    }

    /// Takes `settings` (validated) with their image size: the camera and the previous
    /// frame's camera follow it.
    pub(crate) fn apply_size(&mut self, settings: crate::RenderSettings) {
        let (width, height) = (settings.width, settings.height);
        self.settings = settings;
        (self.frame.desc.width, self.frame.desc.height) = (width, height);
        self.camera = PinholeCamera::new(&self.frame.desc.camera, width, height);
        self.frame.prev_camera = self.frame.prev_camera.resized(width, height);
    }

    /// The current state becomes the previous frame's.
    fn begin_frame(&mut self) {
        self.frame.prev_camera = self.camera.clone();
        for &i in &self.frame.moved_last {
            self.frame.prev_transforms[i as usize] = self.scene.instances[i as usize].transform;
        }
    }

    /// Writes the pose's transforms; returns the instances whose transform changed.
    fn move_instances(&mut self, transforms: &[(u32, Affine3A)]) -> Vec<u32> {
        let mut moved = Vec::new();
        for &(i, t) in transforms {
            let inst = &mut self.scene.instances[i as usize];
            if inst.transform != t {
                inst.transform = t;
                moved.push(i);
            }
        }
        moved.sort_unstable();
        moved.dedup();
        moved
    }

    /// Writes the pose's lights; true when one changed.
    fn move_lights(&mut self, lights: &[(u32, Light)]) -> bool {
        let mut changed = false;
        for (i, l) in lights {
            let slot = &mut self.scene.lights[*i as usize];
            if slot != l {
                *slot = l.clone();
                changed = true;
            }
        }
        changed
    }

    /// Points the camera at `camera`; true when it changed.
    fn move_camera(&mut self, camera: &Camera) -> bool {
        if *camera == self.frame.desc.camera {
            return false;
        }
        self.frame.desc.camera = camera.clone();
        self.scene.camera = Some(camera.clone());
        self.camera = PinholeCamera::new(camera, self.settings.width, self.settings.height);
        true
    }

    /// Brings the light set and the lockstep tables made from it up to date when an
    /// emitter or light moved or the scene's bounding sphere changed; true when it did.
    /// Other moves are remembered and handed to the next update (the light set keeps
    /// per-instance bounds).
    fn update_lights(&mut self, moved: &[u32], lights_moved: bool) -> bool {
        self.frame.lights_stale.extend_from_slice(moved);
        let emitter_moved = moved.iter().any(|&i| self.frame.emitting[i as usize]);
        if !(lights_moved || emitter_moved || (!moved.is_empty() && self.radius_changed())) {
            return false;
        }
        let mut stale = std::mem::take(&mut self.frame.lights_stale);
        stale.sort_unstable();
        stale.dedup();
        self.lights.update_instances(&self.scene, &stale);
        self.lockstep_tables.update_lights(&self.lights);
        true
    }

    /// Whether the bounding sphere the light set gives distant lights their power by
    /// differs from the posed scene's (computed as `LightSet::build` does; only for
    /// scenes with distant lights, else false).
    fn radius_changed(&self) -> bool {
        let bounds = &self.frame.mesh_bounds;
        if bounds.is_empty() {
            return false;
        }
        let world = self
            .scene
            .instances
            .iter()
            .filter_map(|i| bounds.get(i.mesh as usize).map(|b| b.transformed(&i.transform)))
            .fold(Aabb::EMPTY, Aabb::union);
        let r = if world.is_empty() { 0.0 } else { world.bounding_radius() };
        let r = if r.is_finite() && r > 0.0 { r } else { 1.0 };
        r != self.lights.scene_radius()
    }
}
