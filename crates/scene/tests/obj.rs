//! OBJ/MTL loader tests: real files from ../shared and small malformed inputs.

mod common;

use common::{shared, temp_files};
use filtrace_core::{Rgb, Vec3};
use filtrace_scene::{builtin, load, Bsdf, SceneError, Texturable};

fn load_text(tag: &str, obj: &str, extra: &[(&str, &[u8])]) -> Result<filtrace_scene::Scene, SceneError> {
    let mut files: Vec<(&str, &[u8])> = vec![("t.obj", obj.as_bytes())];
    files.extend_from_slice(extra);
    let dir = temp_files(tag, &files);
    load(&dir.join("t.obj"))
}

fn expect_parse_error(tag: &str, obj: &str, want_line: usize, want_text: &str) {
    match load_text(tag, obj, &[]) {
        Err(e @ SceneError::Parse { line: Some(l), .. }) => {
            let msg = e.to_string();
            assert_eq!(l, want_line, "{msg}");
            assert!(msg.contains("t.obj"), "error must name the file: {msg}");
            assert!(msg.contains(&format!(":{want_line}:")), "error must name the line: {msg}");
            assert!(msg.contains(want_text), "'{msg}' should mention '{want_text}'");
        }
        other => panic!("expected a parse error at line {want_line}, got {other:?}"),
    }
}

#[test]
fn cornell_box_obj_has_the_published_bounds() {
    let Some(p) = shared("scenes/cornell_box/cornell_box.obj") else { return };
    let s = load(&p).unwrap();
    let b = s.bounds();
    assert_eq!(b.min, Vec3::ZERO);
    assert!((b.max - Vec3::new(556.0, 548.8, 559.2)).abs().max_element() < 1e-4, "{b:?}");
    // 34 triangles: the light and front wall are commented out, 17 quads remain... minus
    // the light (1 quad, its face line is commented) -> check against a count of `f` lines.
    let src = std::fs::read_to_string(&p).unwrap();
    let quads = src.lines().filter(|l| l.starts_with("f ")).count();
    assert_eq!(s.triangle_count(), 2 * quads);
    assert_eq!(s.triangle_count(), 34);
    // The unlit box gets the default light (and says so), nothing else.
    assert!(s.stats.warnings.iter().all(|w| w.contains("default sky")), "{:?}", s.stats.warnings);
}

#[test]
fn builtin_cornell_equals_the_lit_obj() {
    let Some(p) = shared("scenes/cornell_box/cornell_box_lit.obj") else { return };
    let file = load(&p).unwrap();
    let built = builtin("cornell").unwrap();
    assert_eq!(file.materials, built.materials);
    let tris = |s: &filtrace_scene::Scene| {
        let mut v = Vec::new();
        for (ii, inst) in s.instances.iter().enumerate() {
            let m = &s.meshes[inst.mesh as usize];
            for t in 0..m.triangle_count() {
                let mat = &s.materials[s.material_of(ii as u32, t as u32) as usize];
                let c = m.triangle(t).map(|p| inst.transform.transform_point3(p));
                v.push((c, mat.name.clone()));
            }
        }
        v
    };
    let (a, b) = (tris(&file), tris(&built));
    assert_eq!(a.len(), 36);
    assert_eq!(a, b);
    let names: Vec<_> = file.meshes.iter().map(|m| m.name.as_str()).collect();
    let built_names: Vec<_> = built.meshes.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, built_names);
    assert_eq!(file.stats, built.stats);
}

#[test]
fn builtin_cornell_light_faces_down_and_emits() {
    let s = builtin("cornell").unwrap();
    let light = s.meshes.iter().find(|m| m.name == "light").unwrap();
    for t in 0..light.triangle_count() {
        let [a, b, c] = light.triangle(t);
        let n = (b - a).cross(c - a).normalize();
        assert!((n - Vec3::NEG_Y).length() < 1e-6);
        assert!(a.y == 548.7 && b.y == 548.7 && c.y == 548.7);
        let m = &s.materials[light.material_ids[t] as usize];
        assert_eq!(m.emission, Rgb::new(18.387, 13.9873, 6.75357));
        assert!(!m.two_sided_emission);
    }
}

