//! Scenes and statistics shared by the render integration tests.
#![allow(dead_code)]

use filtrace_core::{Image, Rgb, Vec3};
use filtrace_render::{Film, RenderSettings, Renderer};
use filtrace_scene::{Camera, Material, MaterialId, Mesh, Scene};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

/// `../shared` seen from the workspace root, or `None` (with a message) when absent.
pub fn shared_dir() -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared");
    if p.is_dir() {
        Some(p)
    } else {
        println!("SKIPPED: {} is absent", p.display());
        None
    }
}

/// Appends a quad (p0, p1, p2, p3), counter-clockwise seen from its front, as two triangles.
pub fn push_quad(mesh: &mut Mesh, q: [Vec3; 4], material: MaterialId) {
    let base = mesh.positions.len() as u32;
    mesh.positions.extend(q);
    mesh.indices.push([base, base + 1, base + 2]);
    mesh.indices.push([base, base + 2, base + 3]);
    mesh.material_ids.extend([material, material]);
}

/// The six faces of the axis-aligned box `[lo, hi]`, fronts facing outwards (or inwards).
pub fn box_mesh(lo: Vec3, hi: Vec3, material: MaterialId, inward: bool) -> Mesh {
    let mut m = Mesh { name: "box".into(), ..Mesh::default() };
    let c = |x: usize, y: usize, z: usize| Vec3::new([lo.x, hi.x][x], [lo.y, hi.y][y], [lo.z, hi.z][z]);
    // Outward-facing quads (counter-clockwise seen from outside).
    let faces = [
        [c(0, 0, 0), c(0, 0, 1), c(0, 1, 1), c(0, 1, 0)], // -x
        [c(1, 0, 0), c(1, 1, 0), c(1, 1, 1), c(1, 0, 1)], // +x
        [c(0, 0, 0), c(1, 0, 0), c(1, 0, 1), c(0, 0, 1)], // -y
        [c(0, 1, 0), c(0, 1, 1), c(1, 1, 1), c(1, 1, 0)], // +y
        [c(0, 0, 0), c(0, 1, 0), c(1, 1, 0), c(1, 0, 0)], // -z
        [c(0, 0, 1), c(1, 0, 1), c(1, 1, 1), c(0, 1, 1)], // +z
    ];
    for mut f in faces {
        if inward {
            f.reverse();
        }
        push_quad(&mut m, f, material);
    }
    m
}

pub fn diffuse_emitter(name: &str, albedo: Rgb, emission: Rgb, two_sided: bool) -> Material {
    let mut m = Material::diffuse(name, albedo);
    m.emission = emission;
    m.two_sided_emission = two_sided;
    m
}

pub fn camera(eye: Vec3, target: Vec3, vfov_deg: f32) -> Camera {
    Camera { eye, target, up: Vec3::Y, vfov_deg }
}

pub fn scene_with(camera: Camera) -> Scene {
    Scene { name: "test".into(), camera: Some(camera), ..Scene::default() }
}

pub fn settings(width: u32, height: u32, spp: u32, max_depth: i32) -> RenderSettings {
    RenderSettings { width, height, spp, max_depth, seed: 7 }
}

pub fn render(renderer: &Renderer) -> Film {
    renderer.render(&AtomicBool::new(false))
}

/// Mean over `pixels` of channel `c` of `image`, and the variance of that mean from the
/// per-pixel variances of the mean (pixels estimated independently).
pub fn mean_and_var(image: &Image, variance: &Image, pixels: &[(usize, usize)], c: usize) -> (f64, f64) {
    let n = pixels.len() as f64;
    let mut m = 0.0;
    let mut v = 0.0;
    for &(x, y) in pixels {
        m += image.pixel(x, y)[c] as f64;
        v += variance.pixel(x, y)[c] as f64;
    }
    (m / n, v / (n * n))
}

pub fn all_pixels(w: usize, h: usize) -> Vec<(usize, usize)> {
    (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).collect()
}

/// Pixels whose 3x3 neighbourhood all satisfy `inside` (so that no pixel footprint straddles
/// a silhouette).
pub fn interior_pixels(w: usize, h: usize, inside: impl Fn(usize, usize) -> bool) -> Vec<(usize, usize)> {
    let mut v = Vec::new();
    for y in 1..h.saturating_sub(1) {
        for x in 1..w.saturating_sub(1) {
            if (y - 1..=y + 1).all(|yy| (x - 1..=x + 1).all(|xx| inside(xx, yy))) {
                v.push((x, y));
            }
        }
    }
    v
}
