//! `grass`: a 10 m x 10 m meadow (on 40 m of soil) of thin, curved grass blades (16,000 blades, 5 triangles
//! each) around two rocks, lit by a large warm area light and a blue sky. Geometry
//! finer than a pixel at most distances: the case where screen-space filters, which trust
//! normals and depth, struggle. Deterministic (fixed seed). Units are metres.

use filtrace_core::{Affine3A, Quat, Rgb, Vec3};

use super::rng::SplitMix64;
use crate::error::SceneError;
use crate::shapes;
use crate::types::{Camera, Environment, Instance, Light, Material, MaterialId, Mesh, Scene};

/// Parameters of the meadow. Presets: [`GrassParams::meadow`] (the built-in `grass`),
/// [`GrassParams::sparse`] and [`GrassParams::dense`], to vary how hard the scene is for
/// screen-space filters (more, thinner blades: more sub-pixel occlusion).
#[derive(Clone, Debug, PartialEq)]
pub struct GrassParams {
    /// Number of blades, scattered uniformly over [-4.8, 4.8]^2 m.
    pub blades: usize,
    /// Seed of the layout (SplitMix64).
    pub seed: u64,
    /// Blade height range (m).
    pub height: (f32, f32),
    /// Blade width range at the base (m); blades taper to 20 % before the tip.
    pub width: (f32, f32),
}

impl GrassParams {
    /// The built-in `grass` scene: 16,000 blades, 20-55 cm tall, 2-5 cm wide.
    pub fn meadow() -> Self {
        GrassParams { blades: 16_000, seed: SEED, height: (0.2, 0.55), width: (0.02, 0.05) }
    }

    /// 2,000 wider blades: the ground shows between them.
    pub fn sparse() -> Self {
        GrassParams { blades: 2_000, width: (0.03, 0.07), ..Self::meadow() }
    }

    /// 60,000 thin blades (300k triangles): almost all sub-pixel at 1080p.
    pub fn dense() -> Self {
        GrassParams { blades: 60_000, width: (0.01, 0.03), ..Self::meadow() }
    }

