//! The built-in Cornell box against Mitsuba 3's 4096 spp rendering of the same scene
//! (`../shared/reference/cornell_mitsuba_4096spp.exr`, see its README): same light
//! transport and depth convention, so the images must agree up to noise.
//!
//! Fast tier: a 64 x 64 render against the reference box-downsampled by 8 (a box-filtered
//! 64 x 64 pixel is exactly the mean of the 8 x 8 box-filtered 512 x 512 pixels it covers).
//! Slow tier: the full 512 x 512, 256 spp comparison, per 8 x 8 block, with tolerances from
//! the render's variance and the reference's own noise (no fixed error bound).

mod common;

use common::*;
use filtrace_core::Image;
use filtrace_render::{RenderSettings, Renderer, TraceMode};
use filtrace_scene::builtin;

fn reference() -> Option<Image> {
    let path = shared("reference/cornell_mitsuba_4096spp.exr")?;
    let exr = filtrace_io::read_exr(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let img = exr.layer(&["color"]).expect("an RGB layer");
    assert_eq!((img.width(), img.height(), img.channels()), (512, 512, 3));
    Some(img)
}

fn downsample(img: &Image, f: usize) -> Image {
    let (w, h) = (img.width() / f, img.height() / f);
    let mut out = Image::new(w, h, 3);
    for y in 0..h {
        for x in 0..w {
            let mut s = filtrace_core::Vec3::ZERO;
            for yy in 0..f {
                for xx in 0..f {
                    s += img.rgb(x * f + xx, y * f + yy);
                }
            }
            out.set_rgb(x, y, s / (f * f) as f32);
        }
    }
    out
}

/// Mean over pixels and channels of (x - ref)^2 / (ref^2 + 0.01).
fn relative_mse(x: &Image, r: &Image) -> f64 {
    let n = x.data().len() as f64;
    x.data()
        .iter()
        .zip(r.data())
        .map(|(&a, &b)| ((a - b) as f64).powi(2) / ((b as f64).powi(2) + 0.01))
        .sum::<f64>()
        / n
}

fn render_cornell(size: u32, spp: u32) -> filtrace_render::Aovs {
    let settings = RenderSettings { width: size, height: size, spp, max_depth: 8, seed: 0 };
    // The lockstep tracer: its films equal the scalar tracer's bit for bit (tests/lockstep.rs),
    // so this checks both against Mitsuba.
    let r =
        Renderer::new(builtin("cornell").unwrap(), settings).unwrap().with_trace_mode(TraceMode::Lockstep);
    let film = render(&r);
    assert_eq!(film.dropped_samples(), 0);
    film.aovs()
}

#[test]
fn cornell_64px_matches_downsampled_mitsuba() {
    let Some(reference) = reference() else { return };
    let r = downsample(&reference, 8);
    let a = render_cornell(64, 64);
    // Mean colour within 1% (the README's mean is 0.241207 0.142099 0.060428).
    let (m, mr) = (a.color.mean(), r.mean());
    for c in 0..3 {
        assert!((m[c] / mr[c] - 1.0).abs() < 0.01, "channel {c}: mean {} vs {}", m[c], mr[c]);
    }
    // z-scores per pixel (their rms) and per 4 x 4 block (the worst): a single dark pixel
    // can hold a rare bright path (heavy tail) that a 64-sample variance misses, a block
    // cannot hide a bias. The reference's own noise is ~1/8 of ours per pixel.
    let mut sum_z2 = 0.0f64;
    let mut worst = 0.0f64;
    for by in (0..64).step_by(4) {
        for bx in (0..64).step_by(4) {
            for c in 0..3 {
                let (mut d_sum, mut v_sum, mut r_sum) = (0.0f64, 0.0f64, 0.0f64);
                for y in by..by + 4 {
                    for x in bx..bx + 4 {
                        let d = (a.color.pixel(x, y)[c] - r.pixel(x, y)[c]) as f64;
                        let v = a.variance.pixel(x, y)[c] as f64;
                        sum_z2 += d * d / (v + 1e-8);
                        d_sum += d;
                        v_sum += v;
                        r_sum += r.pixel(x, y)[c] as f64;
                    }
                }
                let z = d_sum / (v_sum.sqrt() + 2e-3 * r_sum + 1e-6);
                worst = worst.max(z.abs());
            }
        }
    }
    let rms_z = (sum_z2 / (64.0 * 64.0 * 3.0)).sqrt();
    println!(
        "64px vs reference: worst block |z| {worst:.2}, rms z {rms_z:.3}, rel MSE {:.2e}",
        relative_mse(&a.color, &r)
    );
    assert!(worst < 5.0, "worst block |z| = {worst}");
    assert!(rms_z < 1.2, "rms z = {rms_z} (a bias shows up as rms z > 1)");
}

/// The reference's own noise variance per pixel, estimated from the image: per 8 x 8 block,
/// the median of the squared residuals `r - mean(4 neighbours)` (variance `1.25 σ²` for
/// independent noise; the median of a χ²₁ variable is 0.455). A median ignores the few
/// pixels of a block on an edge, where the residual is signal, not noise.
fn reference_noise(r: &Image, block: usize) -> Image {
    let (w, h) = (r.width(), r.height());
    let mut out = Image::new(w, h, 3);
    for by in (0..h).step_by(block) {
        for bx in (0..w).step_by(block) {
            for c in 0..3 {
                let mut sq: Vec<f64> = Vec::new();
                for y in by.max(1)..(by + block).min(h - 1) {
                    for x in bx.max(1)..(bx + block).min(w - 1) {
                        let p = |x: usize, y: usize| r.pixel(x, y)[c] as f64;
                        let nb = 0.25 * (p(x - 1, y) + p(x + 1, y) + p(x, y - 1) + p(x, y + 1));
                        sq.push((p(x, y) - nb).powi(2));
                    }
                }
                sq.sort_by(f64::total_cmp);
                let var = sq.get(sq.len() / 2).copied().unwrap_or(0.0) / (1.25 * 0.455);
                for y in by..(by + block).min(h) {
                    for x in bx..(bx + block).min(w) {
                        out.pixel_mut(x, y)[c] = var as f32;
                    }
                }
            }
        }
    }
    out
}

/// |z| that a standard normal exceeds with probability `p` (two-sided): solves
/// `P(χ²₁ > z²) = p` by bisection.
fn normal_quantile_two_sided(p: f64) -> f64 {
    let (mut lo, mut hi) = (0.0f64, 40.0f64);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if filtrace_core::stats::chi2_sf(mid * mid, 1.0) > p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Per 8 x 8 block and channel, `z = Σ(a − r) / sqrt(Σ var_a + Σ var_r)` with `var_a` the
/// render's variance AOV and `var_r` the reference's estimated noise. Returns every z.
/// Also prints the worst blocks.
fn block_z_scores(a: &filtrace_render::Aovs, r: &Image, r_var: &Image, block: usize) -> Vec<f64> {
    let mut zs = Vec::new();
    for by in (0..a.height).step_by(block) {
        for bx in (0..a.width).step_by(block) {
            for c in 0..3 {
                let (mut d, mut v, mut r_sum) = (0.0f64, 0.0f64, 0.0f64);
                for y in by..(by + block).min(a.height) {
                    for x in bx..(bx + block).min(a.width) {
                        d += (a.color.pixel(x, y)[c] - r.pixel(x, y)[c]) as f64;
                        v += (a.variance.pixel(x, y)[c] + r_var.pixel(x, y)[c]) as f64;
                        r_sum += r.pixel(x, y)[c].abs() as f64;
                    }
                }
                // The light seen directly has no noise in either image: there only float
                // rounding (relative 1e-5 of the block) may differ.
                let rounding = 1e-5 * r_sum + 1e-9;
                zs.push(d / (v + rounding * rounding).sqrt());
            }
        }
    }
    let mut worst: Vec<(usize, f64)> = zs.iter().copied().enumerate().collect();
    worst.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
    for (i, z) in worst.iter().take(5) {
        let (b, c) = (i / 3, i % 3);
        let bw = a.width.div_ceil(block);
        println!("block ({}, {}) channel {c}: z = {z:.2}", (b % bw) * block, (b / bw) * block);
    }
    zs
}

/// The full-resolution comparison, with every tolerance from the variances: each 8 x 8 block
/// mean within the Šidák-corrected normal bound (family level 1e-3 over 3 x 4096 blocks),
/// the sum of the squared block z-scores a plausible χ² (p > 1e-4), and the image mean per
/// channel within 4.5 σ of its own standard error.
#[test]
#[ignore = "slow: 512x512 Cornell box at 256 spp against Mitsuba (~67 M samples)"]
fn cornell_512px_256spp_matches_mitsuba() {
    let Some(r) = reference() else { return };
    let a = render_cornell(512, 256);
    let r_var = reference_noise(&r, 8);
    let zs = block_z_scores(&a, &r, &r_var, 8);
    let n = zs.len();
    let z_max = zs.iter().fold(0.0f64, |m, z| m.max(z.abs()));
    let chi2: f64 = zs.iter().map(|z| z * z).sum();
    let p_chi2 = filtrace_core::stats::chi2_sf(chi2, n as f64);
    let bound = normal_quantile_two_sided(filtrace_core::stats::sidak(1e-3, n));
    let mean_var =
        |img: &Image, c: usize| img.data().iter().skip(c).step_by(3).map(|&v| v as f64).sum::<f64>();
    let npx = (a.width * a.height) as f64;
    println!(
        "512px 256spp: rel MSE {:.3e}; {n} block z-scores: max |z| {z_max:.2} (bound {bound:.2}), \
         chi2/n {:.4} (p = {p_chi2:.3e})",
        relative_mse(&a.color, &r),
        chi2 / n as f64
    );
    let (m, mr) = (a.color.mean(), r.mean());
    for c in 0..3 {
        let se = ((mean_var(&a.variance, c) + mean_var(&r_var, c)) / (npx * npx)).sqrt();
        let z = (m[c] - mr[c]) / se;
        println!("channel {c}: mean {} vs reference {} (z = {z:.2}, se {se:.2e})", m[c], mr[c]);
        assert!(z.abs() < 4.5, "channel {c}: image mean {} vs {}: z = {z:.2}", m[c], mr[c]);
    }
    assert!(z_max < bound, "a block differs: max |z| = {z_max:.2} > {bound:.2}");
    assert!(p_chi2 > 1e-4, "block z-scores too spread: chi2 = {chi2:.1} over {n} (p = {p_chi2:.2e})");
}
