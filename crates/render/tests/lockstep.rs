//! The lockstep integrator (8 paths per SIMD lane group) against the scalar one: the films
//! must be bit-identical (every sum, count and G-buffer value), for the AVX2 and the
//! portable lane code, on every built-in scene and on a TOML scene with every material,
//! light type, a texture and the environment. Any wrong lane (an operation in another
//! order, a wrong mask, a lane written twice) changes some bits, so this cheap test is
//! the exactness contract of `integrator::lockstep`.

use filtrace_core::{Affine3A, Quat, Vec3};
use filtrace_render::{Film, PathParams, RayQueries, RenderSettings, Renderer, TraceMode};
use filtrace_scene::animation::Pose;
use filtrace_scene::Scene;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

/// Renders samples `[first, first + count)` then `[first + count, end)` in two passes,
/// after `prepare` (a frame of an animation, moved instances).
fn render(
    scene: &Scene,
    settings: &RenderSettings,
    mode: TraceMode,
    queries: RayQueries,
    prepare: &dyn Fn(&mut Renderer),
) -> Film {
    let mut r = Renderer::new(scene.clone(), settings.clone())
        .unwrap()
        .with_trace_mode(mode)
        .with_ray_queries(queries);
    prepare(&mut r);
    let mut film = r.new_film();
    let cancel = AtomicBool::new(false);
    let half = settings.spp / 2;
    assert!(r.render_pass(&mut film, 0, half, &cancel));
    assert!(r.render_pass(&mut film, half, settings.spp - half, &cancel));
    film
}

/// Every field of every pixel, as bits (so that -0 and +0, or two NaNs, are told apart).
fn film_bits(f: &Film) -> Vec<u64> {
    let mut v = Vec::new();
    for p in f.pixels() {
        v.push(p.samples as u64);
        v.push(p.dropped as u64);
        for c in 0..3 {
            v.extend([p.sum[c], p.sum_sq[c], p.sum_direct[c], p.sum_indirect[c]].map(f64::to_bits));
        }
        let s = &p.surface;
        v.extend(
            [s.albedo.to_array(), s.normal.to_array(), s.position.to_array()]
                .concat()
                .iter()
                .map(|x| x.to_bits() as u64),
        );
        v.push(s.depth.to_bits() as u64);
    }
    v
}

fn assert_identical(name: &str, scene: &Scene, width: u32, height: u32, spp: u32) {
    assert_identical_after(name, scene, width, height, spp, &|_| {});
}

/// [`assert_identical`] on the renderer after `prepare`.
fn assert_identical_after(
    name: &str,
    scene: &Scene,
    width: u32,
    height: u32,
    spp: u32,
    prepare: &dyn Fn(&mut Renderer),
) {
    for params in PathParams::presets() {
        let settings = RenderSettings { width, height, spp, max_depth: params.max_depth, seed: 7 };
        let scalar = render(scene, &settings, TraceMode::Scalar, RayQueries::PerLane, prepare);
        assert!(scalar.total_samples() > 0);
        for (mode, queries) in [
            (TraceMode::Lockstep, RayQueries::PerLane),
            (TraceMode::LockstepPortable, RayQueries::PerLane),
            (TraceMode::Lockstep, RayQueries::Packet),
        ] {
            let lock = render(scene, &settings, mode, queries, prepare);
            let (a, b) = (film_bits(&scalar), film_bits(&lock));
            if a != b {
                let first = a.iter().zip(&b).position(|(x, y)| x != y).unwrap();
                let per_pixel = a.len() / scalar.pixels().len();
                let px = first / per_pixel;
                panic!(
                    "{name}, max_depth {}, {mode:?}, {queries:?}: films differ, first at pixel ({}, {}), field {}:\nscalar   {:?}\nlockstep {:?}",
                    params.max_depth,
                    px % width as usize,
                    px / width as usize,
                    first % per_pixel,
                    scalar.pixels()[px],
                    lock.pixels()[px]
                );
            }
            // The images are the same, so every AOV is too; check that they are not empty.
            assert!(lock.aovs().color.mean().iter().sum::<f64>() > 0.0, "{name}: black image");
        }
    }
}

/// Widths that are not multiples of 8 exercise the masked lanes of the last group.
#[test]
fn lockstep_films_equal_scalar_films_on_builtin_scenes() {
    for name in filtrace_scene::builtin_names() {
        let scene = filtrace_scene::builtin(name).unwrap();
        assert_identical(name, &scene, 29, 18, 5);
    }
}

