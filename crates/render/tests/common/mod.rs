//! Scenes and statistics shared by the render integration tests.
#![allow(dead_code)]

use filtrace_core::{Image, Rgb, Vec3};
use filtrace_render::{Film, IntegratorKind, RenderSettings, Renderer};
use filtrace_scene::{Camera, Material, MaterialId, Mesh, Scene};
use std::sync::atomic::AtomicBool;

/// `../shared/<rel>`, or `None` with a SKIP line when absent (a failure when `CI` is set).
#[allow(unused_imports)]
pub use filtrace_core::shared_data::shared_path as shared;

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

/// z-scores of the difference of two films: over the whole image and over blocks of
/// `block x block` pixels, per channel. Returns the largest |z|.
pub fn max_block_z(a: &Film, b: &Film, block: usize) -> (f64, f64) {
    let (fa, fb) = (a.aovs(), b.aovs());
    let (w, h) = (fa.width, fa.height);
    let z_of = |pixels: &[(usize, usize)], c: usize| {
        let (ma, va) = mean_and_var(&fa.color, &fa.variance, pixels, c);
        let (mb, vb) = mean_and_var(&fb.color, &fb.variance, pixels, c);
        (ma - mb) / (va + vb + 1e-12).sqrt()
    };
    let all = all_pixels(w, h);
    let image_z = (0..3).map(|c| z_of(&all, c).abs()).fold(0.0, f64::max);
    let mut block_z = 0.0f64;
    for by in (0..h).step_by(block) {
        for bx in (0..w).step_by(block) {
            let px: Vec<_> = (by..(by + block).min(h))
                .flat_map(|y| (bx..(bx + block).min(w)).map(move |x| (x, y)))
                .collect();
            for c in 0..3 {
                block_z = block_z.max(z_of(&px, c).abs());
            }
        }
    }
    (image_z, block_z)
}

/// NEE + MIS (default integrator) against BSDF sampling only (another seed): the image
/// means and every 8 x 8 block mean must agree within the z-bounds below, from the films'
/// own variances.
pub fn nee_vs_bsdf_only(label: &str, scene: Scene, size: u32, spp_nee: u32, spp_bsdf: u32, max_depth: i32) {
    let nee = Renderer::new(scene.clone(), settings(size, size, spp_nee, max_depth)).unwrap();
    let mut s = settings(size, size, spp_bsdf, max_depth);
    s.seed = 12345;
    let naive = Renderer::new(scene, s).unwrap().with_integrator(IntegratorKind::BsdfOnly);
    let (fa, fb) = (render(&nee), render(&naive));
    assert_eq!(fa.dropped_samples() + fb.dropped_samples(), 0);
    let (image_z, block_z) = max_block_z(&fa, &fb, 8);
    println!("{label}: image |z| {image_z:.2}, worst block |z| {block_z:.2}");
    // Image mean: |z| < 4.5. Blocks: 3 * (size/8)^2 tests, Sidak-corrected to ~5.
    assert!(image_z < 4.5, "{label}: image means differ: z = {image_z:.2}");
    assert!(block_z < 5.0, "{label}: a block mean differs: z = {block_z:.2}");
}
