//! Tests of emission sampling: chi-square of every light type's directions against the
//! stated density, uniformity of positions (triangle cells, disk moments), selection
//! frequency ∝ power, and the mean flux against the analytic emitted power.

use super::*;
use crate::bsdf::tests::Rng;
use crate::lights::LightSet;
use filtrace_core::luminance;
use filtrace_core::stats::{chi2_sf, chi2_sphere, chi2_statistic, sidak, Chi2Params};
use filtrace_scene::{Environment, Light, Material, Mesh, Scene};

/// Chi-square tests in this file (Šidák family size).
const TESTS: usize = 8;

fn chi2_dirs(name: &str, mut sample: impl FnMut(&mut Rng) -> Option<Vec3>, pdf: impl Fn(Vec3) -> f64) {
    let mut rng = Rng::new(7);
    let res = chi2_sphere(&Chi2Params::standard(), TESTS, |_| sample(&mut rng), pdf);
    assert!(res.passed(), "{name}: {res}");
}

fn tilted_triangle(two_sided: bool) -> AreaLight {
    let tri = [Vec3::new(0.0, 1.0, 0.0), Vec3::new(1.0, 1.3, 0.2), Vec3::new(0.1, 1.5, 1.0)];
    AreaLight::new(tri, Vec3::new(1.0, 2.0, 3.0), two_sided).unwrap()
}

#[test]
fn area_directions_are_cosine_weighted_on_the_emitting_side() {
    for two_sided in [false, true] {
        let a = tilted_triangle(two_sided);
        let side = if two_sided { 0.5 } else { 1.0 };
        chi2_dirs(
            &format!("area two_sided={two_sided}"),
            |r| a.sample_le(r.vec2(), r.vec2()).map(|s| s.dir),
            |d| {
                let c = a.n.dot(d) as f64;
                let c = if two_sided { c.abs() } else { c.max(0.0) };
                side * c / std::f64::consts::PI
            },
        );
        // The stated pdf_dir is that density, and n is on the side of dir.
        let mut rng = Rng::new(3);
        for _ in 0..1000 {
            let Some(s) = a.sample_le(rng.vec2(), rng.vec2()) else { continue };
            let want = side as f32 * s.n.dot(s.dir) / PI;
            assert!(s.n.dot(s.dir) > 0.0 && (s.pdf_dir - want).abs() <= 1e-5 * want.max(1.0), "{s:?}");
            assert!((s.pdf_pos - 1.0 / a.area).abs() < 1e-5 / a.area);
        }
    }
}

/// Positions land uniformly on the triangle: chi-square over the n² equal sub-triangles
/// of the barycentric domain (cell (i, j) of the (b1, b2) grid, lower or upper half).
#[test]
fn area_positions_are_uniform_on_the_triangle() {
    let a = tilted_triangle(false);
    let n = 8usize;
    let mut observed = vec![0.0f64; 2 * n * n];
    let mut rng = Rng::new(11);
    let samples = 64_000;
    // Barycentrics of p from the normal equations of p - p0 = b1 e1 + b2 e2.
    let (e11, e12, e22) = (a.e1.dot(a.e1), a.e1.dot(a.e2), a.e2.dot(a.e2));
    let det = e11 * e22 - e12 * e12;
    let mut mean = Vec3::ZERO;
    for _ in 0..samples {
        // None only for a direction exactly on the horizon (measure zero): redraw.
        let s = loop {
            if let Some(s) = a.sample_le(rng.vec2(), rng.vec2()) {
                break s;
            }
        };
        mean += s.p / samples as f32;
        let d = s.p - a.p0;
        let (r1, r2) = (d.dot(a.e1), d.dot(a.e2));
        let b1 = ((e22 * r1 - e12 * r2) / det).clamp(0.0, 1.0) * n as f32;
        let b2 = ((e11 * r2 - e12 * r1) / det).clamp(0.0, 1.0) * n as f32;
        let (i, j) = ((b1 as usize).min(n - 1), (b2 as usize).min(n - 1));
        let upper = (b1 - i as f32) + (b2 - j as f32) > 1.0;
        observed[2 * (i * n + j) + upper as usize] += 1.0;
    }
    // Sub-triangles inside b1 + b2 <= 1: lower halves with i + j <= n - 1, upper halves
    // with i + j <= n - 2; n² of them, each of equal area.
    let expected: Vec<f64> = (0..2 * n * n)
        .map(|c| {
            let (i, j, upper) = (c / 2 / n, c / 2 % n, c % 2 == 1);
            let inside = if upper { i + j + 2 <= n } else { i + j < n };
            if inside {
                samples as f64 / (n * n) as f64
            } else {
                0.0
            }
        })
        .collect();
    // Cells cut by the clamping of rounding errors at the hypotenuse: allow them by
    // merging the observation into the expected neighbour (none expected in practice).
    let (stat, dof) = chi2_statistic(&observed, &expected, 5.0).expect("no sample outside the triangle");
    let p = chi2_sf(stat, dof as f64);
    assert!(p > sidak(0.01, TESTS), "triangle positions: chi2 {stat} dof {dof} p {p}");
    let centroid = a.p0 + (a.e1 + a.e2) / 3.0;
    assert!((mean - centroid).length() < 0.01, "mean {mean} centroid {centroid}");
}

