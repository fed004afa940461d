//! Tests of the filters against direct naive implementations, and of their documented
//! behaviour (constants, edges, background, NaN, energy, presets, errors).

use crate::pool::Buf;
use crate::*;

/// A small deterministic generator (PCG-like LCG) so tests need no extra crate.
pub(crate) struct Rng(u64);
impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    pub fn f32(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((self.0 >> 40) as f32) / (1u64 << 24) as f32
    }
}

/// A random scene-like G-buffer: 4x4 blocks of random unit normals, a few background pixels,
/// positions and depth that jump between blocks; scene scale 1.
fn random_gbuffer(w: usize, h: usize, rng: &mut Rng, background: bool) -> GBuffer {
    let (mut n, mut p, mut d) = (Vec::new(), Vec::new(), Vec::new());
    let bw = w.div_ceil(4);
    let blocks: Vec<([f32; 3], f32)> = (0..bw * h.div_ceil(4))
        .map(|_| {
            let v = [rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() + 0.1];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            ([v[0] / l, v[1] / l, v[2] / l], rng.f32() * 0.5)
        })
        .collect();
    for y in 0..h {
        for x in 0..w {
            let (nn, off) = blocks[(y / 4) * bw + x / 4];
            let bg = background && rng.f32() < 0.08;
            n.extend_from_slice(if bg { &[0.0; 3] } else { &nn });
            let px = [x as f32 * 0.01, y as f32 * 0.01, off];
            p.extend_from_slice(&px);
            d.push(0.2 + off + 0.3 * rng.f32() * 0.01);
        }
    }
    GBuffer::new(Image::from_vec(w, h, 3, n).unwrap())
        .with_position(Image::from_vec(w, h, 3, p).unwrap())
        .with_depth(Image::from_vec(w, h, 1, d).unwrap())
        .with_scene_scale(1.0)
}

fn random_color(w: usize, h: usize, rng: &mut Rng) -> Image {
    Image::from_vec(w, h, 3, (0..w * h * 3).map(|_| 2.0 * rng.f32()).collect()).unwrap()
}

fn surface(g: &GBuffer, i: usize) -> bool {
    let n = &g.normal.data()[i * 3..i * 3 + 3];
    n.iter().any(|v| *v != 0.0)
}

fn dist2(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum()
}

/// Direct edge-avoiding sum over a list of taps, in f64 with `exp`.
fn naive_pass(
    c: &[f64],
    g: &GBuffer,
    taps: &[(isize, isize, f64)],
    inv: (Option<f64>, Option<f64>, Option<f64>),
) -> Vec<f64> {
    let (w, h) = (g.normal.width(), g.normal.height());
    let nd = g.normal.data();
    let pd = g.position.as_ref().unwrap().data();
    let mut out = vec![0.0; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let (mut s, mut k) = ([0.0f64; 3], 0.0f64);
            for &(dx, dy, hq) in taps {
                let (qx, qy) = (x as isize + dx, y as isize + dy);
                if qx < 0 || qy < 0 || qx >= w as isize || qy >= h as isize {
                    continue;
                }
                let j = qy as usize * w + qx as usize;
                if surface(g, i) != surface(g, j) {
                    continue;
                }
                let mut e = 0.0;
                if let Some(ic) = inv.0 {
                    e += (0..3).map(|ch| (c[i * 3 + ch] - c[j * 3 + ch]).powi(2)).sum::<f64>() * ic;
                }
                if let Some(inn) = inv.1 {
                    e += dist2(&nd[i * 3..i * 3 + 3], &nd[j * 3..j * 3 + 3]) * inn;
                }
                if let Some(ix) = inv.2 {
                    e += dist2(&pd[i * 3..i * 3 + 3], &pd[j * 3..j * 3 + 3]) * ix;
                }
                let wq = hq * (-e).exp();
                for ch in 0..3 {
                    s[ch] += wq * c[j * 3 + ch];
                }
                k += wq;
            }
            for ch in 0..3 {
                out[i * 3 + ch] = s[ch] / k;
            }
        }
    }
    out
}

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

fn assert_close(got: &Image, want: &[f64], tol: f64, what: &str) {
    assert_eq!(got.data().len(), want.len());
    let mut worst = (0.0, 0);
    for (i, (g, w)) in got.data().iter().zip(want).enumerate() {
        let err = (*g as f64 - w).abs() / (1.0 + w.abs());
        if err > worst.0 || err.is_nan() {
            worst = (err, i);
        }
    }
    assert!(worst.0 <= tol, "{what}: worst error {} at value {} (want {})", worst.0, worst.1, want[worst.1]);
}

/// Runs `f` once per build of the hot loops this CPU runs (AVX-512, AVX2, baseline), the
/// build forced by [`crate::simd::with_isa`]; `f` gets the build's name for its messages.
fn for_every_build(f: impl Fn(&str)) {
    let builds = crate::simd::Isa::supported();
    assert!(builds.contains(&crate::simd::Isa::Base));
    for isa in builds {
        crate::simd::with_isa(isa, || {
            assert_eq!(crate::simd::isa(), isa, "the forced build is the one that runs");
            f(&format!("{isa:?}"))
        });
    }
}

