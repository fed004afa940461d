//! glTF animations: node hierarchies, the three sampler kinds and a moving camera, against
//! values computed by hand; malformed animations are errors naming the channel. Each file
//! is built here as JSON with an embedded base64 buffer.

mod common;

use common::{base64, temp_files};
use filtrace_core::Vec3;
use filtrace_scene::{load, Scene, SceneError};

/// A buffer under construction: one triangle (accessors 0 = positions, 1 = u16 indices),
/// then float accessors appended by [`Buf::floats`].
struct Buf {
    bytes: Vec<u8>,
    views: Vec<String>,
    accessors: Vec<String>,
}

impl Buf {
    fn new() -> Self {
        let mut b = Buf { bytes: Vec::new(), views: Vec::new(), accessors: Vec::new() };
        b.floats(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0], "VEC3");
        let at = b.bytes.len();
        b.bytes.extend([0u16, 1, 2, 0].iter().flat_map(|x| x.to_le_bytes()));
        b.views.push(format!(r#"{{"buffer": 0, "byteOffset": {at}, "byteLength": 6}}"#));
        b.accessors.push(r#"{"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}"#.into());
        b
    }

    /// Appends `data` as a float accessor of `ty` (SCALAR, VEC3, VEC4); returns its index.
    fn floats(&mut self, data: &[f32], ty: &str) -> usize {
        let width = match ty {
            "SCALAR" => 1,
            "VEC3" => 3,
            _ => 4,
        };
        let at = self.bytes.len();
        self.bytes.extend(data.iter().flat_map(|x| x.to_le_bytes()));
        let view = self.views.len();
        self.views.push(format!(r#"{{"buffer": 0, "byteOffset": {at}, "byteLength": {}}}"#, data.len() * 4));
        // min and max per component (glTF requires them on animation inputs).
        let bound = |f: fn(f32, f32) -> f32| {
            let v: Vec<String> = (0..width)
                .map(|k| data.iter().skip(k).step_by(width).copied().fold(data[k], f).to_string())
                .collect();
            v.join(", ")
        };
        self.accessors.push(format!(
            r#"{{"bufferView": {view}, "componentType": 5126, "count": {}, "type": "{ty}", "min": [{}], "max": [{}]}}"#,
            data.len() / width,
            bound(f32::min),
            bound(f32::max)
        ));
        self.accessors.len() - 1
    }

    fn json(&self, members: &str) -> String {
        let b64 = base64(&self.bytes);
        format!(
            r#"{{"asset": {{"version": "2.0"}},
  "buffers": [{{"byteLength": {}, "uri": "data:application/octet-stream;base64,{b64}"}}],
  "bufferViews": [{}], "accessors": [{}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1}}]}}],
  {members}}}"#,
            self.bytes.len(),
            self.views.join(", "),
            self.accessors.join(", ")
        )
    }
}

fn load_json(tag: &str, json: &str) -> Result<Scene, SceneError> {
    let dir = temp_files(&format!("gltfanim-{tag}"), &[("t.gltf", json.as_bytes())]);
    load(&dir.join("t.gltf"))
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).abs().max_element() < 1e-5
}

/// Node 0 ("arm", translation keyed LINEAR 0 -> (4, 0, 0) over 2 s) carries node 1 (the
/// mesh, at (0, 1, 0), scale keyed STEP 1 -> 2 at 1 s); node 2 is a camera at (0, 0, 5)
/// turning 90 degrees about +y over 1 s.
fn rig(buf: &mut Buf) -> String {
    let t2 = buf.floats(&[0.0, 2.0], "SCALAR");
    let move_x = buf.floats(&[0.0, 0.0, 0.0, 4.0, 0.0, 0.0], "VEC3");
    let t1 = buf.floats(&[0.0, 1.0], "SCALAR");
    let grow = buf.floats(&[1.0, 1.0, 1.0, 2.0, 2.0, 2.0], "VEC3");
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let turn = buf.floats(&[0.0, 0.0, 0.0, 1.0, 0.0, h, 0.0, h], "VEC4");
    format!(
        r#""nodes": [{{"name": "arm", "children": [1]}}, {{"mesh": 0, "translation": [0, 1, 0]}},
              {{"camera": 0, "translation": [0, 0, 5]}}],
  "cameras": [{{"type": "perspective", "perspective": {{"yfov": 0.8, "znear": 0.1}}}}],
  "scenes": [{{"nodes": [0, 2]}}],
  "animations": [{{"samplers": [
      {{"input": {t2}, "output": {move_x}}},
      {{"input": {t1}, "output": {grow}, "interpolation": "STEP"}},
      {{"input": {t1}, "output": {turn}}}],
    "channels": [
      {{"sampler": 0, "target": {{"node": 0, "path": "translation"}}}},
      {{"sampler": 1, "target": {{"node": 1, "path": "scale"}}}},
      {{"sampler": 2, "target": {{"node": 2, "path": "rotation"}}}}]}}]"#
    )
}

