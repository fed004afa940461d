//! Edge-avoiding À-Trous wavelet filter (Dammertz, Sewtz, Hanika, Lensch 2010,
//! "Edge-Avoiding À-Trous Wavelet Transform for fast Global Illumination Filtering").
//!
//! Repeated 5x5 B3-spline convolutions `(1/16, 1/4, 3/8, 1/4, 1/16)` with `2^i - 1` holes at
//! iteration `i` (step width `2^i`), each tap weighted by the edge-stopping function
//! `w = w_rt * w_n * w_x` (eqs. 2-5) on the current colour level, the normal and the position
//! buffer. `sigma_rt` is halved at every level (`sigma_rt^i = 2^-i sigma_rt`), the normal
//! distance is divided by `stepwidth^2` as in the paper's GLSL shader, the detail levels are
//! discarded and level `N` is the output. Cost: 25 taps per pixel per iteration, independent
//! of the image content.
//!
//! When to use: the fastest filter here; good for noisy direct + indirect light at a few
//! samples per pixel. Any subset of the three weights may be switched off (0 weights is the
//! plain À-Trous transform), which reproduces the paper's Table 2 and Figure 4.

use crate::error::{invalid, require_positive_sigmas, DenoiseError};
use crate::gbuffer::{check_color, from_planes_strided, to_planes_valid, GBuffer, Guides, Planes3};
use crate::kernel::{edge_avoiding_pass, RangeTerms, Tap};
use crate::pool::Buf;
use crate::symmetric::{atrous_level, ring_fits, BandOut, LevelInput};
use filtrace_core::Image;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use crate::kernel::B3_SPLINE;

/// Parameters of [`atrous`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AtrousParams {
    /// Number of levels `N`, 1..=10; the filter footprint is `5 * 2^(N-1)` pixels wide... more
    /// precisely `4 * (2^N - 1) + 1`.
    pub iterations: u32,
    /// `sigma_rt` of the colour term at level 0, in the colour's units; halved each level.
    /// `None` switches `w_rt` off.
    pub sigma_color: Option<f32>,
    /// `sigma_n` of the normal term (unit normals; distance divided by `stepwidth^2`).
    pub sigma_normal: Option<f32>,
    /// `sigma_x` of the position term, in units of the G-buffer's scene scale.
    pub sigma_position: Option<f32>,
}