#[test]
fn with_isa_narrows_and_restores_the_build() {
    use crate::simd::{cpu_isa, isa, with_isa, Isa};
    assert_eq!(isa(), cpu_isa());
    with_isa(Isa::Base, || {
        assert_eq!(isa(), Isa::Base);
        // A wider cap never widens past what was forced, nor past the CPU.
        with_isa(Isa::Avx512, || assert_eq!(isa(), cpu_isa()));
        assert_eq!(isa(), Isa::Base);
    });
    assert_eq!(isa(), cpu_isa());
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

/// The guided filter's bands and lane strips follow the image size and radius only: the
/// result is bit-identical on 1, 2, 3 and 7 threads (several bands: 300 rows at r = 5), with
/// the box passes fused or not, and the baseline build computes the same bits as the AVX2 /
/// AVX-512 ones (no fused multiply-adds in the guided filter).
#[test]
fn guided_is_identical_for_any_thread_count_and_build() {
    let mut rng = Rng::new(13);
    let (w, h) = (157, 300);
    let g = random_gbuffer(w, h, &mut rng, true);
    let mut color = random_color(w, h, &mut rng);
    color.pixel_mut(40, 150)[0] = f32::NAN;
    for p in [
        GuidedParams { radius: 5, ..GuidedParams::paper() },
        GuidedParams::grey(),
        GuidedParams::normal_only(),
    ] {
        let run = |threads: usize, isa: crate::simd::Isa| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| crate::guided::guided_with_isa(&color, &g, &p, isa).unwrap())
        };
        let one = run(1, crate::simd::isa());
        assert_eq!(one.count_non_finite(), 0);
        for threads in [2, 3, 7] {
            assert!(
                one.data() == run(threads, crate::simd::isa()).data(),
                "{p:?}: {threads} threads differ from 1"
            );
        }
        assert!(one.data() == run(2, crate::simd::Isa::Base).data(), "{p:?}: baseline build differs");
        // The fused box passes (crate::fused) in 1-4 walks, and the two passes over the
        // whole coefficient plane, whatever the thread count picks.
        use crate::guided::{guided_with_plan, Plan};
        for plan in [
            Plan::TwoPasses,
            Plan::FusedAuto,
            Plan::Fused { runs: 1 },
            Plan::Fused { runs: 2 },
            Plan::Fused { runs: 4 },
        ] {
            for (threads, isa) in [(1, crate::simd::isa()), (3, crate::simd::Isa::Base)] {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                let got = pool.install(|| guided_with_plan(&color, &g, &p, isa, plan).unwrap());
                assert!(one.data() == got.data(), "{p:?}: {plan:?} on {threads} threads {isa:?} differs");
            }
        }
    }
}

/// The conversion that skips the validity plane gives the same planes, and the validity
/// plane exactly when some colour is not finite.
#[test]
fn to_planes_valid_matches_to_planes_strided() {
    use crate::gbuffer::{to_planes_strided, to_planes_valid};
    let mut rng = Rng::new(14);
    let (w, h, stride) = (37, 29, 48);
    let mut color = random_color(w, h, &mut rng);
    for bad in [None, Some(f32::NAN), Some(f32::NEG_INFINITY)] {
        if let Some(v) = bad {
            color.pixel_mut(36, 28)[2] = v;
        }
        let (p, valid) = to_planes_valid(&color, stride);
        let (q, want) = to_planes_strided(&color, stride);
        for c in 0..3 {
            assert!(p[c][..] == q[c][..], "{bad:?}: plane {c}");
        }
        assert_eq!(valid.is_some(), bad.is_some());
        if let Some(v) = valid {
            assert!(v[..] == want[..]);
        }
    }
}

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

