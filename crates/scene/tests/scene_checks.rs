//! Scene-level checks at load (issue 17, defects 8 and 11): a scene without light or
//! geometry, exact duplicate triangles, control bytes quoted from a file, albedo above 1.

mod common;

use common::{shared, temp_files};
use filtrace_scene::default_light::default_lights;
use filtrace_scene::{load, load_with, LoadOptions, Scene, SceneError};

const TRIANGLE: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";

fn load_file(tag: &str, name: &str, text: &str, options: &LoadOptions) -> Result<Scene, SceneError> {
    let dir = temp_files(&format!("chk-{tag}"), &[(name, text.as_bytes())]);
    load_with(&dir.join(name), options)
}

fn no_default_light() -> LoadOptions {
    LoadOptions { default_light: false }
}

#[test]
fn bare_mesh_without_lights_gets_the_default_light_with_a_warning() {
    let s = load_file("bare", "t.obj", TRIANGLE, &LoadOptions::default()).unwrap();
    assert_eq!(s.lights, default_lights());
    assert!(s.stats.warnings.iter().any(|w| w.contains("default sky") && w.contains("--no-default-light")));
    // Turned off: no light, and a warning that the image will be black.
    let s = load_file("bare-off", "t.obj", TRIANGLE, &no_default_light()).unwrap();
    assert!(s.lights.is_empty());
    assert!(
        s.stats.warnings.iter().any(|w| w.contains("no lights") && w.contains("black")),
        "{:?}",
        s.stats.warnings
    );
    // PLY too.
    let ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
               element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    let s = load_file("bare-ply", "t.ply", ply, &LoadOptions::default()).unwrap();
    assert_eq!(s.lights, default_lights());
}

#[test]
fn shared_meshes_without_lights_are_lit_by_default() {
    for rel in ["scenes/teapot/teapot.obj", "scenes/bunny/bunny_lowres.obj"] {
        let Some(p) = shared(rel) else { continue };
        let s = load(&p).unwrap();
        assert_eq!(s.lights, default_lights(), "{rel}");
    }
}

#[test]
fn an_emissive_material_is_a_light() {
    let mtl = "newmtl lamp\nKe 1 1 1\n";
    let obj = format!("mtllib l.mtl\nusemtl lamp\n{TRIANGLE}");
    let dir = temp_files("chk-emit", &[("t.obj", obj.as_bytes()), ("l.mtl", mtl.as_bytes())]);
    let s = load(&dir.join("t.obj")).unwrap();
    assert!(s.lights.is_empty());
    assert!(s.stats.warnings.is_empty(), "{:?}", s.stats.warnings);
}

#[test]
fn toml_scene_without_lights_warns_and_without_geometry_fails() {
    let toml = "[[objects]]\nshape = \"cube\"\n";
    let s = load_file("toml-dark", "t.toml", toml, &LoadOptions::default()).unwrap();
    assert!(s.lights.is_empty(), "a TOML scene is not lit by default");
    assert!(s.stats.warnings.iter().any(|w| w.contains("no lights")), "{:?}", s.stats.warnings);
    // Only an environment: renders the environment, with a warning.
    let env = "[[lights]]\ntype = \"environment\"\nradiance = [1, 1, 1]\n";
    let s = load_file("toml-env", "t.toml", env, &LoadOptions::default()).unwrap();
    assert!(s.stats.warnings.iter().any(|w| w.contains("no triangles")), "{:?}", s.stats.warnings);
    // Nothing at all, or a point light with nothing to light.
    let point = "[[lights]]\ntype = \"point\"\nposition = [0, 1, 0]\nintensity = [1, 1, 1]\n";
    for (tag, text) in [("toml-empty", "name = \"x\"\n"), ("toml-point", point)] {
        let e = load_file(tag, "t.toml", text, &LoadOptions::default()).unwrap_err();
        assert!(e.to_string().contains("no triangles"), "{tag}: {e}");
    }
}

#[test]
fn mesh_file_without_triangles_is_an_error() {
    let e = load_file("empty-obj", "t.obj", "v 0 0 0\n", &LoadOptions::default()).unwrap_err();
    assert!(e.to_string().contains("t.obj") && e.to_string().contains("no triangles"), "{e}");
}

#[test]
fn exact_duplicate_triangles_are_dropped_with_a_warning() {
    // The same triangle 1000 times (in all three rotations of its corners), its reverse
    // (the back face, kept) and one copy under another material.
    let mut obj = String::from("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\n");
    for i in 0..1000 {
        obj += ["f 1 2 3\n", "f 2 3 1\n", "f 3 1 2\n"][i % 3];
    }
    obj += "f 1 3 2\nusemtl b\nf 1 2 3\n";
    let mtl = b"newmtl a\nKe 1 1 1\nnewmtl b\nKd 0.2 0.2 0.2\n";
    let dir = temp_files("chk-dup", &[("t.obj", obj.as_bytes()), ("m.mtl", mtl)]);
    let s = load(&dir.join("t.obj")).unwrap();
    assert_eq!(s.triangle_count(), 2, "one triangle and its back face");
    let w: Vec<_> = s.stats.warnings.iter().filter(|w| w.contains("duplicate")).collect();
    assert_eq!(w.len(), 1, "{:?}", s.stats.warnings);
    assert!(
        w[0].contains("1000 exact duplicate") && w[0].contains("1 of them had another material"),
        "{w:?}"
    );
}

#[test]
fn control_bytes_from_a_file_are_escaped() {
    let obj = format!("{TRIANGLE}zz\x1b[31mred\x07 1 2\n");
    let s = load_file("esc", "t.obj", &obj, &LoadOptions::default()).unwrap();
    let w: Vec<_> = s.stats.warnings.iter().filter(|w| w.contains("red")).collect();
    assert_eq!(w.len(), 1, "{:?}", s.stats.warnings);
    assert!(!w[0].chars().any(char::is_control), "{:?}", w[0]);
    assert!(w[0].contains("\\u{1b}[31mred\\u{7}"), "{}", w[0]);
    // Errors quote file text too.
    let e = load_file("esc-err", "t.obj", "v 0 \x1b]0;x\x07 0\n", &LoadOptions::default()).unwrap_err();
    assert!(!e.to_string().chars().any(char::is_control), "{e}");
}

#[test]
fn albedo_above_one_is_a_warning() {
    let mtl = b"newmtl hot\nKd 1.5 0.2 0.2\n";
    let obj = format!("mtllib m.mtl\nusemtl hot\n{TRIANGLE}");
    let dir = temp_files("chk-albedo", &[("t.obj", obj.as_bytes()), ("m.mtl", mtl)]);
    let s = load(&dir.join("t.obj")).unwrap();
    assert!(
        s.stats.warnings.iter().any(|w| w.contains("'hot'") && w.contains("albedo 1.5")),
        "{:?}",
        s.stats.warnings
    );
}
