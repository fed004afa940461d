//! Tests for [`LightSet`]: chi-square of `sample_li` directions against `pdf_area` +
//! `pdf_environment`, sample/pdf agreement, selection ∝ power, delta lights, bad input.

use super::*;
use crate::bsdf::tests::Rng;
use filtrace_core::stats::{chi2_sphere, integrate_sphere, Chi2Params};
use filtrace_core::{luminance, Affine3A, Vec3};
use filtrace_scene::{Environment, Instance, Light as SceneLight, Material, Mesh, Scene};
use std::f32::consts::PI;

/// A quad mesh `(c, c + a, c + a + b, c + b)`; front face along `a × b`.
fn quad(c: Vec3, a: Vec3, b: Vec3, material: u32) -> Mesh {
    Mesh {
        name: "quad".into(),
        positions: vec![c, c + a, c + a + b, c + b],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material_ids: vec![material; 2],
        ..Default::default()
    }
}

fn emitter(le: Vec3, two_sided: bool) -> Material {
    Material { emission: le, two_sided_emission: two_sided, ..Material::diffuse("light", Vec3::ZERO) }
}

/// Floor (not emissive), a one-sided 1×1 ceiling quad facing down with Le = 5, and a
/// two-sided 2×0.5 quad placed by an instance transform with Le = (1, 2, 3), plus a sky.
pub(super) fn test_scene(with_env: bool) -> Scene {
    let mut s = Scene::default();
    let grey = s.add_material(Material::diffuse("grey", Vec3::splat(0.5)));
    let bright = s.add_material(emitter(Vec3::splat(5.0), false));
    let coloured = s.add_material(emitter(Vec3::new(1.0, 2.0, 3.0), true));
    s.add_mesh(quad(Vec3::new(-3.0, 0.0, -3.0), Vec3::Z * 6.0, Vec3::X * 6.0, grey));
    // Ceiling light at y = 2, front face down: a × b = X × Z = -Y.
    s.add_mesh(quad(Vec3::new(-0.5, 2.0, -0.5), Vec3::X, Vec3::Z, bright));
    // Side light: object space in the yz plane at x = 0, moved to x = 2.5 by the instance.
    let m = s.meshes.len() as u32;
    s.meshes.push(quad(Vec3::new(0.0, 0.5, -1.0), Vec3::Z * 2.0, Vec3::Y * 0.5, coloured));
    s.instances.push(Instance {
        mesh: m,
        transform: Affine3A::from_translation(Vec3::new(2.5, 0.0, 0.0)),
        material_override: None,
    });
    if with_env {
        s.lights.push(SceneLight::Environment(Environment::Sky {
            zenith: Vec3::new(0.1, 0.2, 0.6),
            horizon: Vec3::new(0.6, 0.6, 0.7),
            ground: Vec3::splat(0.05),
        }));
    }
    s
}

/// Möller–Trumbore, for the test's own ray casting (independent of the accel crate).
fn hit_triangle(o: Vec3, d: Vec3, t: [Vec3; 3]) -> Option<f32> {
    let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let s = o - t[0];
    let u = s.dot(p) / det;
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    let tt = e2.dot(q) / det;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && tt > 1e-6).then_some(tt)
}

/// Nearest emissive triangle along `(p, d)`: `(instance, prim, t, geometric normal)`.
fn nearest_emitter(scene: &Scene, p: Vec3, d: Vec3) -> Option<(u32, u32, f32, Vec3)> {
    let mut best: Option<(u32, u32, f32, Vec3)> = None;
    for (ii, inst) in scene.instances.iter().enumerate() {
        let mesh = &scene.meshes[inst.mesh as usize];
        for prim in 0..mesh.triangle_count() {
            if !scene.materials[scene.material_of(ii as u32, prim as u32) as usize].is_emissive() {
                continue;
            }
            let t = mesh.triangle(prim).map(|v| inst.transform.transform_point3(v));
            if let Some(tt) = hit_triangle(p, d, t) {
                if best.is_none_or(|b| tt < b.2) {
                    let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
                    best = Some((ii as u32, prim as u32, tt, n));
                }
            }
        }
    }
    best
}

