//! What every filter (every preset) promises: constants kept, edges and background
//! respected, NaN not spread, energy kept, clear errors, bounded output.

use super::*;
use filtrace_core::Vec3;

fn all_filters() -> Vec<(String, Filter)> {
    let mut v: Vec<(String, Filter)> = Vec::new();
    for (n, p) in AtrousParams::presets() {
        v.push((format!("atrous {n}"), Filter::Atrous(p)));
    }
    for (n, p) in GuidedParams::presets() {
        v.push((format!("guided {n}"), Filter::Guided(p)));
    }
    for (n, p) in BilateralParams::presets() {
        v.push((format!("bilateral {n}"), Filter::Bilateral(p)));
    }
    v
}

#[test]
fn every_preset_runs_and_keeps_a_constant_image_constant() {
    let mut rng = Rng::new(4);
    let (w, h) = (48, 40);
    let g = random_gbuffer(w, h, &mut rng, true);
    let color = Image::from_vec(w, h, 3, [0.25, 1.5, 7.0].repeat(w * h)).unwrap();
    for (name, f) in all_filters() {
        let out = f.apply(&color, &g).unwrap();
        assert_eq!((out.width(), out.height(), out.channels()), (w, h, 3));
        for (o, c) in out.data().iter().zip(color.data()) {
            assert!((o - c).abs() <= 1e-4 * c, "{name}: {o} vs {c}");
        }
        // The reusing variant gives the same result into a wrongly sized buffer.
        let mut reuse = Image::new(3, 3, 1);
        f.apply_into(&color, &g, &mut reuse).unwrap();
        assert_eq!(reuse, out, "{name}");
    }
}

/// Two surfaces meet at x = w/2 (different normal, position and depth); colour 1 on the left,
/// 0 on the right plus noise. Little colour may cross the edge.
#[test]
fn edges_in_the_guides_are_preserved() {
    let (w, h) = (64, 32);
    let mut rng = Rng::new(5);
    let (mut n, mut p, mut d, mut c) = (vec![], vec![], vec![], vec![]);
    for y in 0..h {
        for x in 0..w {
            let left = x < w / 2;
            n.extend_from_slice(if left { &[1.0, 0.0, 0.0] } else { &[0.0, 0.0, 1.0] });
            p.extend_from_slice(&[x as f32 * 0.002, y as f32 * 0.002, if left { 0.0 } else { 0.5 }]);
            d.push(if left { 0.3 } else { 0.8 });
            let base = if left { 1.0 } else { 0.0 };
            for _ in 0..3 {
                c.push(base + 0.2 * (rng.f32() - 0.5));
            }
        }
    }
    let g = GBuffer::new(Image::from_vec(w, h, 3, n).unwrap())
        .with_position(Image::from_vec(w, h, 3, p).unwrap())
        .with_depth(Image::from_vec(w, h, 1, d).unwrap())
        .with_scene_scale(1.0);
    let color = Image::from_vec(w, h, 3, c).unwrap();
    // Leak: mean over rows of the largest |out - side value| within 3 pixels of the edge.
    let leak = |out: &Image| -> f32 {
        let mut worst = 0.0f32;
        for y in 0..h {
            for x in w / 2 - 3..w / 2 + 3 {
                let want = if x < w / 2 { 1.0 } else { 0.0 };
                worst = worst.max((out.rgb(x, y).x - want).abs());
            }
        }
        worst
    };
    // The guided filter's regularisation lets a little through: a = var / (var + eps).
    let limits: Vec<(Filter, f32)> = vec![
        (Filter::Atrous(AtrousParams::paper()), 0.12),
        (Filter::Atrous(AtrousParams { sigma_color: None, ..AtrousParams::paper() }), 0.12),
        (Filter::Bilateral(BilateralParams::reference()), 0.12),
        (Filter::Guided(GuidedParams::paper()), 0.15),
        (Filter::Guided(GuidedParams::normal_only()), 0.2),
    ];
    for (f, limit) in limits {
        let out = f.apply(&color, &g).unwrap();
        let l = leak(&out);
        assert!(l < limit, "{f:?}: leak {l}");
    }
    // And the test can fail: the plain À-Trous transform does blur across.
    let pure = Filter::Atrous(AtrousParams::pure()).apply(&color, &g).unwrap();
    assert!(leak(&pure) > 0.3, "plain À-Trous should blur the edge, leak {}", leak(&pure));
}

