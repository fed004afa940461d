//! The fast integrator against the naive one, determinism, the direct/indirect split,
//! cancellation and bad input.

mod common;

use common::*;
use filtrace_core::{Rgb, Vec3};
use filtrace_render::integrator::path;
use filtrace_render::{RenderError, RenderSettings, Renderer};
use filtrace_scene::{builtin, Environment, Light, Material, Mesh, Scene};
use std::sync::atomic::AtomicBool;

/// A cube on a ground plane under a sky, lit also by a small two-sided emissive quad.
fn sky_scene() -> Scene {
    let mut s = scene_with(camera(Vec3::new(1.5, 1.2, -3.0), Vec3::new(0.0, 0.3, 0.0), 50.0));
    let ground = s.add_material(Material::diffuse("ground", Rgb::new(0.6, 0.5, 0.4)));
    let cube = s.add_material(Material::diffuse("cube", Rgb::new(0.2, 0.7, 0.3)));
    let lamp = s.add_material(diffuse_emitter("lamp", Rgb::splat(0.1), Rgb::new(6.0, 5.0, 3.0), true));
    let mut plane = Mesh { name: "ground".into(), ..Mesh::default() };
    let k = 3.0;
    push_quad(
        &mut plane,
        [Vec3::new(-k, 0.0, -k), Vec3::new(-k, 0.0, k), Vec3::new(k, 0.0, k), Vec3::new(k, 0.0, -k)],
        ground,
    );
    s.add_mesh(plane);
    s.add_mesh(box_mesh(Vec3::new(-0.5, 0.0, -0.5), Vec3::new(0.5, 1.0, 0.5), cube, false));
    let mut l = Mesh { name: "lamp".into(), ..Mesh::default() };
    push_quad(
        &mut l,
        [
            Vec3::new(0.7, 0.2, -0.6),
            Vec3::new(0.7, 0.8, -0.6),
            Vec3::new(1.1, 0.8, -0.2),
            Vec3::new(1.1, 0.2, -0.2),
        ],
        lamp,
    );
    s.add_mesh(l);
    s.lights.push(Light::Environment(Environment::Sky {
        zenith: Rgb::new(0.3, 0.5, 1.0),
        horizon: Rgb::new(1.0, 0.9, 0.8),
        ground: Rgb::new(0.2, 0.2, 0.2),
    }));
    s
}

fn small_cornell() -> Scene {
    builtin("cornell").expect("built-in Cornell box")
}

/// NEE + MIS and pure BSDF sampling converge to the same image (Cornell box: area light).
#[test]
fn nee_mis_agrees_with_bsdf_only_on_cornell() {
    nee_vs_bsdf_only("cornell", small_cornell(), 24, 64, 512, 8);
}

/// ... and on an open scene with a sky environment and a two-sided emitter (env MIS).
#[test]
fn nee_mis_agrees_with_bsdf_only_under_sky() {
    for max_depth in [2, -1] {
        nee_vs_bsdf_only(&format!("sky, max depth {max_depth}"), sky_scene(), 24, 64, 256, max_depth);
    }
}

/// Same seed, bit-identical film with 1, 2 and 4 threads, also when rendered in passes.
#[test]
fn bit_identical_across_thread_counts_and_passes() {
    let r = Renderer::new(small_cornell(), settings(20, 14, 8, 8)).unwrap();
    let render_on = |threads: usize, passes: &[(u32, u32)]| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let mut film = r.new_film();
            for &(first, count) in passes {
                assert!(r.render_pass(&mut film, first, count, &AtomicBool::new(false)));
            }
            film
        })
    };
    let one = render_on(1, &[(0, 8)]);
    assert_eq!(one.min_samples(), 8);
    for threads in [2, 4] {
        assert!(render_on(threads, &[(0, 8)]).pixels() == one.pixels(), "{threads} threads differ");
    }
    // Progressive passes add the same samples in the same per-pixel order.
    assert!(render_on(2, &[(0, 3), (3, 5)]).pixels() == one.pixels());
    // Another seed gives another image.
    let mut s = r.settings().clone();
    s.seed += 1;
    let other = Renderer::new(small_cornell(), s).unwrap();
    assert!(render(&other).pixels() != one.pixels());
}