/// Total solid-angle density of `sample_li` from `p` towards `d`: the sampler ignores
/// occlusion, so every emitter along the ray contributes.
fn mixture_pdf(lights: &LightSet, scene: &Scene, p: Vec3, d: Vec3) -> f64 {
    let mut area = 0.0;
    for (ii, inst) in scene.instances.iter().enumerate() {
        let mesh = &scene.meshes[inst.mesh as usize];
        for prim in 0..mesh.triangle_count() {
            let t = mesh.triangle(prim).map(|v| inst.transform.transform_point3(v));
            if let Some(tt) = hit_triangle(p, d, t) {
                let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
                area += lights.pdf_area(ii as u32, prim as u32, p, p + d * tt, n);
            }
        }
    }
    (area + lights.pdf_environment(d)) as f64
}

const P: Vec3 = Vec3::new(0.2, 0.1, -0.3);

#[test]
fn build_gathers_world_space_emitters() {
    let scene = test_scene(true);
    let lights = LightSet::build(&scene);
    assert_eq!(lights.len(), 5, "4 emissive triangles + environment");
    assert_eq!(lights.skipped(), 0);
    assert_eq!(lights.area_light_index(0, 0), None, "floor is not emissive");
    assert!(lights.area_light_index(2, 1).is_some());
    assert_eq!(lights.area_light_index(9, 0), None);
    assert_eq!(lights.area_light_index(2, 9), None);
    // The side light was moved to x = 2.5 by its instance transform.
    let i = lights.area_light_index(2, 0).unwrap();
    let Some(a) = lights.area_light(i) else { panic!("not an area light") };
    assert!((a.p0.x - 2.5).abs() < 1e-6 && (a.area - 0.5).abs() < 1e-6);
}

#[test]
fn selection_is_proportional_to_power() {
    let scene = test_scene(true);
    let lights = LightSet::build(&scene);
    let r = scene.bounds().bounding_radius();
    // Ceiling triangles: π · 0.5 · 5; side triangles: π · 0.5 · lum(1,2,3) · 2.
    let p_ceiling = PI * 0.5 * 5.0;
    let p_side = PI * 0.5 * luminance(Vec3::new(1.0, 2.0, 3.0)) * 2.0;
    let p_env = lights.selection_pmf(lights.len() - 1);
    // Total power, recovered from the area lights' share.
    let total = (2.0 * p_ceiling + 2.0 * p_side) / (1.0 - p_env);
    assert!((lights.selection_pmf(lights.area_light_index(1, 0).unwrap()) - p_ceiling / total).abs() < 1e-5);
    assert!((lights.selection_pmf(lights.area_light_index(2, 1).unwrap()) - p_side / total).abs() < 1e-5);
    // Environment power: π R² · π · mean luminance, the mean from a fine quadrature.
    let env = lights.environment().unwrap();
    // The sky varies with y: put y on the quadrature's polar axis (z).
    let mean = integrate_sphere(|d| luminance(env.radiance(Vec3::new(d.x, d.z, d.y))) as f64, 64, 4, 4)
        / (4.0 * std::f64::consts::PI);
    let p_env_expected = PI * r * r * PI * mean as f32;
    assert!((p_env - p_env_expected / total).abs() < 1e-3 * p_env, "{p_env} vs {}", p_env_expected / total);

    // Frequencies: classify sample_li outcomes by where they land.
    let n = 200_000;
    let mut rng = Rng::new(21);
    let (mut ceiling, mut side, mut env_count) = (0usize, 0usize, 0usize);
    for _ in 0..n {
        let (us, u) = (rng.f32(), rng.vec2());
        // P is under the one-sided ceiling light and the side light is two-sided, so no
        // selected light is back-facing and every selection yields a sample.
        let Some(s) = lights.sample_li(P, us, u) else { continue };
        if s.dist.is_infinite() {
            env_count += 1;
        } else if (P + s.wi * s.dist).y > 1.99 {
            ceiling += 1;
        } else {
            side += 1;
        }
    }
    for (count, pmf) in [(ceiling, 2.0 * p_ceiling / total), (side, 2.0 * p_side / total), (env_count, p_env)]
    {
        let f = count as f32 / n as f32;
        let se = (pmf * (1.0 - pmf) / n as f32).sqrt();
        assert!((f - pmf).abs() < 5.0 * se, "frequency {f} vs pmf {pmf}");
    }
}

