//! The Cornell box: the original Cornell box data as shipped in Debian embree-tools 3.13.5
//! (`models/cornell_box.obj`, Apache-2.0, see `../shared/scenes/cornell_box/copyright.embree-tools`),
//! with the light quad enabled at y = 548.7 facing down (-y) and emitting from its front face
//! only, and the colours and radiance of Mitsuba 3.9.1's built-in Cornell box — identical to
//! `../shared/scenes/cornell_box/cornell_box_lit.obj` + `.mtl` (a test checks this).
//! The front wall stays removed; the camera is the classic one ([`Camera::cornell`]).
//!
//! Licence of the geometry data below: Copyright 2009-2018 Intel Corporation (embree),
//! Licensed under the Apache License, Version 2.0 (http://www.apache.org/licenses/LICENSE-2.0);
//! distributed on an "AS IS" BASIS, WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND. Changes: the
//! light quad enabled at y = 548.7, colours from Mitsuba 3.9.1, data written as Rust constants.

use filtrace_core::{Rgb, Vec3};

use crate::types::{Camera, Material, Mesh, Scene};

/// Linear RGB albedo of the white walls and blocks (Mitsuba 3.9.1 `cornell_box()`).
pub const WHITE: [f32; 3] = [0.885809, 0.698859, 0.666422];
/// Albedo of the red (right, x = 556) wall.
pub const RED: [f32; 3] = [0.570068, 0.0430135, 0.0443706];
/// Albedo of the green (left, x = 0) wall.
pub const GREEN: [f32; 3] = [0.105421, 0.37798, 0.076425];
/// Radiance of the light quad.
pub const LIGHT_RADIANCE: [f32; 3] = [18.387, 13.9873, 6.75357];
/// Height of the light quad, just below the ceiling at 548.8.
pub const LIGHT_Y: f32 = 548.7;

/// Material indices of [`cornell`] in `Scene::materials` (the MTL order).
pub const MAT_WHITE: u32 = 0;
pub const MAT_RED: u32 = 1;
pub const MAT_GREEN: u32 = 2;
pub const MAT_BLUE: u32 = 3;
pub const MAT_LIGHT: u32 = 4;

/// One named object of the OBJ: quads (four corners each, in the file's winding) and a material.
pub(crate) struct QuadObject {
    pub name: &'static str,
    pub material: u32,
    pub quads: &'static [[[f32; 3]; 4]],
}