#[test]
fn point_and_spot_directions_follow_their_densities() {
    let p = PointLight { position: Vec3::new(1.0, 2.0, 3.0), intensity: Vec3::splat(2.0) };
    chi2_dirs("point", |r| p.sample_le(r.vec2()).map(|s| s.dir), |_| 1.0 / (4.0 * std::f64::consts::PI));
    let spot = SpotLight::new(Vec3::ZERO, Vec3::new(0.3, -1.0, 0.2), Vec3::ONE, 0.6, 0.9).unwrap();
    let pdf = uniform_cone_pdf(spot.cos_total_width) as f64;
    chi2_dirs(
        "spot",
        |r| spot.sample_le(r.vec2()).map(|s| s.dir),
        |d| if d.dot(spot.axis) >= spot.cos_total_width { pdf } else { 0.0 },
    );
}

fn sky() -> EnvironmentLight {
    let e = Environment::Sky {
        zenith: Vec3::new(0.1, 0.2, 0.6),
        horizon: Vec3::new(0.6, 0.6, 0.7),
        ground: Vec3::splat(0.05),
    };
    EnvironmentLight::new(&[&e])
}

/// Environment rays travel opposite to the sampled direction, which follows `pdf`; their
/// origins lie on the disk of radius R, R back from the centre.
#[test]
fn environment_and_directional_rays_cover_the_scene_disk() {
    let env = sky();
    let (c, r) = (Vec3::new(1.0, -2.0, 0.5), 3.0f32);
    chi2_dirs(
        "environment",
        |g| env.sample_le(g.vec2(), g.vec2(), c, r).map(|s| -s.dir),
        |d| env.pdf(d) as f64,
    );
    let dl = DirectionalLight::new(Vec3::new(0.2, 1.0, -0.3), Vec3::ONE).unwrap();
    let mut rng = Rng::new(9);
    let n = 40_000;
    let mut mean_r2 = 0.0f64;
    for i in 0..n {
        let s = if i % 2 == 0 {
            env.sample_le(rng.vec2(), rng.vec2(), c, r).unwrap()
        } else {
            let s = dl.sample_le(rng.vec2(), c, r).unwrap();
            assert_eq!(s.dir, -dl.to_light);
            s
        };
        let q = s.p - c;
        // Plane of the disk: R behind the centre, perpendicular to dir.
        assert!((q.dot(s.dir) + r).abs() < 1e-4 * r, "{s:?}");
        let radial = q - q.dot(s.dir) * s.dir;
        assert!(radial.length() <= r * (1.0 + 1e-5));
        mean_r2 += (radial.length_squared() / (r * r)) as f64 / n as f64;
    }
    // Uniform on the disk: E[r²/R²] = 1/2, Var = 1/12.
    let sigma = (1.0f64 / 12.0 / n as f64).sqrt();
    assert!((mean_r2 - 0.5).abs() < 5.0 * sigma, "mean r²/R² {mean_r2}");
}

fn quad(c: Vec3, a: Vec3, b: Vec3, material: u32) -> Mesh {
    Mesh {
        name: "quad".into(),
        positions: vec![c, c + a, c + a + b, c + b],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material_ids: vec![material; 2],
        ..Default::default()
    }
}