#[test]
fn chi2_sample_li_against_pdfs() {
    let scene = test_scene(true);
    let lights = LightSet::build(&scene);
    // The quads are small from P: use a finer grid than the BSDF default. The second point
    // is deliberately off the grid's symmetry planes: from (1.5, 1, 0.6) a light edge lies
    // on a cell meridian and the midpoint quadrature of the expected counts was 0.1 % off.
    let params = Chi2Params {
        theta_bins: 40,
        phi_bins: 80,
        samples: 300_000,
        subdivisions: 24,
        ..Chi2Params::standard()
    };
    for (k, p) in [P, Vec3::new(1.3, 0.83, 0.47)].into_iter().enumerate() {
        let mut rng = Rng::new(31 + k as u64);
        let res = chi2_sphere(
            &params,
            2,
            |_| lights.sample_li(p, rng.f32(), rng.vec2()).map(|s| s.wi),
            |d| mixture_pdf(&lights, &scene, p, d),
        );
        assert!(res.passed(), "from {p}: {res}");
    }
}

#[test]
fn sample_pdf_equals_pdf_area_and_pdf_environment() {
    let scene = test_scene(true);
    let lights = LightSet::build(&scene);
    let mut rng = Rng::new(41);
    let (mut n_area, mut n_env) = (0, 0);
    for _ in 0..20_000 {
        let Some(s) = lights.sample_li(P, rng.f32(), rng.vec2()) else { continue };
        assert!(!s.delta && s.pdf > 0.0 && s.li.is_finite());
        let expected = if s.dist.is_finite() {
            n_area += 1;
            let (i, prim, t, n) = nearest_emitter(&scene, P, s.wi).expect("sampled point is on an emitter");
            assert!((t - s.dist).abs() < 1e-3 * s.dist);
            lights.pdf_area(i, prim, P, P + s.wi * s.dist, n)
        } else {
            n_env += 1;
            assert_eq!(s.li, lights.environment_radiance(s.wi));
            lights.pdf_environment(s.wi)
        };
        assert!((s.pdf - expected).abs() <= 1e-3 * expected, "sample pdf {} vs {expected}", s.pdf);
    }
    assert!(n_area > 1000 && n_env > 1000);
}

#[test]
fn one_sided_emitters_are_dark_from_behind() {
    let scene = test_scene(false);
    let lights = LightSet::build(&scene);
    let above = Vec3::new(0.0, 3.0, 0.0);
    let hit = Vec3::new(0.1, 2.0, 0.1);
    assert_eq!(lights.pdf_area(1, 0, above, hit, -Vec3::Y), 0.0);
    assert!(lights.pdf_area(1, 0, P, hit, -Vec3::Y) > 0.0);
    // Two-sided side light has density from both sides.
    let on_side = Vec3::new(2.5, 0.7, 0.0);
    assert!(lights.pdf_area(2, 0, Vec3::new(4.0, 0.7, 0.0), on_side, Vec3::X) > 0.0);
    assert!(lights.pdf_area(2, 0, Vec3::new(1.0, 0.7, 0.0), on_side, Vec3::X) > 0.0);
    // Non-emissive and unknown triangles.
    assert_eq!(lights.pdf_area(0, 0, P, Vec3::ZERO, Vec3::Y), 0.0);
    assert_eq!(lights.pdf_area(7, 0, P, Vec3::ZERO, Vec3::Y), 0.0);
    assert_eq!(lights.pdf_environment(Vec3::Y), 0.0);
    assert_eq!(lights.environment_radiance(Vec3::Y), Vec3::ZERO);
}

