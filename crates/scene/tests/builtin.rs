//! Built-in scenes: deterministic, well-formed, lit, framed.

mod common;

use filtrace_core::Vec3;
use filtrace_scene::builtin::{bunny_room_from, try_builtin};
use filtrace_scene::{builtin, builtin_names, load_scene, Scene, SceneError};

fn world_triangles(s: &Scene) -> Vec<([Vec3; 3], u32)> {
    let mut v = Vec::new();
    for (ii, inst) in s.instances.iter().enumerate() {
        let m = &s.meshes[inst.mesh as usize];
        for t in 0..m.triangle_count() {
            v.push((
                m.triangle(t).map(|p| inst.transform.transform_point3(p)),
                s.material_of(ii as u32, t as u32),
            ));
        }
    }
    v
}

/// The built-in scene, or `None` when it needs a file of `../shared` that is absent (a SKIP,
/// or a failure under `CI`). Any other error fails the test.
fn available(name: &str) -> Option<Scene> {
    match try_builtin(name).expect("listed names are known") {
        Ok(s) => Some(s),
        Err(e) if name == "bunny-room" && common::shared("scenes/bunny/bunny.obj").is_none() => {
            println!("{name}: {e}");
            None
        }
        Err(e) => panic!("{name}: {e}"),
    }
}

#[test]
fn every_builtin_is_well_formed() {
    assert_eq!(builtin_names()[0], "cornell");
    for &name in builtin_names() {
        let Some(s) = available(name) else { continue };
        let tris = world_triangles(&s);
        assert!(!tris.is_empty(), "{name}");
        for m in &s.meshes {
            assert_eq!(m.indices.len(), m.material_ids.len(), "{name}/{}", m.name);
            assert!(m.normals.is_empty() || m.normals.len() == m.positions.len());
            assert!(m.uvs.is_empty() || m.uvs.len() == m.positions.len());
            for &[a, b, c] in &m.indices {
                assert!(a.max(b).max(c) < m.positions.len() as u32);
            }
        }
        for (p, mat) in &tris {
            let n = (p[1] - p[0]).cross(p[2] - p[0]);
            assert!(n.is_finite() && n.length_squared() > 0.0, "{name}: degenerate triangle {p:?}");
            assert!((*mat as usize) < s.materials.len());
        }
        let cam = s.camera.as_ref().unwrap_or_else(|| panic!("{name} has a camera"));
        let has_light = !s.lights.is_empty() || s.materials.iter().any(|m| m.is_emissive());
        assert!(has_light, "{name}");
        let b = s.bounds();
        assert!(b.min.is_finite() && b.max.is_finite());
        // The camera looks towards the scene's centre (within 45 degrees).
        let fwd = (cam.target - cam.eye).normalize();
        assert!(fwd.dot((b.center() - cam.eye).normalize()) > 0.7, "{name}: camera looks away");
        println!(
            "{name}: {} triangles, {} meshes, {} instances",
            tris.len(),
            s.meshes.len(),
            s.instances.len()
        );
    }
}

#[test]
fn builtins_are_deterministic() {
    for &name in builtin_names() {
        let (Some(a), Some(b)) = (available(name), available(name)) else { continue };
        let (ta, tb) = (world_triangles(&a), world_triangles(&b));
        assert_eq!(ta.len(), tb.len());
        for (x, y) in ta.iter().zip(&tb) {
            assert!(x
                .0
                .iter()
                .zip(&y.0)
                .all(|(p, q)| p.to_array().map(f32::to_bits) == q.to_array().map(f32::to_bits)));
            assert_eq!(x.1, y.1);
        }
    }
}

/// Every emissive triangle faces the interior: its normal points towards the camera target's
/// side (the lights of these scenes all shine on what the camera looks at).
#[test]
fn emitters_face_the_scene() {
    for &name in builtin_names() {
        let Some(s) = available(name) else { continue };
        let target = s.camera.as_ref().unwrap().target;
        let mut emitters = 0;
        for (p, mat) in world_triangles(&s) {
            let m = &s.materials[mat as usize];
            if !m.is_emissive() || m.two_sided_emission {
                continue;
            }
            emitters += 1;
            let n = (p[1] - p[0]).cross(p[2] - p[0]);
            let c = (p[0] + p[1] + p[2]) / 3.0;
            assert!(n.dot(target - c) > 0.0, "{name}: an emitter faces away from the scene");
        }
        assert!(emitters > 0 || !s.lights.is_empty(), "{name}");
    }
}

