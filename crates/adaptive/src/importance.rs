//! Importance map (Bauszat et al. 2011, §4.1).
//!
//! For each pixel `p` the normalisation factor `W_p` of the geometry-aware filter
//! kernel (eq. 6) is evaluated with the normal weight `G_σn` (eq. 4) and the position
//! weight `G_σx` (eq. 5) only — no colour exists before sampling — over a square
//! window of radius `r`, with a box spatial kernel (`h(q) = 1`), and divided by the
//! number of pixels in the window, the largest value `W_p` can reach. The importance
//! is `1 - W_p / |window|` in `[0, 1]`: pixels with few similar neighbours benefit
//! least from filtering and get the most samples.
//!
//! Conventions (documented behaviour, tested):
//! * **Window.** `radius = r` means `(2r + 1)²` pixels centred on `p`. The paper
//!   labels windows "2x2 … 10x10"; here its "NxN" is `r = N / 2`.
//! * **Image border.** Only pixels inside the image count, both in `W_p` and in the
//!   window size, so the frame border alone does not raise importance.
//! * **Background.** A pixel whose normal has (near) zero length, or whose normal or
//!   position is not finite, is background: its importance is **0** (nothing is shaded
//!   there, so indirect samples are wasted) and as a neighbour it has weight 0 (it
//!   contributes nothing to a filter), so silhouettes against the background are
//!   important. Normals need not be unit length; they are normalised.
//! * **Position scale.** `σ_x` is in world units ([`PositionScale::World`]) or in
//!   multiples of the median pixel footprint ([`PositionScale::Footprint`], the
//!   default), which makes one preset work for a 1-unit and a 550-unit scene.

use crate::AdaptiveError;
use filtrace_core::{Image, Vec3};
use rayon::prelude::*;

/// Largest supported window radius (a 21x21 window); the paper uses 1-5.
pub const MAX_RADIUS: usize = 10;

/// How the position similarity scale `σ_x` of eq. 5 is given.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum PositionScale {
    /// `σ_x` in world units (as in Dammertz et al. 2010).
    World(f32),
    /// `σ_x = k · f`, with `f` the median world-space distance between horizontally or
    /// vertically adjacent foreground pixels (the pixel footprint), measured on every
    /// other row of the frame.
    Footprint(f32),
}

/// Parameters of the importance map.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ImportanceParams {
    /// Window radius `r` (window `(2r+1)²` pixels), `1..=MAX_RADIUS`. The paper: 2-4
    /// detects edges and high-variance areas; larger spreads importance further from
    /// an edge and costs O(r²) per pixel.
    pub radius: usize,
    /// `σ_n` of the normal weight `exp(-|N_p - N_q|² / σ_n²)` (eq. 4), `> 0`.
    /// 0.3: an 18° normal difference gives weight `e^-1`.
    pub sigma_normal: f32,
    /// `σ_x` of the position weight `exp(-|X_p - X_q|² / σ_x²)` (eq. 5).
    pub sigma_position: PositionScale,
}

impl Default for ImportanceParams {
    fn default() -> Self {
        Self::paper()
    }
}

impl ImportanceParams {
    /// The paper's setting: the "4x4" window (r = 2) used for all its examples,
    /// normal and position weights combined (its Fig. 2c).
    pub fn paper() -> Self {
        Self { radius: 2, sigma_normal: 0.3, sigma_position: PositionScale::Footprint(4.0) }
    }

    /// Cheapest useful map: "2x2" window (r = 1), ~3x faster than `paper()`.
    pub fn fast() -> Self {
        Self { radius: 1, ..Self::paper() }
    }

    /// Wide window (r = 5, the paper's "10x10"): importance spreads further from edges,
    /// which suits wide À-Trous kernels; ~4x the cost of `paper()`.
    pub fn wide() -> Self {
        Self { radius: 5, sigma_position: PositionScale::Footprint(8.0), ..Self::paper() }
    }

