//! TOML scene files: every example under `scenes/` loads, and malformed files name their line.

mod common;

use common::temp_files;
use filtrace_core::{Rgb, Vec3};
use filtrace_scene::{load, Bsdf, Environment, Light, SceneError, Texturable};
use std::path::PathBuf;

fn examples_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes")
}

/// Whether `../shared/scenes` is there (when absent: a SKIP line, or a failure under `CI`).
fn shared_present() -> bool {
    common::shared("scenes").is_some()
}

#[test]
fn every_example_scene_loads() {
    let mut names: Vec<PathBuf> = std::fs::read_dir(examples_dir())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    names.sort();
    assert!(names.len() >= 8, "expected one example per feature, found {names:?}");
    for p in names {
        let text = std::fs::read_to_string(&p).unwrap();
        if text.contains("../shared/") && !shared_present() {
            println!("SKIP: {} needs ../shared", p.display());
            continue;
        }
        let s = load(&p).unwrap_or_else(|e| panic!("{e}"));
        assert!(s.triangle_count() > 0, "{}: no geometry", p.display());
        assert!(s.camera.is_some(), "{}: examples set a camera", p.display());
        let has_light = !s.lights.is_empty() || s.materials.iter().any(|m| m.is_emissive());
        assert!(has_light, "{}: no light", p.display());
        assert!(s.stats.warnings.is_empty(), "{}: {:?}", p.display(), s.stats.warnings);
        let b = s.bounds();
        assert!(b.min.is_finite() && b.max.is_finite(), "{}", p.display());
        println!(
            "{}: {} triangles, {} instances, bounds {:?}",
            p.display(),
            s.triangle_count(),
            s.instances.len(),
            b
        );
    }
}

#[test]
fn toml_cornell_equals_builtin() {
    if !shared_present() {
        return;
    }
    let s = load(&examples_dir().join("cornell.toml")).unwrap();
    let b = filtrace_scene::builtin("cornell").unwrap();
    assert_eq!(s.camera, b.camera);
    assert_eq!(s.materials, b.materials);
    assert_eq!(s.triangle_count(), b.triangle_count());
    assert_eq!(s.bounds(), b.bounds());
}

#[test]
fn instancing_loads_the_mesh_once() {
    if !shared_present() {
        return;
    }
    let s = load(&examples_dir().join("instancing.toml")).unwrap();
    // Floor quad + one teapot mesh, placed 1 + 3 times.
    assert_eq!(s.meshes.len(), 2);
    assert_eq!(s.instances.len(), 4);
    // The teapot's 1,024 triangles include degenerate ones at the patch poles (counted once:
    // the file is loaded once).
    assert_eq!(s.stats.degenerate_triangles_skipped, 32);
    assert_eq!(s.triangle_count(), 2 + 3 * (1024 - 32));
    let copper = s.materials.iter().position(|m| m.name == "copper").unwrap() as u32;
    assert_eq!(s.instances[2].material_override, Some(copper));
    // The rotate form and the matrix form give the same standing-up teapot (up to scale).
    let a = s.instances[1].transform;
    let c = s.instances[3].transform;
    let p = Vec3::new(1.0, 2.0, 3.0);
    let pa = a.transform_point3(p) - Vec3::from(a.translation);
    let pc = c.transform_point3(p) - Vec3::from(c.translation);
    assert!((pa * 0.8 - pc).length() < 1e-5, "{pa} {pc}");
}

