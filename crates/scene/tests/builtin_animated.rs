//! The animated built-in scenes (`cornell-anim`, `classroom`, `colonnade-flight`):
//! deterministic, of the documented size, animated over their frames with frame 0 as the
//! rest pose, and moving only separate, named instances and lights along paths that stay
//! clear of the furniture they pass.

use filtrace_core::{Aabb, Vec3};
use filtrace_scene::animation::Pose;
use filtrace_scene::{builtin, Scene};

const ANIMATED: [(&str, i64); 3] = [("cornell-anim", 48), ("classroom", 48), ("colonnade-flight", 96)];

fn scene(name: &str) -> Scene {
    builtin(name).unwrap_or_else(|| panic!("{name} is a built-in scene"))
}

fn bits(v: Vec3) -> [u32; 3] {
    v.to_array().map(f32::to_bits)
}

/// Every world-space corner of every triangle, as bits.
fn world_bits(s: &Scene) -> Vec<[u32; 3]> {
    let mut out = Vec::new();
    for inst in &s.instances {
        for &p in &s.meshes[inst.mesh as usize].positions {
            out.push(bits(inst.transform.transform_point3(p)));
        }
    }
    out
}

#[test]
fn animated_builtins_are_deterministic_at_every_frame() {
    for (name, last) in ANIMATED {
        let (a, b) = (scene(name), scene(name));
        assert_eq!(world_bits(&a), world_bits(&b), "{name}");
        assert_eq!(a.animation, b.animation, "{name}");
        for f in 0..=last {
            assert_eq!(a.pose_at_frame(f).unwrap(), b.pose_at_frame(f).unwrap(), "{name} frame {f}");
        }
    }
}

#[test]
fn animated_builtins_have_their_documented_sizes_and_clocks() {
    assert_eq!(scene("cornell-anim").triangle_count(), 36);
    assert_eq!(scene("colonnade-flight").triangle_count(), scene("colonnade").triangle_count());
    let classroom = scene("classroom");
    let n = classroom.triangle_count();
    assert!((20_000..100_000).contains(&n), "classroom: {n} triangles, want tens of thousands");
    assert_eq!(n, 38_142, "classroom's triangle count changed: update docs/scenes.md");
    for (name, last) in ANIMATED {
        let clock = scene(name).animation.expect("animated").clock;
        assert_eq!((clock.fps, clock.first, clock.last), (24.0, 0, last), "{name}");
        let e = scene(name).pose_at_frame(last + 1).unwrap_err().to_string();
        assert!(e.contains(&format!("{}", last + 1)) && e.contains("outside"), "{name}: {e}");
    }
}

/// The scene with `pose` applied (what a renderer of that frame sees).
fn posed(s: &Scene, pose: &Pose) -> Scene {
    let mut t = s.clone();
    t.apply_pose(pose);
    t
}

#[test]
fn frame_zero_is_the_rest_pose_and_later_frames_move() {
    for (name, last) in ANIMATED {
        let s = scene(name);
        let rest = world_bits(&s);
        let zero = posed(&s, &s.pose_at_frame(0).unwrap());
        assert_eq!(world_bits(&zero), rest, "{name}: frame 0 moves an instance");
        assert_eq!(zero.lights, s.lights, "{name}: frame 0 moves a light");
        let (c0, c) = (s.camera.clone().unwrap(), zero.camera.clone().unwrap());
        assert!((c0.eye - c.eye).length() < 1e-4 && (c0.target - c.target).length() < 1e-4, "{name}");
        let mut eyes: Vec<Vec3> = Vec::new();
        for f in [last / 4, last / 2, 3 * last / 4] {
            let pose = s.pose_at_frame(f).unwrap();
            let eye = pose.camera.as_ref().expect("the camera is animated").eye;
            assert!(eyes.iter().chain([&c0.eye]).all(|e| (*e - eye).length() > 0.1), "{name} frame {f}");
            eyes.push(eye);
        }
    }
}

