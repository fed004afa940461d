//! The À-Trous filter (and its shared-weight levels) against the paper's direct sums.

use super::*;

/// The À-Trous filter written directly from the paper (eqs. 2-5, shader's normal scaling).
fn naive_atrous(color: &Image, g: &GBuffer, p: &AtrousParams) -> Vec<f64> {
    let b3 = [1.0 / 16.0, 0.25, 3.0 / 8.0, 0.25, 1.0 / 16.0];
    let mut c: Vec<f64> = color.data().iter().map(|v| *v as f64).collect();
    for i in 0..p.iterations {
        let step = (1 << i) as isize;
        let mut taps = Vec::new();
        for ky in 0..5 {
            for kx in 0..5 {
                taps.push(((kx - 2) * step, (ky - 2) * step, b3[kx as usize] * b3[ky as usize]));
            }
        }
        let s = step as f64;
        let inv = (
            p.sigma_color.map(|sr| 1.0 / (sr as f64 / s).powi(2)),
            p.sigma_normal.map(|sn| 1.0 / ((sn as f64).powi(2) * s * s)),
            p.sigma_position.map(|sx| 1.0 / (sx as f64).powi(2)),
        );
        c = naive_pass(&c, g, &taps, inv);
    }
    c
}

#[test]
fn atrous_matches_naive() {
    for_every_build(atrous_matches_naive_on);
}

fn atrous_matches_naive_on(build: &str) {
    let mut rng = Rng::new(1);
    let (w, h) = (37, 29);
    let g = random_gbuffer(w, h, &mut rng, true);
    let color = random_color(w, h, &mut rng);
    let mut cases: Vec<(String, AtrousParams)> =
        AtrousParams::presets().iter().map(|(n, p)| (n.to_string(), *p)).collect();
    cases.push(("position only, 3 levels".into(), AtrousParams { iterations: 3, ..AtrousParams::pure() }));
    cases.push((
        "normal+position".into(),
        AtrousParams { sigma_color: None, sigma_position: Some(0.1), ..AtrousParams::paper() },
    ));
    cases.push((
        "1 level, colour".into(),
        AtrousParams { iterations: 1, sigma_color: Some(0.5), ..AtrousParams::paper() },
    ));
    for (name, p) in cases {
        let fast = atrous(&color, &g, &p).unwrap();
        let naive = naive_atrous(&color, &g, &p);
        assert_close(&fast, &naive, 2e-4, &format!("{build}: {name}"));
    }
}

/// The shared-weight level ([`crate::symmetric`]) against the direct 25-tap sum, level by
/// level, on sizes around the block width and the border widths, with background pixels,
/// invalid colours and every weight subset. Only the summation order differs.
#[test]
fn symmetric_level_matches_direct_pass() {
    for_every_build(symmetric_level_matches_direct_pass_on);
}

fn symmetric_level_matches_direct_pass_on(build: &str) {
    use crate::atrous::{atrous_step, atrous_step_direct};
    use crate::gbuffer::{to_planes, Guides};
    let mut rng = Rng::new(11);
    let mut cases: Vec<AtrousParams> = AtrousParams::presets().iter().map(|(_, p)| *p).collect();
    cases.push(AtrousParams { sigma_color: None, sigma_normal: None, ..AtrousParams::paper() });
    cases.push(AtrousParams { sigma_color: None, sigma_position: Some(0.1), ..AtrousParams::paper() });
    for (w, h) in [(1, 1), (3, 2), (5, 9), (21, 4), (37, 29), (70, 41), (131, 67)] {
        let g = random_gbuffer(w, h, &mut rng, true);
        let mut color = random_color(w, h, &mut rng);
        if w * h > 50 {
            color.data_mut()[3 * (w * h / 3) + 1] = f32::NAN;
            color.data_mut()[3 * (w * h / 2)] = f32::INFINITY;
        }
        let guides = Guides::new(&g, w, h).unwrap();
        let (src, valid) = to_planes(&color);
        let v = if valid.contains(&0.0) { Some(&valid[..]) } else { None };
        for p in &cases {
            for i in 0..5 {
                let n = w * h;
                let mut fast = [Buf::zeros(n), Buf::zeros(n), Buf::zeros(n)];
                let mut direct = [Buf::zeros(n), Buf::zeros(n), Buf::zeros(n)];
                atrous_step(&src, v, &guides, p, i, &mut fast);
                atrous_step_direct(&src, v, &guides, p, i, &mut direct);
                for c in 0..3 {
                    for (k, (a, b)) in fast[c].iter().zip(direct[c].iter()).enumerate() {
                        // A pixel with an invalid colour has no centre weight: at coarse
                        // levels its weights can all be ~1e-30, where the shared-weight pass
                        // flushes those below 2^-100 to 0 (`scaled_exp_neg`) and the direct
                        // one keeps them; only finiteness is compared there.
                        if valid[k] == 0.0 {
                            assert!(a.is_finite(), "{w}x{h} level {i}: pixel {k} is {a}");
                            continue;
                        }
                        assert!(
                            (a - b).abs() <= 2e-6 * (1.0 + b.abs()),
                            "{build}: {w}x{h} level {i} {p:?}: pixel {k} channel {c}: {a} vs {b}"
                        );
                    }
                }
            }
        }
    }
}

/// The band split depends on the thread count; the result must not (bit-identical).
#[test]
fn atrous_is_identical_for_any_thread_count() {
    let mut rng = Rng::new(12);
    let (w, h) = (83, 140);
    let g = random_gbuffer(w, h, &mut rng, true);
    let color = random_color(w, h, &mut rng);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| atrous(&color, &g, &AtrousParams::paper()).unwrap())
    };
    let one = run(1);
    for threads in [2, 3, 7] {
        assert!(one.data() == run(threads).data(), "{threads} threads differ from 1");
    }
}
