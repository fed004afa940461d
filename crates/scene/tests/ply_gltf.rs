//! PLY and glTF loader tests.

mod common;

use common::{base64, shared, temp_files};
use filtrace_core::{Vec2, Vec3};
use filtrace_scene::{load, Bsdf, SceneError};

/// A small mesh written as PLY: a quad with normals and uvs, and a triangle (with an extra
/// `material` element and a face property to skip).
fn ply_mesh() -> (Vec<[f32; 8]>, Vec<Vec<u32>>) {
    let v = vec![
        [0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
        [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0],
        [1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
        [0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0],
        [0.5, 0.5, 1.0, 0.0, 0.6, 0.8, 0.5, 0.5],
    ];
    let f = vec![vec![0, 1, 2, 3], vec![0, 4, 1], vec![2, 2, 3]];
    (v, f)
}

fn header(format: &str, nv: usize, nf: usize) -> String {
    format!(
        "ply\nformat {format} 1.0\ncomment test\nelement vertex {nv}\nproperty float x\nproperty float y\n\
         property float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty float s\n\
         property float t\nelement face {nf}\nproperty list uchar int vertex_indices\nproperty uchar flags\n\
         element material 1\nproperty double shininess\nend_header\n"
    )
}

fn write_ascii() -> Vec<u8> {
    let (v, f) = ply_mesh();
    let mut s = header("ascii", v.len(), f.len());
    for p in &v {
        s += &p.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(" ");
        s += "\n";
    }
    for face in &f {
        s += &format!(
            "{} {} 7\n",
            face.len(),
            face.iter().map(|i| i.to_string()).collect::<Vec<_>>().join(" ")
        );
    }
    s += "12.5\n";
    s.into_bytes()
}

fn write_binary() -> Vec<u8> {
    let (v, f) = ply_mesh();
    let mut b = header("binary_little_endian", v.len(), f.len()).into_bytes();
    for p in &v {
        for x in p {
            b.extend_from_slice(&x.to_le_bytes());
        }
    }
    for face in &f {
        b.push(face.len() as u8);
        for i in face {
            b.extend_from_slice(&(*i as i32).to_le_bytes());
        }
        b.push(7);
    }
    b.extend_from_slice(&12.5f64.to_le_bytes());
    b
}

#[test]
fn ply_ascii_equals_binary() {
    let dir = temp_files("ply", &[("a.ply", &write_ascii()), ("b.ply", &write_binary())]);
    let a = load(&dir.join("a.ply")).unwrap();
    let b = load(&dir.join("b.ply")).unwrap();
    let (ma, mb) = (&a.meshes[0], &b.meshes[0]);
    assert_eq!(ma.positions, mb.positions);
    assert_eq!(ma.normals, mb.normals);
    assert_eq!(ma.uvs, mb.uvs);
    assert_eq!(ma.indices, mb.indices);
    // Quad -> 2 triangles, plus 1 triangle; (2 2 3) is degenerate.
    assert_eq!(ma.indices, vec![[0, 1, 2], [0, 2, 3], [0, 4, 1]]);
    assert_eq!(a.stats.degenerate_triangles_skipped, 1);
    assert_eq!(ma.uvs[2], Vec2::new(1.0, 1.0));
    assert!((ma.normals[4] - Vec3::new(0.0, 0.6, 0.8)).length() < 1e-6);
}

#[test]
fn ply_bunny_ascii_equals_binary() {
    // The low-resolution bunny written both ways from the OBJ.
    let Some(p) = shared("scenes/bunny/bunny_lowres.obj") else { return };
    let s = load(&p).unwrap();
    let m = &s.meshes[0];
    let head = |f: &str| {
        format!(
            "ply\nformat {f} 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
             element face {}\nproperty list uchar uint vertex_index\nend_header\n",
            m.positions.len(),
            m.indices.len()
        )
    };
    let mut ascii = head("ascii");
    let mut bin = head("binary_little_endian").into_bytes();
    for p in &m.positions {
        ascii += &format!("{:?} {:?} {:?}\n", p.x, p.y, p.z);
        for x in p.to_array() {
            bin.extend_from_slice(&x.to_le_bytes());
        }
    }
    for t in &m.indices {
        ascii += &format!("3 {} {} {}\n", t[0], t[1], t[2]);
        bin.push(3);
        for i in t {
            bin.extend_from_slice(&i.to_le_bytes());
        }
    }
    let dir = temp_files("plybunny", &[("a.ply", ascii.as_bytes()), ("b.ply", &bin)]);
    let a = load(&dir.join("a.ply")).unwrap();
    let b = load(&dir.join("b.ply")).unwrap();
    assert_eq!(a.meshes[0].positions, m.positions);
    assert_eq!(a.meshes[0].indices, m.indices);
    assert_eq!(b.meshes[0].positions, m.positions);
    assert_eq!(b.meshes[0].indices, m.indices);
    assert_eq!(a.triangle_count(), 3674 - s.stats.degenerate_triangles_skipped);
}

#[test]
fn malformed_ply_errors_name_file_and_line() {
    let cases: &[(&str, &str, Option<usize>, &str)] = &[
        ("notply", "hello\n", Some(1), "not a PLY"),
        ("badprop", "ply\nformat ascii 1.0\nelement vertex 1\nproperty flot x\nend_header\n", Some(4), "bad property"),
        (
            "badnum",
            "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n0 zz 0\n",
            Some(9),
            "cannot parse number 'zz'",
        ),
        (
            "oob",
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
             element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
            Some(13),
            "out of range",
        ),
        (
            "short",
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n",
            Some(9),
            "end of file",
        ),
        ("noend", "ply\nformat ascii 1.0\nelement vertex 3\n", Some(4), "end_header"),
    ];
    for (tag, text, line, want) in cases {
        let dir = temp_files(&format!("ply-{tag}"), &[("t.ply", text.as_bytes())]);
        match load(&dir.join("t.ply")) {
            Err(e @ SceneError::Parse { .. }) => {
                let SceneError::Parse { line: l, .. } = &e else { unreachable!() };
                let msg = e.to_string();
                assert_eq!(l, line, "{tag}: {msg}");
                assert!(msg.contains("t.ply"), "{msg}");
                assert!(msg.contains(want), "{tag}: '{msg}' should mention '{want}'");
            }
            other => panic!("{tag}: expected a parse error, got {other:?}"),
        }
    }
    // A truncated binary body names the byte offset.
    let mut b = write_binary();
    b.truncate(b.len() - 20);
    let dir = temp_files("ply-trunc", &[("t.ply", &b)]);
    let e = load(&dir.join("t.ply")).unwrap_err();
    assert!(e.to_string().contains("end of file at byte"), "{e}");
}

#[test]
fn gltf_engine_triangle_counts_and_instancing() {
    let Some(p) = shared("scenes/gltf/2CylinderEngine.glb") else { return };
    let s = load(&p).unwrap();
    let unique: usize = s.meshes.iter().map(|m| m.triangle_count()).sum();
    println!(
        "meshes {} instances {} unique {} total {} skipped {}",
        s.meshes.len(),
        s.instances.len(),
        unique,
        s.triangle_count(),
        s.stats.degenerate_triangles_skipped
    );
    // Published counts: 121,496 triangles over instances, 75,730 unique. Check them on the raw
    // file (read with the gltf crate directly), then check that ours are those minus the
    // degenerate triangles, mesh by mesh and instance by instance.
    let (doc, _, _) = gltf::import(&p).unwrap();
    let raw: Vec<usize> = doc
        .meshes()
        .flat_map(|m| m.primitives().map(|p| p.indices().map_or(0, |a| a.count()) / 3).collect::<Vec<_>>())
        .collect();
    assert_eq!(raw.iter().sum::<usize>(), 75_730);
    assert_eq!(raw.len(), s.meshes.len(), "one mesh per primitive");
    assert_eq!(unique + s.stats.degenerate_triangles_skipped, 75_730);
    let raw_total: usize = s.instances.iter().map(|i| raw[i.mesh as usize]).sum();
    assert_eq!(raw_total, 121_496);
    for (m, &r) in s.meshes.iter().zip(&raw) {
        assert!(m.triangle_count() <= r);
    }
    assert!(s.instances.len() > s.meshes.len(), "instancing must not be flattened");
    assert!(s
        .materials
        .iter()
        .all(|m| matches!(m.bsdf, Bsdf::Diffuse { .. } | Bsdf::Plastic { .. } | Bsdf::Conductor { .. })));
    let b = s.bounds();
    assert!(b.min.is_finite() && b.max.is_finite() && !b.is_empty());
}

#[test]
fn gltf_minimal_with_light_camera_and_hierarchy() {
    // A triangle placed twice through a parent/child hierarchy, a spot light and a camera.
    let positions: [f32; 9] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let bytes: Vec<u8> = positions.iter().flat_map(|x| x.to_le_bytes()).collect();
    let uri = format!("data:application/octet-stream;base64,{}", base64(&bytes));
    let json = format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "extensionsUsed": ["KHR_lights_punctual"],
  "extensions": {{"KHR_lights_punctual": {{"lights": [
     {{"type": "spot", "color": [1, 0.5, 0.25], "intensity": 10, "spot": {{"innerConeAngle": 0.2, "outerConeAngle": 0.5}}}},
     {{"type": "directional", "intensity": 3}}]}}}},
  "buffers": [{{"byteLength": 36, "uri": "{uri}"}}],
  "bufferViews": [{{"buffer": 0, "byteLength": 36}}],
  "accessors": [{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                  "min": [0,0,0], "max": [1,1,0]}}],
  "materials": [{{"name": "gold", "pbrMetallicRoughness": {{"baseColorFactor": [1, 0.8, 0.3, 1], "metallicFactor": 1, "roughnessFactor": 0.3}}}},
                {{"name": "lamp", "emissiveFactor": [2, 2, 2], "pbrMetallicRoughness": {{"metallicFactor": 0}}}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "material": 0}},
                             {{"attributes": {{"POSITION": 0}}, "material": 1}}]}}],
  "cameras": [{{"type": "perspective", "perspective": {{"yfov": 0.5, "znear": 0.1}}}}],
  "nodes": [
    {{"children": [1, 2], "translation": [10, 0, 0]}},
    {{"mesh": 0}},
    {{"mesh": 0, "scale": [2, 2, 2]}},
    {{"extensions": {{"KHR_lights_punctual": {{"light": 0}}}}, "translation": [0, 5, 0], "rotation": [-0.7071068, 0, 0, 0.7071068]}},
    {{"camera": 0, "translation": [0, 0, 10]}},
    {{"extensions": {{"KHR_lights_punctual": {{"light": 1}}}}}}
  ],
  "scenes": [{{"nodes": [0, 3, 4, 5]}}],
  "scene": 0
}}"#
    );
    let dir = temp_files("gltf-min", &[("t.gltf", json.as_bytes())]);
    let s = load(&dir.join("t.gltf")).unwrap();
    assert_eq!(s.meshes.len(), 2, "one mesh per primitive");
    assert_eq!(s.instances.len(), 4, "two nodes x two primitives");
    assert_eq!(s.triangle_count(), 4);
    let b = s.bounds();
    assert!(
        (b.min - Vec3::new(10.0, 0.0, 0.0)).length() < 1e-5
            && (b.max - Vec3::new(12.0, 2.0, 0.0)).length() < 1e-5
    );
    match &s.materials[0].bsdf {
        Bsdf::Conductor { eta, k, roughness } => {
            // Normal-incidence Fresnel of eta=1, k equals the base colour.
            let f0 = |k: f32| k * k / (4.0 + k * k);
            assert!((f0(k.y) - 0.8).abs() < 1e-5 && (f0(k.z) - 0.3).abs() < 1e-5);
            assert_eq!(*eta, Vec3::ONE);
            assert!((roughness - 0.3).abs() < 1e-6);
        }
        b => panic!("{b:?}"),
    }
    assert_eq!(s.materials[1].emission, Vec3::splat(2.0));
    match &s.lights[0] {
        filtrace_scene::Light::Spot {
            position,
            direction,
            intensity,
            cos_total_width,
            cos_falloff_start,
        } => {
            assert!((*position - Vec3::new(0.0, 5.0, 0.0)).length() < 1e-5);
            // Rotated -90 degrees about x: -Z becomes -Y (pointing down).
            assert!((*direction - Vec3::NEG_Y).length() < 1e-5, "{direction}");
            // 10 cd / 683 lm/W.
            assert!((*intensity * 683.0 - Vec3::new(10.0, 5.0, 2.5)).abs().max_element() < 1e-4);
            assert!(
                (cos_total_width - 0.5f32.cos()).abs() < 1e-6
                    && (cos_falloff_start - 0.2f32.cos()).abs() < 1e-6
            );
        }
        l => panic!("{l:?}"),
    }
    match &s.lights[1] {
        filtrace_scene::Light::Directional { direction, irradiance } => {
            assert_eq!(*direction, Vec3::Z, "direction points towards the light");
            assert!((*irradiance * 683.0 - Vec3::splat(3.0)).abs().max_element() < 1e-5);
        }
        l => panic!("{l:?}"),
    }
    let c = s.camera.as_ref().unwrap();
    assert_eq!(c.eye, Vec3::new(0.0, 0.0, 10.0));
    assert_eq!(c.target, Vec3::new(0.0, 0.0, 9.0));
    assert!((c.vfov_deg - 0.5f32.to_degrees()).abs() < 1e-4);
}

