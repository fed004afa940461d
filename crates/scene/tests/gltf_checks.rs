//! glTF files that used to load wrongly or not at all (issue 17: defects 5, 6, 12, 13, 11):
//! node cycles and shared children, accessors outside their data or of the wrong type,
//! photometric light units, emissive strength, extensions, camera and colour ranges.
//! Each file is built here as JSON with an embedded base64 buffer.

mod common;

use common::{base64, temp_files};
use filtrace_core::Vec3;
use filtrace_scene::{load, Light, Scene, SceneError};

/// One triangle: 3 float positions (36 bytes), then u16 indices 0 1 2 (6 bytes) and 2 bytes
/// of padding; 6 more positions (72 bytes) at byte 44 for tests that need two triangles.
fn geometry() -> Vec<u8> {
    let mut b: Vec<u8> =
        [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0].iter().flat_map(|x| x.to_le_bytes()).collect();
    b.extend([0u16, 1, 2, 0].iter().flat_map(|x| x.to_le_bytes()));
    let six = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 1.0, 0.0, 1.0, 1.0];
    b.extend(six.iter().flat_map(|x| x.to_le_bytes()));
    b
}

/// A glTF document over [`geometry`]'s buffer (116 bytes) with the given JSON members
/// (`"accessors": ..., "meshes": ...`, without the buffer).
fn doc(members: &str) -> String {
    let b = geometry();
    format!(
        r#"{{"asset": {{"version": "2.0"}},
  "buffers": [{{"byteLength": {}, "uri": "data:application/octet-stream;base64,{}"}}],
  {members}}}"#,
        b.len(),
        base64(&b)
    )
}

/// Views: 0 = the triangle's positions, 1 = its indices, 2 = the six positions.
const VIEWS: &str = r#""bufferViews": [{"buffer": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 6},
                  {"buffer": 0, "byteOffset": 44, "byteLength": 72}]"#;

/// A document whose mesh 0 has one primitive with the given attributes/indices and accessors.
fn one_primitive(accessors: &str, primitive: &str) -> String {
    doc(&format!(
        r#"{VIEWS}, "accessors": [{accessors}], "meshes": [{{"name": "m", "primitives": [{primitive}]}}],
  "nodes": [{{"mesh": 0}}], "scenes": [{{"nodes": [0]}}]"#
    ))
}

fn load_json(tag: &str, json: &str) -> Result<Scene, SceneError> {
    let dir = temp_files(&format!("gltfchk-{tag}"), &[("t.gltf", json.as_bytes())]);
    load(&dir.join("t.gltf"))
}

/// Loading must fail with a message naming the file and containing every one of `want`.
fn expect_error(tag: &str, json: &str, want: &[&str]) {
    match load_json(tag, json) {
        Ok(s) => {
            panic!("{tag}: loaded ({} triangles), expected an error mentioning {want:?}", s.triangle_count())
        }
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.contains("t.gltf"), "{tag}: {msg}");
            for w in want {
                assert!(msg.contains(w), "{tag}: '{msg}' should mention '{w}'");
            }
        }
    }
}

/// The triangle's u16 indices.
const IDX: &str = r#"{"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}"#;

const POS: &str =
    r#"{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]}"#;