/// The animated built-in scenes at a frame other than the rest pose (camera, lights and
/// instances moved by `prepare_frame`), and the classroom with every fourth instance moved
/// (top-level updates under the packets that cross several instances).
#[test]
fn lockstep_films_equal_scalar_films_on_animated_frames() {
    for (name, frame) in [("cornell-anim", 17), ("classroom", 30), ("colonnade-flight", 50)] {
        let scene = filtrace_scene::builtin(name).unwrap();
        let prepare = |r: &mut Renderer| {
            r.prepare_frame(frame).unwrap();
        };
        assert_identical_after(&format!("{name} frame {frame}"), &scene, 29, 18, 4, &prepare);
    }
    let scene = filtrace_scene::builtin("classroom").unwrap();
    let moved = |r: &mut Renderer| {
        let instances = (0..r.scene().instances.len() as u32)
            .step_by(4)
            .map(|i| {
                let t = r.scene().instances[i as usize].transform;
                let shift = Affine3A::from_rotation_translation(
                    Quat::from_rotation_y(0.1 * i as f32),
                    Vec3::new(0.05 * (i % 7) as f32, 0.02, -0.03 * (i % 5) as f32),
                );
                (i, shift * t)
            })
            .collect();
        r.set_pose(&Pose { time: 0.0, camera: None, instances, lights: Vec::new() }).unwrap();
    };
    assert_identical_after("classroom, instances moved", &scene, 29, 18, 4, &moved);
}

/// `../shared/<rel>` from the project root; `None` when absent, a failure under CI.
fn shared(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared").join(rel);
    if p.exists() {
        return Some(p);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "{} not found (../shared is required when CI is set)",
        p.display()
    );
    println!("SKIPPED: {} not found", p.display());
    None
}

/// The benchmark suite's scenes from ../shared (`filtrace bench suite` loads them the same
/// way): the 2CylinderEngine glTF (34 meshes, instanced: packets through the top level),
/// the bunny and the teapot alone (one BVH mesh: the single-object packet kernels).
#[test]
fn lockstep_films_equal_scalar_films_on_shared_suite_scenes() {
    for rel in ["scenes/gltf/2CylinderEngine.glb", "scenes/bunny/bunny.obj", "scenes/teapot/teapot.obj"] {
        let Some(path) = shared(rel) else { continue };
        let scene = filtrace_scene::load(&path).unwrap();
        assert_identical(rel, &scene, 24, 16, 3);
    }
}

/// Rows wider than a pool (`integrator::pool::POOL` pixels): several pools per row, the
/// last one partly filled and ending in a partial group of eight.
#[test]
fn lockstep_films_equal_scalar_films_with_several_pools_per_row() {
    let width = 2 * filtrace_render::integrator::pool::POOL as u32 + 13;
    let scene = filtrace_scene::builtin("cornell").unwrap();
    assert_identical("cornell, several pools per row", &scene, width, 3, 3);
}

#[test]
fn lockstep_films_equal_scalar_films_with_every_feature() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/lockstep_all_features.toml");
    let scene = filtrace_scene::toml_scene::load_toml(&path).unwrap();
    assert!(!scene.textures.is_empty(), "the scene must have a texture");
    assert_identical("lockstep_all_features.toml", &scene, 45, 30, 6);
}

/// The every-feature scene with more than eight materials: nine unused copies put in
/// front, so every material id is above eight (the gathered material table, not the
/// eight-entry one).
#[test]
fn lockstep_films_equal_scalar_films_with_many_materials() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/lockstep_all_features.toml");
    let mut scene = filtrace_scene::toml_scene::load_toml(&path).unwrap();
    const SHIFT: u32 = 9;
    let copies = (0..SHIFT as usize).map(|i| scene.materials[i % scene.materials.len()].clone());
    scene.materials.splice(0..0, copies.collect::<Vec<_>>());
    for mesh in &mut scene.meshes {
        mesh.material_ids.iter_mut().for_each(|m| *m += SHIFT);
    }
    for inst in &mut scene.instances {
        if let Some(m) = &mut inst.material_override {
            *m += SHIFT;
        }
    }
    assert!(scene.materials.len() > 8 + SHIFT as usize / 2);
    assert_identical("lockstep_all_features.toml, materials shifted by 9", &scene, 45, 30, 4);
}

/// A scene with more than eight instances (the every-feature scene's instances copied
/// and moved): the instances' rows by gathers (`InstanceRows` of any length).
#[test]
fn lockstep_films_equal_scalar_films_with_many_instances() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/lockstep_all_features.toml");
    let mut scene = filtrace_scene::toml_scene::load_toml(&path).unwrap();
    let base = scene.instances.clone();
    let mut k = 0.0f32;
    while scene.instances.len() <= 16 {
        k += 1.0;
        for inst in &base {
            let mut copy = inst.clone();
            copy.transform = Affine3A::from_translation(Vec3::new(0.37 * k, 0.0, -0.61 * k)) * inst.transform;
            scene.instances.push(copy);
        }
    }
    assert_identical("lockstep_all_features.toml, instances copied", &scene, 45, 30, 4);
}