    /// All named presets, for tests and benchmarks.
    pub fn presets() -> [(&'static str, Self); 3] {
        [("paper", Self::paper()), ("fast", Self::fast()), ("wide", Self::wide())]
    }

    /// This preset with another radius.
    pub fn with_radius(self, radius: usize) -> Self {
        Self { radius, ..self }
    }

    /// Checks the ranges documented on the fields.
    pub fn validate(&self) -> Result<(), AdaptiveError> {
        if self.radius == 0 || self.radius > MAX_RADIUS {
            return Err(AdaptiveError::InvalidParameter {
                name: "radius",
                value: self.radius.to_string(),
                expected: "1..=10",
            });
        }
        if !(self.sigma_normal.is_finite() && self.sigma_normal > 0.0) {
            return Err(AdaptiveError::InvalidParameter {
                name: "sigma_normal",
                value: self.sigma_normal.to_string(),
                expected: "finite and > 0",
            });
        }
        let (PositionScale::World(s) | PositionScale::Footprint(s)) = self.sigma_position;
        if !(s.is_finite() && s > 0.0) {
            return Err(AdaptiveError::InvalidParameter {
                name: "sigma_position",
                value: s.to_string(),
                expected: "finite and > 0",
            });
        }
        Ok(())
    }
}

/// The G-buffer as the map sees it: unit normals and positions, `None` = background.
struct Surfels {
    width: usize,
    height: usize,
    surf: Vec<Option<(Vec3, Vec3)>>,
}

fn check_layers(normal: &Image, position: &Image) -> Result<(), AdaptiveError> {
    if !normal.same_size(position) {
        return Err(AdaptiveError::SizeMismatch {
            normal: (normal.width(), normal.height()),
            position: (position.width(), position.height()),
        });
    }
    for (layer, im) in [("normal", normal), ("position", position)] {
        if im.channels() < 3 {
            return Err(AdaptiveError::Channels { layer, expected: 3, found: im.channels() });
        }
    }
    if normal.pixel_count() == 0 {
        return Err(AdaptiveError::EmptyImage);
    }
    Ok(())
}

/// Normal and position of a foreground pixel, `None` for background (see module docs).
#[inline]
fn surfel(normal: &Image, position: &Image, x: usize, y: usize) -> Option<(Vec3, Vec3)> {
    let n = normal.rgb(x, y);
    let p = position.rgb(x, y);
    let len2 = n.length_squared();
    (n.is_finite() && p.is_finite() && len2 > 1e-12).then(|| (n / len2.sqrt(), p))
}

impl Surfels {
    fn new(normal: &Image, position: &Image) -> Self {
        let (width, height) = (normal.width(), normal.height());
        let surf = (0..width * height)
            .into_par_iter()
            .map(|i| surfel(normal, position, i % width, i / width))
            .collect();
        Self { width, height, surf }
    }
}

/// `σ_x` in world units for these layers: `World(s)` is `s`; `Footprint(k)` is `k`
/// times the median distance between adjacent (right, below) foreground pixels.
/// Returns `None` when no such pair with a non-zero distance exists (the position
/// weight is then switched off: every weight is 1).
pub fn resolve_sigma_position(
    normal: &Image,
    position: &Image,
    params: &ImportanceParams,
) -> Result<Option<f32>, AdaptiveError> {
    check_layers(normal, position)?;
    params.validate()?;
    Ok(sigma_x(&Surfels::new(normal, position), params))
}

fn sigma_x(s: &Surfels, params: &ImportanceParams) -> Option<f32> {
    match params.sigma_position {
        PositionScale::World(w) => Some(w),
        PositionScale::Footprint(k) => {
            // Every other row is plenty for a median and halves the cost.
            let rows: Vec<Vec<f32>> = (0..s.height)
                .into_par_iter()
                .step_by(2)
                .map(|y| {
                    let mut d = Vec::with_capacity(2 * s.width);
                    let row = &s.surf[y * s.width..(y + 1) * s.width];
                    let below = (y + 1 < s.height).then(|| &s.surf[(y + 1) * s.width..(y + 2) * s.width]);
                    for x in 0..s.width {
                        let Some((_, a)) = row[x] else { continue };
                        let right = row.get(x + 1).copied().flatten();
                        let down = below.and_then(|b| b[x]);
                        for (_, b) in [right, down].into_iter().flatten() {
                            let v = a.distance(b);
                            if v > 0.0 && v.is_finite() {
                                d.push(v);
                            }
                        }
                    }
                    d
                })
                .collect();
            let mut d: Vec<f32> = rows.concat();
            if d.is_empty() {
                return None;
            }
            let mid = d.len() / 2;
            let (_, m, _) = d.select_nth_unstable_by(mid, f32::total_cmp);
            Some(k * *m)
        }
    }
}

/// The importance map `1 - W_p / |window|` as a 1-channel image (see module docs).
///
/// `normal` and `position` are world-space G-buffer layers with at least 3 channels
/// (extra channels are ignored). O(r²) per pixel, parallel over rows.
///
/// ```
/// use filtrace_adaptive::{importance_map, ImportanceParams};
/// use filtrace_core::Image;
/// // A flat, camera-facing plane: every neighbour is similar in normal, and the
/// // position weight is the same for every interior pixel.
/// let normal = Image::from_vec(8, 8, 3, [0.0, 0.0, 1.0].repeat(64)).unwrap();
/// let mut position = Image::new(8, 8, 3);
/// for y in 0..8 { for x in 0..8 { position.pixel_mut(x, y)[..2].copy_from_slice(&[x as f32, y as f32]); } }
/// let imp = importance_map(&normal, &position, &ImportanceParams::paper()).unwrap();
/// assert_eq!(imp.channels(), 1);
/// assert!(imp.data().iter().all(|v| (0.0..=1.0).contains(v)));
/// ```
pub fn importance_map(
    normal: &Image,
    position: &Image,
    params: &ImportanceParams,
) -> Result<Image, AdaptiveError> {
    check_layers(normal, position)?;
    params.validate()?;
    let s = Surfels::new(normal, position);
    let inv_sn2 = 1.0 / (params.sigma_normal * params.sigma_normal);
    let inv_sx2 = sigma_x(&s, params).map_or(0.0, |sx| 1.0 / (sx * sx));
    let (w, h, r) = (s.width, s.height, params.radius as isize);
    let soa = SoaSurfels::new(&s, inv_sn2.sqrt(), inv_sx2.sqrt());

    // W_p (eq. 6) without the colour term and with h(q) = 1. G(p, q) = G(q, p), so each
    // pair is evaluated once: for every offset o of the forward half-window, the weight
    // image w_o(p) = G(p, p + o) is computed, then added to W at p and at p + o.
    // Half the exponentials of the direct sum; each pass is two parallel sweeps.
    let mut w_sum = vec![1.0f32; w * h]; // the centre pixel, G(p, p) = 1
    let mut w_o = vec![0.0f32; w * h];
    for dy in 0..=r {
        for dx in -r..=r {
            if dy == 0 && dx <= 0 {
                continue;
            }
            if dy as usize >= h || dx.unsigned_abs() >= w {
                continue;
            }
            pair_weights(&soa, dx, dy as usize, &mut w_o);
            scatter(&w_o, w, dx, dy as usize, &mut w_sum);
        }
    }

    // Importance 1 - W_p / |window ∩ image|; background 0.
    let mut out = Image::new(w, h, 1);
    let ru = r as usize;
    out.data_mut().par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let rows = (y + ru).min(h - 1) - y.saturating_sub(ru) + 1;
        for (x, o) in row.iter_mut().enumerate() {
            let i = y * w + x;
            if soa.mask[i] == 0.0 {
                *o = 0.0; // background: nothing to shade
                continue;
            }
            let cols = (x + ru).min(w - 1) - x.saturating_sub(ru) + 1;
            *o = (1.0 - w_sum[i] / (rows * cols) as f32).clamp(0.0, 1.0);
        }
    });
    debug_assert_eq!(out.count_non_finite(), 0);
    Ok(out)
}