/// The objects of `cornell_box_lit.obj`, in file order, quads fan-triangulated as (0,1,2),(0,2,3).
pub(crate) const OBJECTS: &[QuadObject] = &[
    QuadObject {
        name: "floor",
        material: MAT_WHITE,
        quads: &[
            [[552.8, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 559.2], [549.6, 0.0, 559.2]],
            [[290.0, 0.0, 114.0], [240.0, 0.0, 272.0], [82.0, 0.0, 225.0], [130.0, 0.0, 65.0]],
            [[472.0, 0.0, 406.0], [314.0, 0.0, 456.0], [265.0, 0.0, 296.0], [423.0, 0.0, 247.0]],
        ],
    },
    QuadObject {
        name: "light",
        material: MAT_LIGHT,
        quads: &[[
            [343.0, LIGHT_Y, 227.0],
            [343.0, LIGHT_Y, 332.0],
            [213.0, LIGHT_Y, 332.0],
            [213.0, LIGHT_Y, 227.0],
        ]],
    },
    QuadObject {
        name: "ceiling",
        material: MAT_WHITE,
        quads: &[[[556.0, 548.8, 0.0], [556.0, 548.8, 559.2], [0.0, 548.8, 559.2], [0.0, 548.8, 0.0]]],
    },
    QuadObject {
        name: "back_wall",
        material: MAT_WHITE,
        quads: &[[[549.6, 0.0, 559.2], [0.0, 0.0, 559.2], [0.0, 548.8, 559.2], [556.0, 548.8, 559.2]]],
    },
    QuadObject {
        name: "green_wall",
        material: MAT_GREEN,
        quads: &[[[0.0, 0.0, 559.2], [0.0, 0.0, 0.0], [0.0, 548.8, 0.0], [0.0, 548.8, 559.2]]],
    },
    QuadObject {
        name: "red_wall",
        material: MAT_RED,
        quads: &[[[552.8, 0.0, 0.0], [549.6, 0.0, 559.2], [556.0, 548.8, 559.2], [556.0, 548.8, 0.0]]],
    },
    QuadObject {
        name: "short_block",
        material: MAT_WHITE,
        quads: &[
            [[130.0, 165.0, 65.0], [82.0, 165.0, 225.0], [240.0, 165.0, 272.0], [290.0, 165.0, 114.0]],
            [[290.0, 0.0, 114.0], [290.0, 165.0, 114.0], [240.0, 165.0, 272.0], [240.0, 0.0, 272.0]],
            [[130.0, 0.0, 65.0], [130.0, 165.0, 65.0], [290.0, 165.0, 114.0], [290.0, 0.0, 114.0]],
            [[82.0, 0.0, 225.0], [82.0, 165.0, 225.0], [130.0, 165.0, 65.0], [130.0, 0.0, 65.0]],
            [[240.0, 0.0, 272.0], [240.0, 165.0, 272.0], [82.0, 165.0, 225.0], [82.0, 0.0, 225.0]],
        ],
    },
    QuadObject {
        name: "tall_block",
        material: MAT_WHITE,
        quads: &[
            [[423.0, 330.0, 247.0], [265.0, 330.0, 296.0], [314.0, 330.0, 456.0], [472.0, 330.0, 406.0]],
            [[423.0, 0.0, 247.0], [423.0, 330.0, 247.0], [472.0, 330.0, 406.0], [472.0, 0.0, 406.0]],
            [[472.0, 0.0, 406.0], [472.0, 330.0, 406.0], [314.0, 330.0, 456.0], [314.0, 0.0, 456.0]],
            [[314.0, 0.0, 456.0], [314.0, 330.0, 456.0], [265.0, 330.0, 296.0], [265.0, 0.0, 296.0]],
            [[265.0, 0.0, 296.0], [265.0, 330.0, 296.0], [423.0, 330.0, 247.0], [423.0, 0.0, 247.0]],
        ],
    },
];

/// The five materials of `cornell_box_lit.mtl`, in file order.
pub fn cornell_materials() -> Vec<Material> {
    let mut light = Material::diffuse("light", Rgb::ZERO);
    light.emission = Rgb::from(LIGHT_RADIANCE);
    vec![
        Material::diffuse("white", Rgb::from(WHITE)),
        Material::diffuse("red", Rgb::from(RED)),
        Material::diffuse("green", Rgb::from(GREEN)),
        Material::diffuse("blue", Rgb::new(0.1, 0.1, 0.8)),
        light,
    ]
}

/// A mesh made of quads (each split into triangles (0,1,2) and (0,2,3)), all of one material.
pub(crate) fn quad_mesh(name: &str, material: u32, quads: &[[[f32; 3]; 4]]) -> Mesh {
    let mut m = Mesh { name: name.to_string(), ..Mesh::default() };
    for q in quads {
        let base = m.positions.len() as u32;
        m.positions.extend(q.iter().map(|&p| Vec3::from(p)));
        m.indices.push([base, base + 1, base + 2]);
        m.indices.push([base, base + 2, base + 3]);
        m.material_ids.extend([material, material]);
    }
    m
}

/// The Cornell box scene: 36 triangles in 8 meshes, one area light, the classic camera.
pub fn cornell() -> Scene {
    let mut s = Scene { name: "cornell".into(), camera: Some(Camera::cornell()), ..Scene::default() };
    s.materials = cornell_materials();
    for o in OBJECTS {
        s.add_mesh(quad_mesh(o.name, o.material, o.quads));
    }
    s
}