/// A scene with eight lights of every kind: the lockstep integrator's in-lane light choice
/// (`SmallLights`) with lanes that fall back to the per-lane code for other light kinds.
#[test]
fn lockstep_films_equal_scalar_films_with_few_lights() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/lockstep_few_lights.toml");
    let scene = filtrace_scene::toml_scene::load_toml(&path).unwrap();
    let lights = filtrace_render::lights::LightSet::build(&scene);
    assert!((2..=8).contains(&lights.len()), "{} lights", lights.len());
    assert_identical("lockstep_few_lights.toml", &scene, 45, 30, 6);
}

/// The lights of the open scenes (bunny, teapot, engine: the default sky and sun) in
/// variants that reach every branch of the environment's lane code: a sky with black
/// ground (zero-weight bands), a constant environment, a sky with a constant one, the sun
/// alone, and the sky with several suns (more than one directional light in the table).
#[test]
fn lockstep_films_equal_scalar_films_with_sky_and_sun_variants() {
    use filtrace_scene::{Environment, Light};
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/lockstep_few_lights.toml");
    let base = filtrace_scene::toml_scene::load_toml(&path).unwrap();
    let sky = |ground: f32| {
        Light::Environment(Environment::Sky {
            zenith: Vec3::new(1.0, 1.1, 1.3),
            horizon: Vec3::splat(0.8),
            ground: Vec3::splat(ground),
        })
    };
    let constant = Light::Environment(Environment::Constant { radiance: Vec3::new(0.2, 0.3, 0.4) });
    let sun = |d: Vec3, e: f32| Light::Directional { direction: d, irradiance: Vec3::splat(e) };
    let sun1 = sun(Vec3::new(0.5, 1.0, 0.8), 2.0);
    let variants: [(&str, Vec<Light>); 5] = [
        ("sky with black ground + sun", vec![sky(0.0), sun1.clone()]),
        ("constant environment", vec![constant.clone()]),
        ("sky + constant + sun", vec![sky(0.3), constant, sun1.clone()]),
        ("sun alone", vec![sun1.clone()]),
        ("sky + three suns", vec![sky(0.3), sun1, sun(Vec3::new(-1.0, 0.5, 0.2), 0.7), sun(Vec3::Y, 0.3)]),
    ];
    for (name, lights) in variants {
        let mut scene = base.clone();
        scene.lights = lights;
        assert_identical(name, &scene, 37, 22, 4);
    }
}

/// The lane utilisation counters add up: every group counts its lanes, lanes alive only
/// decrease with the vertex.
#[test]
fn lane_stats_are_consistent() {
    let scene = filtrace_scene::builtin("cornell").unwrap();
    let settings = RenderSettings { width: 20, height: 8, spp: 2, max_depth: 8, seed: 0 };
    let r = Renderer::new(scene, settings).unwrap();
    let s = r.lane_stats(0, 2);
    // 20 = 8 + 8 + 4 pixels per row: 3 groups per row and sample.
    assert_eq!(s.groups, 3 * 8 * 2);
    assert_eq!(s.camera_lanes, 20 * 8 * 2);
    assert!(s.alive[0] <= s.camera_lanes && s.alive[0] > 0);
    assert!(s.alive.windows(2).all(|w| w[1] <= w[0]), "{:?}", s.alive);
    assert!(s.mean_utilisation() > 0.0 && s.mean_utilisation() <= 1.0);
}

/// The lockstep tracer alone is deterministic across thread counts (it is equal to the
/// scalar tracer, which is; this checks it directly on a larger image and one pass).
#[test]
fn lockstep_is_bit_identical_across_thread_counts() {
    let scene = filtrace_scene::builtin("cornell").unwrap();
    let settings = RenderSettings { width: 67, height: 41, spp: 3, max_depth: 8, seed: 3 };
    let r = Renderer::new(scene, settings).unwrap().with_trace_mode(TraceMode::Lockstep);
    let films: Vec<Vec<u64>> = [1, 2, 3]
        .iter()
        .map(|&t| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(t).build().unwrap();
            film_bits(&pool.install(|| r.render(&AtomicBool::new(false))))
        })
        .collect();
    assert!(films[0] == films[1] && films[1] == films[2]);
}