/// Background (zero normal) and surface pixels never mix, in either direction.
#[test]
fn background_and_surface_never_mix() {
    let (w, h) = (40, 30);
    let mut rng = Rng::new(6);
    let mut g = random_gbuffer(w, h, &mut rng, false);
    let mut color = Image::new(w, h, 3);
    let nd = g.normal.data_mut();
    for y in 0..h {
        for x in 0..w {
            let bg = (x as i32 - 20).pow(2) + (y as i32 - 15).pow(2) < 64;
            if bg {
                nd[(y * w + x) * 3..(y * w + x) * 3 + 3].fill(0.0);
            }
            color.set_rgb(x, y, if bg { Vec3::splat(5.0) } else { Vec3::splat(1.0) });
        }
    }
    for (name, f) in all_filters() {
        let out = f.apply(&color, &g).unwrap();
        for (o, c) in out.data().iter().zip(color.data()) {
            assert!((o - c).abs() < 1e-4 * c, "{name}: {o} vs {c}");
        }
    }
}

/// Non-finite colour values are counted out: they neither spread nor bias their neighbours,
/// and their own pixel gets a finite value from the neighbours.
#[test]
fn nan_and_inf_do_not_spread() {
    let (w, h) = (50, 40);
    let mut rng = Rng::new(7);
    let g = random_gbuffer(w, h, &mut rng, true);
    let mut color = Image::filled(w, h, 3, 0.5);
    for &(x, y, v) in
        &[(3, 3, f32::NAN), (25, 20, f32::INFINITY), (26, 20, f32::NEG_INFINITY), (49, 39, f32::NAN)]
    {
        color.pixel_mut(x, y)[1] = v;
    }
    for (name, f) in all_filters() {
        let out = f.apply(&color, &g).unwrap();
        assert_eq!(out.count_non_finite(), 0, "{name}");
        for (i, o) in out.data().iter().enumerate() {
            // Surface pixels rebuild invalid values from neighbours; the guided filter
            // passes background through with non-finite values set to 0.
            let px = i / 3;
            let bad_bg = !color.data()[px * 3..px * 3 + 3].iter().all(|v| v.is_finite()) && !surface(&g, px);
            if !bad_bg {
                assert!((o - 0.5).abs() < 1e-4, "{name}: pixel {px} = {o}");
            }
        }
    }
}

/// Mean preservation: every output is a normalised average, so each input's total weight
/// sums to the pixel count; for i.i.d. noise the output mean equals the input mean up to a
/// few noise standard deviations of the mean.
#[test]
fn energy_mean_is_preserved_on_noise() {
    let (w, h) = (128, 96);
    let mut rng = Rng::new(8);
    let g = random_gbuffer(w, h, &mut rng, false);
    let color = random_color(w, h, &mut rng); // uniform [0, 2]: sigma = 0.577
    let mean_in = color.mean();
    let sigma_mean = 0.577 / ((w * h) as f64).sqrt();
    for (name, f) in all_filters() {
        let out = f.apply(&color, &g).unwrap();
        let mean_out = out.mean();
        for c in 0..3 {
            let dev = (mean_out[c] - mean_in[c]).abs();
            assert!(
                dev < 6.0 * sigma_mean * 3.0,
                "{name}: mean {} vs {} ({} sigma)",
                mean_out[c],
                mean_in[c],
                dev / sigma_mean
            );
        }
    }
}

