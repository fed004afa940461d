//! Fuzzing of the scene loaders other than OBJ and PLY (see `fuzz.rs` for those): TOML scenes,
//! MTL libraries, glTF JSON and binary glTF. Each case mutates a valid seed file (byte flips,
//! truncations, splices, numeric extremes) and must end in `Ok` with a well-formed scene or in
//! an error: never a panic, never a case over [`CASE_LIMIT`], never growth past the address-space
//! limit of the child process the test runs in (`fuzz_support`).
//!
//! Fast tier: [`FAST_CASES`] per format. Slow tier (`--ignored`): [`SLOW_CASES`] per format.
//!
//! Generated glTF has no `children`; node cycles and shared children are tested one by one
//! in `gltf_checks.rs`.

mod common;
mod fuzz_support;

use common::base64;
use std::path::{Path, PathBuf};

use filtrace_scene::toml_scene::parse_toml;
use filtrace_scene::validate::sanitize;
use filtrace_scene::{load, Scene};
use fuzz_support::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};

/// What a loader that returned `Ok` promises: indices and material ids in range, finite
/// non-degenerate triangles, instances of existing meshes, finite transforms and camera.
fn well_formed(s: &Scene) {
    for m in &s.meshes {
        assert_eq!(m.indices.len(), m.material_ids.len());
        assert!(m.normals.is_empty() || m.normals.len() == m.positions.len());
        assert!(m.uvs.is_empty() || m.uvs.len() == m.positions.len());
        for (k, t) in m.indices.iter().enumerate() {
            assert!(t.iter().all(|&i| (i as usize) < m.positions.len()));
            let [a, b, c] = m.triangle(k);
            assert!(a.is_finite() && b.is_finite() && c.is_finite(), "non-finite triangle kept");
        }
        assert!(m.material_ids.iter().all(|&id| (id as usize) < s.materials.len()));
    }
    for inst in &s.instances {
        assert!((inst.mesh as usize) < s.meshes.len());
        assert!(inst.transform.is_finite(), "non-finite instance transform");
        assert!(inst.material_override.is_none_or(|id| (id as usize) < s.materials.len()));
    }
    if let Some(c) = &s.camera {
        assert!(c.eye.is_finite() && c.target.is_finite() && c.up.is_finite() && c.vfov_deg.is_finite());
    }
}

/// Runs `cases` mutations (up to `max_edits` each) of `seeds` through `check(seed index,
/// bytes)` (true: the loader returned `Ok`) under
/// a watchdog, deterministically (the runner's seed is fixed: a failure in CI reproduces
/// locally). At least 5 % of the cases must load: mutations that all die at the first syntax
/// check would test nothing deeper.
fn fuzz(format: &str, seeds: &[Vec<u8>], max_edits: usize, cases: u32, check: impl Fn(usize, &[u8]) -> bool) {
    assert!(!seeds.is_empty());
    let dog = Watchdog::new(CASE_LIMIT);
    let config = Config { cases, failure_persistence: None, ..Config::default() };
    let rng = TestRng::from_seed(RngAlgorithm::ChaCha, &[17; 32]);
    let mut runner = TestRunner::new_with_rng(config, rng);
    let strategy = (0..seeds.len(), mutations(max_edits));
    let loaded = std::cell::Cell::new(0u32);
    let result = runner.run(&strategy, |(i, muts)| {
        dog.case(format!("{format} seed {i}, mutations {muts:?}"));
        loaded.set(loaded.get() + check(i, &apply(&seeds[i], &muts)) as u32);
        Ok(())
    });
    if let Err(e) = result {
        panic!("{format}: {e}");
    }
    let ok = loaded.get();
    println!("{format}: {cases} cases, {ok} loaded, the others ended in an error");
    assert!(ok * 20 >= cases, "{format}: only {ok} of {cases} mutated files loaded");
}

/// Loads `bytes` written to `dir/name` with [`load`] (which sanitizes), checking an `Ok`.
fn load_bytes(dir: &Path, name: &str, bytes: &[u8]) -> bool {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write the fuzz case");
    load(&path).map(|s| well_formed(&s)).is_ok()
}

// ---------------------------------------------------------------- TOML scenes

fn scenes_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes")
}

