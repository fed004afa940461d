//! Every scene file type through the binary (TOML, OBJ + MTL, PLY, glTF + .bin): the EXR that
//! `filtrace render` writes holds exactly (bit for bit, every layer) what an in-process
//! render of the same scene and settings gives: the command adds nothing and loses nothing
//! between the renderer and the file.

use filtrace_core::Image;
use filtrace_render::{RenderSettings, Renderer};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::AtomicBool;

const WIDTH: u32 = 16;
const HEIGHT: u32 = 12;
const SPP: u32 = 3;
const SEED: u64 = 7;

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("filtrace-e2e-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&d).ok();
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A floor and a smaller emitting quad above it, facing down (OBJ + MTL with `Ke`).
fn write_obj(dir: &Path) -> PathBuf {
    std::fs::write(dir.join("tiny.mtl"), "newmtl floor\nKd 0.8 0.6 0.4\nnewmtl light\nKd 0 0 0\nKe 4 4 4\n")
        .unwrap();
    let obj = "mtllib tiny.mtl\n\
        v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\n\
        v -0.5 1 -0.5\nv 0.5 1 -0.5\nv 0.5 1 0.5\nv -0.5 1 0.5\n\
        usemtl floor\nf 4 3 2 1\nusemtl light\nf 5 6 7 8\n";
    let path = dir.join("tiny.obj");
    std::fs::write(&path, obj).unwrap();
    path
}

/// Two triangles of a tilted quad (ASCII PLY; the default grey material, no light).
fn write_ply(dir: &Path) -> PathBuf {
    let ply = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
        property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n\
        -1 -1 0\n1 -1 0.5\n1 1 0\n-1 1 -0.5\n3 0 1 2\n3 0 2 3\n";
    let path = dir.join("tiny.ply");
    std::fs::write(&path, ply).unwrap();
    path
}

/// A diffuse floor triangle and an emissive triangle facing +z, in a glTF with its buffer
/// in a `.bin` beside it.
fn write_gltf(dir: &Path) -> PathBuf {
    let vertices: [[f32; 3]; 6] = [
        [-1.0, 0.0, -1.0],
        [-1.0, 0.0, 1.0],
        [1.0, 0.0, 1.0],
        [-0.5, 0.2, 0.0],
        [0.5, 0.2, 0.0],
        [0.0, 0.9, 0.0],
    ];
    let bytes: Vec<u8> = vertices.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(dir.join("tiny.bin"), &bytes).unwrap();
    let gltf = r#"{
  "asset": {"version": "2.0"},
  "scene": 0,
  "scenes": [{"nodes": [0, 1]}],
  "nodes": [{"mesh": 0}, {"mesh": 1}],
  "meshes": [
    {"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]},
    {"primitives": [{"attributes": {"POSITION": 1}, "material": 1}]}
  ],
  "materials": [
    {"pbrMetallicRoughness": {"baseColorFactor": [0.7, 0.7, 0.7, 1], "metallicFactor": 0}},
    {"emissiveFactor": [1, 0.8, 0.6], "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1]}}
  ],
  "buffers": [{"uri": "tiny.bin", "byteLength": 72}],
  "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 72}],
  "accessors": [
    {"bufferView": 0, "byteOffset": 0, "componentType": 5126, "count": 3, "type": "VEC3",
     "min": [-1, 0, -1], "max": [1, 0, 1]},
    {"bufferView": 0, "byteOffset": 36, "componentType": 5126, "count": 3, "type": "VEC3",
     "min": [-0.5, 0.2, 0], "max": [0.5, 0.9, 0]}
  ]
}"#;
    let path = dir.join("tiny.gltf");
    std::fs::write(&path, gltf).unwrap();
    path
}

/// The layers `filtrace render` writes, rendered in process as the command does (same
/// settings, passes of `max(spp / 16, 1)` samples).
fn render_in_process(scene: &str) -> Vec<(&'static str, Image)> {
    let scene = filtrace_scene::load_scene(scene).unwrap();
    let settings = RenderSettings { width: WIDTH, height: HEIGHT, spp: SPP, max_depth: 8, seed: SEED };
    let renderer = Renderer::new(scene, settings).unwrap();
    let mut film = renderer.new_film();
    let step = default_pass_spp(SPP);
    let mut first = 0;
    while first < SPP {
        let count = step.min(SPP - first);
        renderer.render_pass(&mut film, first, count, &AtomicBool::new(false));
        first += count;
    }
    let a = film.aovs();
    vec![
        ("color", a.color),
        ("direct", a.direct),
        ("indirect", a.indirect),
        ("albedo", a.albedo),
        ("normal", a.normal),
        ("position", a.position),
        ("depth", a.depth),
        ("variance", a.variance),
    ]
}

/// `filtrace render`'s default samples per pass.
fn default_pass_spp(spp: u32) -> u32 {
    (spp / 16).max(1)
}

fn render_through_binary(scene: &str, out: &Path) {
    let o = Command::new(env!("CARGO_BIN_EXE_filtrace"))
        .args(["render", scene, "--res", &format!("{WIDTH}x{HEIGHT}"), "--spp", &SPP.to_string()])
        .args(["--seed", &SEED.to_string(), "--threads", "2", "--out"])
        .arg(out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{scene}: {}", String::from_utf8_lossy(&o.stderr));
}

/// Renders `scene` both ways and compares every layer bit for bit; returns the colour mean.
fn check_scene(scene: &Path, dir: &Path) -> [f64; 3] {
    let arg = scene.to_str().unwrap();
    let out = dir.join(format!("{}.exr", scene.file_stem().unwrap().to_string_lossy()));
    render_through_binary(arg, &out);
    let file = filtrace_io::read_exr(&out).unwrap();
    let mut color_mean = [0.0; 3];
    for (name, want) in render_in_process(arg) {
        let got = file.require_layer(&[name]).unwrap();
        assert_eq!(
            (got.width(), got.height(), got.channels()),
            (want.width(), want.height(), want.channels())
        );
        let same = got.data().iter().zip(want.data()).all(|(a, b)| a.to_bits() == b.to_bits());
        assert!(same, "{arg}: layer {name} differs from the in-process render");
        if name == "color" {
            let m = want.mean();
            color_mean = [m[0], m[1], m[2]];
        }
        if name == "albedo" || name == "normal" {
            assert!(want.data().iter().any(|v| *v != 0.0), "{arg}: the {name} layer is empty");
        }
    }
    color_mean
}

#[test]
fn toml_scene_file_matches_an_in_process_render() {
    let dir = temp_dir("toml");
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell.toml");
    let mean = check_scene(&scene, &dir);
    assert!(mean.iter().all(|m| *m > 0.0), "{mean:?}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn obj_with_mtl_matches_an_in_process_render() {
    let dir = temp_dir("obj");
    let mean = check_scene(&write_obj(&dir), &dir);
    assert!(mean.iter().all(|m| *m > 0.0), "the emitter lights the image: {mean:?}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn ply_matches_an_in_process_render() {
    let dir = temp_dir("ply");
    check_scene(&write_ply(&dir), &dir);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn gltf_with_bin_matches_an_in_process_render() {
    let dir = temp_dir("gltf");
    let mean = check_scene(&write_gltf(&dir), &dir);
    assert!(mean.iter().all(|m| *m > 0.0), "the emitter is seen: {mean:?}");
    std::fs::remove_dir_all(&dir).ok();
}