/// A firefly in a flat interior region keeps its energy (the kernels are symmetric there).
#[test]
fn interior_firefly_energy_is_preserved_by_linear_filters() {
    let (w, h) = (160, 160);
    let normal = Image::from_vec(w, h, 3, [0.0, 1.0, 0.0].repeat(w * h)).unwrap();
    let pos: Vec<f32> =
        (0..w * h).flat_map(|i| [(i % w) as f32 * 1e-4, (i / w) as f32 * 1e-4, 0.0]).collect();
    let depth = Image::filled(w, h, 1, 0.5);
    let g = GBuffer::new(normal)
        .with_position(Image::from_vec(w, h, 3, pos).unwrap())
        .with_depth(depth)
        .with_scene_scale(1.0);
    let mut color = Image::new(w, h, 3);
    color.set_rgb(80, 80, Vec3::splat(1000.0));
    for f in [
        Filter::Atrous(AtrousParams::pure()),
        Filter::Atrous(AtrousParams { sigma_color: None, ..AtrousParams::paper() }),
        Filter::Guided(GuidedParams::paper()),
        Filter::Bilateral(BilateralParams::reference_wide()),
    ] {
        let out = f.apply(&color, &g).unwrap();
        let total: f64 = out.data().iter().map(|v| *v as f64).sum::<f64>() / 3.0;
        assert!((total - 1000.0).abs() < 1.0, "{f:?}: total {total}");
    }
}

#[test]
fn bad_input_gives_clear_errors() {
    let mut rng = Rng::new(9);
    let g = random_gbuffer(8, 8, &mut rng, false);
    let c = random_color(8, 8, &mut rng);
    let small = random_color(8, 7, &mut rng);
    let f = Filter::Atrous(AtrousParams::paper());
    assert!(matches!(f.apply(&small, &g), Err(DenoiseError::SizeMismatch { buffer: "normal", .. })));
    assert!(matches!(
        f.apply(&Image::new(8, 8, 4), &g),
        Err(DenoiseError::ChannelCount { buffer: "colour", .. })
    ));
    let no_pos = GBuffer::new(g.normal.clone());
    assert!(matches!(f.apply(&c, &no_pos), Err(DenoiseError::MissingGuide { .. })));
    assert!(matches!(
        Filter::Guided(GuidedParams::paper()).apply(&c, &no_pos),
        Err(DenoiseError::MissingGuide { buffer: "depth", .. })
    ));
    let bad = [
        Filter::Atrous(AtrousParams { iterations: 0, ..AtrousParams::paper() }),
        Filter::Atrous(AtrousParams { iterations: 11, ..AtrousParams::paper() }),
        Filter::Atrous(AtrousParams { sigma_normal: Some(f32::NAN), ..AtrousParams::paper() }),
        Filter::Guided(GuidedParams { eps_depth: 0.0, ..GuidedParams::paper() }),
        Filter::Guided(GuidedParams { radius: 0, ..GuidedParams::paper() }),
        Filter::Bilateral(BilateralParams { radius: 65, ..BilateralParams::reference() }),
        Filter::Bilateral(BilateralParams { sigma_spatial: -1.0, ..BilateralParams::reference() }),
    ];
    for f in bad {
        let e = f.apply(&c, &g).unwrap_err();
        assert!(matches!(e, DenoiseError::InvalidParameter { .. }), "{f:?}: {e}");
        assert!(!e.to_string().is_empty());
    }
    let mut g2 = g.clone();
    g2.depth = Some(Image::new(8, 8, 3));
    assert!(matches!(
        Filter::Guided(GuidedParams::paper()).apply(&c, &g2),
        Err(DenoiseError::ChannelCount { buffer: "depth", .. })
    ));
    // Empty images are fine.
    let e = GBuffer::new(Image::new(0, 0, 3));
    for (_, f) in all_filters() {
        let out = f.apply(
            &Image::new(0, 0, 3),
            &e.clone().with_position(Image::new(0, 0, 3)).with_depth(Image::new(0, 0, 1)),
        );
        assert_eq!(out.unwrap().pixel_count(), 0);
    }
}

