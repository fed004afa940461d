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
    /// vertically adjacent foreground pixels (the pixel footprint), measured on the frame.
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
            let mut d: Vec<f32> = (0..s.height)
                .into_par_iter()
                .flat_map_iter(|y| {
                    let at = move |x: usize, y: usize| s.surf[y * s.width + x];
                    (0..s.width).flat_map(move |x| {
                        let right = (x + 1 < s.width).then(|| (at(x, y), at(x + 1, y)));
                        let down = (y + 1 < s.height).then(|| (at(x, y), at(x, y + 1)));
                        [right, down].into_iter().flatten().filter_map(|pair| match pair {
                            (Some((_, a)), Some((_, b))) => Some(a.distance(b)),
                            _ => None,
                        })
                    })
                })
                .filter(|v| *v > 0.0 && v.is_finite())
                .collect();
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
    let (w, h, r) = (s.width, s.height, params.radius);
    let mut out = Image::new(w, h, 1);
    out.data_mut().par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let (y0, y1) = (y.saturating_sub(r), (y + r).min(h - 1));
        for (x, o) in row.iter_mut().enumerate() {
            let Some((np, xp)) = s.surf[y * w + x] else {
                *o = 0.0; // background: nothing to shade
                continue;
            };
            let (x0, x1) = (x.saturating_sub(r), (x + r).min(w - 1));
            // W_p (eq. 6) without the colour term and with h(q) = 1.
            let mut w_p = 0.0f32;
            for qy in y0..=y1 {
                for q in &s.surf[qy * w + x0..=qy * w + x1] {
                    if let Some((nq, xq)) = q {
                        let e = (np - *nq).length_squared() * inv_sn2 + (xp - *xq).length_squared() * inv_sx2;
                        w_p += (-e).exp();
                    }
                }
            }
            let window = ((y1 - y0 + 1) * (x1 - x0 + 1)) as f32;
            *o = (1.0 - w_p / window).clamp(0.0, 1.0);
        }
    });
    debug_assert_eq!(out.count_non_finite(), 0);
    Ok(out)
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