#[test]
fn negative_indices_and_ngons() {
    let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0.5 1.5 0\nv 0 1 0\nf -5 -4 -3 -2 -1\nvt 0 0\nvn 0 0 1\nf 1/1/1 2/-1/-1 3/1/1\n";
    let s = load_text("neg", obj, &[]).unwrap();
    // Pentagon -> 3 triangles (fan), plus one triangle with uv and normals that repeats the
    // fan's first triangle (dropped as an exact duplicate).
    assert_eq!(s.triangle_count(), 3);
    let m = &s.meshes[0];
    // Fan triangulation around vertex 0, counter-clockwise as in the file.
    assert_eq!(m.triangle(0), [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0)]);
    assert_eq!(m.triangle(2), [Vec3::ZERO, Vec3::new(0.5, 1.5, 0.0), Vec3::Y]);
    for t in 0..3 {
        let [a, b, c] = m.triangle(t);
        assert!((b - a).cross(c - a).z > 0.0);
    }
    // Mixed references: some vertices have normals and some do not -> flat shading.
    assert!(m.normals.is_empty());
    assert_eq!(m.uvs.len(), m.positions.len());
}

#[test]
fn all_vertex_forms_parse() {
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n\
               g a\nf 1 2 3\ng b\nf 1/1 2/2 3/3\ng c\nf 1//1 2//1 3//1\ng d\nf 1/1/1 2/2/1 3/3/1\n";
    let s = load_text("forms", obj, &[]).unwrap();
    assert_eq!(s.meshes.len(), 4);
    let names: Vec<_> = s.meshes.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["a", "b", "c", "d"]);
    assert!(s.meshes[0].uvs.is_empty() && s.meshes[0].normals.is_empty());
    assert_eq!(s.meshes[1].uvs[1], filtrace_core::Vec2::new(1.0, 0.0));
    assert_eq!(s.meshes[2].normals, vec![Vec3::Z; 3]);
    assert_eq!(s.meshes[3].normals.len(), 3);
    assert_eq!(s.meshes[3].uvs.len(), 3);
}

#[test]
fn degenerate_triangles_are_skipped_and_counted() {
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nv nan 0 0\n\
               f 1 2 3\nf 1 1 2\nf 1 2 4\nf 1 2 5\nf 1 2 3 3\n";
    let s = load_text("degen", obj, &[]).unwrap();
    // Kept: (1 2 3); skipped: repeated index, collinear (zero area), NaN corner, and (1 3 3);
    // the first fan triangle of (1 2 3 3) repeats (1 2 3) and is dropped as a duplicate.
    assert_eq!(s.triangle_count(), 1);
    assert_eq!(s.stats.degenerate_triangles_skipped, 4);
    for m in &s.meshes {
        assert!(m.positions.iter().all(|p| p.is_finite()));
    }
}

#[test]
fn missing_mtl_is_a_warning_with_default_grey() {
    let obj = "mtllib nowhere.mtl\nusemtl red\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    let s = load_text("nomtl", obj, &[]).unwrap();
    assert!(s.stats.warnings.iter().any(|w| w.contains("nowhere.mtl")), "{:?}", s.stats.warnings);
    assert_eq!(s.materials.len(), 1);
    assert_eq!(s.materials[0].bsdf, Bsdf::Diffuse { reflectance: Texturable::Constant(Rgb::splat(0.5)) });
}

#[test]
fn mtl_materials_map_to_bsdfs() {
    let mtl = "newmtl shiny\nKd 0.2 0.3 0.4\nKs 0.5 0.5 0.5\nNs 98\nd 1\nillum 2\n\
               newmtl lamp\nKd 0 0 0\nKe 5 4 3\n";
    let obj = "mtllib t.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl shiny\nf 1 2 3\nusemtl lamp\nf 3 2 1\n";
    let s = load_text("mtl", obj, &[("t.mtl", mtl.as_bytes())]).unwrap();
    assert!(s.stats.warnings.is_empty(), "{:?}", s.stats.warnings);
    let shiny = s.materials.iter().find(|m| m.name == "shiny").unwrap();
    // Ns = 98: alpha = sqrt(2/100) = 0.1414, r = sqrt(alpha) = 0.3761.
    match &shiny.bsdf {
        Bsdf::Plastic { diffuse, roughness, ior } => {
            assert_eq!(*diffuse, Texturable::Constant(Rgb::new(0.2, 0.3, 0.4)));
            assert!((roughness - 0.02f32.sqrt().sqrt()).abs() < 1e-6);
            assert_eq!(*ior, 1.5);
        }
        b => panic!("expected plastic, got {b:?}"),
    }
    let lamp = s.materials.iter().find(|m| m.name == "lamp").unwrap();
    assert_eq!(lamp.emission, Rgb::new(5.0, 4.0, 3.0));
    let m = &s.meshes[0];
    assert_eq!(s.materials[m.material_ids[0] as usize].name, "shiny");
    assert_eq!(s.materials[m.material_ids[1] as usize].name, "lamp");
}