/// The G-buffer as flat arrays, pre-scaled by `1/σ_n` and `1/σ_x` so that the exponent
/// of `G_σn · G_σx` is a plain squared distance; background has mask 0 and zero vectors.
struct SoaSurfels {
    width: usize,
    n: [Vec<f32>; 3],
    x: [Vec<f32>; 3],
    mask: Vec<f32>,
}

impl SoaSurfels {
    fn new(s: &Surfels, inv_sn: f32, inv_sx: f32) -> Self {
        let len = s.surf.len();
        let mut n = [vec![0.0; len], vec![0.0; len], vec![0.0; len]];
        let mut x = [vec![0.0; len], vec![0.0; len], vec![0.0; len]];
        let mut mask = vec![0.0; len];
        for (i, v) in s.surf.iter().enumerate() {
            if let Some((nv, xv)) = v {
                for k in 0..3 {
                    n[k][i] = nv[k] * inv_sn;
                    x[k][i] = xv[k] * inv_sx;
                }
                mask[i] = 1.0;
            }
        }
        // A position scaled to infinity (huge coordinates, tiny σ_x) would give inf - inf.
        for xs in &mut x {
            for v in xs.iter_mut().filter(|v| !v.is_finite()) {
                *v = f32::MAX.sqrt();
            }
        }
        Self { width: s.width, n, x, mask }
    }
}