#[test]
fn point_light_inverse_square() {
    let mut scene = Scene::default();
    let i = Vec3::new(10.0, 20.0, 30.0);
    scene.lights.push(SceneLight::Point { position: Vec3::new(0.0, 4.0, 0.0), intensity: i });
    let lights = LightSet::build(&scene);
    for d in [0.5f32, 1.0, 3.0] {
        let p = Vec3::new(0.0, 4.0 - d, 0.0);
        let s = lights.sample_li(p, 0.3, Vec2::new(0.1, 0.9)).unwrap();
        assert!(s.delta && s.pdf == 1.0 && (s.dist - d).abs() < 1e-5);
        assert!((s.li - i / (d * d)).abs().max_element() < 1e-4 * i.max_element() / (d * d));
        assert!((s.wi - Vec3::Y).length() < 1e-6);
    }
}

#[test]
fn spot_falloff_values_and_power() {
    let (cs, cw) = (20f32.to_radians().cos(), 30f32.to_radians().cos());
    let i = Vec3::splat(8.0);
    let spot = SpotLight::new(Vec3::ZERO, -Vec3::Y * 3.0, i, cw, cs).unwrap();
    assert_eq!(spot.falloff(1.0), 1.0);
    assert_eq!(spot.falloff(cs), 1.0);
    assert_eq!(spot.falloff(cw), 0.0);
    assert_eq!(spot.falloff(0.0), 0.0);
    let c25 = 25f32.to_radians().cos();
    let t = (c25 - cw) / (cs - cw);
    assert!((spot.falloff(c25) - t * t * (3.0 - 2.0 * t)).abs() < 1e-6);
    // Through the LightSet: a point 2 below the light, 25° off axis.
    let mut scene = Scene::default();
    scene.lights.push(SceneLight::Spot {
        position: Vec3::ZERO,
        direction: -Vec3::Y,
        intensity: i,
        cos_total_width: cw,
        cos_falloff_start: cs,
    });
    let lights = LightSet::build(&scene);
    let dir = Vec3::new(25f32.to_radians().sin(), -c25, 0.0);
    let s = lights.sample_li(dir * 2.0, 0.5, Vec2::ZERO).unwrap();
    assert!((s.li - i * spot.falloff(c25) / 4.0).abs().max_element() < 1e-4);
    assert!(lights.sample_li(Vec3::new(2.0, -1.0, 0.0), 0.5, Vec2::ZERO).is_none(), "outside the cone");
    // By symmetry the falloff can be integrated about the quadrature's polar axis z.
    // Power = ∫ I falloff dω (numerically) = 2π (1 − (cs + cw)/2) lum(I).
    let phi = integrate_sphere(|d| (8.0 * spot.falloff(-d.z)) as f64, 400, 4, 4);
    assert!((phi as f32 - spot.power()).abs() < 1e-3 * spot.power(), "{phi} vs {}", spot.power());
}

#[test]
fn directional_light_is_a_delta() {
    let mut scene = test_scene(false);
    scene
        .lights
        .push(SceneLight::Directional { direction: Vec3::new(0.0, 2.0, 0.0), irradiance: Vec3::splat(3.0) });
    let lights = LightSet::build(&scene);
    let r = scene.bounds().bounding_radius();
    let idx = lights.len() - 1;
    let pmf = lights.selection_pmf(idx);
    // Find u_select landing on the directional light (last in the CDF).
    let s = lights.sample_li(P, 0.999_999, Vec2::splat(0.5)).unwrap();
    assert!(s.delta && s.dist.is_infinite() && s.wi == Vec3::Y && s.li == Vec3::splat(3.0));
    assert!((s.pdf - pmf).abs() < 1e-6);
    let total_area = 2.0 * PI * 0.5 * 5.0 + 2.0 * PI * 0.5 * luminance(Vec3::new(1.0, 2.0, 3.0)) * 2.0;
    let p_dir = PI * r * r * 3.0;
    assert!((pmf - p_dir / (p_dir + total_area)).abs() < 1e-5);
}

