//! The per-window ridge regression of the guided filter (Bauszat et al. 2011 eqs. 8-9):
//! `a_k = (Sigma_k + eps U)^-1 cov_k(I, p)` by Cholesky, 16 windows at a time.

use crate::stripbox::{vmul, vsub, S, V};

/// From the window sums `s` of 16 windows (one per lane), the ridge-regression coefficients
/// of each window, written as `[1, a (a*3+c), b (c)]`, or all zeros when the window holds no
/// fit pixel or is centred outside the image (`inside` 0). Every scalar of the solve is one
/// vector across the windows; branch-free, the divisions by the Cholesky diagonal done
/// once as reciprocals. Same operations per lane as [`solve_window`] (bit-identical, tested).
#[inline(always)]
pub(super) fn solve_lanes<const D: usize, const K1: usize>(
    s: &[V; K1],
    eps: &[f32; D],
    inside: &V,
    o: &mut [V],
) {
    let m = moments::<D, K1>(s, eps);
    // A window counts when it holds fit pixels, is centred inside and its mean is finite.
    let n = s[0];
    let ok: [bool; S] =
        std::array::from_fn(|l| n[l] >= 0.5 && inside[l] > 0.0 && (0..3).all(|c| m.mp[c][l].is_finite()));
    // `well`: every pivot at least eps / 2 (see the module docs) and finite coefficients,
    // else the box mean.
    let mut well = [true; S];
    let (lm, rl) = cholesky(&m.sig, eps, &mut well);
    let mut a_all = [[[0.0f32; S]; D]; 3];
    let mut b_all = [[0.0f32; S]; 3];
    for c in 0..3 {
        let (a, b) = regress_channel(&lm, &rl, &m, c);
        for l in 0..S {
            well[l] &= b[l].is_finite() && a.iter().all(|a| a[l].is_finite());
        }
        (a_all[c], b_all[c]) = (a, b);
    }
    write_coefficients(&a_all, &b_all, &m.mp, &ok, &well, o);
}

/// `c - a b` lane by lane (the same rounding as the scalar solve: no fused multiply-add).
#[inline(always)]
fn fms(c: V, a: V, b: V) -> V {
    vsub(c, vmul(a, b))
}

/// The window statistics the regression reads, per lane: the guide means, `Sigma_k + eps U`,
/// the colour means and `cov_k(I, p)`.
struct Moments<const D: usize> {
    mi: [V; D],
    sig: [[V; D]; D],
    mp: [V; 3],
    cov: [[V; 3]; D],
}

/// The [`Moments`] of 16 windows from their sums `s` (empty windows divide by 1).
#[inline(always)]
fn moments<const D: usize, const K1: usize>(s: &[V; K1], eps: &[f32; D]) -> Moments<D> {
    let kp = 1 + D + D * (D + 1) / 2; // index of m p
    let kc = kp + 3; // index of m I p
    let inv: V = s[0].map(|n| 1.0 / if n >= 0.5 { n } else { 1.0 });
    let mut mi = [[0.0f32; S]; D];
    for a in 0..D {
        mi[a] = vmul(s[1 + a], inv);
    }
    // Sigma_k + eps U
    let mut sig = [[[0.0f32; S]; D]; D];
    let mut k = 1 + D;
    for a in 0..D {
        for b in a..D {
            let v = fms(vmul(s[k], inv), mi[a], mi[b]);
            sig[a][b] = v;
            sig[b][a] = v;
            k += 1;
        }
    }
    for a in 0..D {
        sig[a][a] = sig[a][a].map(|v| v.max(0.0) + eps[a]);
    }
    let mut mp = [[0.0f32; S]; 3];
    for c in 0..3 {
        mp[c] = vmul(s[kp + c], inv);
    }
    // cov_k(I, p)
    let mut cov = [[[0.0f32; S]; 3]; D];
    for a in 0..D {
        for c in 0..3 {
            cov[a][c] = fms(vmul(s[kc + a * 3 + c], inv), mi[a], mp[c]);
        }
    }
    Moments { mi, sig, mp, cov }
}

/// Cholesky `Sigma = L L^T` (SPD: the diagonal holds at least eps > 0): `L` below the
/// diagonal and `rl = 1 / L_jj`. Clears `well` in lanes with a pivot below `eps / 2`.
#[inline(always)]
fn cholesky<const D: usize>(
    sig: &[[V; D]; D],
    eps: &[f32; D],
    well: &mut [bool; S],
) -> ([[V; D]; D], [V; D]) {
    let mut lm = [[[0.0f32; S]; D]; D];
    let mut rl = [[0.0f32; S]; D];
    for j in 0..D {
        let mut d = sig[j][j];
        for k in 0..j {
            d = fms(d, lm[j][k], lm[j][k]);
        }
        for l in 0..S {
            well[l] &= d[l] >= 0.5 * eps[j];
        }
        let floor = 1e-12 + eps[j] * 1e-6;
        rl[j] = d.map(|v| 1.0 / v.max(floor).sqrt());
        for i in j + 1..D {
            let mut v = sig[i][j];
            for k in 0..j {
                v = fms(v, lm[i][k], lm[j][k]);
            }
            lm[i][j] = vmul(v, rl[j]);
        }
    }
    (lm, rl)
}