#[test]
fn map_kd_is_loaded_and_linearised() {
    // A 2x1 PNG: sRGB 128 grey and pure red.
    let mut png = Vec::new();
    let img = image::RgbImage::from_raw(2, 1, vec![128, 128, 128, 255, 0, 0]).unwrap();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png).unwrap();
    let mtl = "newmtl tex\nmap_Kd -s 1 1 1 tex.png\n";
    let obj = "mtllib t.mtl\nusemtl tex\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1\n";
    let s = load_text("mapkd", obj, &[("t.mtl", mtl.as_bytes()), ("tex.png", &png)]).unwrap();
    assert_eq!(s.textures.len(), 1);
    let t = &s.textures[0];
    assert_eq!((t.width, t.height), (2, 1));
    assert!((t.texels[0].x - 0.215_861).abs() < 1e-4, "{:?}", t.texels[0]);
    assert_eq!(t.texels[1], Rgb::new(1.0, 0.0, 0.0));
    assert_eq!(
        s.materials[0].bsdf,
        Bsdf::Diffuse { reflectance: Texturable::Texture { texture: 0, factor: Rgb::ONE } }
    );
}

#[test]
fn malformed_obj_errors_name_file_and_line() {
    let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    expect_parse_error("oob", &format!("{tri}f 1 2 4\n"), 4, "out of range");
    expect_parse_error("neg-oob", &format!("{tri}\nf -1 -2 -4\n"), 5, "out of range");
    expect_parse_error("zero", &format!("{tri}f 0 1 2\n"), 4, "index 0");
    expect_parse_error("num", "v 0 0 0\nv 1 x 0\n", 2, "cannot parse number 'x'");
    expect_parse_error("short-v", "v 0 0\n", 1, "expected 3 numbers");
    expect_parse_error("two", &format!("{tri}f 1 2\n"), 4, "at least 3");
    expect_parse_error("vt-oob", &format!("{tri}f 1/1 2/1 3/1\n"), 4, "texture coordinate index");
    expect_parse_error("bad-vert", &format!("{tri}f 1/1/1/1 2 3\n"), 4, "bad face vertex");
}

#[test]
fn malformed_mtl_errors_name_the_mtl_file_and_line() {
    let obj = "mtllib bad.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    let mtl = "newmtl a\nKd 0.5 0.5 0.5\nKe 1 oops 1\n";
    match load_text("badmtl", obj, &[("bad.mtl", mtl.as_bytes())]) {
        Err(e @ SceneError::Parse { line: Some(3), .. }) => {
            assert!(e.to_string().contains("bad.mtl:3:"), "{e}")
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn missing_obj_is_an_io_error() {
    let e = load(std::path::Path::new("/definitely/not/here.obj")).unwrap_err();
    assert!(matches!(e, SceneError::Io { .. }), "{e:?}");
}

#[test]
fn mtllib_with_several_libraries() {
    let obj = "mtllib a.mtl b.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl fromb\nf 1 2 3\n";
    let a = b"newmtl froma\nKd 1 0 0\n";
    let b = b"newmtl fromb\nKd 0 1 0\n";
    let s = load_text("multi-mtl", obj, &[("a.mtl", a), ("b.mtl", b)]).unwrap();
    assert!(s.stats.warnings.iter().all(|w| w.contains("default sky")), "{:?}", s.stats.warnings);
    assert_eq!(s.materials.len(), 2);
    assert_eq!(s.materials[s.meshes[0].material_ids[0] as usize].name, "fromb");
}
