//! `classroom`: the kind of scene the many-light thesis evaluates on (rapidly changing
//! visibility). A 9 x 3.2 x 9 m room holds 5 rows of 4 two-seat desks with 2 chairs each,
//! all on thin (14 mm) tubular legs; a blackboard on the front wall (-z), three windows with
//! mullions in the left wall (-x) as dim area lights. Two point lights move along paths:
//! `lamp_low` sweeps the aisles below the desk tops, so the shadows of hundreds of legs
//! rake across the floor, and `lamp_high` crosses the room above the desks. The camera
//! walks down the right aisle, low past the desks, and turns to face the class; the
//! teacher's chair (its own mesh and instance, `teacher_chair`) slides and spins.
//!
//! 49 frames (0..=48) at 24 frames per second; frame 0's pose is the rest pose. Desks and
//! chairs are instances of one desk and one chair mesh.

use filtrace_core::{Affine3A, Quat, Rgb, Vec3};

use super::furniture::{add_box, chair, desk, teacher_desk};
use crate::animation::{
    AnimNode, CameraTrack, Clock, Interpolation, LightTrack, SceneAnimation, Track, TrackError,
    TransformTrack,
};
use crate::shapes;
use crate::types::{Camera, Instance, Light, Material, MaterialId, Mesh, Scene};

pub const CLASSROOM_FPS: f32 = 24.0;
pub const CLASSROOM_LAST_FRAME: i64 = 48;
/// Rows (along z) and columns (along x) of desks; two chairs per desk.
pub const DESK_ROWS: usize = 5;
pub const DESK_COLUMNS: usize = 4;

/// The room: x in [-4.5, 4.5], y in [0, 3.2], z in [-4, 5].
const ROOM: (f32, f32, f32, f32, f32) = (-4.5, 4.5, 3.2, -4.0, 5.0);

/// Frames of the keys of every path below.
const KEY_FRAMES: [i64; 5] = [0, 12, 24, 36, 48];
/// `lamp_low`: up the aisle at x = -1.8 and back, below the desk tops (0.75 m) and
/// bobbing between 0.35 and 0.6 m, among the legs.
const LAMP_LOW: [[f32; 3]; 5] =
    [[-1.8, 0.5, 4.4], [-1.8, 0.35, 1.5], [-1.8, 0.6, -1.2], [-1.8, 0.4, 1.5], [-1.8, 0.5, 4.4]];
/// `lamp_high`: a zig-zag over the desks.
const LAMP_HIGH: [[f32; 3]; 5] =
    [[3.5, 2.4, 4.2], [-3.5, 2.6, 1.0], [3.0, 2.2, -2.0], [-3.0, 2.4, -3.3], [3.5, 2.4, 4.2]];
/// Camera eyes and targets: down the right aisle (x = 3.9), low past the desks, then
/// across the front to face the class.
const EYES: [[f32; 3]; 5] =
    [[3.8, 1.6, 4.6], [3.9, 1.3, 2.0], [3.9, 1.0, -0.8], [3.3, 1.2, -3.0], [-1.0, 1.5, -3.6]];
const TARGETS: [[f32; 3]; 5] =
    [[-1.0, 0.8, -1.0], [-2.5, 0.6, -0.5], [-3.0, 0.7, 0.5], [-3.0, 0.9, 2.0], [-1.0, 0.8, 4.0]];

pub fn classroom() -> Scene {
    let mut s = Scene { name: "classroom".into(), ..Scene::default() };
    let m = Materials::add(&mut s);
    room(&mut s, &m);
    blackboard_and_windows(&mut s, &m);
    desks_and_chairs(&mut s, &m);
    let teacher = s.meshes.len() as u32;
    s.add_mesh(teacher_desk(m.wood));
    s.instances[teacher as usize].transform = Affine3A::from_translation(Vec3::new(0.0, 0.0, -2.6));
    let mut chair_mesh = chair(m.seat, m.metal);
    chair_mesh.name = "teacher_chair".into();
    s.add_mesh(chair_mesh);
    let teacher_chair = (s.instances.len() - 1) as u32;
    s.lights = vec![
        Light::Point { position: Vec3::from(LAMP_LOW[0]), intensity: Rgb::new(1.6, 1.3, 1.0) },
        Light::Point { position: Vec3::from(LAMP_HIGH[0]), intensity: Rgb::new(3.0, 3.0, 3.4) },
    ];
    let rest = Camera { eye: EYES[0].into(), target: TARGETS[0].into(), up: Vec3::Y, vfov_deg: 55.0 };
    s.camera = Some(rest.clone());
    let clock = Clock::new(CLASSROOM_FPS, 0, CLASSROOM_LAST_FRAME).expect("a valid clock");
    let anim = animation(clock, rest, teacher_chair).expect("valid built-in keys");
    s.instances[teacher_chair as usize].transform = anim.node_transforms(0.0)[0];
    s.animation = Some(anim);
    s
}

