//! TOML animation: poses against hand-computed values, and malformed tracks naming their line.

mod common;

use common::temp_files;
use filtrace_core::{Affine3A, Quat, Vec3};
use filtrace_scene::toml_scene::parse_toml;
use filtrace_scene::{load, Light, Scene};
use std::path::Path;

const BASE: &str = r#"
[camera]
eye = [0, 1, 10]
target = [0, 1, 0]

[[objects]]
name = "box"
shape = "cube"
transform = { scale = 2, translate = [1, 0, 0] }

[[lights]]
name = "lamp"
type = "point"
position = [0, 5, 0]
intensity = [10, 10, 10]

[animation]
fps = 10
frames = [0, 20]
"#;

fn parse(tracks: &str) -> Result<Scene, String> {
    parse_toml(&format!("{BASE}\n{tracks}"), Path::new("anim.toml")).map_err(|e| e.to_string())
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).abs().max_element() < 1e-5
}

#[test]
fn object_camera_and_light_tracks_give_the_expected_pose() {
    let scene = parse(
        r#"
[[tracks]]
target = "box"
property = "translate"
keys = [ { frame = 0, value = [1, 0, 0] }, { frame = 20, value = [5, 0, 0] } ]

[[tracks]]
target = "box"
property = "rotate"
keys = [ { t = 0, value = { deg = 0, axis = [0, 1, 0] } }, { t = 2, value = { deg = 90, axis = [0, 1, 0] } } ]

[[tracks]]
target = "camera"
property = "vfov"
interpolation = "step"
keys = [ { t = 0, value = 40 }, { t = 1, value = 60 } ]

[[tracks]]
target = "lamp"
property = "position"
keys = [ { t = 0, value = [0, 5, 0] }, { t = 2, value = [4, 5, 0] } ]
"#,
    )
    .unwrap();
    let pose = scene.pose_at_frame(10).unwrap(); // t = 1 s
    assert_eq!(pose.time, 1.0);
    assert_eq!(pose.camera.as_ref().unwrap().vfov_deg, 60.0);
    assert_eq!(pose.camera.as_ref().unwrap().eye, Vec3::new(0.0, 1.0, 10.0));
    let (inst, m) = pose.instances[0];
    assert_eq!(inst, 0);
    // Halfway: translation (3, 0, 0), rotation 45 degrees about y, the file's scale 2 kept.
    let expected = Affine3A::from_scale_rotation_translation(
        Vec3::splat(2.0),
        Quat::from_rotation_y(45f32.to_radians()),
        Vec3::new(3.0, 0.0, 0.0),
    );
    assert!(m.abs_diff_eq(expected, 1e-5), "{m:?}");
    match &pose.lights[..] {
        [(0, Light::Point { position, intensity })] => {
            assert!(close(*position, Vec3::new(2.0, 5.0, 0.0)), "{position:?}");
            assert_eq!(intensity.max_element(), 10.0);
        }
        other => panic!("{other:?}"),
    }
    let mut moved = scene.clone();
    moved.apply_pose(&pose);
    assert!(moved.instances[0].transform.abs_diff_eq(expected, 1e-5));
    assert_eq!(moved.meshes[0].positions, scene.meshes[0].positions, "meshes stay in object space");
}

/// A posed scene places the object where a still scene written with the pose's transform does.
#[test]
fn posed_scene_equals_a_still_scene_built_at_the_new_place() {
    let scene = parse(
        r#"
[[tracks]]
target = "box"
property = "translate"
keys = [ { t = 0, value = [1, 0, 0] }, { t = 2, value = [1, 4, 0] } ]
"#,
    )
    .unwrap();
    let mut posed = scene.clone();
    posed.apply_pose(&scene.pose_at_frame(20).unwrap());
    let still_src = BASE.replace("translate = [1, 0, 0]", "translate = [1, 4, 0]");
    let still = parse_toml(&still_src, Path::new("still.toml")).unwrap();
    assert!(posed.instances[0].transform.abs_diff_eq(still.instances[0].transform, 1e-6));
    assert_eq!(posed.bounds(), still.bounds());
}

#[test]
fn still_scenes_have_an_empty_pose_at_every_frame() {
    let scene = parse_toml(&BASE.replace("[animation]\nfps = 10\nframes = [0, 20]", ""), Path::new("s.toml"))
        .unwrap();
    assert!(scene.animation.is_none());
    let pose = scene.pose_at_frame(7).unwrap();
    let mut posed = scene.clone();
    posed.apply_pose(&pose);
    assert_eq!(posed.camera, scene.camera);
    assert_eq!(posed.lights, scene.lights);
    assert_eq!(posed.instances[0].transform, scene.instances[0].transform);
}

#[test]
fn mesh_file_objects_move_their_instances_and_lights_together() {
    let dir =
        temp_files("anim-mesh", &[("tri.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"), ("tri.mtl", b"")]);
    let src = r#"
[camera]
eye = [0, 0, 5]
target = [0, 0, 0]
[[objects]]
name = "tri"
mesh = "tri.obj"
transform = { translate = [0, 0, 1] }
[animation]
fps = 1
frames = [0, 1]
[[tracks]]
target = "tri"
property = "translate"
keys = [ { t = 0, value = [0, 0, 1] }, { t = 1, value = [0, 0, 3] } ]
"#;
    std::fs::write(dir.join("s.toml"), src).unwrap();
    let scene = load(&dir.join("s.toml")).unwrap();
    let pose = scene.pose_at_frame(1).unwrap();
    let (_, m) = pose.instances[0];
    assert!(close(m.transform_point3(Vec3::ZERO), Vec3::new(0.0, 0.0, 3.0)));
}

