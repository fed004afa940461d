//! The sample sums of the He–Owen step (thesis 5.2.2): G, ∇G and ∇²G at the record's
//! parameters, and G at the line search's trial points.
//!
//! The number J of enabled techniques is a const parameter (1 to 4, fixed per sampler
//! configuration), so the loops over techniques unroll and each sample's rank-one
//! Hessian update runs as whole rows of three J × J blocks (αα, αβ, ββ), which the
//! compiler turns into vector operations. Every accumulator still sums its own terms in
//! sample order with the scalar formulas' operations, so the result is the same bit for
//! bit whatever the block layout or instruction set (Rust never contracts `a * b + c`
//! into an FMA): the loops are compiled twice, for the baseline and, after
//! [`filtrace_core::cpu::isa`], for AVX2.

// Index loops over the small matrices read as the formulas they implement.
#![allow(clippy::needless_range_loop)]

use crate::cache::history::StoredSample;
use crate::cache::TECHNIQUES;
use filtrace_core::cpu::{isa, Isa};

/// Variables of one record: α' and β of up to 4 techniques.
pub(crate) const MAX_VARS: usize = 2 * TECHNIQUES;

/// Most trial points one [`objectives`] call evaluates.
pub(crate) const MAX_TRIALS: usize = 16;

/// G's sample estimate with its gradient and Hessian over the 2J variables (α' then β).
pub(crate) struct Moments {
    pub weight: f64,
    pub objective: f64,
    pub gradient: [f64; MAX_VARS],
    pub hessian: [[f64; MAX_VARS]; MAX_VARS],
}

/// Accumulates G, ∇G, ∇²G at `x` (α' then β of the techniques `ts`, J = `ts.len()`) over
/// the weighted samples, normalised by the weight sum:
/// `∂G/∂α_k = −r² P_k / s²`, `∂G/∂β_k = −2 r Q_k / s`, `∂²G/∂α_k∂α_m = 2 r² P_k P_m / s³`,
/// `∂²G/∂β_k∂β_m = 2 Q_k Q_m / s`, `∂²G/∂α_k∂β_m = 2 r P_k Q_m / s²`, each times `1/q0`.
/// The Hessian of a sample is the rank-one `(2/s) u uᵀ` with `u = (r P / s, Q)`: one
/// division per sample; the upper triangle is summed and mirrored at the end.
pub(crate) fn moments(level: Isa, x: &[f64; MAX_VARS], ts: &[usize], samples: &[StoredSample]) -> Moments {
    match ts.len() {
        1 => moments_of::<1>(level, x, ts, samples),
        2 => moments_of::<2>(level, x, ts, samples),
        3 => moments_of::<3>(level, x, ts, samples),
        _ => moments_of::<4>(level, x, ts, samples),
    }
}

/// The sampled G at each trial point (α' then β as in [`moments`], at most
/// [`MAX_TRIALS`]), normalised like [`moments`]; +∞ where a sample has `s ≤ 0`.
pub(crate) fn objectives(
    level: Isa,
    trials: &[[f64; MAX_VARS]],
    ts: &[usize],
    samples: &[StoredSample],
) -> Vec<f64> {
    match ts.len() {
        1 => objectives_of::<1>(level, trials, ts, samples),
        2 => objectives_of::<2>(level, trials, ts, samples),
        3 => objectives_of::<3>(level, trials, ts, samples),
        _ => objectives_of::<4>(level, trials, ts, samples),
    }
}

/// The sums of [`moments`] for J techniques before normalisation; the Hessian as blocks,
/// of which `aa` and `bb` are read on and above the diagonal only.
struct Sums<const J: usize> {
    weight: f64,
    objective: f64,
    grad_alpha: [f64; J],
    grad_beta: [f64; J],
    aa: [[f64; J]; J],
    ab: [[f64; J]; J],
    bb: [[f64; J]; J],
}

