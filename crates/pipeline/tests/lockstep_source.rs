//! The filtered pipeline on the lockstep tracer against the scalar reference: with the
//! renderer in `TraceMode::Lockstep` / `LockstepPortable` the source traces its batches (rows
//! of guide rays, blocks of further samples, the adaptive pre-pass, blocks of §4.3 path
//! slots) in SIMD lanes; in `TraceMode::Scalar` one key at a time. Every layer of every frame
//! must be the same bit for bit (the exactness contract of
//! `filtrace_render::integrator::lockstep`), on the built-in scenes and on a TOML scene with
//! every material, light type, a texture and the environment, for every filter, with
//! several paths per guide ray, with adaptive counts and with explicit batches.

use std::path::PathBuf;

use filtrace_adaptive::AdaptiveParams;
use filtrace_pipeline::*;
use filtrace_render::{PathParams, RenderSettings, Renderer, TraceMode};
use filtrace_scene::Scene;

#[path = "support/frames.rs"]
mod frames;
use frames::assert_frames_identical;

const MODES: [TraceMode; 2] = [TraceMode::Lockstep, TraceMode::LockstepPortable];

fn source(scene: &Scene, w: u32, h: u32, max_depth: i32, mode: TraceMode) -> RenderSource {
    let rs = RenderSettings { width: w, height: h, spp: 1, max_depth, seed: 13 };
    RenderSource::new(Renderer::new(scene.clone(), rs).unwrap().with_trace_mode(mode))
}

fn builtin(name: &str) -> Scene {
    filtrace_scene::builtin::builtin(name).unwrap_or_else(|| panic!("built-in {name}"))
}

/// The render crate's scene with every material, light type, a texture and an environment.
fn all_features() -> Scene {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../render/tests/data/lockstep_all_features.toml");
    filtrace_scene::toml_scene::load_toml(&path).unwrap()
}

/// The frame of `st` with filter `filter`, adaptive counts when `adaptive`, explicit
/// batches of `batch` slots; the lane groups the source ran.
fn frame(
    src: &RenderSource,
    filter: &str,
    st: &PipelineSettings,
    adaptive: bool,
    batch: Option<usize>,
) -> (Frame, u64) {
    let f = filter_by_name(filter, Some(src.scene_scale())).unwrap();
    let mut p = FilteredRenderer::new(src, f, st.clone()).unwrap();
    p.set_batch_size(batch);
    src.take_lane_stats();
    let frame = if adaptive {
        p.render_frame_adaptive(&AdaptiveParams::paper()).unwrap().0.clone()
    } else {
        p.render_frame().unwrap().clone()
    };
    (frame, src.take_lane_stats().groups)
}

/// Scalar and lockstep frames of `scene` for the given filters and ways of running.
fn assert_lockstep_frames_are_scalar_frames(name: &str, scene: &Scene, filters: &[&str], w: u32, h: u32) {
    for params in PathParams::presets() {
        let scalar = source(scene, w, h, params.max_depth, TraceMode::Scalar);
        let lanes: Vec<RenderSource> =
            MODES.iter().map(|&m| source(scene, w, h, params.max_depth, m)).collect();
        for &filter in filters {
            for (adaptive, batch, paths) in
                [(false, None, 1), (false, None, 3), (true, None, 1), (true, Some(37), 1)]
            {
                let st = PipelineSettings {
                    spp: 4,
                    indirect_paths: paths,
                    seed: 13,
                    ..PipelineSettings::paper(w, h)
                };
                let what = format!(
                    "{name}, max_depth {}, {filter}, adaptive {adaptive}, batch {batch:?}, {paths} paths",
                    params.max_depth
                );
                let (want, scalar_groups) = frame(&scalar, filter, &st, adaptive, batch);
                assert_eq!(scalar_groups, 0, "{what}: the scalar source ran lanes");
                assert!(want.images.color.mean()[0] > 0.0, "{what}: the test needs light");
                for (src, mode) in lanes.iter().zip(MODES) {
                    let (got, groups) = frame(src, filter, &st, adaptive, batch);
                    assert!(groups > 0, "{what}, {mode:?}: no lane group ran");
                    assert_frames_identical(&got, &want, &format!("{what}, {mode:?}"));
                }
            }
        }
    }
}

#[test]
fn lockstep_pipeline_frames_equal_scalar_frames_on_the_cornell_box_for_every_filter() {
    let filters = ["none", "atrous", "guided", "bilateral"];
    assert_lockstep_frames_are_scalar_frames("cornell", &builtin("cornell"), &filters, 37, 21);
}

#[test]
fn lockstep_pipeline_frames_equal_scalar_frames_on_the_bunny_room() {
    assert_lockstep_frames_are_scalar_frames("bunny-room", &builtin("bunny-room"), &["guided"], 29, 17);
}

#[test]
fn lockstep_pipeline_frames_equal_scalar_frames_with_every_material_and_light() {
    let scene = all_features();
    assert_lockstep_frames_are_scalar_frames("lockstep_all_features.toml", &scene, &["atrous"], 45, 30);
}

#[test]
fn lockstep_batches_equal_the_per_key_methods() {
    // The batch methods of the lockstep source against the scalar per-key methods on the
    // same source, key by key: further samples of several sample numbers, guide rays with
    // 0..5 paths (misses included), first hits and path slots in any order.
    let scene = all_features();
    let src = source(&scene, 24, 16, 5, TraceMode::Lockstep);
    let key = |x: u32, y: u32, sample: u32| SampleKey { x, y, sample, seed: 13 };
    let film = |x: u32, y: u32, j: f32| filtrace_core::Vec2::new(x as f32 + j, y as f32 + 0.9 - j);
    let mut rays = Vec::new();
    for y in 0..16 {
        for x in 0..24 {
            let s = (x * 7 + y * 3) % 5;
            let paths = if (x + y) % 3 == 0 { s } else { 0 };
            let sample = if paths > 0 { 0 } else { s + 1 };
            rays.push(EyeRay { key: key(x, y, sample), film: film(x, y, 0.1 + 0.15 * s as f32), paths });
        }
    }
    let bits = |e: &EyeSample| {
        let f = |v: filtrace_core::Vec3| v.to_array().map(f32::to_bits);
        (
            e.hit.map(|h| (f(h.normal), h.depth.to_bits())),
            f(e.albedo),
            f(e.position),
            f(e.direct),
            f(e.indirect),
        )
    };
    let mut out = vec![EyeSample::default(); rays.len()];
    src.trace_batch(&rays, &mut out);
    for (r, e) in rays.iter().zip(&out) {
        assert_eq!(bits(e), bits(&src.trace(r.key, r.film, r.paths)), "trace_batch {r:?}");
    }
    src.first_hits(&rays, &mut out);
    for (r, e) in rays.iter().zip(&out) {
        assert_eq!(bits(e), bits(&src.first_hit(r.key, r.film)), "first_hits {r:?}");
    }
    let slots: Vec<PathSlot> = rays
        .iter()
        .rev()
        .map(|r| PathSlot { key: SampleKey { sample: 0, ..r.key }, film: r.film, path: r.key.sample % 3 })
        .collect();
    src.trace_path_batch(&slots, &mut out);
    for (s, e) in slots.iter().zip(&out) {
        assert_eq!(bits(e), bits(&src.trace_path(s.key, s.film, s.path)), "trace_path_batch {s:?}");
    }
    assert!(src.take_lane_stats().groups > 0);
}
