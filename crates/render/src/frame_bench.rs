//! Benchmarks of the per-frame renderer ([`crate::frame`]), shared by `filtrace bench
//! animation` and the criterion bench `benches/animation.rs`: the cost of a frame update
//! when one small object moves in a large scene, against building everything anew, and
//! the sampling speed of an animated scene against the same scene built still.

use crate::renderer::{render_bench, BenchResult, RenderSettings, Renderer};
use crate::{FrameError, FrameUpdate};
use filtrace_accel::TopLevelUpdate;
use filtrace_core::{Affine3A, Quat, Rgb, Vec3};
use filtrace_scene::animation::{AnimNode, Clock, Interpolation, SceneAnimation, Track, TransformTrack};
use filtrace_scene::builtin::{grass_with, GrassParams};
use filtrace_scene::{shapes, Instance, Material, Scene, SceneError};

/// Frames of [`moving_object_scene`]'s animation (24 per second).
pub const FRAMES: i64 = 48;

/// The `grass` meadow with `blades` blades (5 triangles each: 200,000 blades are a million
/// triangles) and one ball of 960 triangles that rolls across it over [`FRAMES`] frames,
/// the last instance of the scene.
pub fn moving_object_scene(blades: usize) -> Result<Scene, SceneError> {
    let mut s = grass_with(&GrassParams { blades, ..GrassParams::meadow() })?;
    let material = s.add_material(Material::diffuse("ball", Rgb::new(0.7, 0.2, 0.1)));
    s.meshes.push(shapes::sphere(32, material));
    let ball = s.instances.len() as u32;
    s.instances.push(Instance {
        mesh: s.meshes.len() as u32 - 1,
        transform: Affine3A::IDENTITY,
        material_override: None,
    });
    let clock =
        Clock::new(24.0, 0, FRAMES - 1).map_err(|e| SceneError::Invalid { message: e.to_string() })?;
    let end = (FRAMES - 1) as f32 / 24.0;
    let invalid = |e: filtrace_scene::animation::TrackError| SceneError::Invalid { message: e.to_string() };
    let path = [Vec3::new(-3.0, 0.3, 1.0), Vec3::new(0.0, 0.3, 0.0), Vec3::new(3.0, 0.3, -1.0)];
    let turns = [0.0f32, 3.0, 6.0].map(Quat::from_rotation_z);
    let mut track = TransformTrack::at_rest(&Affine3A::IDENTITY);
    track.translation =
        Some(Track::new(vec![0.0, end / 2.0, end], path.to_vec(), Interpolation::Linear).map_err(invalid)?);
    track.rotation =
        Some(Track::new(vec![0.0, end / 2.0, end], turns.to_vec(), Interpolation::Linear).map_err(invalid)?);
    let mut anim = SceneAnimation::new(clock);
    anim.nodes.push(AnimNode { name: "ball".into(), parent: None, track });
    anim.instances.push((ball, 0, Affine3A::from_scale(Vec3::splat(0.3))));
    s.animation = Some(anim);
    Ok(s)
}

/// `scene` at frame `frame` of its animation, with the animation removed: the same world,
/// built still.
pub fn still_at(scene: &Scene, frame: i64) -> Result<Scene, FrameError> {
    let pose = scene.pose_at_frame(frame).map_err(FrameError::Clock)?;
    let mut still = scene.clone();
    still.apply_pose(&pose);
    still.animation = None;
    Ok(still)
}

/// Timings of the updates of a run of frames.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct UpdateTimings {
    pub frames: usize,
    pub mean_s: f64,
    pub min_s: f64,
    pub max_s: f64,
    /// How the top level was updated, per kind.
    pub refits: usize,
    pub rebuilds: usize,
    pub full_rebuilds: usize,
    pub lights_updated: usize,
    /// Triangle records rewritten per frame (the moved instances' triangles).
    pub triangle_records: usize,
}

/// Moves `renderer` through frames `0..frames` (`frames` at least 2), `rounds` times, and
/// times every update but the first of each round (the first jumps back from the end).
pub fn time_updates(
    renderer: &mut Renderer,
    frames: i64,
    rounds: usize,
) -> Result<UpdateTimings, FrameError> {
    let mut updates: Vec<FrameUpdate> = Vec::new();
    for _ in 0..rounds.max(1) {
        renderer.prepare_frame(0)?;
        for f in 1..frames.max(2) {
            updates.push(renderer.prepare_frame(f)?);
        }
    }
    let secs: Vec<f64> = updates.iter().map(|u| u.seconds).collect();
    let count = |k: TopLevelUpdate| updates.iter().filter(|u| u.top_level == k).count();
    Ok(UpdateTimings {
        frames: updates.len(),
        mean_s: secs.iter().sum::<f64>() / secs.len() as f64,
        min_s: secs.iter().copied().fold(f64::INFINITY, f64::min),
        max_s: secs.iter().copied().fold(0.0, f64::max),
        refits: count(TopLevelUpdate::Refit),
        rebuilds: count(TopLevelUpdate::Rebuilt),
        full_rebuilds: count(TopLevelUpdate::Full),
        lights_updated: updates.iter().filter(|u| u.lights_updated).count(),
        triangle_records: updates.iter().map(|u| u.triangle_records).max().unwrap_or(0),
    })
}

/// Seconds to build a renderer (acceleration structure, light set, shading records) for
/// `scene` from scratch: what a frame costs without per-frame updates.
pub fn time_full_build(scene: &Scene, settings: &RenderSettings) -> Result<f64, crate::RenderError> {
    Ok(Renderer::new(scene.clone(), settings.clone())?.build_seconds())
}

/// Samples per second of frame `frame` of `scene` reached by updates, and of the same
/// frame built still ([`still_at`]), each on `threads` threads: `(animated, still)`.
pub fn animated_vs_still(
    scene: &Scene,
    settings: &RenderSettings,
    frame: i64,
    threads: usize,
) -> Result<(BenchResult, BenchResult), Box<dyn std::error::Error>> {
    let mut animated = Renderer::new(scene.clone(), settings.clone())?;
    animated.prepare_frame(0)?;
    animated.prepare_frame(frame)?;
    let still = Renderer::new(still_at(scene, frame)?, settings.clone())?;
    Ok((render_bench(&animated, threads), render_bench(&still, threads)))
}