/// Constant environment L: uniform pdf, and the irradiance estimator Σ L cos / pdf → π L.
#[test]
fn constant_environment_irradiance() {
    let mut scene = Scene::default();
    scene.lights.push(SceneLight::Environment(Environment::Constant { radiance: Vec3::splat(2.0) }));
    let lights = LightSet::build(&scene);
    assert!((lights.pdf_environment(Vec3::new(0.3, -0.5, 0.1).normalize()) - 1.0 / (4.0 * PI)).abs() < 1e-6);
    let mut rng = Rng::new(51);
    let n = 200_000;
    let (mut sum, mut sq) = (0.0f64, 0.0f64);
    for _ in 0..n {
        let s = lights.sample_li(Vec3::ZERO, rng.f32(), rng.vec2()).unwrap();
        let w = (s.li.x * s.wi.y.max(0.0) / s.pdf) as f64;
        sum += w;
        sq += w * w;
    }
    let mean = sum / n as f64;
    let se = ((sq / n as f64 - mean * mean) / n as f64).sqrt();
    assert!((mean - 2.0 * std::f64::consts::PI).abs() < 5.0 * se, "E = {mean} ± {se}");
}

#[test]
fn sky_radiance_and_sampling() {
    let env = EnvironmentLight::new(&[&Environment::Sky {
        zenith: Vec3::new(0.0, 0.0, 4.0),
        horizon: Vec3::new(1.0, 1.0, 1.0),
        ground: Vec3::splat(0.1),
    }]);
    assert_eq!(env.radiance(Vec3::Y), Vec3::new(0.0, 0.0, 4.0));
    assert_eq!(env.radiance(Vec3::X), Vec3::ONE);
    assert_eq!(env.radiance(-Vec3::Y), Vec3::splat(0.1));
    assert!((env.radiance(Vec3::new(0.0, 0.5, 0.866)) - Vec3::new(0.5, 0.5, 2.5)).length() < 1e-5);
    // Sampling against its own pdf; directions map y → the test's z axis.
    let mut rng = Rng::new(61);
    let res = chi2_sphere(
        &Chi2Params::standard(),
        1,
        |_| env.sample(rng.vec2()).map(|(d, _)| Vec3::new(d.x, d.z, d.y)),
        |d| env.pdf(Vec3::new(d.x, d.z, d.y)) as f64,
    );
    assert!(res.passed(), "{res}");
    let mut rng = Rng::new(62);
    for _ in 0..1000 {
        let (d, pdf) = env.sample(rng.vec2()).unwrap();
        assert!((pdf - env.pdf(d)).abs() < 1e-4 * pdf);
    }
}

#[test]
fn bad_input_is_skipped_not_a_panic() {
    let empty = LightSet::build(&Scene::default());
    assert!(empty.is_empty());
    assert!(empty.sample_li(Vec3::ZERO, 0.5, Vec2::splat(0.5)).is_none());
    assert_eq!(empty.pdf_area(0, 0, Vec3::ZERO, Vec3::ONE, Vec3::Y), 0.0);

    let mut s = Scene::default();
    let m = s.add_material(emitter(Vec3::splat(1.0), false));
    let nan = s.add_material(emitter(Vec3::new(f32::NAN, 1.0, 1.0), false));
    s.add_mesh(quad(Vec3::splat(f32::NAN), Vec3::X, Vec3::Z, m)); // NaN corners
    s.add_mesh(quad(Vec3::ZERO, Vec3::X, Vec3::X, m)); // degenerate
    s.add_mesh(quad(Vec3::ZERO, Vec3::X, Vec3::Z, 99)); // unknown material
    s.add_mesh(quad(Vec3::ZERO, Vec3::X, Vec3::Z, nan)); // NaN emission
    s.instances.push(Instance { mesh: 42, transform: Affine3A::IDENTITY, material_override: None });
    s.lights.push(SceneLight::Spot {
        position: Vec3::ZERO,
        direction: Vec3::ZERO,
        intensity: Vec3::ONE,
        cos_total_width: 0.5,
        cos_falloff_start: 0.9,
    });
    s.lights.push(SceneLight::Point { position: Vec3::splat(f32::INFINITY), intensity: Vec3::ONE });
    s.lights.push(SceneLight::Directional { direction: Vec3::ZERO, irradiance: Vec3::ONE });
    s.lights.push(SceneLight::Environment(Environment::Constant { radiance: Vec3::ZERO }));
    let lights = LightSet::build(&s);
    assert!(lights.is_empty(), "{} lights", lights.len());
    assert!(lights.skipped() >= 8, "skipped {}", lights.skipped());
}