/// What an animation moves are instances with a mesh of their own, named as their node,
/// and lights; nothing else changes between poses.
#[test]
fn moving_instances_are_separate_and_named() {
    for (name, last) in ANIMATED {
        let s = scene(name);
        let anim = s.animation.as_ref().unwrap();
        for &(inst, node, _) in &anim.instances {
            let mesh = s.instances[inst as usize].mesh;
            let sharing = s.instances.iter().filter(|i| i.mesh == mesh).count();
            assert_eq!(sharing, 1, "{name}: a moving instance shares its mesh");
            assert_eq!(s.meshes[mesh as usize].name, anim.nodes[node as usize].name, "{name}");
        }
        let moved: Vec<u32> = anim.instances.iter().map(|i| i.0).collect();
        let (a, b) =
            (posed(&s, &s.pose_at_frame(0).unwrap()), posed(&s, &s.pose_at_frame(last / 3).unwrap()));
        for (i, (x, y)) in a.instances.iter().zip(&b.instances).enumerate() {
            let same = x.transform == y.transform;
            assert_eq!(same, !moved.contains(&(i as u32)), "{name}: instance {i}");
        }
    }
    assert_eq!(scene("cornell-anim").animation.unwrap().nodes[0].name, "light");
    let classroom = scene("classroom").animation.unwrap();
    let lamps: Vec<&str> = classroom.lights.iter().map(|l| l.name.as_str()).collect();
    assert_eq!(lamps, ["lamp_low", "lamp_high"]);
    assert_eq!(classroom.nodes[0].name, "teacher_chair");
}

/// World bounds of every instance of a mesh named `mesh_name`.
fn boxes_of(s: &Scene, mesh_name: &str) -> Vec<Aabb> {
    s.instances
        .iter()
        .filter(|i| s.meshes[i.mesh as usize].name == mesh_name)
        .map(|i| s.meshes[i.mesh as usize].bounds().transformed(&i.transform))
        .collect()
}

fn inside(b: &Aabb, p: Vec3, margin: f32) -> bool {
    p.cmpge(b.min - Vec3::splat(margin)).all() && p.cmple(b.max + Vec3::splat(margin)).all()
}

fn light_position(pose: &Pose, light: u32) -> Vec3 {
    match pose.lights.iter().find(|l| l.0 == light).map(|l| &l.1) {
        Some(filtrace_scene::Light::Point { position, .. }) => *position,
        other => panic!("light {light} is not a moving point light: {other:?}"),
    }
}

/// Sampled at four times the frame rate: the classroom's lamps and camera never enter a desk
/// or chair, the low lamp stays below the desk tops and every path stays in the room; the
/// flight's camera never enters a pillar or beam; the Cornell light stays on the ceiling.
#[test]
fn paths_stay_clear_of_the_geometry_they_pass() {
    let c = scene("classroom");
    let room = c.bounds();
    let furniture: Vec<Aabb> =
        ["desk", "chair", "teacher_desk"].iter().flat_map(|n| boxes_of(&c, n)).collect();
    let anim = c.animation.as_ref().unwrap();
    for q in 0..=4 * 48 {
        let t = q as f32 / (4.0 * 24.0);
        let pose = anim.pose(&c.lights, t);
        let chair = posed(&c, &pose);
        let teacher = boxes_of(&chair, "teacher_chair");
        let points = [light_position(&pose, 0), light_position(&pose, 1), pose.camera.as_ref().unwrap().eye];
        for (k, p) in points.into_iter().enumerate() {
            assert!(inside(&room, p, -0.1), "classroom t {t}: point {k} {p} leaves the room");
            let hit = furniture.iter().chain(&teacher).find(|b| inside(b, p, 0.03));
            assert!(hit.is_none(), "classroom t {t}: point {k} {p} inside {hit:?}");
        }
        assert!(light_position(&pose, 0).y < 0.7, "t {t}: lamp_low rises above the desk tops");
    }
    let f = scene("colonnade-flight");
    let pillars = boxes_of(&f, "pillar");
    let hall = f.bounds();
    let flight = f.animation.as_ref().unwrap();
    for q in 0..=4 * 96 {
        let eye = flight.pose(&f.lights, q as f32 / 96.0).camera.unwrap().eye;
        assert!(inside(&hall, eye, -0.2) || eye.z > 0.0, "flight: eye {eye} leaves the hall");
        let hit = pillars.iter().find(|b| inside(b, eye, 0.15));
        assert!(hit.is_none(), "flight step {q}: eye {eye} inside {hit:?}");
    }
    let cb = scene("cornell-anim");
    for frame in 0..=48 {
        let moved = posed(&cb, &cb.pose_at_frame(frame).unwrap());
        let light = boxes_of(&moved, "light")[0];
        assert!(light.min.x > 10.0 && light.max.x < 540.0 && light.min.z > 10.0 && light.max.z < 549.0);
        assert_eq!(light.min.y, filtrace_scene::builtin::LIGHT_Y, "frame {frame}");
    }
}