#[test]
fn a_node_hierarchy_moves_its_mesh_and_camera() {
    let mut buf = Buf::new();
    let members = rig(&mut buf);
    let scene = load_json("rig", &buf.json(&members)).unwrap();
    let anim = scene.animation.as_ref().expect("the file is animated");
    assert_eq!((anim.clock.fps, anim.clock.first, anim.clock.last), (24.0, 0, 48));
    let animation_warnings = scene.stats.warnings.iter().filter(|w| w.contains("animation"));
    assert_eq!(animation_warnings.count(), 0, "{:?}", scene.stats.warnings);

    // Frame 24 = 1 s: arm at (2, 0, 0); the mesh at arm + (0, 1, 0), scaled by 2 (STEP).
    let pose = scene.pose_at_frame(24).unwrap();
    let (inst, m) = pose.instances[0];
    assert_eq!(inst, 0);
    assert!(close(m.transform_point3(Vec3::X), Vec3::new(4.0, 1.0, 0.0)), "{m:?}");
    // Frame 12 = 0.5 s: arm at (1, 0, 0), scale still 1.
    let (_, m) = scene.pose_at_frame(12).unwrap().instances[0];
    assert!(close(m.transform_point3(Vec3::X), Vec3::new(2.0, 1.0, 0.0)), "{m:?}");

    // The camera looked along -z at rest; turned 90 degrees about +y it looks along -x.
    let cam = pose.camera.expect("the camera node moves");
    assert!(close(cam.eye, Vec3::new(0.0, 0.0, 5.0)), "{cam:?}");
    assert!(close((cam.target - cam.eye).normalize(), Vec3::NEG_X), "{cam:?}");
    assert!((cam.vfov_deg - 0.8f32.to_degrees()).abs() < 1e-4);

    // The rest pose is what was loaded: frame 0 equals the scene as placed.
    let mut posed = scene.clone();
    posed.apply_pose(&scene.pose_at_frame(0).unwrap());
    assert!(posed.instances[0].transform.abs_diff_eq(scene.instances[0].transform, 1e-6));
    assert_eq!(posed.camera, scene.camera);
}

/// glTF spec Appendix C with keys (t=0, v=0, out=(1,0,0)) and (t=2, v=(1,0,0), in=0), at
/// t = 1: s = 0.5, m0 = 2 * 1, so x = 0.125 * 2 + 0.5 * 1 = 0.75.
#[test]
fn cubic_spline_channels_follow_the_spec() {
    let mut buf = Buf::new();
    let t = buf.floats(&[0.0, 2.0], "SCALAR");
    let out = buf.floats(
        &[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        "VEC3",
    );
    let members = format!(
        r#""nodes": [{{"mesh": 0}}], "scenes": [{{"nodes": [0]}}],
  "animations": [{{"samplers": [{{"input": {t}, "output": {out}, "interpolation": "CUBICSPLINE"}}],
    "channels": [{{"sampler": 0, "target": {{"node": 0, "path": "translation"}}}}]}}]"#
    );
    let scene = load_json("cubic", &buf.json(&members)).unwrap();
    let (_, m) = scene.pose_at_frame(24).unwrap().instances[0];
    assert!(close(m.translation.into(), Vec3::new(0.75, 0.0, 0.0)), "{m:?}");
}

#[test]
fn a_file_without_animations_is_still() {
    let buf = Buf::new();
    let scene =
        load_json("still", &buf.json(r#""nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}]"#)).unwrap();
    assert!(scene.animation.is_none());
}

#[test]
fn malformed_animations_are_errors_naming_the_channel() {
    let channel = |buf: &mut Buf, times: &[f32], values: &[f32], interp: &str, node: &str| {
        let t = buf.floats(times, "SCALAR");
        let v = buf.floats(values, "VEC3");
        format!(
            r#""nodes": [{node}], "scenes": [{{"nodes": [0]}}],
  "animations": [{{"samplers": [{{"input": {t}, "output": {v}, "interpolation": "{interp}"}}],
    "channels": [{{"sampler": 0, "target": {{"node": 0, "path": "translation"}}}}]}}]"#
        )
    };
    let plain = r#"{"mesh": 0}"#;
    /// (tag, key times, values, interpolation, node JSON, expected message part)
    type Case<'a> = (&'a str, &'a [f32], &'a [f32], &'a str, &'a str, &'a str);
    let cases: [Case; 4] = [
        ("order", &[1.0, 0.5], &[0.0; 6], "LINEAR", plain, "not after"),
        ("nan", &[0.0, f32::NAN], &[0.0; 6], "LINEAR", plain, "non-finite time"),
        ("cubic-count", &[0.0, 1.0], &[0.0; 6], "CUBICSPLINE", plain, "3 outputs per key"),
        (
            "matrix",
            &[0.0, 1.0],
            &[0.0; 6],
            "LINEAR",
            r#"{"mesh": 0, "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]}"#,
            "matrix",
        ),
    ];
    for (tag, times, values, interp, node, want) in cases {
        let mut buf = Buf::new();
        let members = channel(&mut buf, times, values, interp, node);
        let json = buf.json(&members);
        let e = match load_json(tag, &json) {
            Ok(_) => panic!("{tag}: loaded, expected an error mentioning '{want}'"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains("t.gltf") && e.contains("animation 0 channel 0"), "{tag}: {e}");
        assert!(e.contains(want), "{tag}: '{e}' should mention '{want}'");
    }
}