/// `out[p] = G(p, p + (dx, dy))` for every `p` whose partner is inside the image
/// (0 elsewhere and for background on either side).
fn pair_weights(s: &SoaSurfels, dx: isize, dy: usize, out: &mut [f32]) {
    let w = s.width;
    let h = out.len() / w;
    let (x0, x1) = if dx >= 0 { (0, w - dx as usize) } else { ((-dx) as usize, w) };
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        if y + dy >= h {
            row.fill(0.0);
            return;
        }
        let (a, b) = (y * w, (y + dy) * w);
        let q = |x: usize| (b as isize + x as isize + dx) as usize;
        row[..x0].fill(0.0);
        row[x1..].fill(0.0);
        let (qa, len) = (q(x0), x1 - x0);
        let pa = a + x0;
        let np = [&s.n[0][pa..pa + len], &s.n[1][pa..pa + len], &s.n[2][pa..pa + len]];
        let nq = [&s.n[0][qa..qa + len], &s.n[1][qa..qa + len], &s.n[2][qa..qa + len]];
        let xp = [&s.x[0][pa..pa + len], &s.x[1][pa..pa + len], &s.x[2][pa..pa + len]];
        let xq = [&s.x[0][qa..qa + len], &s.x[1][qa..qa + len], &s.x[2][qa..qa + len]];
        let (mp, mq) = (&s.mask[pa..pa + len], &s.mask[qa..qa + len]);
        let out = &mut row[x0..x0 + len];
        // Exponent first, then the exponential, in two flat loops that vectorise.
        for i in 0..len {
            let d = |a: &[f32], b: &[f32]| (a[i] - b[i]) * (a[i] - b[i]);
            out[i] = d(np[0], nq[0])
                + d(np[1], nq[1])
                + d(np[2], nq[2])
                + d(xp[0], xq[0])
                + d(xp[1], xq[1])
                + d(xp[2], xq[2]);
        }
        for ((o, a), b) in out.iter_mut().zip(mp).zip(mq) {
            *o = a * b * exp_neg(*o);
        }
    });
}

/// `w_sum[p] += w_o[p] + w_o[p - o]`: each pair's weight counts for both its pixels.
fn scatter(w_o: &[f32], w: usize, dx: isize, dy: usize, w_sum: &mut [f32]) {
    w_sum.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (v, o) in row.iter_mut().zip(&w_o[y * w..(y + 1) * w]) {
            *v += o;
        }
        if y >= dy {
            let src = &w_o[(y - dy) * w..(y - dy + 1) * w];
            // Pixel x receives from x - dx in row y - dy.
            let (lo, hi) = if dx >= 0 { (dx as usize, w) } else { (0, w - (-dx) as usize) };
            for x in lo..hi {
                row[x] += src[(x as isize - dx) as usize];
            }
        }
    });
}