/// One light of every type: a one-sided quad (Le 5), a two-sided quad (Le (1,2,3)),
/// point, spot, directional and a sky, plus a floor for the bounds.
fn all_lights_scene() -> Scene {
    let mut s = Scene::default();
    let grey = s.add_material(Material::diffuse("grey", Vec3::splat(0.5)));
    let emit = |le: Vec3, two: bool| Material {
        emission: le,
        two_sided_emission: two,
        ..Material::diffuse("light", Vec3::ZERO)
    };
    let bright = s.add_material(emit(Vec3::splat(5.0), false));
    let coloured = s.add_material(emit(Vec3::new(1.0, 2.0, 3.0), true));
    s.add_mesh(quad(Vec3::new(-3.0, 0.0, -3.0), Vec3::Z * 6.0, Vec3::X * 6.0, grey));
    s.add_mesh(quad(Vec3::new(-0.5, 2.0, -0.5), Vec3::X, Vec3::Z, bright));
    s.add_mesh(quad(Vec3::new(2.0, 0.5, -1.0), Vec3::Z * 2.0, Vec3::Y * 0.5, coloured));
    s.lights.push(Light::Point { position: Vec3::new(0.0, 1.5, 0.0), intensity: Vec3::new(3.0, 2.0, 1.0) });
    s.lights.push(Light::Spot {
        position: Vec3::new(1.0, 2.5, 0.0),
        direction: Vec3::new(0.0, -1.0, 0.2),
        intensity: Vec3::splat(4.0),
        cos_total_width: 0.7,
        cos_falloff_start: 0.9,
    });
    s.lights.push(Light::Directional { direction: Vec3::new(0.3, 1.0, 0.1), irradiance: Vec3::splat(0.5) });
    s.lights.push(Light::Environment(Environment::Sky {
        zenith: Vec3::new(0.1, 0.2, 0.6),
        horizon: Vec3::new(0.6, 0.6, 0.7),
        ground: Vec3::splat(0.05),
    }));
    s
}

/// Emitted power per channel, from each light's own definition (not from `power()`),
/// and per light its kind.
fn analytic_power(set: &LightSet) -> (Vec3, Vec<EmitterKind>) {
    let r = set.scene_radius();
    let disk = PI * r * r;
    let mut total = Vec3::ZERO;
    let mut per_kind = Vec::new();
    for i in 0..set.len() {
        let kind = set.emitter_kind(i).unwrap();
        let phi = match kind {
            EmitterKind::Area => {
                let a = set.area_light(i).unwrap();
                a.le * (PI * a.area * if a.two_sided { 2.0 } else { 1.0 })
            }
            EmitterKind::Point => set.point_light(i).unwrap().intensity * (4.0 * PI),
            EmitterKind::Spot => {
                // ∫ smoothstep over the cone: 2π [(1 − cs) + (cs − cw)/2].
                let s = set.spot_light(i).unwrap();
                let (cs, cw) = (s.cos_falloff_start, s.cos_total_width);
                s.intensity * (2.0 * PI * ((1.0 - cs) + 0.5 * (cs - cw)))
            }
            EmitterKind::Directional => set.directional_light(i).unwrap().irradiance * disk,
            EmitterKind::Environment => {
                // πR² ∫ L dω with L a function of y: 2π ∫_{-1}^{1} L(y) dy (midpoint rule).
                let env = set.environment().unwrap();
                let m = 20_000;
                let mut int = Vec3::ZERO;
                for k in 0..m {
                    let y = -1.0 + 2.0 * (k as f32 + 0.5) / m as f32;
                    let d = Vec3::new((1.0 - y * y).sqrt(), y, 0.0);
                    int += env.radiance(d) * (2.0 / m as f32);
                }
                int * (2.0 * PI) * disk
            }
        };
        total += phi;
        per_kind.push(kind);
    }
    (total, per_kind)
}

