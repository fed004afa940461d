//! The per-pixel inputs of the guided filter's two box passes, converted once from the
//! interleaved colour and G-buffer into the lane-strip layout of [`crate::stripbox`].

use crate::gbuffer::{depth_scale, is_valid_color, surface_at, GBuffer};
use crate::pool::Buf;
use crate::simd::Isa;
use crate::stripbox::{vecs, vecs_mut, Strips, S, V};
use filtrace_core::Image;
use rayon::prelude::*;

/// The depth guide `depth / scale` is clamped to `[0, DEPTH_GUIDE_MAX]`: everything beyond
/// 4 depth scales is "far" alike, and the running sums of its squares stay small enough for
/// f32 (the scale is the 99th percentile of surface depths, so few pixels reach it).
const DEPTH_GUIDE_MAX: f32 = 4.0;

/// Planes of [`Inputs`] after the `D` guidance planes.
pub(super) const P_COLOR: usize = 0;
pub(super) const P_MASK: usize = 3;
pub(super) const P_SURFACE: usize = 4;

/// The per-pixel inputs of both passes in the lane-strip layout of [`crate::stripbox`]: per
/// row, `D + 5` planes of `len` vectors: the guidance `I_a` centred (`I - 0.5`, which leaves
/// `a` unchanged and keeps the running sums small), the sanitised colour `p` (non-finite
/// values replaced by 0), the fit mask `m` (1 on surface pixels with a finite colour) and the
/// surface indicator `s`. Padding lanes are all 0.
pub(super) struct Inputs<const D: usize> {
    pub(super) st: Strips,
    data: Buf,
}

impl<const D: usize> Inputs<D> {
    const PLANES: usize = D + 5;

    /// Converts the interleaved colour and guides (one pass over them, rows in parallel).
    pub(super) fn new(color: &Image, g: &GBuffer, st: Strips, isa: Isa) -> Self {
        let (w, len) = (st.w, st.len);
        let row = Self::PLANES * len * S;
        let mut data = Buf::uninit(st.h * row);
        // Depth divided by the depth scale, as `Guides` does.
        let depth = g.depth.as_ref().filter(|_| D == 4).map(|d| (d.data(), 1.0 / depth_scale(g, d)));
        let src = Src { c: color.data(), n: g.normal.data(), g, depth };
        // (`convert_row` writes every lane, padding included: no need to clear `data`.)
        let rows_per_item = (16 * 1024 / w).max(1);
        data.par_chunks_mut(rows_per_item * row).enumerate().for_each(|(item, rows)| {
            for (ry, out) in rows.chunks_exact_mut(row).enumerate() {
                convert_row_isa::<D>(&st, &src, item * rows_per_item + ry, vecs_mut(out), isa);
            }
        });
        Self { st, data }
    }

    /// Per colour channel, `[min, max]` over the fit pixels (`[0, 0]` when there are none).
    pub(super) fn fit_range(&self) -> [[f32; 2]; 3] {
        let row = Self::PLANES * self.st.len * S;
        let merge = |a: [[f32; 2]; 3], b: [[f32; 2]; 3]| -> [[f32; 2]; 3] {
            std::array::from_fn(|c| [a[c][0].min(b[c][0]), a[c][1].max(b[c][1])])
        };
        let empty = [[f32::INFINITY, f32::NEG_INFINITY]; 3];
        let r = self
            .data
            .par_chunks(row)
            .map(|row| {
                let v = vecs(row);
                let len = self.st.len;
                let mut r = empty;
                for j in 0..len {
                    let m = v[(D + P_MASK) * len + j];
                    for c in 0..3 {
                        let p = v[(D + P_COLOR + c) * len + j];
                        for l in 0..S {
                            if m[l] > 0.0 {
                                r[c] = [r[c][0].min(p[l]), r[c][1].max(p[l])];
                            }
                        }
                    }
                }
                r
            })
            .reduce(|| empty, merge);
        r.map(|[lo, hi]| if lo <= hi { [lo, hi] } else { [0.0, 0.0] })
    }

