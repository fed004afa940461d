//! The bilateral filter against the direct edge-avoiding sum.

use super::*;

#[test]
fn bilateral_matches_naive() {
    for_every_build(bilateral_matches_naive_on);
}

fn bilateral_matches_naive_on(build: &str) {
    let mut rng = Rng::new(2);
    let (w, h) = (23, 19);
    let g = random_gbuffer(w, h, &mut rng, true);
    let color = random_color(w, h, &mut rng);
    for p in [
        BilateralParams::small(),
        BilateralParams {
            radius: 7,
            sigma_spatial: 3.0,
            sigma_color: Some(0.7),
            ..BilateralParams::reference()
        },
        BilateralParams { radius: 30, sigma_spatial: 9.0, ..BilateralParams::reference() },
    ] {
        let fast = bilateral(&color, &g, &p).unwrap();
        let r = p.radius as isize;
        let mut taps = Vec::new();
        for dy in -r..=r {
            for dx in -r..=r {
                taps.push((
                    dx,
                    dy,
                    (-((dx * dx + dy * dy) as f64) / (2.0 * (p.sigma_spatial as f64).powi(2))).exp(),
                ));
            }
        }
        let inv = |s: Option<f32>| s.map(|s| 1.0 / (s as f64).powi(2));
        let c: Vec<f64> = color.data().iter().map(|v| *v as f64).collect();
        let naive =
            naive_pass(&c, &g, &taps, (inv(p.sigma_color), inv(p.sigma_normal), inv(p.sigma_position)));
        assert_close(&fast, &naive, 2e-4, &format!("{build}: {p:?}"));
    }
}