/// `exp(-e)` for `e >= 0` (0 for `e > 87`), absolute error below 2.5e-7 (relative below
/// 1e-6 for `e < 10`): `2^(-e·log2 e)`
/// split into an integer power (exponent bits) and a degree-6 polynomial for the
/// fractional power. Branch-free so the loops in [`pair_weights`] vectorise; the library
/// `expf` is not inlined and made the map 2x slower (bench adaptive, 1024x768, r = 2).
#[inline(always)]
fn exp_neg(e: f32) -> f32 {
    let t = (-e * std::f32::consts::LOG2_E).max(-126.0);
    // Round to nearest by the 1.5·2^23 trick: `f32::round` is a libm call on baseline
    // x86-64 and kept this loop scalar.
    const MAGIC: f32 = 12_582_912.0;
    let fl = (t + MAGIC) - MAGIC;
    let f = t - fl; // in [-0.5, 0.5]
                    // 2^f = e^(f ln 2), |f ln 2| <= 0.35: the Taylor series to degree 6 errs < 2e-7.
    let l = std::f32::consts::LN_2;
    let z = f * l;
    let p = 1.0
        + z * (1.0 + z * (0.5 + z * (1.0 / 6.0 + z * (1.0 / 24.0 + z * (1.0 / 120.0 + z * (1.0 / 720.0))))));
    // fl is an integer in [-126, 0]: its exponent bits are exact, `fl + 127` in [1, 127].
    let bits = ((fl + 127.0) as u32) << 23;
    let v = p * f32::from_bits(bits);
    if e > 87.0 {
        0.0
    } else {
        v
    }
}

/// Reference implementation of [`importance_map`]: one pixel at a time, straight
/// from eqs. 4-6, reading the layers directly. For tests.
pub fn importance_map_naive(
    normal: &Image,
    position: &Image,
    params: &ImportanceParams,
) -> Result<Image, AdaptiveError> {
    let sx = resolve_sigma_position(normal, position, params)?;
    let (w, h, r) = (normal.width() as i64, normal.height() as i64, params.radius as i64);
    let mut out = Image::new(w as usize, h as usize, 1);
    for y in 0..h {
        for x in 0..w {
            let Some((np, xp)) = surfel(normal, position, x as usize, y as usize) else {
                continue;
            };
            let (mut w_p, mut count) = (0.0f64, 0.0f64);
            for dy in -r..=r {
                for dx in -r..=r {
                    let (qx, qy) = (x + dx, y + dy);
                    if qx < 0 || qy < 0 || qx >= w || qy >= h {
                        continue;
                    }
                    count += 1.0;
                    if let Some((nq, xq)) = surfel(normal, position, qx as usize, qy as usize) {
                        let g_n = (-((np - nq).length_squared() as f64)
                            / (params.sigma_normal as f64).powi(2))
                        .exp();
                        let g_x = sx.map_or(1.0, |sx| {
                            (-((xp - xq).length_squared() as f64) / (sx as f64).powi(2)).exp()
                        });
                        w_p += g_n * g_x;
                    }
                }
            }
            out.pixel_mut(x as usize, y as usize)[0] = (1.0 - w_p / count).clamp(0.0, 1.0) as f32;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    #[test]
    fn fast_exp_matches_std() {
        let mut worst = 0.0f64;
        for i in 0..200_000 {
            let e = i as f32 * 1e-3; // 0 .. 200
            let want = (-(e as f64)).exp();
            let got = super::exp_neg(e) as f64;
            // Relative error is limited by the f32 range reduction for large e, where the
            // weights are negligible; what matters for W_p is the absolute error.
            assert!((got - want).abs() < 2.5e-7, "exp(-{e}) = {want}, got {got}");
            if e < 10.0 {
                worst = worst.max(((got - want) / want).abs());
            }
        }
        assert!(worst < 1e-6, "relative error {worst}");
        assert_eq!(super::exp_neg(0.0), 1.0);
        assert_eq!(super::exp_neg(f32::INFINITY), 0.0);
    }
}
