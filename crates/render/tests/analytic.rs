//! Analytic scenes: the integrator must reproduce closed-form radiance.
//!
//! Tolerances come from the film's own variance estimate (z-tests); since the sampler is
//! Owen-scrambled QMC, the sample variance over-estimates the error and the tests are
//! conservative, yet a bias of a few percent (a missing bounce, a double-counted MIS
//! strategy) is many standard errors.

mod common;

use common::*;
use filtrace_core::Vec2;
use filtrace_core::{Rgb, Vec3};
use filtrace_render::{PinholeCamera, Renderer};
use filtrace_scene::{Environment, Light, Material, Mesh};

const Z_MAX: f64 = 5.0;

/// A closed box with emission E and albedo rho on every inside face, the camera inside.
fn furnace_box(rho: Rgb, e: Rgb) -> filtrace_scene::Scene {
    let mut s = scene_with(camera(Vec3::new(0.1, -0.2, -0.5), Vec3::new(0.3, 0.1, 1.0), 70.0));
    let m = s.add_material(diffuse_emitter("wall", rho, e, false));
    s.add_mesh(box_mesh(Vec3::splat(-1.0), Vec3::splat(1.0), m, true));
    s
}

/// White furnace (closed box): every surface has radiance E * sum_{k < N} rho^k with
/// `N = max_depth` segments, and E / (1 - rho) unbounded.
#[test]
fn closed_emissive_box_matches_the_geometric_series() {
    let rho = Rgb::new(0.8, 0.5, 0.2);
    let e = Rgb::new(1.0, 0.5, 2.0);
    for max_depth in [1, 2, 3, 8, -1] {
        let r = Renderer::new(furnace_box(rho, e), settings(24, 24, 64, max_depth)).unwrap();
        let film = render(&r);
        assert_eq!(film.dropped_samples(), 0);
        let a = film.aovs();
        let px = all_pixels(24, 24);
        for c in 0..3 {
            let expect = if max_depth < 0 {
                e[c] as f64 / (1.0 - rho[c] as f64)
            } else {
                e[c] as f64 * (1.0 - (rho[c] as f64).powi(max_depth)) / (1.0 - rho[c] as f64)
            };
            let (m, v) = mean_and_var(&a.color, &a.variance, &px, c);
            // 1e-4 relative floor: f32 accumulation, and max_depth 1 has zero variance.
            let z = (m - expect) / (v + (1e-4 * expect).powi(2)).sqrt();
            assert!(
                z.abs() < Z_MAX,
                "max_depth {max_depth} channel {c}: mean {m} expected {expect} (z = {z:.2})"
            );
            // One bounce more would be far outside wherever it is detectable.
            if max_depth > 0 {
                let next = e[c] as f64 * (rho[c] as f64).powi(max_depth);
                if next > 4.0 * Z_MAX * v.sqrt() {
                    assert!((m - expect).abs() < 0.25 * next, "channel {c}: {m} vs {expect}");
                }
            }
        }
    }
}

/// A convex diffuse box inside a constant environment L: the box never sees itself, so its
/// radiance is rho * L for max_depth >= 2 and 0 for max_depth 1; the background is L.
#[test]
fn convex_box_in_constant_environment() {
    let rho = Rgb::new(0.7, 0.4, 0.9);
    let l_env = Rgb::new(1.0, 2.0, 0.5);
    let (w, h) = (32, 32);
    for max_depth in [1, 2, 8] {
        let mut s = scene_with(camera(Vec3::new(2.0, 1.5, -3.0), Vec3::ZERO, 45.0));
        let m = s.add_material(Material::diffuse("box", rho));
        s.add_mesh(box_mesh(Vec3::splat(-0.6), Vec3::splat(0.6), m, false));
        s.lights.push(Light::Environment(Environment::Constant { radiance: l_env }));
        let r = Renderer::new(s, settings(w as u32, h as u32, 64, max_depth)).unwrap();
        let a = render(&r).aovs();
        let on_box = |x: usize, y: usize| a.normal.rgb(x, y) != Vec3::ZERO;
        let object = interior_pixels(w, h, on_box);
        let background = interior_pixels(w, h, |x, y| !on_box(x, y));
        assert!(object.len() > 100 && background.len() > 100, "{} {}", object.len(), background.len());
        for &(x, y) in &background {
            assert!((a.color.rgb(x, y) - l_env).abs().max_element() < 1e-6);
            assert_eq!(a.albedo.rgb(x, y), Vec3::ZERO);
            assert_eq!(a.depth.pixel(x, y)[0], 0.0);
        }
        for c in 0..3 {
            let expect = if max_depth == 1 { 0.0 } else { (rho[c] * l_env[c]) as f64 };
            let (m, v) = mean_and_var(&a.color, &a.variance, &object, c);
            let z = (m - expect) / (v + (1e-4 * expect).powi(2) + 1e-12).sqrt();
            assert!(z.abs() < Z_MAX, "max_depth {max_depth} channel {c}: {m} vs {expect} (z {z:.2})");
            // Every pixel individually, with a looser bound.
            for &(x, y) in &object {
                let sd = (a.variance.pixel(x, y)[c] as f64).sqrt();
                let d = a.color.pixel(x, y)[c] as f64 - expect;
                assert!(d.abs() <= 6.0 * sd + 1e-4 * expect + 1e-9, "pixel ({x},{y}) c{c}: {d} sd {sd}");
            }
        }
    }
}