    /// Every preset, for tests and experiments.
    pub fn presets() -> [(&'static str, GrassParams); 3] {
        [("meadow", Self::meadow()), ("sparse", Self::sparse()), ("dense", Self::dense())]
    }
}

/// Seed of the built-in layout.
pub const SEED: u64 = 0x0067_7261_7373; // "grass" in ASCII

/// The built-in `grass` scene ([`GrassParams::meadow`]).
pub fn grass() -> Scene {
    // The preset is valid (tested), so this cannot fail.
    grass_with(&GrassParams::meadow()).unwrap_or_default()
}

/// The meadow with parameters `p`; an error if a range is empty, not positive or not finite,
/// or if there are more than 5 million blades.
pub fn grass_with(p: &GrassParams) -> Result<Scene, SceneError> {
    let range_ok = |(a, b): (f32, f32)| a.is_finite() && b.is_finite() && a > 0.0 && a <= b;
    if !range_ok(p.height) || !range_ok(p.width) || p.blades > 5_000_000 {
        return Err(SceneError::Invalid { message: format!("grass: bad parameters {p:?}") });
    }
    let mut s = Scene { name: "grass".into(), ..Scene::default() };
    let soil = s.add_material(Material::diffuse("soil", Rgb::new(0.22, 0.16, 0.1)));
    let blade_a = s.add_material(Material::diffuse("grass", Rgb::new(0.12, 0.38, 0.06)));
    let blade_b = s.add_material(Material::diffuse("dry_grass", Rgb::new(0.35, 0.36, 0.1)));
    let rock = s.add_material(Material::diffuse("rock", Rgb::new(0.4, 0.4, 0.42)));
    let mut sun = Material::diffuse("sun_panel", Rgb::ZERO);
    sun.emission = Rgb::new(30.0, 26.0, 20.0);
    let sun = s.add_material(sun);

    let mut ground = shapes::quad(soil);
    ground.name = "ground".into();
    // 40 m of soil, so that no gap to the sky's ground colour shows near the horizon.
    ground.positions.iter_mut().for_each(|p| *p *= 40.0);
    s.add_mesh(ground);

    s.add_mesh(blades(p, [blade_a, blade_b]));

    let sphere = s.meshes.len() as u32;
    let mut m = shapes::sphere(32, rock);
    m.name = "rock".into();
    s.meshes.push(m);
    for (pos, scale) in [
        (Vec3::new(-0.8, 0.0, 0.3), Vec3::new(0.5, 0.3, 0.4)),
        (Vec3::new(1.0, 0.0, -1.2), Vec3::splat(0.35)),
    ] {
        s.instances.push(Instance {
            mesh: sphere,
            transform: Affine3A::from_scale_rotation_translation(scale, Quat::IDENTITY, pos),
            material_override: None,
        });
    }

    // A 3 m x 3 m light panel high on one side, tilted towards the meadow (a low "sun").
    let c = Vec3::new(6.0, 5.0, -3.0);
    let to_centre = (Vec3::ZERO - c).normalize();
    let e1 = to_centre.cross(Vec3::Y).normalize() * 3.0;
    let e2 = e1.cross(to_centre).normalize() * 3.0;
    // Faces e2 x e1 = to_centre |e1|^2 (e1 is perpendicular to to_centre).
    let mut panel = shapes::parallelogram(c - 0.5 * (e1 + e2), e2, e1, sun);
    panel.name = "sun_panel".into();
    s.add_mesh(panel);
    s.lights.push(Light::Environment(Environment::Sky {
        zenith: Rgb::new(0.2, 0.35, 0.8),
        horizon: Rgb::new(0.7, 0.8, 0.95),
        ground: Rgb::splat(0.1),
    }));
    s.camera = Some(Camera {
        eye: Vec3::new(0.0, 2.4, 5.5),
        target: Vec3::new(0.0, 0.0, -0.5),
        up: Vec3::Y,
        vfov_deg: 40.0,
    });
    Ok(s)
}

/// `p.blades` blades scattered uniformly over [-4.8, 4.8]^2: each a curved strip of two quads
/// and a tip triangle, bent in a random direction.
fn blades(p: &GrassParams, materials: [MaterialId; 2]) -> Mesh {
    let mut rng = SplitMix64::new(p.seed);
    let mut m = Mesh { name: "grass_blades".into(), ..Mesh::default() };
    for _ in 0..p.blades {
        let root = Vec3::new(rng.range(-4.8, 4.8), 0.0, rng.range(-4.8, 4.8));
        let facing = rng.range(0.0, std::f32::consts::TAU);
        let side = Vec3::new(facing.cos(), 0.0, facing.sin());
        let bend_dir = Vec3::new(-side.z, 0.0, side.x);
        let height = rng.range(p.height.0, p.height.1);
        let width = rng.range(p.width.0, p.width.1);
        let bend = rng.range(0.05, 0.35) * height;
        let mat = materials[(rng.next_f32() < 0.25) as usize];
        // Points along the spine at t = 0, 0.45, 0.8, 1 with a quadratic bend.
        let spine = |t: f32| root + Vec3::Y * (height * t) + bend_dir * (bend * t * t);
        let half_width = |t: f32| 0.5 * width * (1.0 - 0.8 * t);
        let base = m.positions.len() as u32;
        for t in [0.0, 0.45, 0.8] {
            let c = spine(t);
            m.positions.push(c - side * half_width(t));
            m.positions.push(c + side * half_width(t));
        }
        m.positions.push(spine(1.0));
        for [a, b, c] in [[0, 1, 3], [0, 3, 2], [2, 3, 5], [2, 5, 4], [4, 5, 6]] {
            m.indices.push([base + a, base + b, base + c]);
            m.material_ids.push(mat);
        }
    }
    m
}