#[test]
fn well_formed_triangle_loads() {
    let idx = r#"{"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}"#;
    let s = load_json(
        "ok",
        &one_primitive(&format!("{POS}, {idx}"), r#"{"attributes": {"POSITION": 0}, "indices": 1}"#),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.triangle_count(), 1);
}

#[test]
fn node_cycles_are_errors_naming_the_node() {
    let tri = format!(
        r#"{VIEWS}, "accessors": [{POS}], "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}]"#
    );
    // A node that lists itself (this grew memory without limit).
    let own = doc(&format!(
        r#"{tri}, "nodes": [{{"mesh": 0, "name": "loop", "children": [0]}}], "scenes": [{{"nodes": [0]}}]"#
    ));
    expect_error("self", &own, &["node 0 ('loop')", "cycle"]);
    // A two-node cycle below a root.
    let two = doc(&format!(
        r#"{tri}, "nodes": [{{"children": [1]}}, {{"mesh": 0, "children": [2]}}, {{"children": [1]}}], "scenes": [{{"nodes": [0]}}]"#
    ));
    expect_error("two", &two, &["node 1", "node"]);
    // A cycle of parent links only (every node has one parent, no root).
    let ring = doc(&format!(
        r#"{tri}, "nodes": [{{"mesh": 0, "children": [1]}}, {{"children": [2]}}, {{"children": [0]}}], "scenes": [{{"nodes": [0]}}]"#
    ));
    expect_error("ring", &ring, &["cycle"]);
}

#[test]
fn shared_children_are_errors_naming_the_node() {
    let tri = format!(
        r#"{VIEWS}, "accessors": [{POS}], "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}]"#
    );
    let diamond = doc(&format!(
        r#"{tri}, "nodes": [{{"children": [1, 2]}}, {{"children": [3]}}, {{"children": [3]}}, {{"mesh": 0, "name": "leaf"}}],
  "scenes": [{{"nodes": [0]}}]"#
    ));
    expect_error("diamond", &diamond, &["node 3 ('leaf')", "node 1", "node 2", "disjoint trees"]);
    // 40 levels that each list the next node twice: 2^40 paths before the fix.
    let nodes: Vec<String> =
        (0..40).map(|i| format!(r#"{{"mesh": 0, "children": [{0}, {0}]}}"#, i + 1)).collect();
    let chain = doc(&format!(
        r#"{tri}, "nodes": [{}, {{"mesh": 0}}], "scenes": [{{"nodes": [0]}}]"#,
        nodes.join(", ")
    ));
    expect_error("chain", &chain, &["node 1", "listed twice"]);
    // A root listed twice in the scene.
    let twice = doc(&format!(r#"{tri}, "nodes": [{{"mesh": 0}}], "scenes": [{{"nodes": [0, 0]}}]"#));
    expect_error("root-twice", &twice, &["node 0", "reached twice"]);
}

#[test]
fn accessors_outside_their_data_are_errors_naming_mesh_and_primitive() {
    let six = r#"{"bufferView": 2, "componentType": 5126, "count": 6, "type": "VEC3", "min": [0,0,0], "max": [1,1,1]}"#;
    let prim_idx = r#"{"attributes": {"POSITION": 0}, "indices": 1}"#;
    let cases: &[(&str, String, &str)] = &[
        // Indices past their 6-byte view: gave 2 triangles (non-indexed) with exit 0.
        (
            "idx-past-view",
            format!(
                r#"{six}, {{"bufferView": 1, "byteOffset": 2, "componentType": 5123, "count": 3, "type": "SCALAR"}}"#
            ),
            "indices",
        ),
        // Positions past their view: reported "primitive without POSITION".
        (
            "pos-past-view",
            format!(
                r#"{{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]}}, {IDX}"#
            ),
            "POSITION",
        ),
        // A count whose byte size overflows.
        (
            "overflow",
            format!(
                r#"{{"bufferView": 0, "componentType": 5126, "count": 4611686018427387904, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]}}, {IDX}"#
            ),
            "POSITION",
        ),
        // A byte stride smaller than one element (a debug assertion in the gltf crate).
        (
            "stride",
            format!(
                r#"{{"bufferView": 3, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]}}, {IDX}"#
            ),
            "byteStride 4",
        ),
        // Wrong component types.
        (
            "pos-u16",
            format!(
                r#"{{"bufferView": 0, "componentType": 5123, "count": 3, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]}}, {IDX}"#
            ),
            "POSITION",
        ),
        (
            "idx-float",
            format!(r#"{POS}, {{"bufferView": 2, "componentType": 5126, "count": 3, "type": "SCALAR"}}"#),
            "indices",
        ),
        (
            "idx-vec2",
            format!(r#"{POS}, {{"bufferView": 2, "componentType": 5123, "count": 3, "type": "VEC2"}}"#),
            "indices",
        ),
        // An index that names a vertex the primitive does not have.
        (
            "idx-value",
            format!(
                r#"{{"bufferView": 0, "componentType": 5126, "count": 2, "type": "VEC3", "min": [0,0,0], "max": [1,0,0]}}, {IDX}"#
            ),
            "out of range",
        ),
    ];
    for (tag, accessors, want) in cases {
        let views = VIEWS.replace("]", r#", {"buffer": 0, "byteLength": 36, "byteStride": 4}]"#);
        let json = doc(&format!(
            r#"{views}, "accessors": [{accessors}], "meshes": [{{"name": "m", "primitives": [{prim_idx}]}}],
  "nodes": [{{"mesh": 0}}], "scenes": [{{"nodes": [0]}}]"#
        ));
        expect_error(tag, &json, &["mesh 0 (m) primitive 0", want]);
    }
    // A buffer view that runs past the end of the loaded buffer.
    let json = doc(&format!(
        r#""bufferViews": [{{"buffer": 0, "byteOffset": 100, "byteLength": 36}}], "accessors": [{POS}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}], "nodes": [{{"mesh": 0}}], "scenes": [{{"nodes": [0]}}]"#
    ));
    match load_json("view-past-buffer", &json) {
        Ok(s) => panic!("loaded {} triangles from a view past the buffer", s.triangle_count()),
        Err(e) => assert!(e.to_string().contains("t.gltf"), "{e}"),
    }
}

#[test]
fn blender_light_units_are_converted_from_photometric() {
    // Written as Blender 3.4's exporter writes a 1000 W point light, a 500 W spot and a
    // 3 W/m^2 sun ("Standard" lighting mode): W / (4 pi) x 683 cd, and W/m^2 x 683 lux.
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/blender_lights.gltf");
    let s = load(&p).unwrap_or_else(|e| panic!("{e}"));
    let close = |a: Vec3, b: f32| (a - Vec3::splat(b)).abs().max_element() < 1e-3 * b;
    let per_sr = |watts: f32| watts / (4.0 * std::f32::consts::PI);
    assert_eq!(s.lights.len(), 3, "{:?}", s.lights);
    match &s.lights[0] {
        Light::Point { intensity, .. } => assert!(close(*intensity, per_sr(1000.0)), "{intensity}"),
        l => panic!("{l:?}"),
    }
    match &s.lights[1] {
        Light::Spot { intensity, .. } => assert!(close(*intensity, per_sr(500.0)), "{intensity}"),
        l => panic!("{l:?}"),
    }
    match &s.lights[2] {
        Light::Directional { irradiance, .. } => assert!(close(*irradiance, 3.0), "{irradiance}"),
        l => panic!("{l:?}"),
    }
    // KHR_materials_emissive_strength (5) multiplies the emissive factor.
    assert!((s.materials[0].emission - Vec3::new(5.0, 2.5, 1.25)).abs().max_element() < 1e-6);
    assert!(s.stats.warnings.is_empty(), "{:?}", s.stats.warnings);
}

#[test]
fn unsupported_extensions_warn_or_fail() {
    let base = format!(
        r#"{VIEWS}, "accessors": [{POS}], "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}],
  "nodes": [{{"mesh": 0}}], "scenes": [{{"nodes": [0]}}]"#
    );
    let used = doc(&format!(r#""extensionsUsed": ["KHR_texture_transform", "KHR_lights_punctual"], {base}"#));
    let s = load_json("ext-used", &used).unwrap_or_else(|e| panic!("{e}"));
    let w: Vec<_> = s.stats.warnings.iter().filter(|w| w.contains("extensions")).collect();
    assert_eq!(w.len(), 1, "{:?}", s.stats.warnings);
    assert!(w[0].contains("KHR_texture_transform") && !w[0].contains("KHR_lights_punctual"), "{w:?}");
    let required = doc(&format!(
        r#""extensionsUsed": ["KHR_draco_mesh_compression"], "extensionsRequired": ["KHR_draco_mesh_compression"], {base}"#
    ));
    expect_error("ext-required", &required, &["KHR_draco_mesh_compression"]);
}

#[test]
fn camera_fov_and_base_colour_out_of_range_are_errors() {
    let base = format!(r#"{VIEWS}, "accessors": [{POS}], "scenes": [{{"nodes": [0, 1]}}]"#);
    for yfov in ["0", "-1", "3.2"] {
        let json = doc(&format!(
            r#"{base}, "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}],
  "cameras": [{{"type": "perspective", "perspective": {{"yfov": {yfov}, "znear": 0.1}}}}],
  "nodes": [{{"mesh": 0}}, {{"camera": 0}}]"#
        ));
        expect_error(&format!("yfov{yfov}"), &json, &["camera 0", "yfov"]);
    }
    let json = doc(&format!(
        r#"{base}, "materials": [{{"name": "hot", "pbrMetallicRoughness": {{"baseColorFactor": [1.5, 0.5, 0.5, 1]}}}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "material": 0}}]}}], "nodes": [{{"mesh": 0}}, {{}}]"#
    ));
    expect_error("albedo", &json, &["material 0 ('hot')", "baseColorFactor"]);
}