#[test]
fn procedural_scenes_are_complex() {
    let c = builtin("colonnade").unwrap();
    // One pillar mesh placed many times.
    let pillar = c.meshes.iter().position(|m| m.name == "pillar").unwrap() as u32;
    assert!(c.instances.iter().filter(|i| i.mesh == pillar).count() >= 40);
    let g = builtin("grass").unwrap();
    assert!(g.triangle_count() >= 50_000, "{}", g.triangle_count());
    assert_eq!(g.stats.degenerate_triangles_skipped, 0);
}

#[test]
fn bunny_room_stands_the_bunny_in_the_room() {
    let Some(s) = available("bunny-room") else { return };
    let bunny = s.meshes.iter().position(|m| m.name != "floor" && m.triangle_count() > 1000).unwrap();
    let inst = s.instances.iter().find(|i| i.mesh as usize == bunny).unwrap();
    let b = s.meshes[bunny].bounds().transformed(&inst.transform);
    let room = builtin("cornell").unwrap().bounds();
    // The transformed box of the rotated bunny is a bound, so check the exact vertices too.
    let ys: Vec<f32> =
        s.meshes[bunny].positions.iter().map(|p| inst.transform.transform_point3(*p).y).collect();
    let min_y = ys.iter().copied().fold(f32::INFINITY, f32::min);
    let max_y = ys.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    assert!(min_y.abs() < 1e-2, "bunny floats: {min_y}");
    assert!((max_y - 300.0).abs() < 1e-2);
    assert!(b.min.cmpge(room.min).all() && b.max.cmple(room.max).all(), "{b:?} outside {room:?}");
    assert!(s.triangle_count() > 56_000);
}

#[test]
fn bunny_room_without_the_file_is_an_error() {
    let e = bunny_room_from(&["/nowhere/bunny.obj".into()]).unwrap_err();
    assert!(matches!(e, SceneError::Invalid { .. }));
    assert!(e.to_string().contains("/nowhere/bunny.obj"), "{e}");
}

#[test]
fn load_scene_takes_names_and_paths() {
    assert_eq!(load_scene("cornell").unwrap().triangle_count(), 36);
    let e = load_scene("no-such-scene").unwrap_err().to_string();
    assert!(e.contains("cornell") && e.contains("colonnade"), "lists the built-ins: {e}");
    let p = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/environment.toml");
    assert!(load_scene(p.to_str().unwrap()).is_ok());
    let e = load_scene("scene.xyz").unwrap_err();
    assert!(matches!(e, SceneError::Unsupported { .. }), "{e:?}");
}

#[test]
fn builtins_pass_the_loader_checks_unchanged() {
    for &name in builtin_names() {
        let Some(s) = available(name) else { continue };
        let mut t = s.clone();
        filtrace_scene::validate::sanitize(&mut t, std::path::Path::new(name)).unwrap();
        assert_eq!(t.stats, s.stats, "{name}: sanitize had to repair something");
    }
}

#[test]
fn every_grass_preset_is_well_formed_and_bad_parameters_are_errors() {
    use filtrace_scene::builtin::{grass_with, GrassParams};
    for (name, p) in GrassParams::presets() {
        let s = grass_with(&p).unwrap();
        let blades = s.meshes.iter().find(|m| m.name == "grass_blades").unwrap();
        assert_eq!(blades.triangle_count(), 5 * p.blades, "{name}");
        for t in 0..blades.triangle_count() {
            let [a, b, c] = blades.triangle(t);
            assert!((b - a).cross(c - a).length_squared() > 0.0, "{name}: degenerate blade triangle");
        }
        let h = blades.bounds().extent().y;
        assert!(h <= p.height.1 + 1e-5 && h > p.height.0, "{name}: height {h}");
    }
    assert_eq!(
        grass_with(&GrassParams::meadow()).unwrap().triangle_count(),
        builtin("grass").unwrap().triangle_count()
    );
    for bad in [
        GrassParams { width: (0.0, 0.01), ..GrassParams::meadow() },
        GrassParams { height: (0.5, 0.2), ..GrassParams::meadow() },
        GrassParams { width: (f32::NAN, 0.01), ..GrassParams::meadow() },
        GrassParams { blades: usize::MAX, ..GrassParams::meadow() },
    ] {
        assert!(matches!(grass_with(&bad), Err(SceneError::Invalid { .. })), "{bad:?}");
    }
}