impl AtrousParams {
    /// The paper's configuration: 5 iterations, all three weights. The paper gives no sigma
    /// values; it sets `sigma_rt` "to include variations of the scale of the maximum
    /// intensity" so that level 0 depends on `w_n, w_x` only. The values here are ours: 1.0
    /// for radiance (or demodulated illumination) of order 1, a normal sigma that stops at
    /// creases at fine levels, and a position sigma of 5% of the scene size.
    pub fn paper() -> Self {
        Self { iterations: 5, sigma_color: Some(1.0), sigma_normal: Some(0.3), sigma_position: Some(0.05) }
    }
    /// Faster: 4 iterations (Bauszat 2011 Table 2 lists 4, 5 and 6).
    pub fn interactive() -> Self {
        Self { iterations: 4, ..Self::paper() }
    }
    /// Plain À-Trous (no edge-stopping, "0 weights" in Table 2 / Figure 4).
    pub fn pure() -> Self {
        Self { iterations: 5, sigma_color: None, sigma_normal: None, sigma_position: None }
    }
    /// Colour weight only ("bilateral approximation", Figure 4).
    pub fn color_only() -> Self {
        Self { sigma_normal: None, sigma_position: None, ..Self::paper() }
    }
    /// Colour and normal weights (Figure 4).
    pub fn color_normal() -> Self {
        Self { sigma_position: None, ..Self::paper() }
    }
    /// Every preset, for tests and benchmarks.
    pub fn presets() -> [(&'static str, Self); 5] {
        [
            ("paper", Self::paper()),
            ("interactive", Self::interactive()),
            ("pure", Self::pure()),
            ("color_only", Self::color_only()),
            ("color_normal", Self::color_normal()),
        ]
    }
    /// Number of edge-stopping weights switched on (Table 2's `# W`).
    pub fn weight_count(&self) -> usize {
        [self.sigma_color, self.sigma_normal, self.sigma_position].iter().filter(|s| s.is_some()).count()
    }

    pub fn validate(&self) -> Result<(), DenoiseError> {
        if !(1..=10).contains(&self.iterations) {
            return Err(invalid("iterations", format!("must be 1..=10, got {}", self.iterations)));
        }
        require_positive_sigmas(self.sigma_color, self.sigma_normal, self.sigma_position)
    }
}

impl Default for AtrousParams {
    fn default() -> Self {
        Self::paper()
    }
}

/// The 25 taps of iteration `i`: the B3 kernel with step width `2^i` (the direct pass).
pub(crate) fn atrous_taps(i: u32) -> Vec<Tap> {
    let step = 1isize << i;
    let mut taps = Vec::with_capacity(25);
    for (ky, hy) in B3_SPLINE.iter().enumerate() {
        for (kx, hx) in B3_SPLINE.iter().enumerate() {
            taps.push(Tap { dx: (kx as isize - 2) * step, dy: (ky as isize - 2) * step, h: hx * hy });
        }
    }
    taps
}

/// Edge-stopping terms of iteration `i` (`1/sigma^2`).
pub(crate) fn atrous_terms(p: &AtrousParams, i: u32) -> RangeTerms {
    let step = (1u32 << i) as f32;
    RangeTerms {
        // sigma_rt^i = 2^-i sigma_rt
        inv_color: p.sigma_color.map(|s| {
            let s_i = s / step;
            1.0 / (s_i * s_i)
        }),
        // dist2 / stepwidth^2 (GLSL shader in the paper)
        inv_normal: p.sigma_normal.map(|s| 1.0 / (s * s * step * step)),
        inv_position: p.sigma_position.map(|s| 1.0 / (s * s)),
    }
}

/// Filters `color` (3 channels) guided by `guide`. See the module docs.
pub fn atrous(color: &Image, guide: &GBuffer, params: &AtrousParams) -> Result<Image, DenoiseError> {
    let mut out = Image::new(color.width(), color.height(), 3);
    atrous_into(color, guide, params, &mut out)?;
    Ok(out)
}

/// [`atrous`] writing into `out` (resized to the colour's size when it differs).
pub fn atrous_into(
    color: &Image,
    guide: &GBuffer,
    params: &AtrousParams,
    out: &mut Image,
) -> Result<(), DenoiseError> {
    check_color(color)?;
    params.validate()?;
    let (w, h) = (color.width(), color.height());
    let stride = if (0..params.iterations).all(|i| ring_fits(w, 1 << i)) { level_stride(w) } else { w };
    // À-Trous reads depth only as the position when no position buffer is given.
    let g = Guides::new_strided(guide, w, h, stride)?;
    g.require_position(params.sigma_position)?;
    let (mut src, valid) = to_planes_valid(color, stride);
    if out.width() != w || out.height() != h || out.channels() != 3 {
        *out = Image::new(w, h, 3);
    }
    let n = stride * h;
    // Only the padding columns need values (finite: masked lanes read them); the levels
    // write every pixel.
    let mut dst: Planes3 = [Buf::uninit(n), Buf::uninit(n), Buf::uninit(n)];
    if stride > w {
        for d in &mut dst {
            d.par_chunks_mut(stride).for_each(|row| row[w..].fill(0.0));
        }
    }
    // Invalid (non-finite) colours are absent at every level: their pixels get values from
    // valid neighbours but never pass them on (a block of invalid pixels would otherwise
    // spread its placeholder values at the coarser levels). The validity plane exists only
    // when some colour is invalid.
    let v = valid.as_deref().map(|v| &v[..]);
    let last = params.iterations - 1;
    for i in 0..last {
        atrous_step(&src, v, &g, params, i, &mut dst);
        std::mem::swap(&mut src, &mut dst);
    }
    // The last level writes the interleaved output directly (when it takes the shared-weight
    // pass: always but for rows of ~100 000 pixels).
    if ring_fits(w, 1 << last) {
        level_shared(&src, v, &g, params, last, BandOut::Rgb(out.data_mut()));
    } else {
        atrous_step(&src, v, &g, params, last, &mut dst);
        from_planes_strided(&dst, stride, out);
    }
    Ok(())
}

/// Row stride of the planes the levels run on: a multiple of 16 values (64-byte rows)
/// that is an odd number of cache lines, so that rows `step`, `2 step` apart fall into
/// different L1 sets. With `stride = width = 1920` (30 KB per 4 rows) rows 8 and 16 apart
/// are 4 KB-aliased, which slows the step-8 and step-16 levels (docs/perf-filters.md).
fn level_stride(width: usize) -> usize {
    let s = width.div_ceil(16) * 16;
    if (s / 16) & 1 == 0 {
        s + 16
    } else {
        s
    }
}

/// One level `c_{i+1} = c_i * h_i` with the edge-stopping weights (eq. 2), each symmetric
/// weight evaluated once ([`crate::symmetric`]); rows too wide for its ring of weight rows
/// (~100 000 pixels) take the direct 25-tap pass.
pub(crate) fn atrous_step(
    input: &Planes3,
    valid: Option<&[f32]>,
    g: &Guides,
    params: &AtrousParams,
    i: u32,
    out: &mut Planes3,
) {
    if !ring_fits(g.width, 1 << i) {
        debug_assert_eq!(g.stride, g.width, "the direct pass runs on unpadded planes");
        return atrous_step_direct(input, valid, g, params, i, out);
    }
    let [o0, o1, o2] = out;
    level_shared(input, valid, g, params, i, BandOut::Planes([o0, o1, o2]));
}

/// [`atrous_step`]'s shared-weight pass (rows that fit its ring) into `out`.
fn level_shared(
    input: &Planes3,
    valid: Option<&[f32]>,
    g: &Guides,
    params: &AtrousParams,
    i: u32,
    out: BandOut,
) {
    with_inpainted(input, valid, g, i, |input| {
        let terms = atrous_terms(params, i);
        let n = [&g.normal[0][..], &g.normal[1][..], &g.normal[2][..]];
        // Switched-off terms never read their planes: the normals stand in for absent positions.
        let (x, terms) = match (&g.position, terms.inv_position) {
            (Some(p), Some(_)) => ([&p[0][..], &p[1][..], &p[2][..]], terms),
            _ => (n, RangeTerms { inv_position: None, ..terms }),
        };
        let a = LevelInput {
            c: [&input[0], &input[1], &input[2]],
            n,
            x,
            s: &g.surface,
            v: valid,
            width: g.width,
            height: g.height,
            stride: g.stride,
        };
        atrous_level(&a, 1 << i, terms, out);
    });
}

/// [`atrous_step`] by the direct 25-tap sum of [`edge_avoiding_pass`] (every weight
/// evaluated from both ends): the reference the shared-weight level is tested against.
pub(crate) fn atrous_step_direct(
    input: &Planes3,
    valid: Option<&[f32]>,
    g: &Guides,
    params: &AtrousParams,
    i: u32,
    out: &mut Planes3,
) {
    with_inpainted(input, valid, g, i, |input| {
        edge_avoiding_pass(input, valid, g, &atrous_taps(i), atrous_terms(params, i), out)
    });
}

/// Calls `f` with the level's input; at level 0 a pixel with an invalid colour has no colour
/// of its own to compare, so it first gets the mean of its valid neighbours (w_rt then
/// compares against something sane).
fn with_inpainted(input: &Planes3, valid: Option<&[f32]>, g: &Guides, i: u32, f: impl FnOnce(&Planes3)) {
    match valid.filter(|v| i == 0 && v.contains(&0.0)) {
        Some(v) => f(&inpaint_invalid(input, v, g.width, g.height, g.stride)),
        None => f(input),
    }
}

/// Replaces invalid pixels by the mean of their valid 3x3 neighbours (0 when none); planes
/// of `stride` values per row.
pub(crate) fn inpaint_invalid(p: &Planes3, valid: &[f32], w: usize, h: usize, stride: usize) -> Planes3 {
    let mut out = p.clone();
    for y in 0..h {
        for x in 0..w {
            let i = y * stride + x;
            if valid[i] != 0.0 {
                continue;
            }
            let (mut s, mut n) = ([0.0f32; 3], 0.0f32);
            for yy in y.saturating_sub(1)..(y + 2).min(h) {
                for xx in x.saturating_sub(1)..(x + 2).min(w) {
                    let j = yy * stride + xx;
                    if valid[j] != 0.0 {
                        for c in 0..3 {
                            s[c] += p[c][j];
                        }
                        n += 1.0;
                    }
                }
            }
            for c in 0..3 {
                out[c][i] = if n > 0.0 { s[c] / n } else { 0.0 };
            }
        }
    }
    out
}