#[test]
fn catmull_rom_camera_path_passes_through_its_keys() {
    let scene = parse(
        r#"
[[tracks]]
target = "camera"
property = "eye"
interpolation = "catmull-rom"
keys = [ { t = 0, value = [0, 1, 10] }, { t = 1, value = [5, 1, 5] }, { t = 2, value = [0, 1, 0] } ]
"#,
    )
    .unwrap();
    for (frame, eye) in
        [(0, Vec3::new(0.0, 1.0, 10.0)), (10, Vec3::new(5.0, 1.0, 5.0)), (20, Vec3::new(0.0, 1.0, 0.0))]
    {
        let cam = scene.pose_at_frame(frame).unwrap().camera.unwrap();
        assert!(close(cam.eye, eye), "frame {frame}: {:?}", cam.eye);
    }
}

/// Each malformed input names the line of the offending key or track.
#[test]
fn malformed_tracks_are_errors_naming_the_line() {
    let track = |target: &str, property: &str, keys: &str| {
        format!("[[tracks]]\ntarget = \"{target}\"\nproperty = \"{property}\"\nkeys = [\n{keys}\n]\n")
    };
    let cases = [
        (
            track("box", "translate", "{ t = 1, value = [0, 0, 0] },\n{ t = 0.5, value = [1, 0, 0] }"),
            "not after",
            Some("t = 0.5"),
        ),
        (
            track("box", "translate", "{ t = 0, value = [0, 0, 0] },\n{ t = nan, value = [1, 0, 0] }"),
            "finite",
            Some("t = nan"),
        ),
        (
            track("box", "rotate", "{ t = 0, value = [0, 0, 0, 1] },\n{ t = 1, value = [0, 0, 0, 0] }"),
            "zero length",
            Some("[0, 0, 0, 0]"),
        ),
        (
            track("box", "translate", "{ t = 0, value = [0, 0, 0] },\n{ t = 1, value = [nan, 0, 0] }"),
            "finite",
            Some("[nan, 0, 0]"),
        ),
        (
            track("chair", "translate", "{ t = 0, value = [0, 0, 0] }"),
            "no object or light is named 'chair'",
            None,
        ),
        (track("box", "position", "{ t = 0, value = [0, 0, 0] }"), "no property 'position'", None),
        (track("lamp", "direction", "{ t = 0, value = [0, 0, 1] }"), "no direction", None),
        (track("camera", "vfov", "{ t = 0, value = 0 }"), "(0, 180)", None),
        (track("box", "scale", "{ t = 0, value = [1, 0, 1] }"), "non-zero", None),
        (
            track("box", "translate", "{ t = 0, frame = 1, value = [0, 0, 0] }"),
            "exactly one of `t` or `frame`",
            None,
        ),
        (track("box", "translate", ""), "no keys", None::<&str>),
        (
            track("box", "translate", "{ t = 0, value = [0, 0, 0] }")
                + &track("box", "translate", "{ t = 0, value = [1, 0, 0] }"),
            "keyed by an earlier track",
            None,
        ),
    ];
    for (src, needle, line) in cases {
        let e = parse(&src).unwrap_err();
        let full = format!("{BASE}\n{src}");
        assert!(e.contains(needle), "expected '{needle}' in: {e}\n{src}");
        assert!(e.starts_with("anim.toml:"), "names the file: {e}");
        if let Some(marker) = line {
            let line = full.lines().position(|l| l.contains(marker)).unwrap() + 1;
            assert!(e.starts_with(&format!("anim.toml:{line}:")), "expected line {line}: {e}");
        }
    }
}

#[test]
fn animation_table_and_frame_range_are_checked() {
    let no_anim = BASE.replace("[animation]\nfps = 10\nframes = [0, 20]", "");
    let src = format!(
        "{no_anim}\n[[tracks]]\ntarget = \"box\"\nproperty = \"scale\"\nkeys = [ {{ t = 0, value = 1 }} ]\n"
    );
    let e = parse_toml(&src, Path::new("a.toml")).unwrap_err().to_string();
    assert!(e.contains("[animation]"), "{e}");
    let e = parse_toml(&BASE.replace("fps = 10", "fps = 0"), Path::new("a.toml")).unwrap_err().to_string();
    assert!(e.contains("frame rate"), "{e}");
    let e =
        parse_toml(&BASE.replace("frames = [0, 20]", "frames = [5, 2]"), Path::new("a.toml")).unwrap_err();
    assert!(e.to_string().contains("empty"), "{e}");
    let scene = parse("").unwrap();
    let e = scene.pose_at_frame(21).unwrap_err().to_string();
    assert!(e.contains("outside") && e.contains("0..20"), "{e}");
    let e = parse_toml(&BASE.replace("name = \"lamp\"", "name = \"box\""), Path::new("a.toml")).unwrap_err();
    assert!(e.to_string().contains("used twice"), "{e}");
}

#[test]
fn the_example_animation_loads_and_moves() {
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/animation.toml");
    let scene = load(&path).unwrap();
    let anim = scene.animation.as_ref().expect("the example is animated");
    assert_eq!((anim.clock.first, anim.clock.last), (0, 48));
    assert_eq!(anim.key_range(), Some((0.0, 2.0)));
    let cam = scene.pose_at_frame(24).unwrap().camera.unwrap();
    assert!(close(cam.eye, Vec3::new(3.0, 2.5, 5.0)), "{:?}", cam.eye);
    let pose = scene.pose_at_frame(48).unwrap();
    assert!(close(pose.instances[0].1.translation.into(), Vec3::new(1.0, 0.5, 0.0)));
}