/// color = direct + indirect for every sample (exactly), and the split is the right one:
/// the `direct` of a full render is exactly the colour of a direct-only render (same
/// sampler dimensions), and `direct_light` reproduces the direct light at a first hit.
#[test]
fn direct_plus_indirect_is_color_and_direct_is_depth_two() {
    let (w, h) = (16u32, 16u32);
    let full = Renderer::new(small_cornell(), settings(w, h, 4, 8)).unwrap();
    let direct_only = Renderer::new(small_cornell(), settings(w, h, 4, 2)).unwrap();
    let mut indirect_sum = 0.0;
    for y in 0..h {
        for x in 0..w {
            for i in 0..4 {
                let s = full.trace_sample(x, y, i).radiance;
                let p = s.to_pixel_sample();
                assert_eq!(p.color, p.direct + p.indirect);
                let d = direct_only.trace_sample(x, y, i).radiance;
                assert_eq!(d.indirect, Rgb::ZERO);
                assert_eq!(s.direct, d.direct, "pixel ({x},{y}) sample {i}: {s:?} {d:?}");
                indirect_sum += s.indirect.element_sum();
            }
        }
    }
    assert!(indirect_sum > 0.0);

    // direct_light at the first hit equals the direct part of the path (for non-emitters).
    let ctx = full.context();
    let params = full.path_params();
    let mut compared = 0;
    for y in 0..h {
        for x in 0..w {
            let ray = full.camera().generate_ray(x, y, filtrace_core::Vec2::splat(0.5));
            let Some(si) = ctx.intersect(&ray) else { continue };
            if ctx.emitted(&si) != Rgb::ZERO {
                continue;
            }
            let a = path::trace_from_hit(&ctx, &params, &si, &mut full.sampler(x, y, 1));
            let b = path::direct_light(&ctx, &si, &mut full.sampler(x, y, 1));
            assert_eq!(a.direct, b, "pixel ({x},{y})");
            compared += 1;
        }
    }
    assert!(compared > 100);

    // The film's AOVs keep the identity up to rounding of the f64 sums.
    let a = render(&full).aovs();
    for (c, (d, i)) in a.color.data().iter().zip(a.direct.data().iter().zip(a.indirect.data())) {
        assert!((c - (d + i)).abs() <= 1e-5 * c.abs().max(1e-3));
    }
}

/// The G-buffer comes from sample 0 through the pixel centre: depth is the distance along
/// the centre ray to the position, normals are unit and face the camera, misses are zero.
#[test]
fn g_buffer_comes_from_the_centre_ray() {
    let r = Renderer::new(sky_scene(), settings(24, 24, 2, 8)).unwrap();
    let a = render(&r).aovs();
    let (mut hits, mut misses) = (0, 0);
    for y in 0..24 {
        for x in 0..24 {
            let ray = r.camera().generate_ray(x as u32, y as u32, filtrace_core::Vec2::splat(0.5));
            let n = a.normal.rgb(x, y);
            let depth = a.depth.pixel(x, y)[0];
            if n == Vec3::ZERO {
                misses += 1;
                assert_eq!((a.position.rgb(x, y), depth, a.albedo.rgb(x, y)), (Vec3::ZERO, 0.0, Vec3::ZERO));
                continue;
            }
            hits += 1;
            assert!((n.length() - 1.0).abs() < 1e-5 && n.dot(ray.dir) < 0.0);
            assert!((ray.at(depth) - a.position.rgb(x, y)).length() < 1e-4 * depth.max(1.0));
        }
    }
    assert!(hits > 100 && misses > 10, "{hits} {misses}");
}

#[test]
fn cancelled_pass_keeps_the_film_consistent() {
    let r = Renderer::new(small_cornell(), settings(16, 16, 4, 8)).unwrap();
    let mut film = r.new_film();
    assert!(r.render_pass(&mut film, 0, 2, &AtomicBool::new(false)));
    let before = film.pixels().to_vec();
    assert!(!r.render_pass(&mut film, 2, 2, &AtomicBool::new(true)));
    assert!(film.pixels() == &before[..], "a pass cancelled before it started changes nothing");
    assert_eq!(film.min_samples(), 2);
    assert_eq!(film.total_samples(), 2 * 256);
}

#[test]
fn bad_settings_are_clear_errors() {
    let scene = small_cornell();
    let ok = RenderSettings::default();
    let cases = [
        (RenderSettings { width: 0, ..ok.clone() }, "no pixels"),
        (RenderSettings { height: 40000, ..ok.clone() }, "too large"),
        (RenderSettings { width: 20000, height: 20000, ..ok.clone() }, "too large"),
        (RenderSettings { spp: 0, ..ok.clone() }, "samples per pixel"),
        (RenderSettings { max_depth: 0, ..ok.clone() }, "max depth 0"),
        (RenderSettings { max_depth: -2, ..ok.clone() }, "max depth -2"),
    ];
    for (s, msg) in cases {
        let err = Renderer::new(scene.clone(), s.clone()).err().unwrap_or_else(|| panic!("{s:?} accepted"));
        assert!(err.to_string().contains(msg), "{err}");
    }
    assert!(matches!(
        Renderer::new(scene, RenderSettings { max_depth: 0, ..ok }).err(),
        Some(RenderError::InvalidMaxDepth(0))
    ));
}

/// Scenes without camera, lights or geometry render (black where nothing emits) without
/// panicking or producing non-finite values.
#[test]
fn degenerate_scenes_render() {
    let mut no_camera = small_cornell();
    no_camera.camera = None;
    let mut no_lights = small_cornell();
    no_lights.materials[4].emission = Rgb::ZERO;
    let empty = Scene::default();
    for (name, scene) in [("no camera", no_camera), ("no lights", no_lights), ("empty", empty)] {
        let r = Renderer::new(scene, settings(8, 8, 2, -1)).unwrap();
        let film = render(&r);
        let a = film.aovs();
        assert_eq!(film.dropped_samples(), 0, "{name}");
        assert_eq!(a.color.count_non_finite(), 0, "{name}");
        if name == "no camera" {
            let framed = filtrace_scene::default_camera_for(r.scene().bounds());
            assert_eq!(r.camera().eye, framed.eye);
            assert!(a.normal.data().iter().any(|&v| v != 0.0), "the framed camera sees the box");
        } else {
            assert_eq!(a.color.mean()[0], 0.0, "{name}");
        }
    }
}