#[test]
fn materials_and_lights_convert() {
    let s = load(&examples_dir().join("materials.toml")).unwrap();
    let by = |n: &str| s.materials.iter().find(|m| m.name == n).unwrap();
    assert!(matches!(by("checker").bsdf, Bsdf::Diffuse { reflectance: Texturable::Texture { .. } }));
    assert_eq!(s.textures.len(), 1);
    assert_eq!((s.textures[0].width, s.textures[0].height), (64, 64));
    match &by("gold").bsdf {
        Bsdf::Conductor { eta, k, roughness } => {
            assert!(eta.x < 0.2 && k.x > 3.0 && *roughness == 0.2);
        }
        b => panic!("{b:?}"),
    }
    assert_eq!(
        by("red-plastic").bsdf,
        Bsdf::Plastic { diffuse: Texturable::Constant(Rgb::new(0.6, 0.05, 0.05)), roughness: 0.15, ior: 1.5 }
    );
    assert_eq!(by("lamp").emission, Rgb::splat(8.0));
    let lamp = s.meshes.iter().find(|m| m.name == "ceiling-lamp").unwrap();
    let inst = s.instances.iter().find(|i| s.meshes[i.mesh as usize].name == "ceiling-lamp").unwrap();
    let [a, b, c] = lamp.triangle(0).map(|p| inst.transform.transform_point3(p));
    assert!(((b - a).cross(c - a).normalize() - Vec3::NEG_Y).length() < 1e-5, "lamp must face down");

    let s = load(&examples_dir().join("spot-light.toml")).unwrap();
    match &s.lights[0] {
        Light::Spot { direction, cos_total_width, cos_falloff_start, .. } => {
            assert!((*direction - Vec3::new(-2.0, -4.0, -2.0).normalize()).length() < 1e-6);
            assert!((cos_total_width - 25f32.to_radians().cos()).abs() < 1e-6);
            assert!((cos_falloff_start - 18f32.to_radians().cos()).abs() < 1e-6);
        }
        l => panic!("{l:?}"),
    }
    let s = load(&examples_dir().join("sun-sky.toml")).unwrap();
    assert!(matches!(s.lights[0], Light::Directional { .. }));
    assert!(matches!(s.lights[1], Light::Environment(Environment::Sky { .. })));
    let s = load(&examples_dir().join("area-lights.toml")).unwrap();
    let q = s.meshes.iter().find(|m| m.name == "quad_light").unwrap();
    let [a, b, c] = q.triangle(0);
    assert!(((b - a).cross(c - a).normalize() - Vec3::NEG_Y).length() < 1e-6);
    assert!(s.materials[q.material_ids[0] as usize].is_emissive());
}

fn expect_error(tag: &str, text: &str, line: usize, want: &str) {
    let dir = temp_files(&format!("toml-{tag}"), &[("t.toml", text.as_bytes())]);
    match load(&dir.join("t.toml")) {
        Err(e @ SceneError::Parse { line: Some(_), .. }) => {
            let msg = e.to_string();
            assert!(msg.contains(&format!("t.toml:{line}:")), "{tag}: want line {line}: {msg}");
            assert!(msg.contains(want), "{tag}: '{msg}' should mention '{want}'");
        }
        other => panic!("{tag}: expected a parse error, got {other:?}"),
    }
}

#[test]
fn malformed_toml_errors_name_file_and_line() {
    expect_error("syntax", "name = \"x\"\n[camera\n", 2, "");
    expect_error("unknown-top", "name = \"x\"\ncolour = 3\n", 2, "unknown field `colour`");
    expect_error(
        "unknown-camera",
        "[camera]\neye = [0, 0, 1]\ntarget = [0, 0, 0]\nfov = 40\n",
        4,
        "unknown field `fov`",
    );
    expect_error(
        "unknown-material-key",
        "[[materials]]\nname = \"a\"\ntype = \"diffuse\"\ncolor = [1, 1, 1]\n\n[[materials]]\nname = \"b\"\ntype = \"diffuse\"\nshiny = 1\n",
        9,
        "unknown field `shiny`",
    );
    expect_error("bad-type", "[[materials]]\nname = \"a\"\ntype = \"diffuse\"\ncolor = \"red\"\n", 4, "");
    expect_error(
        "unknown-mat-type",
        "\n\n[[materials]]\nname = \"a\"\ntype = \"glass\"\n",
        3,
        "unknown type 'glass'",
    );
    expect_error(
        "unknown-metal",
        "[[materials]]\nname = \"a\"\ntype = \"conductor\"\nmetal = \"unobtainium\"\n",
        1,
        "unknown metal",
    );
    expect_error(
        "key-not-for-type",
        "[[materials]]\nname = \"a\"\ntype = \"diffuse\"\nior = 1.5\n",
        1,
        "'ior' does not apply",
    );
    expect_error(
        "unknown-material-ref",
        "[[objects]]\nshape = \"cube\"\n\n[[objects]]\nshape = \"cube\"\nmaterial = \"nope\"\n",
        4,
        "unknown material 'nope'",
    );
    expect_error("unknown-shape", "[[objects]]\nshape = \"torus\"\n", 1, "unknown shape");
    expect_error(
        "name-twice",
        "[[objects]]\nshape = \"cube\"\nname = \"x\"\n[[objects]]\nshape = \"quad\"\nname = \"x\"\n",
        4,
        "used twice",
    );
    expect_error("mesh-and-shape", "[[objects]]\nshape = \"cube\"\nmesh = \"a.obj\"\n", 1, "exactly one");
    expect_error("missing-mesh", "\n[[objects]]\nmesh = \"nowhere.obj\"\n", 2, "nowhere.obj");
    expect_error("singular", "[[objects]]\nshape = \"cube\"\ntransform = { scale = 0 }\n", 1, "invertible");
    expect_error(
        "bad-matrix",
        "[[objects]]\nshape = \"cube\"\ntransform = { matrix = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[1,0,0,1]] }\n",
        1,
        "last row",
    );
    expect_error(
        "unknown-transform-key",
        "[[objects]]\nshape = \"cube\"\ntransform = { shear = 1 }\n",
        3,
        "shear",
    );
    expect_error(
        "light-missing",
        "[[lights]]\ntype = \"point\"\nposition = [0, 1, 0]\n",
        1,
        "missing 'intensity'",
    );
    expect_error("light-type", "[[lights]]\ntype = \"laser\"\n", 1, "unknown light type");
    expect_error(
        "light-key",
        "[[lights]]\ntype = \"sun\"\ndirection = [0, 1, 0]\nirradiance = [1, 1, 1]\nposition = [0, 0, 0]\n",
        1,
        "'position' does not apply",
    );
    expect_error(
        "negative",
        "[[lights]]\ntype = \"environment\"\nradiance = [1, -1, 1]\n",
        1,
        "non-negative",
    );
    expect_error("camera", "[camera]\neye = [0, 0, 0]\ntarget = [0, 0, 0]\n", 1, "coincide");
}

