//! Importance map: fast vs naive for every preset, analytic cases, degenerate input.

use filtrace_adaptive::synthetic::grass_gbuffer;
use filtrace_adaptive::{
    importance_map, importance_map_naive, AdaptiveError, ImportanceParams, PositionScale,
};
use filtrace_core::{Image, Vec3};

fn max_abs_diff(a: &Image, b: &Image) -> f32 {
    a.data().iter().zip(b.data()).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

#[test]
fn fast_matches_naive_for_every_preset_and_radius() {
    let (n, p) = grass_gbuffer(61, 47, 40, 7);
    let mut all = ImportanceParams::presets().to_vec();
    for r in [1, 3, 4, 10] {
        all.push(("radius", ImportanceParams::paper().with_radius(r)));
    }
    all.push((
        "world",
        ImportanceParams { sigma_position: PositionScale::World(0.05), ..ImportanceParams::paper() },
    ));
    for (name, params) in all {
        let fast = importance_map(&n, &p, &params).unwrap();
        let naive = importance_map_naive(&n, &p, &params).unwrap();
        let d = max_abs_diff(&fast, &naive);
        assert!(d < 1e-5, "{name} r={}: max difference {d}", params.radius);
        assert!(fast.data().iter().all(|v| (0.0..=1.0).contains(v)));
    }
}

/// A plane with constant normal whose positions are all equal: every weight is 1, so
/// `W_p = |window|` and the importance is exactly 0 everywhere (border included).
#[test]
fn identical_neighbours_give_zero_importance() {
    let n = Image::from_vec(9, 5, 3, [0.0, 1.0, 0.0].repeat(45)).unwrap();
    let p = Image::from_vec(9, 5, 3, [1.0, 2.0, 3.0].repeat(45)).unwrap();
    let imp = importance_map(&n, &p, &ImportanceParams::paper()).unwrap();
    assert!(imp.data().iter().all(|&v| v == 0.0), "{:?}", imp.data());
}

/// Two half-planes with opposite normals at the same position: a neighbour on the
/// other side has weight exp(-4/σ_n²) ≈ 0, so the importance of a pixel next to the
/// crease is the fraction of its window on the other side.
#[test]
fn crease_importance_is_fraction_of_dissimilar_window() {
    let (w, h) = (10, 7);
    let mut n = Image::new(w, h, 3);
    for y in 0..h {
        for x in 0..w {
            n.set_rgb(x, y, if x < 5 { Vec3::Z } else { -Vec3::Z });
        }
    }
    let p = Image::filled(w, h, 3, 0.5);
    let params = ImportanceParams::paper(); // r = 2
    let imp = importance_map(&n, &p, &params).unwrap();
    // Interior row y = 3: x = 4 sees columns 2..=6, two of them (5, 6) dissimilar.
    let at = |x| imp.pixel(x, 3)[0];
    assert!((at(4) - 2.0 / 5.0).abs() < 1e-6, "{}", at(4));
    assert!((at(3) - 1.0 / 5.0).abs() < 1e-6, "{}", at(3));
    assert_eq!(at(1), 0.0);
    assert_eq!(at(0), 0.0, "the frame border alone must not raise importance");
}

/// Background (zero-length or non-finite normal) has importance 0 and weight 0.
#[test]
fn background_has_zero_importance_and_no_weight() {
    let (w, h) = (7, 7);
    let mut n = Image::from_vec(w, h, 3, [0.0, 0.0, 2.0].repeat(w * h)).unwrap(); // not unit
    let p = Image::filled(w, h, 3, 1.0);
    for y in 0..h {
        n.set_rgb(0, y, Vec3::ZERO);
        n.set_rgb(1, y, Vec3::splat(f32::NAN));
    }
    let imp = importance_map(&n, &p, &ImportanceParams::fast()).unwrap(); // r = 1
    for y in 0..h {
        assert_eq!(imp.pixel(0, y)[0], 0.0);
        assert_eq!(imp.pixel(1, y)[0], 0.0);
        assert_eq!(imp.pixel(4, y)[0], 0.0);
    }
    // x = 2 (interior row): 3 of its 9 window pixels are background.
    assert!((imp.pixel(2, 3)[0] - 1.0 / 3.0).abs() < 1e-6);
    assert_eq!(imp.count_non_finite(), 0);
}

#[test]
fn one_pixel_image_has_zero_importance() {
    let n = Image::from_vec(1, 1, 3, vec![0.0, 0.0, 1.0]).unwrap();
    let p = Image::new(1, 1, 3);
    let imp = importance_map(&n, &p, &ImportanceParams::wide()).unwrap();
    assert_eq!(imp.data(), &[0.0]);
}

#[test]
fn complex_geometry_is_more_important_than_the_plane() {
    let (n, p) = grass_gbuffer(200, 120, 60, 3);
    let imp = importance_map(&n, &p, &ImportanceParams::paper()).unwrap();
    // Mean importance over blade pixels (normal with a -z component) vs ground pixels
    // far from any blade (normal +y with all window normals +y).
    let (mut blade, mut nb, mut ground, mut ng) = (0.0, 0, 0.0, 0);
    for y in 2..118 {
        for x in 2..198 {
            let v = imp.pixel(x, y)[0] as f64;
            if n.rgb(x, y).z < -0.5 {
                blade += v;
                nb += 1;
            } else if (y - 2..=y + 2).all(|yy| (x - 2..=x + 2).all(|xx| n.rgb(xx, yy) == Vec3::Y)) {
                ground += v;
                ng += 1;
            }
        }
    }
    assert!(nb > 100 && ng > 100);
    let (blade, ground) = (blade / nb as f64, ground / ng as f64);
    assert!(blade > 2.0 * ground, "blade {blade} vs ground {ground}");
}

#[test]
fn bad_input_is_an_error() {
    let n = Image::new(4, 4, 3);
    let p = Image::new(4, 4, 3);
    let ok = ImportanceParams::paper();
    assert!(matches!(importance_map(&n, &Image::new(4, 3, 3), &ok), Err(AdaptiveError::SizeMismatch { .. })));
    assert!(matches!(importance_map(&Image::new(4, 4, 2), &p, &ok), Err(AdaptiveError::Channels { .. })));
    assert_eq!(
        importance_map(&Image::new(0, 0, 3), &Image::new(0, 0, 3), &ok),
        Err(AdaptiveError::EmptyImage)
    );
    for bad in [
        ok.with_radius(0),
        ok.with_radius(11),
        ImportanceParams { sigma_normal: f32::NAN, ..ok },
        ImportanceParams { sigma_normal: 0.0, ..ok },
        ImportanceParams { sigma_position: PositionScale::Footprint(-1.0), ..ok },
        ImportanceParams { sigma_position: PositionScale::World(f32::INFINITY), ..ok },
    ] {
        let e = importance_map(&n, &p, &bad).unwrap_err();
        assert!(matches!(e, AdaptiveError::InvalidParameter { .. }), "{e}");
        assert!(!e.to_string().is_empty());
    }
}

/// Every G-buffer value a renderer might emit (NaN, inf, huge) yields a finite map.
#[test]
fn non_finite_gbuffer_values_never_spread() {
    let (mut n, mut p) = grass_gbuffer(32, 32, 10, 1);
    n.pixel_mut(3, 3)[0] = f32::NAN;
    p.pixel_mut(10, 10)[2] = f32::INFINITY;
    p.pixel_mut(11, 10)[1] = 1e30;
    let imp = importance_map(&n, &p, &ImportanceParams::paper()).unwrap();
    assert_eq!(imp.count_non_finite(), 0);
    assert_eq!(imp.pixel(3, 3)[0], 0.0);
    assert_eq!(imp.pixel(10, 10)[0], 0.0);
}