struct Materials {
    floor: MaterialId,
    wall: MaterialId,
    board: MaterialId,
    wood: MaterialId,
    seat: MaterialId,
    metal: MaterialId,
    window: MaterialId,
}

impl Materials {
    fn add(s: &mut Scene) -> Self {
        let mut window = Material::diffuse("window", Rgb::ZERO);
        window.emission = Rgb::new(0.9, 1.0, 1.2);
        Materials {
            floor: s.add_material(Material::diffuse("floor", Rgb::new(0.45, 0.32, 0.2))),
            wall: s.add_material(Material::diffuse("wall", Rgb::new(0.75, 0.73, 0.68))),
            board: s.add_material(Material::diffuse("blackboard", Rgb::new(0.04, 0.12, 0.07))),
            wood: s.add_material(Material::diffuse("wood", Rgb::new(0.6, 0.45, 0.3))),
            seat: s.add_material(Material::diffuse("seat", Rgb::new(0.55, 0.14, 0.08))),
            metal: s.add_material(Material::diffuse("metal", Rgb::new(0.3, 0.3, 0.32))),
            window: s.add_material(window),
        }
    }
}

fn named(mut m: Mesh, name: &str) -> Mesh {
    m.name = name.to_string();
    m
}

/// Floor, ceiling and the four walls, all facing into the room.
fn room(s: &mut Scene, m: &Materials) {
    let (x0, x1, h, z0, z1) = ROOM;
    let p = Vec3::new;
    let (w, d) = (x1 - x0, z1 - z0);
    let faces = [
        ("floor", p(x0, 0.0, z1), p(w, 0.0, 0.0), p(0.0, 0.0, -d), m.floor),
        ("ceiling", p(x0, h, z0), p(w, 0.0, 0.0), p(0.0, 0.0, d), m.wall),
        ("front_wall", p(x0, 0.0, z0), p(w, 0.0, 0.0), p(0.0, h, 0.0), m.wall),
        ("back_wall", p(x1, 0.0, z1), p(-w, 0.0, 0.0), p(0.0, h, 0.0), m.wall),
        ("left_wall", p(x0, 0.0, z1), p(0.0, 0.0, -d), p(0.0, h, 0.0), m.wall),
        ("right_wall", p(x1, 0.0, z0), p(0.0, 0.0, d), p(0.0, h, 0.0), m.wall),
    ];
    for (name, corner, e1, e2, mat) in faces {
        s.add_mesh(named(shapes::parallelogram(corner, e1, e2, mat), name));
    }
}

/// The blackboard with its frame and chalk tray, and three windows (area lights facing
/// +x) behind a cross of mullions each.
fn blackboard_and_windows(s: &mut Scene, m: &Materials) {
    let (x0, _, _, z0, _) = ROOM;
    let mut board = Mesh { name: "blackboard".into(), ..Mesh::default() };
    add_box(&mut board, Vec3::new(0.0, 1.5, z0 + 0.015), Vec3::new(4.0, 1.2, 0.03), m.board);
    for (c, size) in [
        (Vec3::new(0.0, 2.12, z0 + 0.03), Vec3::new(4.1, 0.05, 0.05)),
        (Vec3::new(0.0, 0.88, z0 + 0.05), Vec3::new(4.1, 0.04, 0.1)),
        (Vec3::new(-2.03, 1.5, z0 + 0.03), Vec3::new(0.05, 1.25, 0.05)),
        (Vec3::new(2.03, 1.5, z0 + 0.03), Vec3::new(0.05, 1.25, 0.05)),
    ] {
        add_box(&mut board, c, size, m.wood);
    }
    s.add_mesh(board);
    let mut mullions = Mesh { name: "mullions".into(), ..Mesh::default() };
    for z in [-2.5f32, 0.5, 3.5] {
        let glass = shapes::parallelogram(
            Vec3::new(x0 + 0.01, 1.0, z + 0.8),
            Vec3::new(0.0, 0.0, -1.6),
            Vec3::new(0.0, 1.5, 0.0),
            m.window,
        );
        s.add_mesh(named(glass, "window"));
        add_box(&mut mullions, Vec3::new(x0 + 0.06, 1.75, z), Vec3::new(0.06, 1.5, 0.05), m.wood);
        add_box(&mut mullions, Vec3::new(x0 + 0.06, 1.9, z), Vec3::new(0.06, 0.05, 1.6), m.wood);
    }
    s.add_mesh(mullions);
}