/// Mean of `f` over the footprint of pixel `(x, y)` on the plane `y = 0` (a 16 x 16 grid of
/// sub-pixel positions: the box filter's expectation, to far below the tests' tolerances).
fn footprint_mean(cam: &PinholeCamera, x: usize, y: usize, f: impl Fn(Vec3) -> f64) -> f64 {
    let n = 16;
    let mut sum = 0.0;
    for j in 0..n {
        for i in 0..n {
            let off = Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
            let ray = cam.generate_ray(x as u32, y as u32, off);
            let t = -ray.origin.y / ray.dir.y;
            sum += f(ray.at(t));
        }
    }
    sum / (n * n) as f64
}

/// Diffuse plane under a point light (pbrt's classic check): L_o = rho/pi * I cos(theta) / d^2.
#[test]
fn plane_under_point_light() {
    let rho = 0.6f32;
    let intensity = Rgb::new(3.0, 2.0, 1.0);
    let light_pos = Vec3::new(0.3, 1.0, 0.2);
    let mut s = scene_with(camera(Vec3::new(0.0, 3.0, -0.01), Vec3::ZERO, 40.0));
    let m = s.add_material(Material::diffuse("plane", Rgb::splat(rho)));
    let mut mesh = Mesh { name: "plane".into(), ..Mesh::default() };
    let k = 5.0;
    push_quad(
        &mut mesh,
        [Vec3::new(-k, 0.0, -k), Vec3::new(-k, 0.0, k), Vec3::new(k, 0.0, k), Vec3::new(k, 0.0, -k)],
        m,
    );
    s.add_mesh(mesh);
    s.lights.push(Light::Point { position: light_pos, intensity });
    for max_depth in [2, 8] {
        let r = Renderer::new(s.clone(), settings(48, 48, 16, max_depth)).unwrap();
        let a = render(&r).aovs();
        let mut checked = 0;
        for (x, y) in interior_pixels(48, 48, |_, _| true) {
            let p = a.position.rgb(x, y);
            assert!(p.y.abs() < 1e-5, "every pixel sees the plane");
            let irradiance = |p: Vec3| {
                let d = light_pos - p;
                (d.y / d.length() / d.length_squared()) as f64
            };
            let e = footprint_mean(r.camera(), x, y, irradiance) as f32;
            let expect = intensity * (rho / std::f32::consts::PI * e);
            let got = a.color.rgb(x, y);
            // The only noise is the pixel jitter: within the film's standard error.
            let sd = a.variance.rgb(x, y).powf(0.5);
            let tol = 5.0 * sd + 2e-4 * expect;
            assert!((got - expect).abs().cmple(tol).all(), "({x},{y}) {got} vs {expect} (sd {sd})");
            // Direct light only: nothing indirect (there is one plane).
            assert_eq!(a.indirect.rgb(x, y), Vec3::ZERO);
            checked += 1;
        }
        assert!(checked > 1000);
    }
}

/// Irradiance at `p` (normal `n`) from a uniform polygon of radiance 1 (Lambert's formula:
/// E = 1/2 sum_i theta_i (Gamma_i . n)).
fn polygon_irradiance(p: Vec3, n: Vec3, poly: &[Vec3]) -> f64 {
    let mut e = 0.0f64;
    for i in 0..poly.len() {
        let a = (poly[i] - p).normalize().as_dvec3();
        let b = (poly[(i + 1) % poly.len()] - p).normalize().as_dvec3();
        let theta = a.dot(b).clamp(-1.0, 1.0).acos();
        e += 0.5 * theta * a.cross(b).normalize().dot(n.as_dvec3());
    }
    e.abs()
}

