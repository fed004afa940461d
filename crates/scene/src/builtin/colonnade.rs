//! `colonnade`: a hall with four rows of thin square pillars joined by thin beams, lit by a
//! tall window-like area light low on one side wall. The pillars and beams cast long, thin,
//! overlapping shadows across the floor and back wall: many small penumbrae and occlusion
//! boundaries, the case where screen-space filters blur shadow detail. Units are metres.
//!
//! One cube mesh is placed 57 times (40 pillars, 17 beams and rails): instancing, not copies.

use filtrace_core::{Affine3A, Quat, Rgb, Vec3};

use crate::shapes;
use crate::types::{Camera, Instance, Material, Scene};

/// Rows x columns of pillars.
pub const PILLAR_ROWS: usize = 4;
pub const PILLAR_COLUMNS: usize = 10;
/// Side of a pillar's square cross-section (m).
pub const PILLAR_WIDTH: f32 = 0.14;
/// Radiance of the window light.
pub const WINDOW_RADIANCE: f32 = 12.0;

pub fn colonnade() -> Scene {
    let mut s = Scene { name: "colonnade".into(), ..Scene::default() };
    let floor = s.add_material(Material::diffuse("floor", Rgb::new(0.65, 0.62, 0.58)));
    let wall = s.add_material(Material::diffuse("wall", Rgb::new(0.7, 0.7, 0.7)));
    let stone = s.add_material(Material::diffuse("stone", Rgb::new(0.8, 0.76, 0.7)));
    let mut lamp = Material::diffuse("window", Rgb::ZERO);
    lamp.emission = Rgb::new(WINDOW_RADIANCE, 0.95 * WINDOW_RADIANCE, 0.85 * WINDOW_RADIANCE);
    let lamp = s.add_material(lamp);

    // The hall: x in [-8, 8], y in [0, 5], z in [-6, 6]; open towards the camera (+z).
    let (x0, x1, h, z0, z1) = (-8.0, 8.0, 5.0, -6.0, 6.0);
    let p = Vec3::new;
    s.add_mesh(named(
        shapes::parallelogram(p(x0, 0.0, z1), p(x1 - x0, 0.0, 0.0), p(0.0, 0.0, z0 - z1), floor),
        "floor",
    ));
    s.add_mesh(named(
        shapes::parallelogram(p(x0, h, z0), p(x1 - x0, 0.0, 0.0), p(0.0, 0.0, z1 - z0), wall),
        "ceiling",
    ));
    s.add_mesh(named(
        shapes::parallelogram(p(x0, 0.0, z0), p(x1 - x0, 0.0, 0.0), p(0.0, h, 0.0), wall),
        "back_wall",
    ));
    s.add_mesh(named(
        shapes::parallelogram(p(x0, 0.0, z1), p(0.0, 0.0, z0 - z1), p(0.0, h, 0.0), wall),
        "left_wall",
    ));
    s.add_mesh(named(
        shapes::parallelogram(p(x1, 0.0, z0), p(0.0, 0.0, z1 - z0), p(0.0, h, 0.0), wall),
        "right_wall",
    ));
    // The window: 8 m long, 2.5 m tall, just inside the right wall, facing -x.
    s.add_mesh(named(
        shapes::parallelogram(p(x1 - 0.01, 1.0, -4.0), p(0.0, 0.0, 8.0), p(0.0, 2.5, 0.0), lamp),
        "window_light",
    ));

    // Pillars: unit cubes scaled to thin boxes, rows along x, slightly rotated about y so
    // that their shadow edges are not axis-aligned.
    let cube = s.meshes.len() as u32;
    s.meshes.push(named(shapes::cube(stone), "pillar"));
    let pillar_h = 4.2;
    for r in 0..PILLAR_ROWS {
        let z = -4.5 + 3.0 * r as f32;
        for c in 0..PILLAR_COLUMNS {
            let x = -6.3 + 1.4 * c as f32;
            let rot = Quat::from_rotation_y((7.0 * (r * PILLAR_COLUMNS + c) as f32).to_radians());
            s.instances.push(Instance {
                mesh: cube,
                transform: Affine3A::from_scale_rotation_translation(
                    Vec3::new(PILLAR_WIDTH, pillar_h, PILLAR_WIDTH),
                    rot,
                    Vec3::new(x, 0.5 * pillar_h, z),
                ),
                material_override: None,
            });
        }
        // Two thin beams along each row at the pillars' tops and one lower rail.
        for (y, t) in [(pillar_h + 0.06, 0.12), (pillar_h - 0.6, 0.05), (1.1, 0.04)] {
            s.instances.push(Instance {
                mesh: cube,
                transform: Affine3A::from_scale_rotation_translation(
                    Vec3::new(13.2, t, t),
                    Quat::IDENTITY,
                    Vec3::new(0.0, y, z),
                ),
                material_override: None,
            });
        }
    }
    // Cross beams over the rows (along z), every other column.
    for c in (0..PILLAR_COLUMNS).step_by(2) {
        let x = -6.3 + 1.4 * c as f32;
        s.instances.push(Instance {
            mesh: cube,
            transform: Affine3A::from_scale_rotation_translation(
                Vec3::new(0.1, 0.1, 9.4),
                Quat::IDENTITY,
                Vec3::new(x, pillar_h + 0.18, 0.0),
            ),
            material_override: None,
        });
    }
    // In the aisle between the last two rows, near the left wall, looking towards the window:
    // the pillars' shadows run across the floor towards the camera.
    s.camera = Some(Camera { eye: p(-7.2, 1.7, 3.0), target: p(2.0, 0.8, 0.0), up: Vec3::Y, vfov_deg: 60.0 });
    s
}

fn named(mut m: crate::types::Mesh, name: &str) -> crate::types::Mesh {
    m.name = name.to_string();
    m
}