/// The mean flux of `LightSet::sample_le` equals the total emitted power (z-test per
/// channel, 5σ), and light kinds are chosen with the light set's power-proportional
/// selection probabilities (chi-square). Note: those use the light set's selection
/// powers, where the environment counts `π²R² mean L` (irradiance-based), a quarter of
/// the flux `4π²R² mean L` it emits through the scene's disk (pbrt-v4 `Phi`); the flux
/// estimate is unbiased for any selection.
#[test]
fn flux_estimate_matches_power_and_selection_is_power_proportional() {
    let set = LightSet::build(&all_lights_scene());
    assert_eq!(set.len(), 4 + 4, "4 triangles + point, spot, directional, environment");
    let (want, per_kind) = analytic_power(&set);
    let n = 400_000usize;
    let mut rng = Rng::new(21);
    let (mut sum, mut sum2) = ([0.0f64; 3], [0.0f64; 3]);
    let kinds = [
        EmitterKind::Area,
        EmitterKind::Point,
        EmitterKind::Spot,
        EmitterKind::Directional,
        EmitterKind::Environment,
    ];
    let mut counts = [0.0f64; 5];
    for _ in 0..n {
        let Some(s) = set.sample_le(rng.f32(), rng.vec2(), rng.vec2()) else { continue };
        counts[kinds.iter().position(|&k| k == s.kind).unwrap()] += 1.0;
        let f = s.flux();
        for c in 0..3 {
            sum[c] += f[c] as f64;
            sum2[c] += (f[c] as f64).powi(2);
        }
    }
    for c in 0..3 {
        let mean = sum[c] / n as f64;
        let sigma = ((sum2[c] / n as f64 - mean * mean) / n as f64).sqrt();
        let w = want[c] as f64;
        assert!(
            (mean - w).abs() < 5.0 * sigma + 1e-4 * w,
            "channel {c}: mean flux {mean} vs power {w} (σ {sigma})"
        );
    }
    // Selection ∝ power(): area π A lum(Le) (×2), point 4π lum(I), spot and distant as
    // in the lights' docs; recomputed here for the area and point lights.
    for (i, kind) in per_kind.iter().enumerate() {
        let want = match kind {
            EmitterKind::Area => {
                let a = set.area_light(i).unwrap();
                Some(PI * a.area * luminance(a.le) * if a.two_sided { 2.0 } else { 1.0 })
            }
            EmitterKind::Point => Some(4.0 * PI * luminance(set.point_light(i).unwrap().intensity)),
            _ => None,
        };
        if let (Some(w), Some(w0)) = (want, set.area_light(0).map(|a| a.power())) {
            let ratio = set.selection_pmf(i) / set.selection_pmf(0);
            assert!(
                (ratio - w / w0).abs() < 1e-4 * (w / w0),
                "light {i}: pmf ratio {ratio} vs power ratio {}",
                w / w0
            );
        }
    }
    let expected: Vec<f64> = kinds
        .iter()
        .map(|k| {
            (0..set.len()).filter(|&i| per_kind[i] == *k).map(|i| set.selection_pmf(i) as f64).sum::<f64>()
                * n as f64
        })
        .collect();
    let (stat, dof) = chi2_statistic(&counts, &expected, 5.0).unwrap();
    let p = chi2_sf(stat, dof as f64);
    assert!(p > sidak(0.01, TESTS), "selection counts {counts:?} vs {expected:?}: p = {p}");
}

#[test]
fn sample_le_of_each_light_has_pmf_one_and_bad_lights_give_none() {
    let set = LightSet::build(&all_lights_scene());
    let mut rng = Rng::new(2);
    for i in 0..set.len() {
        let s = set.sample_le_of(i, rng.vec2(), rng.vec2()).unwrap();
        assert_eq!(s.pmf, 1.0);
        assert_eq!(Some(s.kind), set.emitter_kind(i));
        assert!((s.dir.length() - 1.0).abs() < 1e-4, "{s:?}");
    }
    assert!(set.sample_le_of(set.len(), rng.vec2(), rng.vec2()).is_none());
    assert!(LightSet::default().sample_le(0.5, rng.vec2(), rng.vec2()).is_none());
    // A spot light pointing at a falloff of zero along the sampled edge still never
    // returns a zero-radiance sample.
    let spot = SpotLight::new(Vec3::ZERO, Vec3::Y, Vec3::ONE, 0.5, 0.5).unwrap();
    for _ in 0..1000 {
        if let Some(s) = spot.sample_le(rng.vec2()) {
            assert!(s.le.max_element() > 0.0);
        }
    }
}