/// The example scenes that need nothing outside the repository (every feature of the format).
fn toml_seeds() -> Vec<Vec<u8>> {
    let mut names: Vec<PathBuf> = std::fs::read_dir(scenes_dir())
        .expect("scenes/ is readable")
        .map(|e| e.expect("scenes/ entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    names.sort();
    names
        .iter()
        .map(|p| std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display())))
        .filter(|t| !String::from_utf8_lossy(t).contains("../shared/"))
        .collect()
}

fn fuzz_toml(cases: u32) {
    let path = scenes_dir().join("fuzz-case.toml");
    fuzz("toml", &toml_seeds(), 3, cases, |_, bytes| {
        let text = String::from_utf8_lossy(bytes);
        let Ok(mut s) = parse_toml(&text, &path) else { return false };
        let ok = sanitize(&mut s, &path).is_ok();
        if ok {
            well_formed(&s);
        }
        ok
    });
}

#[test]
fn toml_fuzz() {
    if limited_child("toml_fuzz", false) {
        fuzz_toml(FAST_CASES);
    }
}

#[test]
#[ignore = "slow: fuzz"]
fn toml_fuzz_slow() {
    if limited_child("toml_fuzz_slow", true) {
        fuzz_toml(SLOW_CASES);
    }
}

// ---------------------------------------------------------------- MTL libraries

const MTL_OBJ: &str = "mtllib fuzz.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\n\
vn 0 0 1\nusemtl red\nf 1/1/1 2/2/1 3/3/1\nusemtl shiny\nf 1/1/1 3/3/1 4/1/1\nusemtl lamp\nf 2 3 4\n";

const MTL_SEED: &str = "# every statement the loader reads, and some it ignores\n\
newmtl red\nKd 0.8 0.1 0.1\nKa 0 0 0\nd 1.0\nillum 2\n\
newmtl shiny\nKd 0.2 0.3 0.4\nKs 0.5 0.5 0.5\nNs 250\nNi 1.5\nmap_Kd tex.png\n\
newmtl lamp\nKd 0 0 0\nKe 17 12 4\nTr 0\nmap_Bump bump.png\n";

/// A 2 x 2 RGB PNG for `map_Kd`.
fn tiny_png() -> Vec<u8> {
    let img = image::RgbImage::from_fn(2, 2, |x, y| image::Rgb([(x * 200) as u8, (y * 200) as u8, 50]));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).expect("encode PNG");
    out.into_inner()
}

fn fuzz_mtl(cases: u32) {
    let dir = temp_dir("mtl");
    std::fs::write(dir.join("fuzz.obj"), MTL_OBJ).unwrap();
    std::fs::write(dir.join("tex.png"), tiny_png()).unwrap();
    // The seed itself loads, with its three materials.
    std::fs::write(dir.join("fuzz.mtl"), MTL_SEED).unwrap();
    let s = load(&dir.join("fuzz.obj")).unwrap_or_else(|e| panic!("MTL seed: {e}"));
    assert!(s.materials.len() >= 3 && s.textures.len() == 1, "{:?}", s.stats.warnings);
    fuzz("mtl", &[MTL_SEED.as_bytes().to_vec()], 4, cases, |_, bytes| {
        std::fs::write(dir.join("fuzz.mtl"), bytes).unwrap();
        load(&dir.join("fuzz.obj")).map(|s| well_formed(&s)).is_ok()
    });
}

#[test]
fn mtl_fuzz() {
    if limited_child("mtl_fuzz", false) {
        fuzz_mtl(FAST_CASES);
    }
}

#[test]
#[ignore = "slow: fuzz"]
fn mtl_fuzz_slow() {
    if limited_child("mtl_fuzz_slow", true) {
        fuzz_mtl(SLOW_CASES);
    }
}

// ---------------------------------------------------------------- glTF (JSON and binary)

/// The binary buffer of the seed: 4 positions, 4 normals, 4 uvs (f32), 6 u16 indices.
fn gltf_buffer() -> Vec<u8> {
    let mut b = Vec::new();
    let f = |b: &mut Vec<u8>, v: &[f32]| v.iter().for_each(|x| b.extend_from_slice(&x.to_le_bytes()));
    f(&mut b, &[0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0.]);
    f(&mut b, &[0., 0., 1., 0., 0., 1., 0., 0., 1., 0., 0., 1.]);
    f(&mut b, &[0., 0., 1., 0., 1., 1., 0., 1.]);
    for i in [0u16, 1, 2, 0, 2, 3] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    b // 48 + 48 + 32 + 12 = 140 bytes
}