/// `DESK_ROWS` x `DESK_COLUMNS` desks, each with two chairs behind it (+z), slightly
/// turned and pushed back by a deterministic pattern so that no two are quite alike.
fn desks_and_chairs(s: &mut Scene, m: &Materials) {
    let desk_mesh = s.meshes.len() as u32;
    s.meshes.push(desk(m.wood, m.metal));
    let chair_mesh = desk_mesh + 1;
    s.meshes.push(chair(m.seat, m.metal));
    let place = |mesh: u32, at: Vec3, turn_deg: f32| Instance {
        mesh,
        transform: Affine3A::from_rotation_translation(Quat::from_rotation_y(turn_deg.to_radians()), at),
        material_override: None,
    };
    for r in 0..DESK_ROWS {
        let z = -1.8 + 1.3 * r as f32;
        for c in 0..DESK_COLUMNS {
            let x = -2.7 + 1.8 * c as f32;
            let k = (r * DESK_COLUMNS + c) as f32;
            s.instances.push(place(desk_mesh, Vec3::new(x, 0.0, z), 0.0));
            for (side, phase) in [(-0.33f32, 0.0f32), (0.33, 1.7)] {
                let wobble = (1.3 * k + phase).sin();
                let at = Vec3::new(x + side, 0.0, z + 0.5 + 0.06 * wobble);
                s.instances.push(place(chair_mesh, at, 8.0 * wobble));
            }
        }
    }
}

fn vec3_track(frames: &[i64], values: &[[f32; 3]], clock: &Clock) -> Result<Track<Vec3>, TrackError> {
    let times = frames.iter().map(|&f| f as f32 / clock.fps).collect();
    Track::new(times, values.iter().map(|&v| Vec3::from(v)).collect(), Interpolation::CatmullRom)
}

/// The teacher's chair (node 0), both lamps and the camera, keyed at `KEY_FRAMES`.
fn animation(clock: Clock, rest: Camera, teacher_chair: u32) -> Result<SceneAnimation, TrackError> {
    let mut anim = SceneAnimation::new(clock);
    let mut chair = TransformTrack::at_rest(&Affine3A::IDENTITY);
    let slide = [[0.0, 0.0, -3.6], [0.9, 0.0, -3.5], [0.0, 0.0, -3.4], [-0.9, 0.0, -3.5], [0.0, 0.0, -3.6]];
    chair.translation = Some(vec3_track(&KEY_FRAMES, &slide, &clock)?);
    let spins = KEY_FRAMES.iter().map(|&f| Quat::from_rotation_y(std::f32::consts::PI * f as f32 / 24.0));
    let times = KEY_FRAMES.iter().map(|&f| f as f32 / clock.fps).collect();
    chair.rotation = Some(Track::new(times, spins.collect(), Interpolation::Linear)?);
    anim.nodes.push(AnimNode { name: "teacher_chair".into(), parent: None, track: chair });
    anim.instances.push((teacher_chair, 0, Affine3A::IDENTITY));
    for (light, name, path) in [(0u32, "lamp_low", &LAMP_LOW), (1, "lamp_high", &LAMP_HIGH)] {
        anim.lights.push(LightTrack {
            name: name.into(),
            light,
            position: Some(vec3_track(&KEY_FRAMES, path, &clock)?),
            direction: None,
            intensity: None,
        });
    }
    let mut camera = CameraTrack::at_rest(rest);
    camera.eye = Some(vec3_track(&KEY_FRAMES, &EYES, &clock)?);
    camera.target = Some(vec3_track(&KEY_FRAMES, &TARGETS, &clock)?);
    anim.camera = Some(camera);
    Ok(anim)
}