fn moments_of<const J: usize>(
    level: Isa,
    x: &[f64; MAX_VARS],
    ts: &[usize],
    samples: &[StoredSample],
) -> Moments {
    let ts: [usize; J] = std::array::from_fn(|k| ts[k]);
    let alpha: [f64; J] = std::array::from_fn(|k| x[k]);
    let beta: [f64; J] = std::array::from_fn(|k| x[J + k]);
    #[cfg(target_arch = "x86_64")]
    if level.has_avx2() && isa().has_avx2() {
        // SAFETY: the CPU runs AVX2 and FMA (checked just above).
        return assemble(unsafe { sums_avx2(&alpha, &beta, &ts, samples) });
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (level, isa);
    assemble(sums(&alpha, &beta, &ts, samples))
}

/// [`sums`] compiled for AVX2 + FMA (the same source; only the instruction selection
/// differs).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn sums_avx2<const J: usize>(
    alpha: &[f64; J],
    beta: &[f64; J],
    ts: &[usize; J],
    samples: &[StoredSample],
) -> Sums<J> {
    sums(alpha, beta, ts, samples)
}

#[inline(always)]
fn sums<const J: usize>(
    alpha: &[f64; J],
    beta: &[f64; J],
    ts: &[usize; J],
    samples: &[StoredSample],
) -> Sums<J> {
    let mut m = Sums {
        weight: 0.0,
        objective: 0.0,
        grad_alpha: [0.0; J],
        grad_beta: [0.0; J],
        aa: [[0.0; J]; J],
        ab: [[0.0; J]; J],
        bb: [[0.0; J]; J],
    };
    for fb in samples {
        let w = fb.weight as f64;
        m.weight += w;
        let (p, q) = gather(fb, ts);
        let (mut s, mut predicted) = (0.0f64, 0.0f64);
        for k in 0..J {
            s += alpha[k] * p[k];
            predicted += beta[k] * q[k];
        }
        let r = fb.value as f64 - predicted;
        let a = w * fb.inv_pdf as f64;
        if !(s > 0.0 && a.is_finite() && r.is_finite()) {
            continue;
        }
        // u = (r P / s, Q).
        let r_s = r / s;
        let ua = p.map(|p| p * r_s);
        let inv_s = 1.0 / s;
        let (ar_s, c) = (a * r * inv_s, 2.0 * a * inv_s);
        m.objective += ar_s * r;
        for k in 0..J {
            m.grad_alpha[k] -= ar_s * ua[k];
            m.grad_beta[k] -= 2.0 * ar_s * q[k];
        }
        let (ca, cb) = (ua.map(|u| c * u), q.map(|u| c * u));
        for row in 0..J {
            for col in 0..J {
                m.aa[row][col] += ca[row] * ua[col];
                m.ab[row][col] += ca[row] * q[col];
                m.bb[row][col] += cb[row] * q[col];
            }
        }
    }
    m
}

/// A sample's `P_k(j)` and `Q_k(j)` of the techniques `ts` as f64.
#[inline(always)]
fn gather<const J: usize>(fb: &StoredSample, ts: &[usize; J]) -> ([f64; J], [f64; J]) {
    if J == TECHNIQUES {
        // Every technique enabled: `ts` is 0, 1, 2, 3.
        (std::array::from_fn(|k| fb.pmf[k] as f64), std::array::from_fn(|k| fb.cv[k] as f64))
    } else {
        (std::array::from_fn(|k| fb.pmf[ts[k]] as f64), std::array::from_fn(|k| fb.cv[ts[k]] as f64))
    }
}

/// The normalised [`Moments`] of the block sums, the Hessian mirrored from its upper
/// triangle.
fn assemble<const J: usize>(m: Sums<J>) -> Moments {
    let mut out = Moments {
        weight: m.weight,
        objective: m.objective,
        gradient: [0.0; MAX_VARS],
        hessian: [[0.0; MAX_VARS]; MAX_VARS],
    };
    let h = &mut out.hessian;
    for row in 0..J {
        out.gradient[row] = m.grad_alpha[row];
        out.gradient[J + row] = m.grad_beta[row];
        for col in row..J {
            h[row][col] = m.aa[row][col];
            h[J + row][J + col] = m.bb[row][col];
        }
        for col in 0..J {
            h[row][J + col] = m.ab[row][col];
        }
    }
    for row in 0..2 * J {
        for col in 0..row {
            h[row][col] = h[col][row];
        }
    }
    if out.weight > 0.0 {
        let inv = 1.0 / out.weight;
        out.objective *= inv;
        out.gradient.iter_mut().for_each(|g| *g *= inv);
        out.hessian.iter_mut().flatten().for_each(|h| *h *= inv);
    }
    out
}