/// Demodulation round-trips, and filtering illumination keeps an albedo texture sharp.
#[test]
fn demodulation_keeps_texture_sharp() {
    let (w, h) = (32, 32);
    let mut rng = Rng::new(10);
    let g = random_gbuffer(w, h, &mut rng, false);
    let mut albedo = Image::new(w, h, 3);
    let mut color = Image::new(w, h, 3);
    for y in 0..h {
        for x in 0..w {
            let a = if (x / 2 + y / 2) % 2 == 0 { 0.8 } else { 0.1 }; // checker
            albedo.set_rgb(x, y, Vec3::splat(a));
            color.set_rgb(x, y, Vec3::splat(a * 2.0)); // constant illumination 2
        }
    }
    let round = remodulate(&demodulate(&color, &albedo, 0.01).unwrap(), &albedo, 0.01).unwrap();
    assert_eq!(round, color);
    let g = g.with_albedo(albedo.clone());
    for (name, f) in all_filters() {
        let out = f.apply_demodulated(&color, &g, DEFAULT_ALBEDO_EPS).unwrap();
        for (o, c) in out.data().iter().zip(color.data()) {
            assert!((o - c).abs() < 1e-4, "{name}: {o} vs {c}");
        }
        // Without demodulation the checkerboard is blurred.
        let blurred = f.apply(&color, &g).unwrap();
        let err: f32 = blurred.data().iter().zip(color.data()).map(|(o, c)| (o - c).abs()).sum();
        assert!(err > 1.0, "{name}: filtering the colour directly should blur the texture");
    }
    assert!(demodulate(&color, &Image::new(3, 3, 3), 0.01).is_err());
    assert!(demodulate(&color, &albedo, 0.0).is_err());
}

/// Weight sums that underflow (every neighbour extremely far in colour) must not turn into
/// `0 * inf = NaN`: the pixel keeps its own value instead.
#[test]
fn underflowing_weight_sums_stay_finite() {
    let (w, h) = (9, 9);
    let normal = Image::from_vec(w, h, 3, [0.0, 0.0, 1.0].repeat(w * h)).unwrap();
    let g = GBuffer::new(normal);
    // Every colour invalid but one far-off corner: a pixel two steps away sees only that
    // corner, through the B3 kernel's smallest weight (1/256) times exp(-87).
    let mut color = Image::filled(w, h, 3, f32::NAN);
    color.set_rgb(0, 0, Vec3::splat(1e4));
    let p = AtrousParams { iterations: 3, sigma_color: Some(1e-3), sigma_normal: None, sigma_position: None };
    let out = atrous(&color, &g, &p).unwrap();
    assert_eq!(out.count_non_finite(), 0);
    let b = BilateralParams {
        radius: 3,
        sigma_spatial: 2.0,
        sigma_color: Some(1e-3),
        sigma_normal: None,
        sigma_position: None,
    };
    assert_eq!(bilateral(&color, &g, &b).unwrap().count_non_finite(), 0);
}

/// Cycles' AOVs: depth `1e10` where rays escape, also on edge pixels whose normal is set.
/// Those pixels are background, the depth scale comes from the surfaces (not 1e10), and the
/// guided filter's output stays finite and inside the input's range, with the scale
/// estimated and with Blender's explicit scene scale (docs/reliability.md: the values the
/// unbounded filter gave).
#[test]
fn cycles_escaped_ray_depth_is_background_and_outputs_stay_in_range() {
    // A sphere (with its ring of edge pixels) above a floor that starts a window's height
    // below it: the floor's windows see the running sums after the ring's huge depths.
    let (w, h) = (96, 128);
    let mut rng = Rng::new(17);
    let (mut n, mut d, mut c) = (Vec::new(), Vec::new(), Vec::new());
    for y in 0..h {
        for x in 0..w {
            let r2 = (x as i32 - 30).pow(2) + (y as i32 - 24).pow(2);
            let inside = r2 < 400 || y >= 80;
            let edge = !inside && r2 < 480;
            let normal = if inside || edge { [0.3, 0.2, 0.93] } else { [0.0; 3] };
            n.extend_from_slice(&normal);
            d.push(if inside { 10.0 + 0.1 * x as f32 + rng.f32() } else { 1e10 });
            // Edge pixels mix surface and sky: noisy like the surface.
            let v = if inside || edge { 2.0 * rng.f32() } else { 0.6 };
            c.extend_from_slice(&[v, 0.5 * v, 0.6]);
        }
    }
    let color = Image::from_vec(w, h, 3, c).unwrap();
    let g =
        GBuffer::new(Image::from_vec(w, h, 3, n).unwrap()).with_depth(Image::from_vec(w, h, 1, d).unwrap());
    let scale = crate::gbuffer::depth_scale(&g, g.depth.as_ref().unwrap());
    assert!((10.0..25.0).contains(&scale), "depth scale {scale} comes from surfaces only");
    for scene_scale in [None, Some(16.75)] {
        let g = GBuffer { scene_scale, ..g.clone() };
        for (name, f) in all_filters() {
            let Ok(out) = f.apply(&color, &g) else { continue }; // (presets needing a position)
            for (i, (o, c)) in out.data().iter().zip(color.data()).enumerate() {
                assert!(o.is_finite() && (0.0..=2.0).contains(o), "{name} {scene_scale:?}: value {i} = {o}");
                // The guided filter passes background (edge pixels included) through.
                if name.starts_with("guided") && !crate::gbuffer::surface_at(&g, i / 3) {
                    assert_eq!(o, c, "{name} {scene_scale:?}: background {i}");
                }
            }
        }
    }
}