#[test]
fn a_nested_mesh_error_keeps_the_inner_file_and_line() {
    let obj = "v 0 0 0\nv 1 0 0\nf 1 2 3\n";
    let toml = "[[objects]]\nmesh = \"bad.obj\"\n";
    let dir = temp_files("toml-nested", &[("t.toml", toml.as_bytes()), ("bad.obj", obj.as_bytes())]);
    let e = load(&dir.join("t.toml")).unwrap_err().to_string();
    assert!(e.contains("t.toml:1:") && e.contains("bad.obj:3:"), "{e}");
}

#[test]
fn missing_camera_is_none_and_default_camera_frames_the_bounds() {
    let dir = temp_files(
        "toml-nocam",
        &[("t.toml", b"[[objects]]\nshape = \"sphere\"\ntransform = { translate = [10, 0, 0] }\n")],
    );
    let s = load(&dir.join("t.toml")).unwrap();
    assert!(s.camera.is_none());
    let b = s.bounds();
    let c = filtrace_scene::default_camera_for(b);
    assert_eq!(c.target, b.center());
    // Every corner of the box is inside the vertical and horizontal (square image) field of view.
    let fwd = (c.target - c.eye).normalize();
    let half = (0.5 * c.vfov_deg).to_radians();
    for i in 0..8 {
        let p = Vec3::new(
            if i & 1 == 0 { b.min.x } else { b.max.x },
            if i & 2 == 0 { b.min.y } else { b.max.y },
            if i & 4 == 0 { b.min.z } else { b.max.z },
        );
        let d = (p - c.eye).normalize();
        assert!(d.dot(fwd).acos() < half, "corner {p} outside the view");
    }
    // Outside the box.
    assert!(!(c.eye.cmpge(b.min).all() && c.eye.cmple(b.max).all()));
}

#[test]
fn transforms_apply_scale_then_rotate_then_translate() {
    let toml = "[[objects]]\nshape = \"cube\"\n\
                transform = { scale = [2, 1, 1], rotate = { deg = 90, axis = [0, 0, 1] }, translate = [0, 0, 5] }\n\
                [[objects]]\nshape = \"cube\"\n\
                transform = { matrix = [[0, -1, 0, 0], [2, 0, 0, 0], [0, 0, 1, 5], [0, 0, 0, 1]] }\n";
    let dir = temp_files("toml-trs", &[("t.toml", toml.as_bytes())]);
    let s = load(&dir.join("t.toml")).unwrap();
    // (1, 0, 0) -> scale (2, 0, 0) -> 90 degrees about z (0, 2, 0) -> translate (0, 2, 5).
    for i in &s.instances {
        let p = i.transform.transform_point3(Vec3::X);
        assert!((p - Vec3::new(0.0, 2.0, 5.0)).length() < 1e-5, "{p}");
        let q = i.transform.transform_point3(Vec3::Y);
        assert!((q - Vec3::new(-1.0, 0.0, 5.0)).length() < 1e-5, "{q}");
    }
}