fn objectives_of<const J: usize>(
    level: Isa,
    trials: &[[f64; MAX_VARS]],
    ts: &[usize],
    samples: &[StoredSample],
) -> Vec<f64> {
    let ts: [usize; J] = std::array::from_fn(|k| ts[k]);
    let n = trials.len().min(MAX_TRIALS);
    let mut points = [([0.0; J], [0.0; J]); MAX_TRIALS];
    for (point, x) in points.iter_mut().zip(&trials[..n]) {
        *point = (std::array::from_fn(|k| x[k]), std::array::from_fn(|k| x[J + k]));
    }
    let points = &points[..n];
    #[cfg(target_arch = "x86_64")]
    let (sums, weight) = if level.has_avx2() && isa().has_avx2() {
        // SAFETY: the CPU runs AVX2 and FMA (checked just above).
        unsafe { trial_sums_avx2(points, &ts, samples) }
    } else {
        trial_sums(points, &ts, samples)
    };
    #[cfg(not(target_arch = "x86_64"))]
    let (sums, weight) = {
        let _ = level;
        trial_sums(points, &ts, samples)
    };
    sums[..n].iter().map(|s| if weight > 0.0 { s / weight } else { *s }).collect()
}

/// [`trial_sums`] compiled for AVX2 + FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn trial_sums_avx2<const J: usize>(
    points: &[([f64; J], [f64; J])],
    ts: &[usize; J],
    samples: &[StoredSample],
) -> ([f64; MAX_TRIALS], f64) {
    trial_sums(points, ts, samples)
}

/// Per trial point `(α', β)` the unnormalised `Σ a r² / s`, and the weight sum.
#[inline(always)]
fn trial_sums<const J: usize>(
    points: &[([f64; J], [f64; J])],
    ts: &[usize; J],
    samples: &[StoredSample],
) -> ([f64; MAX_TRIALS], f64) {
    let (mut sums, mut weight) = ([0.0f64; MAX_TRIALS], 0.0f64);
    for fb in samples {
        let w = fb.weight as f64;
        weight += w;
        let a = w * fb.inv_pdf as f64;
        let (p, q) = gather(fb, ts);
        for ((alpha, beta), sum) in points.iter().zip(sums.iter_mut()) {
            let s: f64 = (0..J).map(|k| alpha[k] * p[k]).sum();
            let r = fb.value as f64 - (0..J).map(|k| beta[k] * q[k]).sum::<f64>();
            if s > 0.0 && a.is_finite() {
                *sum += a * r * r / s;
            } else {
                *sum = f64::INFINITY;
            }
        }
    }
    (sums, weight)
}

#[cfg(test)]
mod tests {
    use super::*;
    use filtrace_core::rng::SplitMix64;

    /// The straightforward sums (the code before the blocks): one loop over the 2J
    /// variables, the upper triangle of `(2a/s) u uᵀ` per sample.
    fn reference_moments(x: &[f64; MAX_VARS], ts: &[usize], samples: &[StoredSample]) -> Moments {
        let (j, dim) = (ts.len(), 2 * ts.len());
        let mut m = Moments {
            weight: 0.0,
            objective: 0.0,
            gradient: [0.0; MAX_VARS],
            hessian: [[0.0; MAX_VARS]; MAX_VARS],
        };
        for fb in samples {
            m.weight += fb.weight as f64;
            let mut u = [0.0f64; MAX_VARS];
            let (mut s, mut predicted) = (0.0f64, 0.0f64);
            for (k, &t) in ts.iter().enumerate() {
                let (p, q) = (fb.pmf[t] as f64, fb.cv[t] as f64);
                s += x[k] * p;
                predicted += x[j + k] * q;
                (u[k], u[j + k]) = (p, q);
            }
            let r = fb.value as f64 - predicted;
            let a = fb.weight as f64 * fb.inv_pdf as f64;
            if !(s > 0.0 && a.is_finite() && r.is_finite()) {
                continue;
            }
            let r_s = r / s;
            u[..j].iter_mut().for_each(|p| *p *= r_s);
            let inv_s = 1.0 / s;
            let (ar_s, c) = (a * r * inv_s, 2.0 * a * inv_s);
            m.objective += ar_s * r;
            for k in 0..j {
                m.gradient[k] -= ar_s * u[k];
                m.gradient[j + k] -= 2.0 * ar_s * u[j + k];
            }
            for row in 0..dim {
                let cu = c * u[row];
                for col in row..dim {
                    m.hessian[row][col] += cu * u[col];
                }
            }
        }
        for row in 0..dim {
            for col in 0..row {
                m.hessian[row][col] = m.hessian[col][row];
            }
        }
        if m.weight > 0.0 {
            let inv = 1.0 / m.weight;
            m.objective *= inv;
            m.gradient.iter_mut().for_each(|g| *g *= inv);
            m.hessian.iter_mut().flatten().for_each(|h| *h *= inv);
        }
        m
    }