    /// Plane `q` at position `j` of row `y`.
    #[inline(always)]
    pub(super) fn get(&self, q: usize, y: usize, j: usize) -> V {
        vecs(&self.data)[(y * Self::PLANES + q) * self.st.len + j]
    }
}

/// The interleaved inputs of [`Inputs::new`]: colour, normal, the G-buffer (for
/// [`surface_at`]), `(depth, 1 / depth scale)` when depth guides.
struct Src<'a> {
    c: &'a [f32],
    n: &'a [f32],
    g: &'a GBuffer,
    depth: Option<(&'a [f32], f32)>,
}

/// Row `y` of [`Inputs`] (`out`: its `D + 5` planes of `len` vectors): position by
/// position, the 16 pixels `len` apart gathered into lanes and converted as vectors.
#[inline(always)]
fn convert_row<const D: usize>(st: &Strips, src: &Src, y: usize, out: &mut [V]) {
    let (w, len) = (st.w, st.len);
    for j in 0..len {
        // D + 5 <= 9 planes. One lane per segment; lanes past the image's end stay 0
        // (background, no fit).
        let mut v = [[0.0f32; S]; 9];
        for l in 0..st.lanes_in_image(j) {
            let i = y * w + l * len + j;
            let px = &src.n[3 * i..3 * i + 3];
            // Surface (`surface_at`: normal set, depth valid): normal normalised; 0 on background.
            let surface = surface_at(src.g, i);
            let inv =
                if surface { 1.0 / (px[0] * px[0] + px[1] * px[1] + px[2] * px[2]).sqrt() } else { 0.0 };
            let nn = if surface { [px[0] * inv, px[1] * inv, px[2] * inv] } else { [0.0; 3] };
            if D == 1 {
                // The mean of the [0,1]-scaled normal, centred: (n0 + n1 + n2) / 6.
                v[0][l] = (nn[0] + nn[1] + nn[2]) / 6.0;
            } else {
                for a in 0..3 {
                    v[a][l] = 0.5 * nn[a];
                }
            }
            if let Some((d, inv_scale)) = src.depth {
                let dv = d[i];
                v[3][l] = if surface { (dv * inv_scale).clamp(0.0, DEPTH_GUIDE_MAX) } else { 0.0 } - 0.5;
            }
            let cp = &src.c[3 * i..3 * i + 3];
            let valid = cp.iter().all(|v| is_valid_color(*v));
            for k in 0..3 {
                v[D + P_COLOR + k][l] = if valid { cp[k] } else { 0.0 };
            }
            let s = if surface { 1.0 } else { 0.0 };
            v[D + P_MASK][l] = if valid { s } else { 0.0 };
            v[D + P_SURFACE][l] = s;
        }
        for (q, v) in v[..D + 5].iter().enumerate() {
            out[q * len + j] = *v;
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn convert_row_avx512<const D: usize>(st: &Strips, src: &Src, y: usize, out: &mut [V]) {
    convert_row::<D>(st, src, y, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn convert_row_avx2<const D: usize>(st: &Strips, src: &Src, y: usize, out: &mut [V]) {
    convert_row::<D>(st, src, y, out)
}

fn convert_row_isa<const D: usize>(st: &Strips, src: &Src, y: usize, out: &mut [V], isa: Isa) {
    #[cfg(target_arch = "x86_64")]
    match isa {
        // SAFETY: `isa()` reports Avx512 / Avx2 only when those features were detected.
        Isa::Avx512 => return unsafe { convert_row_avx512::<D>(st, src, y, out) },
        Isa::Avx2 => return unsafe { convert_row_avx2::<D>(st, src, y, out) },
        Isa::Base => {}
    }
    let _ = isa;
    convert_row::<D>(st, src, y, out)
}
