//! The guided filter against a per-window least-squares solve, and its determinism.

use super::*;

/// The guided filter's bands and lane strips follow the image size and radius only: the
/// result is bit-identical on 1, 2, 3 and 7 threads (several bands: 300 rows at r = 5), and
/// the baseline build computes the same bits as the AVX2 / AVX-512 ones (no fused
/// multiply-adds in the guided filter).
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
    // Clamped to the fit pixels' range (the guided module docs, "Bounded output").
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