/// The light chi-square test has power: claiming the area density without the
/// solid-angle conversion (`pmf / A` instead of `pmf d² / (|cos| A)`) is rejected.
#[test]
fn chi2_rejects_area_measure_pdf() {
    let scene = test_scene(false);
    let lights = LightSet::build(&scene);
    let mut rng = Rng::new(71);
    let wrong = |d: Vec3| -> f64 {
        let Some((i, prim, _, _)) = nearest_emitter(&scene, P, d) else { return 0.0 };
        let idx = lights.area_light_index(i, prim).unwrap();
        let Some(a) = lights.area_light(idx) else { return 0.0 };
        (lights.selection_pmf(idx) / a.area) as f64
    };
    let params = Chi2Params { samples: 100_000, ..Chi2Params::standard() };
    let res = chi2_sphere(&params, 1, |_| lights.sample_li(P, rng.f32(), rng.vec2()).map(|s| s.wi), wrong);
    assert!(!res.passed(), "{res}");
}

/// The (instance, prim) → light table agrees with a brute-force search over all area
/// lights by world-space vertices, for every triangle of the scene.
#[test]
fn area_lookup_matches_brute_force() {
    let scene = test_scene(true);
    let lights = LightSet::build(&scene);
    for (ii, inst) in scene.instances.iter().enumerate() {
        let mesh = &scene.meshes[inst.mesh as usize];
        for prim in 0..mesh.triangle_count() {
            let t = mesh.triangle(prim).map(|v| inst.transform.transform_point3(v));
            let brute = lights.lights().iter().position(|l| match l {
                Light::Area(a) => (a.p0 - t[0]).length() < 1e-6 && (a.p0 + a.e1 - t[1]).length() < 1e-6,
                _ => false,
            });
            assert_eq!(lights.area_light_index(ii as u32, prim as u32), brute, "instance {ii} prim {prim}");
        }
    }
}

/// Slow tier: 5x the samples of the fast test, finer integration, more viewpoints (one
/// 0.5 from the side light). Left out: viewpoints that see a light very small or at very
/// grazing angles, where the midpoint quadrature of the expected counts, not the sampler,
/// limits the test. Example: 0.1 under the ceiling light the light's pdf integrates
/// (quadrature with z as polar axis) to 1.00096 at 24², 48² and 96² points per cell, but
/// to 0.99997 with y as polar axis; the exact solid angle matches the quadrature of the
/// indicator to 8e-5. 1.5M samples resolve such 0.1 % errors.
#[test]
#[ignore = "slow: light chi-square with 1.5M samples from three points"]
fn chi2_sample_li_thorough() {
    let scene = test_scene(true);
    let lights = LightSet::build(&scene);
    let points = [P, Vec3::new(1.3, 0.83, 0.47), Vec3::new(2.0, 0.77, 0.05)];
    let params = Chi2Params {
        theta_bins: 40,
        phi_bins: 80,
        samples: 1_500_000,
        subdivisions: 48,
        ..Chi2Params::standard()
    };
    let mut failures = Vec::new();
    for (k, p) in points.into_iter().enumerate() {
        // Seeds 91..: with 81.. the third point failed by chance (p = 2.5e-3 against the
        // Šidák threshold 3.3e-3) once light selection became an alias table, which maps
        // `u_select` differently. A scan of seeds 83..88 at that point gave p = 2.5e-3, 0.14,
        // 0.81, 0.37, 0.20, 0.51 with the alias table and 0.094, 0.084, 0.24, 0.010, 0.50,
        // 0.66 with the old CDF search: no systematic difference, so new seeds were drawn
        // (once, untried) rather than the threshold loosened.
        let mut rng = Rng::new(91 + k as u64);
        let res = chi2_sphere(
            &params,
            points.len(),
            |_| lights.sample_li(p, rng.f32(), rng.vec2()).map(|s| s.wi),
            |d| mixture_pdf(&lights, &scene, p, d),
        );
        if !res.passed() {
            failures.push(format!("from {p}: {res}"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