#[test]
fn malformed_gltf_json_names_the_line() {
    let dir = temp_files(
        "gltf-bad",
        &[("t.gltf", b"{\n  \"asset\": {\"version\": \"2.0\"},\n  \"nodes\": [ oops ]\n}\n")],
    );
    match load(&dir.join("t.gltf")) {
        Err(e @ SceneError::Parse { line: Some(3), .. }) => {
            assert!(e.to_string().contains("t.gltf:3:"), "{e}")
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn non_finite_data_never_leaves_a_loader() {
    // PLY: a NaN vertex used only by a (skipped) triangle is removed; bounds stay finite.
    let ply =
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
               element face 2\nproperty list uchar int vertex_indices\nend_header\n\
               0 0 0\nnan 0 0\n1 0 0\n0 1 0\n3 0 2 3\n3 0 1 2\n";
    let dir = temp_files("ply-nan", &[("t.ply", ply.as_bytes())]);
    let s = load(&dir.join("t.ply")).unwrap();
    assert_eq!(s.stats.degenerate_triangles_skipped, 1);
    assert_eq!(s.meshes[0].positions.len(), 3);
    assert_eq!(s.meshes[0].triangle(0), [Vec3::ZERO, Vec3::X, Vec3::Y]);
    let b = s.bounds();
    assert!(b.min.is_finite() && b.max.is_finite());
    // OBJ: a NaN texture coordinate and an infinite normal are repaired with warnings.
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt nan 0\nvn 0 0 inf\nf 1/1/1 2/1/1 3/1/1\n";
    let dir = temp_files("obj-nan", &[("t.obj", obj.as_bytes())]);
    let s = load(&dir.join("t.obj")).unwrap();
    assert!(s.meshes[0].uvs.iter().all(|t| t.is_finite()));
    assert!(s.meshes[0].normals.is_empty());
    assert!(s.stats.warnings.iter().any(|w| w.contains("texture coordinates")), "{:?}", s.stats.warnings);
}
