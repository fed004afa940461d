//! NEE + MIS against BSDF sampling only on glossy materials: a room whose floor is a rough
//! conductor and whose box is a GGX-coated plastic (then the other way round), at several
//! roughnesses down to 0 (the minimum alpha), lit by an area light and a sky. MIS weights
//! that are wrong for a glossy lobe (a pdf that disagrees with the sampler, a lobe treated as
//! specular on one side only) shift the NEE image away from the BSDF-only one; the bounds
//! are z-scores from the two films' own variances (`common::nee_vs_bsdf_only`).

mod common;

use common::*;
use filtrace_core::{Rgb, Vec3};
use filtrace_scene::{Bsdf, Environment, Light, Material, Mesh, Scene, Texturable};

fn conductor(roughness: f32) -> Material {
    Material {
        name: format!("gold r={roughness}"),
        // Gold's complex index at R, G, B (as in the BSDF tests).
        bsdf: Bsdf::Conductor {
            eta: Rgb::new(0.143, 0.374, 1.442),
            k: Rgb::new(3.983, 2.385, 1.603),
            roughness,
        },
        emission: Rgb::ZERO,
        two_sided_emission: false,
    }
}

fn plastic(roughness: f32) -> Material {
    Material {
        name: format!("plastic r={roughness}"),
        bsdf: Bsdf::Plastic { diffuse: Texturable::Constant(Rgb::new(0.2, 0.4, 0.7)), roughness, ior: 1.5 },
        emission: Rgb::ZERO,
        two_sided_emission: false,
    }
}

/// Floor of `floor`, a box of `object`, a diffuse back wall, a large two-sided area light
/// above and behind the box (its glossy reflection on the floor is in view) and a sky.
fn glossy_room(floor: Material, object: Material) -> Scene {
    let mut s = scene_with(camera(Vec3::new(0.0, 1.6, 3.2), Vec3::new(0.0, 0.3, 0.0), 55.0));
    let floor = s.add_material(floor);
    let object = s.add_material(object);
    let wall = s.add_material(Material::diffuse("wall", Rgb::new(0.6, 0.6, 0.5)));
    let lamp = s.add_material(diffuse_emitter("lamp", Rgb::splat(0.0), Rgb::new(4.0, 3.6, 3.0), true));
    let k = 3.0;
    let mut plane = Mesh { name: "floor".into(), ..Mesh::default() };
    push_quad(
        &mut plane,
        [Vec3::new(-k, 0.0, -k), Vec3::new(-k, 0.0, k), Vec3::new(k, 0.0, k), Vec3::new(k, 0.0, -k)],
        floor,
    );
    s.add_mesh(plane);
    let mut back = Mesh { name: "wall".into(), ..Mesh::default() };
    push_quad(
        &mut back,
        [
            Vec3::new(-k, 0.0, -2.0),
            Vec3::new(k, 0.0, -2.0),
            Vec3::new(k, 2.5, -2.0),
            Vec3::new(-k, 2.5, -2.0),
        ],
        wall,
    );
    s.add_mesh(back);
    s.add_mesh(box_mesh(Vec3::new(-0.5, 0.0, -0.8), Vec3::new(0.4, 0.9, 0.1), object, false));
    let mut light = Mesh { name: "lamp".into(), ..Mesh::default() };
    push_quad(
        &mut light,
        [
            Vec3::new(-1.2, 2.2, -1.8),
            Vec3::new(1.2, 2.2, -1.8),
            Vec3::new(1.2, 1.6, -0.6),
            Vec3::new(-1.2, 1.6, -0.6),
        ],
        lamp,
    );
    s.add_mesh(light);
    s.lights.push(Light::Environment(Environment::Sky {
        zenith: Rgb::new(0.2, 0.35, 0.8),
        horizon: Rgb::new(0.9, 0.8, 0.7),
        ground: Rgb::new(0.1, 0.1, 0.1),
    }));
    s
}

/// Each roughness with the conductor floor + plastic box and with the plastic floor +
/// conductor box, so that both materials are seen directly and in reflection.
fn check_roughnesses(roughnesses: &[f32], size: u32, spp_nee: u32, spp_bsdf: u32) {
    for &r in roughnesses {
        for (name, floor, object) in
            [("conductor floor", conductor(r), plastic(r)), ("plastic floor", plastic(r), conductor(r))]
        {
            nee_vs_bsdf_only(
                &format!("{name}, roughness {r}"),
                glossy_room(floor, object),
                size,
                spp_nee,
                spp_bsdf,
                6,
            );
        }
    }
}

/// Roughness 0 maps to the minimum alpha (1e-3): a near-mirror, where the NEE term is almost
/// all weighted away by MIS and the BSDF sample carries the light.
#[test]
fn nee_mis_agrees_with_bsdf_only_on_glossy_materials() {
    check_roughnesses(&[0.0, 0.15, 0.4, 0.8], 24, 64, 256);
}

#[test]
#[ignore = "slow: glossy MIS at 8 roughnesses, 48 x 48, 256 vs 1024 spp"]
fn nee_mis_agrees_with_bsdf_only_on_glossy_materials_thorough() {
    check_roughnesses(&[0.0, 0.03, 0.08, 0.15, 0.25, 0.4, 0.6, 1.0], 48, 256, 1024);
}