/// The coefficients of colour channel `c`: `a = Sigma^-1 cov_c` (`L y = cov_c`, then
/// `L^T a = y`) and `b = mean p_c - a . mean I`.
#[inline(always)]
fn regress_channel<const D: usize>(lm: &[[V; D]; D], rl: &[V; D], m: &Moments<D>, c: usize) -> ([V; D], V) {
    let mut y = [[0.0f32; S]; D];
    for i in 0..D {
        let mut v = m.cov[i][c];
        for k in 0..i {
            v = fms(v, lm[i][k], y[k]);
        }
        y[i] = vmul(v, rl[i]);
    }
    let mut a = [[0.0f32; S]; D];
    for i in (0..D).rev() {
        let mut v = y[i];
        for k in i + 1..D {
            v = fms(v, lm[k][i], a[k]);
        }
        a[i] = vmul(v, rl[i]);
    }
    let mut b = m.mp[c];
    for i in 0..D {
        b = fms(b, a[i], m.mi[i]);
    }
    (a, b)
}

/// `o = [1, a (a*3+c), b (c)]` per lane; windows that do not count: zeros;
/// ill-conditioned ones: the box mean (a = 0, b = mean p).
#[inline(always)]
fn write_coefficients<const D: usize>(
    a_all: &[[V; D]; 3],
    b_all: &[V; 3],
    mp: &[V; 3],
    ok: &[bool; S],
    well: &[bool; S],
    o: &mut [V],
) {
    let pick = |v: V, fallback: V| -> V {
        std::array::from_fn(|l| {
            if !ok[l] {
                0.0
            } else if well[l] {
                v[l]
            } else {
                fallback[l]
            }
        })
    };
    o[0] = std::array::from_fn(|l| if ok[l] { 1.0 } else { 0.0 });
    for c in 0..3 {
        for i in 0..D {
            o[1 + i * 3 + c] = pick(a_all[c][i], [0.0; S]);
        }
        o[1 + 3 * D + c] = pick(b_all[c], mp[c]);
    }
}

/// [`solve_lanes`] for one window, written plainly: the reference the lane solve is
/// tested against (`o` as in [`solve_lanes`], 4 + 3D values).
#[cfg(test)]
fn solve_window<const D: usize, const K1: usize>(s: &[f32; K1], eps: &[f32; D], o: &mut [f32]) {
    let kp = 1 + D + D * (D + 1) / 2;
    let kc = kp + 3;
    o.fill(0.0);
    let n = s[0];
    if n < 0.5 {
        return;
    }
    let mut well = true;
    let inv = 1.0 / n;
    let mut mi = [0.0f32; D];
    for a in 0..D {
        mi[a] = s[1 + a] * inv;
    }
    let mut sig = [[0.0f32; D]; D];
    let mut k = 1 + D;
    for a in 0..D {
        for b in a..D {
            let v = s[k] * inv - mi[a] * mi[b];
            sig[a][b] = v;
            sig[b][a] = v;
            k += 1;
        }
    }
    for a in 0..D {
        sig[a][a] = sig[a][a].max(0.0) + eps[a];
    }
    let mp = [s[kp] * inv, s[kp + 1] * inv, s[kp + 2] * inv];
    if !mp.iter().all(|v| v.is_finite()) {
        return;
    }
    let mut cov = [[0.0f32; 3]; D];
    for a in 0..D {
        for c in 0..3 {
            cov[a][c] = s[kc + a * 3 + c] * inv - mi[a] * mp[c];
        }
    }
    let mut l = [[0.0f32; D]; D];
    let mut rl = [0.0f32; D];
    for j in 0..D {
        let mut d = sig[j][j];
        for k in 0..j {
            d -= l[j][k] * l[j][k];
        }
        well &= d >= 0.5 * eps[j];
        rl[j] = 1.0 / d.max(1e-12 + eps[j] * 1e-6).sqrt();
        for i in j + 1..D {
            let mut v = sig[i][j];
            for k in 0..j {
                v -= l[i][k] * l[j][k];
            }
            l[i][j] = v * rl[j];
        }
    }
    let mut ab = [([0.0f32; D], 0.0f32); 3];
    for c in 0..3 {
        let mut y = [0.0f32; D];
        for i in 0..D {
            let mut v = cov[i][c];
            for k in 0..i {
                v -= l[i][k] * y[k];
            }
            y[i] = v * rl[i];
        }
        let mut a = [0.0f32; D];
        for i in (0..D).rev() {
            let mut v = y[i];
            for k in i + 1..D {
                v -= l[k][i] * a[k];
            }
            a[i] = v * rl[i];
        }
        let mut b = mp[c];
        for i in 0..D {
            b -= a[i] * mi[i];
        }
        well &= b.is_finite() && a.iter().all(|a| a.is_finite());
        ab[c] = (a, b);
    }
    o[0] = 1.0;
    for (c, (a, b)) in ab.into_iter().enumerate() {
        for i in 0..D {
            o[1 + i * 3 + c] = if well { a[i] } else { 0.0 };
        }
        o[1 + 3 * D + c] = if well { b } else { mp[c] };
    }
}