    fn reference_objectives(trials: &[[f64; MAX_VARS]], ts: &[usize], samples: &[StoredSample]) -> Vec<f64> {
        let j = ts.len();
        let (mut sums, mut weight) = (vec![0.0f64; trials.len()], 0.0f64);
        for fb in samples {
            weight += fb.weight as f64;
            let a = fb.weight as f64 * fb.inv_pdf as f64;
            for (x, sum) in trials.iter().zip(sums.iter_mut()) {
                let s: f64 = (0..j).map(|k| x[k] * fb.pmf[ts[k]] as f64).sum();
                let r = fb.value as f64 - (0..j).map(|k| x[j + k] * fb.cv[ts[k]] as f64).sum::<f64>();
                if s > 0.0 && a.is_finite() {
                    *sum += a * r * r / s;
                } else {
                    *sum = f64::INFINITY;
                }
            }
        }
        sums.iter().map(|s| if weight > 0.0 { s / weight } else { *s }).collect()
    }

    /// Random samples with skewed magnitudes, some with a zero pmf where the mixture
    /// then vanishes, and some zero weights.
    fn samples(n: usize, seed: u64) -> Vec<StoredSample> {
        let mut rng = SplitMix64::new(seed);
        let mut f = |scale: f32| scale * rng.next_f32() * rng.next_f32();
        (0..n)
            .map(|i| StoredSample {
                pmf: std::array::from_fn(|k| if i % 17 == 3 { 0.0 } else { f(1.0 + k as f32) }),
                cv: std::array::from_fn(|_| f(3.0)),
                inv_pdf: 1.0 / (0.01 + f(1.0)),
                value: f(5.0),
                weight: if i % 11 == 0 { 0.0 } else { f(1.0) },
            })
            .collect()
    }

    fn bits(m: &Moments) -> Vec<u64> {
        let mut v = vec![m.weight.to_bits(), m.objective.to_bits()];
        v.extend(m.gradient.iter().map(|g| g.to_bits()));
        v.extend(m.hessian.iter().flatten().map(|h| h.to_bits()));
        v
    }

    /// Every technique subset and instruction-set level gives the reference's bits.
    #[test]
    fn block_sums_equal_the_straightforward_sums_bit_for_bit() {
        let subsets: [&[usize]; 5] = [&[3], &[0, 3], &[0, 1, 3], &[1, 2, 3], &[0, 1, 2, 3]];
        let mut levels = vec![Isa::Base];
        if isa().has_avx2() {
            levels.push(Isa::Avx2);
        }
        for (case, ts) in subsets.iter().enumerate() {
            let all = samples(300, case as u64);
            let j = ts.len();
            let mut x = [0.0f64; MAX_VARS];
            for k in 0..j {
                (x[k], x[j + k]) = (0.9 / j as f64 * (1.0 + 0.1 * k as f64), 0.3 + 0.2 * k as f64);
            }
            let trials: Vec<[f64; MAX_VARS]> =
                (0..10).map(|t| x.map(|v| v * (1.0 - 0.05 * t as f64))).collect();
            let want = bits(&reference_moments(&x, ts, &all));
            let want_g: Vec<u64> =
                reference_objectives(&trials, ts, &all).iter().map(|g| g.to_bits()).collect();
            for &level in &levels {
                assert_eq!(bits(&moments(level, &x, ts, &all)), want, "{ts:?} {level:?}");
                for range in [0..2, 2..10] {
                    let got: Vec<u64> = objectives(level, &trials[range.clone()], ts, &all)
                        .iter()
                        .map(|g| g.to_bits())
                        .collect();
                    assert_eq!(got, want_g[range], "{ts:?} {level:?}");
                }
            }
        }
    }
}