#[test]
fn polygon_irradiance_formula_sanity() {
    // A huge square close above the point covers the hemisphere: E -> pi.
    let k = 1e4;
    let poly = [Vec3::new(-k, 1.0, -k), Vec3::new(k, 1.0, -k), Vec3::new(k, 1.0, k), Vec3::new(-k, 1.0, k)];
    assert!((polygon_irradiance(Vec3::ZERO, Vec3::Y, &poly) - std::f64::consts::PI).abs() < 1e-3);
}

/// Diffuse plane under a one-sided emissive quad facing it: L_o = rho/pi * L_e * E(p), with
/// E from the polygon formula. Tests area-light sampling, MIS with BSDF sampling and
/// one-sided emission (the quad's back, seen from above, is black).
#[test]
fn plane_under_area_light() {
    let rho = Rgb::new(0.5, 0.7, 0.3);
    let le = Rgb::new(4.0, 3.0, 5.0);
    let quad = [
        Vec3::new(-0.5, 1.0, -0.4),
        Vec3::new(0.5, 1.0, -0.4),
        Vec3::new(0.5, 1.0, 0.6),
        Vec3::new(-0.5, 1.0, 0.6),
    ];
    // Winding: (p1-p0)x(p2-p0) = (1,0,0)x(1,0,1) = (0,-1,0): the front faces the plane.
    let mut s = scene_with(camera(Vec3::new(0.0, 0.6, -2.5), Vec3::new(0.0, 0.0, 0.3), 60.0));
    let m_plane = s.add_material(Material::diffuse("plane", rho));
    let m_light = s.add_material(diffuse_emitter("light", Rgb::ZERO, le, false));
    let mut plane = Mesh { name: "plane".into(), ..Mesh::default() };
    let k = 4.0;
    push_quad(
        &mut plane,
        [Vec3::new(-k, 0.0, -k), Vec3::new(-k, 0.0, k), Vec3::new(k, 0.0, k), Vec3::new(k, 0.0, -k)],
        m_plane,
    );
    s.add_mesh(plane);
    let mut light = Mesh { name: "light".into(), ..Mesh::default() };
    push_quad(&mut light, quad, m_light);
    s.add_mesh(light);
    let (w, h) = (40, 40);
    for max_depth in [2, 8] {
        let r = Renderer::new(s.clone(), settings(w, h, 64, max_depth)).unwrap();
        let a = render(&r).aovs();
        let on_plane =
            |x: usize, y: usize| a.normal.rgb(x, y) != Vec3::ZERO && a.position.rgb(x, y).y.abs() < 1e-4;
        let pixels = interior_pixels(w as usize, h as usize, on_plane);
        assert!(pixels.len() > 400, "{}", pixels.len());
        let mut worst = 0.0f64;
        let mut sum_d = [0.0f64; 3];
        let mut sum_v = [0.0f64; 3];
        for &(x, y) in &pixels {
            let e = footprint_mean(r.camera(), x, y, |p| polygon_irradiance(p, Vec3::Y, &quad));
            for c in 0..3 {
                let expect = rho[c] as f64 / std::f64::consts::PI * le[c] as f64 * e;
                let d = a.color.pixel(x, y)[c] as f64 - expect;
                let v = a.variance.pixel(x, y)[c] as f64;
                worst = worst.max(d.abs() / (6.0 * v.sqrt() + 1e-3 * expect));
                sum_d[c] += d;
                sum_v[c] += v;
            }
        }
        assert!(worst < 1.0, "max_depth {max_depth}: a pixel is off by {worst} of its tolerance");
        for c in 0..3 {
            let z = sum_d[c] / (sum_v[c] + 1e-12).sqrt();
            assert!(z.abs() < Z_MAX, "max_depth {max_depth} channel {c}: mean error z = {z:.2}");
        }
        // The light's front face is visible from below: emission seen directly.
        let lit: Vec<_> = interior_pixels(w as usize, h as usize, |x, y| a.position.rgb(x, y).y > 0.999);
        for &(x, y) in &lit {
            assert!((a.color.rgb(x, y) - le).abs().max_element() < 1e-5);
        }
    }
}