/// The per-channel `[lo, hi]` of the valid input colours, widened to 0 when some value is
/// invalid (a pixel without any valid neighbour in reach is 0: no data).
fn valid_range(color: &Image) -> [[f32; 2]; 3] {
    let mut r = [[f32::INFINITY, f32::NEG_INFINITY]; 3];
    let mut invalid = false;
    for px in color.data().chunks_exact(3) {
        if px.iter().all(|v| crate::gbuffer::is_valid_color(*v)) {
            for c in 0..3 {
                r[c] = [r[c][0].min(px[c]), r[c][1].max(px[c])];
            }
        } else {
            invalid = true;
        }
    }
    r.map(|[lo, hi]| if invalid || lo > hi { [lo.min(0.0), hi.max(0.0)] } else { [lo, hi] })
}

mod bounded {
    use super::*;
    use proptest::prelude::*;

    const SPECIALS: [f32; 7] = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 3e38, -3e38, 1e10, 1e-30];

    proptest! {
        #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

        /// Every filter (every preset, with and without a scene scale), on random inputs
        /// whose colours and guides hold NaN, infinities, `3e38` and Cycles' `1e10`: the
        /// output is finite and inside the range of the valid input colours (up to the
        /// weights' rounding).
        #[test]
        fn every_filter_output_is_finite_and_within_the_input_range(
            w in 1usize..14, h in 1usize..11, seed in any::<u64>(),
            specials in prop::collection::vec((0usize..1000, 0usize..4, 0usize..7), 0..12),
            scale in prop::option::of(prop::sample::select(vec![1e-3f32, 1.0, 16.75, 1e8])),
        ) {
            let mut rng = super::Rng::new(seed);
            let mut g = random_gbuffer(w, h, &mut rng, true);
            g.scene_scale = scale;
            let mut color = Image::from_vec(w, h, 3, (0..w * h * 3).map(|_| 4.0 * rng.f32() - 1.0).collect()).unwrap();
            for (at, buffer, kind) in specials {
                let v = SPECIALS[kind];
                let im = match buffer {
                    0 => &mut color,
                    1 => &mut g.normal,
                    2 => g.position.as_mut().unwrap(),
                    _ => g.depth.as_mut().unwrap(),
                };
                let k = at % im.data().len();
                im.data_mut()[k] = v;
            }
            let range = valid_range(&color);
            for (name, f) in all_filters() {
                let out = f.apply(&color, &g).unwrap();
                for (i, o) in out.data().iter().enumerate() {
                    let [lo, hi] = range[i % 3];
                    let tol = 1e-5 * lo.abs().max(hi.abs());
                    prop_assert!(o.is_finite() && *o >= lo - tol && *o <= hi + tol,
                        "{}: value {} = {} outside [{}, {}]", name, i, o, lo, hi);
                }
            }
        }
    }
}