#[cfg(test)]
mod lane_tests {
    use super::super::{k1, k2};
    use super::*;

    /// A window whose sums are spoilt by rounding (a computed `Sigma` that is not positive
    /// semi-definite, or sums that overflowed) falls back to the box mean `a = 0`,
    /// `b = mean(p)`, or is skipped when even the mean is not finite; lanes and the scalar
    /// solve agree bit for bit.
    #[test]
    fn ill_conditioned_windows_fall_back_to_the_box_mean() {
        const D: usize = 4;
        const K1: usize = k1(D);
        let kp = 1 + D + D * (D + 1) / 2;
        let eps = [0.01, 0.01, 0.01, 0.02];
        let mut sums = [[0.0f32; K1]; S];
        for (l, s) in sums.iter_mut().enumerate() {
            s[0] = 10.0;
            // Mean guide 0.5 but mean square ~0: variance -0.25 (impossible).
            s[1..1 + D].fill(5.0);
            // Off-diagonal `I_0 I_1` sums huge: an indefinite Sigma.
            s[1 + D + 1] = 1e6 * l as f32;
            s[kp..kp + 3].copy_from_slice(&[3.0, 4.0, 5.0]);
            s[kp + 3..].fill(1e5);
            if l == 5 {
                s[kp] = f32::INFINITY; // an overflowed colour sum: window skipped
            }
        }
        let lanes: [V; K1] = std::array::from_fn(|k| std::array::from_fn(|l| sums[l][k]));
        let mut o = [[7.0f32; S]; k2(D)];
        solve_lanes::<D, K1>(&lanes, &eps, &[1.0; S], &mut o);
        for l in 0..S {
            let mut one = [7.0f32; k2(D)];
            solve_window::<D, K1>(&sums[l], &eps, &mut one);
            let got: Vec<f32> = o.iter().map(|v| v[l]).collect();
            assert_eq!(got, one, "lane {l}");
            let want: Vec<f32> = if l == 5 {
                vec![0.0; k2(D)]
            } else {
                [1.0].into_iter().chain([0.0; 3 * D]).chain([0.3, 0.4, 0.5]).collect()
            };
            assert_eq!(got, want, "lane {l}");
        }
    }

    /// The 16-lane solve is bit-identical to the per-window solve, empty windows and windows
    /// centred outside the image included.
    #[test]
    fn lane_solve_matches_scalar_solve() {
        const D: usize = 4;
        const K1: usize = k1(D);
        let (kp, kc) = (1 + D + D * (D + 1) / 2, 1 + D + D * (D + 1) / 2 + 3);
        let mut state = 12345u32;
        let mut rnd = move || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
        let eps = [1e-3, 2e-3, 1e-2, 5e-4];
        for trial in 0..50 {
            // Window sums of random pixel sets (so Sigma is a real covariance).
            let mut sums = [[0.0f32; K1]; S];
            for (l, s) in sums.iter_mut().enumerate() {
                let count = if (trial + l) % 7 == 0 { 0 } else { 1 + (trial * 3 + l) % 20 };
                for _ in 0..count {
                    let i: [f32; D] = std::array::from_fn(|_| rnd());
                    let p: [f32; 3] = std::array::from_fn(|_| rnd() * 2.0);
                    s[0] += 1.0;
                    let mut k = 1;
                    for a in 0..D {
                        s[k] += i[a];
                        k += 1;
                    }
                    for a in 0..D {
                        for b in a..D {
                            s[k] += i[a] * i[b];
                            k += 1;
                        }
                    }
                    for c in 0..3 {
                        s[kp + c] += p[c];
                    }
                    for a in 0..D {
                        for c in 0..3 {
                            s[kc + a * 3 + c] += i[a] * p[c];
                        }
                    }
                }
            }
            let lanes: [V; K1] = std::array::from_fn(|k| std::array::from_fn(|l| sums[l][k]));
            let inside: V = std::array::from_fn(|l| if (trial + l) % 11 == 3 { 0.0 } else { 1.0 });
            let mut o = [[7.0f32; S]; k2(D)];
            solve_lanes::<D, K1>(&lanes, &eps, &inside, &mut o);
            for l in 0..S {
                let mut one = [7.0f32; k2(D)];
                if inside[l] > 0.0 {
                    solve_window::<D, K1>(&sums[l], &eps, &mut one);
                } else {
                    one = [0.0; k2(D)];
                }
                let got: Vec<f32> = o.iter().map(|v| v[l]).collect();
                assert_eq!(got, one, "trial {trial} lane {l}");
            }
        }
    }
}