/// Solves `A x = b` (n x n, row-major) by Gaussian elimination with partial pivoting.
fn solve(mut a: Vec<f64>, mut b: Vec<f64>, n: usize) -> Vec<f64> {
    for col in 0..n {
        let piv = (col..n).max_by(|&i, &j| a[i * n + col].abs().total_cmp(&a[j * n + col].abs())).unwrap();
        for k in 0..n {
            a.swap(col * n + k, piv * n + k);
        }
        b.swap(col, piv);
        for row in col + 1..n {
            let f = a[row * n + col] / a[col * n + col];
            for k in col..n {
                a[row * n + k] -= f * a[col * n + k];
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = vec![0.0; n];
    for row in (0..n).rev() {
        let s: f64 = (row + 1..n).map(|k| a[row * n + k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row * n + row];
    }
    x
}

/// The guided filter by a least-squares solve per window: minimise
/// `sum_i (a . I_i + b - p_i)^2 + n sum_c eps_c a_c^2` over the window's surface pixels
/// (He et al. 2010 eq. 3 with per-channel eps), then average `a, b` over covering windows.
fn naive_guided(color: &Image, g: &GBuffer, p: &GuidedParams) -> Vec<f64> {
    let (w, h) = (color.width(), color.height());
    let r = p.radius as isize;
    let nd = g.normal.data();
    let guide = |i: usize| -> Vec<f64> {
        let n: Vec<f64> = (0..3).map(|c| 0.5 * nd[i * 3 + c] as f64 + 0.5).collect();
        match p.guidance {
            Guidance::GreyNormal => vec![(n[0] + n[1] + n[2]) / 3.0],
            Guidance::Normal => n,
            Guidance::NormalDepth => {
                vec![
                    n[0],
                    n[1],
                    n[2],
                    g.depth.as_ref().unwrap().data()[i] as f64 / g.scene_scale.unwrap() as f64,
                ]
            }
        }
    };
    let eps: Vec<f64> = match p.guidance {
        Guidance::GreyNormal => vec![p.eps_normal as f64],
        Guidance::Normal => vec![p.eps_normal as f64; 3],
        Guidance::NormalDepth => {
            vec![p.eps_normal as f64, p.eps_normal as f64, p.eps_normal as f64, p.eps_depth as f64]
        }
    };
    let d = eps.len();
    let mut acc = vec![0.0f64; w * h * (3 * d + 3)];
    let mut cnt = vec![0.0f64; w * h];
    for ky in 0..h as isize {
        for kx in 0..w as isize {
            let win: Vec<usize> = (ky - r..=ky + r)
                .flat_map(|y| (kx - r..=kx + r).map(move |x| (x, y)))
                .filter(|&(x, y)| x >= 0 && y >= 0 && x < w as isize && y < h as isize)
                .map(|(x, y)| y as usize * w + x as usize)
                .collect();
            let fit: Vec<usize> = win.iter().copied().filter(|&i| surface(g, i)).collect();
            if fit.is_empty() {
                continue;
            }
            let n = fit.len() as f64;
            let m = d + 1;
            let mut ata = vec![0.0; m * m];
            for &i in &fit {
                let mut row = guide(i);
                row.push(1.0);
                for a in 0..m {
                    for b in 0..m {
                        ata[a * m + b] += row[a] * row[b];
                    }
                }
            }
            for a in 0..d {
                ata[a * m + a] += n * eps[a];
            }
            for c in 0..3 {
                let mut atb = vec![0.0; m];
                for &i in &fit {
                    let mut row = guide(i);
                    row.push(1.0);
                    for a in 0..m {
                        atb[a] += row[a] * color.data()[i * 3 + c] as f64;
                    }
                }
                let theta = solve(ata.clone(), atb, m);
                for &i in &win {
                    for a in 0..d {
                        acc[i * (3 * d + 3) + a * 3 + c] += theta[a];
                    }
                    acc[i * (3 * d + 3) + 3 * d + c] += theta[d];
                }
            }
            for &i in &win {
                cnt[i] += 1.0;
            }
        }
    }
    // Clamped to the fit pixels' range (guided.rs, "Bounded output").
    let fit_px: Vec<usize> = (0..w * h).filter(|&i| surface(g, i)).collect();
    let lo = |c: usize| fit_px.iter().map(|&i| color.data()[i * 3 + c] as f64).fold(f64::INFINITY, f64::min);
    let hi =
        |c: usize| fit_px.iter().map(|&i| color.data()[i * 3 + c] as f64).fold(f64::NEG_INFINITY, f64::max);
    let mut out = vec![0.0; w * h * 3];
    for i in 0..w * h {
        for c in 0..3 {
            out[i * 3 + c] = if surface(g, i) && cnt[i] > 0.0 {
                let gi = guide(i);
                let s = &acc[i * (3 * d + 3)..];
                let q = ((0..d).map(|a| s[a * 3 + c] * gi[a]).sum::<f64>() + s[3 * d + c]) / cnt[i];
                q.clamp(lo(c), hi(c))
            } else {
                color.data()[i * 3 + c] as f64
            };
        }
    }
    out
}

#[test]
fn guided_matches_per_window_least_squares() {
    for_every_build(guided_matches_per_window_least_squares_on);
}

fn guided_matches_per_window_least_squares_on(build: &str) {
    let mut rng = Rng::new(3);
    let (w, h) = (26, 21);
    let g = random_gbuffer(w, h, &mut rng, true);
    let color = random_color(w, h, &mut rng);
    for guidance in [Guidance::GreyNormal, Guidance::Normal, Guidance::NormalDepth] {
        for (radius, eps_normal, eps_depth) in
            [(1, 0.01, 0.02), (3, 0.01, 0.03), (5, 0.05, 0.01), (40, 0.01, 0.01)]
        {
            let p = GuidedParams { radius, guidance, eps_normal, eps_depth };
            let fast = guided(&color, &g, &p).unwrap();
            let naive = naive_guided(&color, &g, &p);
            assert_close(&fast, &naive, 2e-3, &format!("{build}: {p:?}"));
        }
    }
}

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
use filtrace_core::Vec3;

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
/// estimated and with Blender's explicit scene scale (before the fix: 1.4e10 here, -1e6 on
/// the Cycles frame).
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
