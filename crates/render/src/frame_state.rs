//! The renderer's frame bookkeeping ([`FrameState`]) and the descriptions of a frame and of
//! an update ([`FrameDesc`], [`FrameUpdate`], [`FrameError`]); the updates themselves are
//! in [`crate::frame`].

use crate::camera::PinholeCamera;
use crate::settings::RenderError;
use filtrace_accel::TopLevelUpdate;
use filtrace_core::{Aabb, Affine3A};
use filtrace_scene::animation::ClockError;
use filtrace_scene::{Camera, Light, Scene};
use std::fmt;

/// One frame: which, when, seen from where, at what size.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameDesc {
    /// Frame number of the scene's clock (0 for a renderer never moved to a frame).
    pub index: i64,
    /// Seconds on the scene's clock.
    pub time: f32,
    pub camera: Camera,
    pub width: u32,
    pub height: u32,
}

/// What a frame update did.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FrameUpdate {
    /// Instances whose transform changed.
    pub moved_instances: usize,
    /// What the acceleration structure did.
    pub top_level: TopLevelUpdate,
    /// Per-triangle shading records rewritten (the moved instances' triangles).
    pub triangle_records: usize,
    /// The light set was updated (an emitter or light moved, or the scene's bounds).
    pub lights_updated: bool,
    pub camera_moved: bool,
    /// Wall time of the update.
    pub seconds: f64,
}

/// Why a frame could not be set.
#[derive(Clone, Debug, PartialEq)]
pub enum FrameError {
    /// The frame is outside the scene's animation.
    Clock(ClockError),
    /// A pose named an instance the scene does not have.
    UnknownInstance(u32),
    /// A pose named a light the scene does not have.
    UnknownLight(u32),
    /// A new resolution was rejected.
    Resolution(RenderError),
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FrameError::Clock(e) => write!(f, "{e}"),
            FrameError::UnknownInstance(i) => write!(f, "the pose moves instance {i}, which the scene lacks"),
            FrameError::UnknownLight(i) => write!(f, "the pose moves light {i}, which the scene lacks"),
            FrameError::Resolution(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for FrameError {}

/// The renderer's frame bookkeeping: the current frame and what the previous one needs.
#[derive(Clone, Debug)]
pub(crate) struct FrameState {
    pub(crate) desc: FrameDesc,
    /// The camera of the previous frame (the current one until something moves).
    pub(crate) prev_camera: PinholeCamera,
    /// Every instance's transform in the previous frame.
    pub(crate) prev_transforms: Vec<Affine3A>,
    /// Instances moved by the last update: their `prev_transforms` catch up at the next.
    pub(crate) moved_last: Vec<u32>,
    /// Per instance: it may have emissive triangles (moving it updates the light set).
    pub(crate) emitting: Vec<bool>,
    /// Instances moved since the light set was last updated.
    pub(crate) lights_stale: Vec<u32>,
    /// Per mesh: object-space bounds, for the scene's bounding sphere; empty when the
    /// scene has no distant light (whose power depends on that sphere).
    pub(crate) mesh_bounds: Vec<Aabb>,
}

/// The instances `scene`'s animation moves.
pub fn animated_instances(scene: &Scene) -> Vec<u32> {
    scene.animation.as_ref().map_or_else(Vec::new, |a| a.instances.iter().map(|&(i, _, _)| i).collect())
}

impl FrameState {
    pub(crate) fn new(scene: &Scene, camera: Camera, pinhole: &PinholeCamera) -> Self {
        let distant =
            scene.lights.iter().any(|l| matches!(l, Light::Directional { .. } | Light::Environment(_)));
        FrameState {
            desc: FrameDesc { index: 0, time: 0.0, camera, width: pinhole.width(), height: pinhole.height() },
            prev_camera: pinhole.clone(),
            prev_transforms: scene.instances.iter().map(|i| i.transform).collect(),
            moved_last: Vec::new(),
            emitting: emitting_instances(scene),
            lights_stale: Vec::new(),
            mesh_bounds: if distant { scene.meshes.iter().map(|m| m.bounds()).collect() } else { Vec::new() },
        }
    }
}

/// Per instance: whether any material its triangles may use emits (conservative: the
/// mesh's material list, or the override).
fn emitting_instances(scene: &Scene) -> Vec<bool> {
    let emits = |id: u32| scene.materials.get(id as usize).is_some_and(|m| m.is_emissive());
    let mesh_emits: Vec<bool> =
        scene.meshes.iter().map(|m| m.material_ids.iter().any(|&id| emits(id))).collect();
    scene
        .instances
        .iter()
        .map(|i| match i.material_override {
            Some(id) => emits(id),
            None => mesh_emits.get(i.mesh as usize).copied().unwrap_or(false),
        })
        .collect()
}
