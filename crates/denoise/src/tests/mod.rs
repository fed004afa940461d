//! Tests of the filters against direct naive implementations, and of their documented
//! behaviour (constants, edges, background, NaN, energy, presets, errors): one module per
//! filter, and `every_filter` for what all of them promise. The shared random inputs and
//! the naive edge-avoiding pass live here.

use crate::pool::Buf;
use crate::*;
mod atrous;
mod bilateral;
mod every_filter;
mod guided;

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