/// A glTF document using every part the loader reads: two materials (plastic with a texture,
/// metal), an emissive one, a camera, the three punctual light kinds, one mesh instanced by
/// two nodes. `buffer_uri`: the buffer's `uri` (`None` in a GLB: the BIN chunk).
fn gltf_json(buffer_uri: Option<&str>, image_uri: &str) -> String {
    let uri = buffer_uri.map(|u| format!(r#""uri": "{u}", "#)).unwrap_or_default();
    format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "extensionsUsed": ["KHR_lights_punctual"],
  "scene": 0,
  "scenes": [{{"nodes": [0, 1, 2, 3, 4, 5]}}],
  "nodes": [
    {{"mesh": 0, "translation": [0.5, 0, -1]}},
    {{"mesh": 0, "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 2,0,0,1]}},
    {{"camera": 0, "translation": [0, 0.5, 4], "rotation": [0, 0, 0, 1]}},
    {{"extensions": {{"KHR_lights_punctual": {{"light": 0}}}}, "translation": [0, 3, 0]}},
    {{"extensions": {{"KHR_lights_punctual": {{"light": 1}}}}, "rotation": [-0.707, 0, 0, 0.707]}},
    {{"extensions": {{"KHR_lights_punctual": {{"light": 2}}}}, "scale": [1, 2, 1]}}
  ],
  "cameras": [{{"type": "perspective", "perspective": {{"yfov": 0.8, "znear": 0.01, "zfar": 100, "aspectRatio": 1.5}}}}],
  "extensions": {{"KHR_lights_punctual": {{"lights": [
    {{"type": "point", "color": [1, 0.9, 0.8], "intensity": 20}},
    {{"type": "directional", "intensity": 3}},
    {{"type": "spot", "intensity": 50, "spot": {{"innerConeAngle": 0.3, "outerConeAngle": 0.6}}}}
  ]}}}},
  "meshes": [{{"name": "quad", "primitives": [
    {{"attributes": {{"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}}, "indices": 3, "material": 0, "mode": 4}},
    {{"attributes": {{"POSITION": 4}}, "material": 1}},
    {{"attributes": {{"POSITION": 0}}, "indices": 3, "material": 2}}
  ]}}],
  "materials": [
    {{"name": "plastic", "pbrMetallicRoughness": {{"baseColorFactor": [0.8, 0.7, 0.6, 1], "baseColorTexture": {{"index": 0}}, "metallicFactor": 0, "roughnessFactor": 0.4}}}},
    {{"name": "metal", "pbrMetallicRoughness": {{"baseColorFactor": [0.9, 0.6, 0.3, 1], "metallicFactor": 1, "roughnessFactor": 0.2}}}},
    {{"name": "lamp", "emissiveFactor": [1, 1, 0.5], "emissiveTexture": {{"index": 0}}, "doubleSided": true}}
  ],
  "textures": [{{"source": 0}}],
  "images": [{{"uri": "{image_uri}"}}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}},
    {{"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"}},
    {{"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"}},
    {{"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"}},
    {{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}}
  ],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
    {{"buffer": 0, "byteOffset": 48, "byteLength": 48}},
    {{"buffer": 0, "byteOffset": 96, "byteLength": 32}},
    {{"buffer": 0, "byteOffset": 128, "byteLength": 12}}
  ],
  "buffers": [{{{uri}"byteLength": 140}}]
}}"#
    )
}

/// A `.glb`: 12-byte header, JSON chunk (space padded), BIN chunk (zero padded).
fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let mut j = json.as_bytes().to_vec();
    while !j.len().is_multiple_of(4) {
        j.push(b' ');
    }
    let mut b = bin.to_vec();
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
    let total = 12 + 8 + j.len() + 8 + b.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&j);
    out.extend_from_slice(&(b.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&b);
    out
}

/// Seeds: the buffer embedded as a data URI, and as a file next to the glTF.
fn gltf_seeds(dir: &Path) -> Vec<Vec<u8>> {
    std::fs::write(dir.join("quad.bin"), gltf_buffer()).unwrap();
    std::fs::write(dir.join("tex.png"), tiny_png()).unwrap();
    let data_uri = format!("data:application/octet-stream;base64,{}", base64(&gltf_buffer()));
    let png_uri = format!("data:image/png;base64,{}", base64(&tiny_png()));
    vec![
        gltf_json(Some(&data_uri), &png_uri).into_bytes(),
        gltf_json(Some("quad.bin"), "tex.png").into_bytes(),
    ]
}

/// The seeds load as intended (so that the mutations start from files that reach every part).
fn check_gltf_seed(dir: &Path, name: &str, bytes: &[u8]) {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    let s = load(&path).unwrap_or_else(|e| panic!("glTF seed {name}: {e}"));
    assert_eq!((s.instances.len(), s.lights.len(), s.textures.len()), (6, 3, 1), "{:?}", s.stats.warnings);
    assert!(s.camera.is_some());
}

fn fuzz_gltf(cases: u32) {
    let dir = temp_dir("gltf");
    let seeds = gltf_seeds(&dir);
    for (i, s) in seeds.iter().enumerate() {
        check_gltf_seed(&dir, &format!("seed{i}.gltf"), s);
    }
    fuzz("gltf", &seeds, 2, cases, |_, bytes| load_bytes(&dir, "fuzz.gltf", bytes));
}

fn fuzz_glb(cases: u32) {
    let dir = temp_dir("glb");
    let png_uri = format!("data:image/png;base64,{}", base64(&tiny_png()));
    let json = gltf_json(None, &png_uri);
    let seed = glb(&json, &gltf_buffer());
    check_gltf_seed(&dir, "seed.glb", &seed);
    // Seed 0: the container's bytes mutated (lengths, chunk types); seed 1: the JSON chunk
    // mutated and wrapped in a consistent container (reaches the document behind it).
    let seeds = [seed, json.into_bytes()];
    fuzz("glb", &seeds, 2, cases, |i, bytes| {
        let file = if i == 0 { bytes.to_vec() } else { glb(&String::from_utf8_lossy(bytes), &gltf_buffer()) };
        load_bytes(&dir, "fuzz.glb", &file)
    });
}

#[test]
fn gltf_fuzz() {
    if limited_child("gltf_fuzz", false) {
        fuzz_gltf(FAST_CASES);
    }
}

#[test]
#[ignore = "slow: fuzz"]
fn gltf_fuzz_slow() {
    if limited_child("gltf_fuzz_slow", true) {
        fuzz_gltf(SLOW_CASES);
    }
}

#[test]
fn glb_fuzz() {
    if limited_child("glb_fuzz", false) {
        fuzz_glb(FAST_CASES);
    }
}

#[test]
#[ignore = "slow: fuzz"]
fn glb_fuzz_slow() {
    if limited_child("glb_fuzz_slow", true) {
        fuzz_glb(SLOW_CASES);
    }
}

/// Found by `gltf_fuzz`: a POSITION accessor index past the accessor list panicked inside
/// gltf-json's validation (index out of bounds); it is now an error naming the file.
#[test]
fn gltf_position_accessor_index_out_of_range_is_an_error() {
    let dir = temp_dir("gltf-position-index");
    let json = gltf_json(Some("quad.bin"), "tex.png").replace(r#""POSITION": 4}"#, r#""POSITION": 9}"#);
    std::fs::write(dir.join("quad.bin"), gltf_buffer()).unwrap();
    std::fs::write(dir.join("tex.png"), tiny_png()).unwrap();
    let path = dir.join("bad.gltf");
    std::fs::write(&path, json).unwrap();
    let e = load(&path).expect_err("an out-of-range accessor index is an error").to_string();
    assert!(e.contains("bad.gltf"), "{e}");
}

/// Found by `glb_fuzz` under the memory limit: a GLB header claiming 2 GiB made gltf allocate
/// 2 GiB before reading a 4 kB file (an abort under the limit, a 2 GiB process without).
#[test]
fn glb_header_length_beyond_the_file_is_an_error() {
    let dir = temp_dir("glb-length");
    let mut bytes = glb(&gltf_json(None, "tex.png"), &gltf_buffer());
    bytes[8..12].copy_from_slice(&0x8000_0000u32.to_le_bytes());
    let path = dir.join("huge.glb");
    std::fs::write(&path, bytes).unwrap();
    let e = load(&path).expect_err("a header longer than the file is an error").to_string();
    assert!(e.contains("huge.glb") && e.contains("2147483648"), "{e}");
}
