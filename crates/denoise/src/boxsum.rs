//! Sliding-window sums in `O(N)`, independent of the radius (He et al. 2010 compute the
//! guided filter's means by box filtering; Bauszat et al. 2011 by summed-area tables).
//!
//! For `K` quantities per pixel at once, the window sums over `(2r+1) x (2r+1)` windows
//! clipped to the image are built from running sums: per band of rows, column sums are
//! updated by adding the row entering the window and subtracting the row leaving it, then
//! each output row is a running sum along x of the column sums. The `K` quantities of a pixel
//! are contiguous (`[f32; K]`), so every update is a vector operation over `K`. Quantities are
//! produced on the fly by a closure (e.g. products `m I_a I_b`), never stored as images.
//!
//! Bands run in parallel; each starts by summing its first window directly (cost `2r+1`
//! rows), the price of independence between bands. A band's running sums round differently
//! from a sum carried over from the band above, so the band height depends only on the
//! image and the radius, never on the thread count: the same input gives the same bits on
//! any number of threads.

use crate::simd::Isa;
use rayon::prelude::*;

/// Rows per parallel band: at least four window heights and 64 rows, so that the `2r+1` start-up
/// rows of a band cost at most about an eighth of its sliding work (the start-up adds
/// `2r+1` rows where sliding adds and subtracts two per row). Independent of the thread
/// count (see the module note); a 1080-row image at r = 32 has 4 bands.
fn band_rows(h: usize, r: usize) -> usize {
    // Equal bands (as many as fit at that height), so 2 threads stay balanced: 512 rows at
    // r = 24 give 2 bands of 256, not 196 + 196 + 120.
    let bands = (h / (4 * (2 * r + 1)).max(64)).max(1);
    h.div_ceil(bands).max(1)
}

/// The per-pixel quantities of a box pass and what to do with their window sums.
/// Implemented by structs (not closures) so that `#[inline(always)]` pulls both into the
/// AVX2 build of [`box_sums`].
pub(crate) trait BoxPass<const K: usize>: Sync {
    /// The quantities of pixel `(x, y)`.
    fn quantities(&self, x: usize, y: usize) -> [f32; K];
    /// Uses `sums[i]`, the window sums around `(x0 + i, y)`, to write `out` (the output
    /// values of those pixels).
    fn consume(&self, x0: usize, y: usize, sums: &[[f32; K]], out: &mut [f32]);
}

/// Pixels per horizontal chunk: the chunk's window sums (`CHUNK * K` floats) stay in L1
/// between the running sum and `consume`.
const CHUNK: usize = 64;

/// The work of one band of rows `y0..y1`; `out` holds the band's rows (`out_stride` values
/// per pixel).
#[inline(always)]
fn band<const K: usize, B: BoxPass<K>>(
    w: usize,
    h: usize,
    r: usize,
    y0: usize,
    out: &mut [f32],
    out_stride: usize,
    pass: &B,
) {
    let rows = out.len() / (w * out_stride);
    let y1 = y0 + rows;
    // Column sums of the window rows around the current row.
    let mut col = vec![[0.0f32; K]; w];
    let mut win = [[0.0f32; K]; CHUNK];
    for yy in y0.saturating_sub(r)..=(y0 + r).min(h - 1) {
        for (x, c) in col.iter_mut().enumerate() {
            let q = pass.quantities(x, yy);
            for k in 0..K {
                c[k] += q[k];
            }
        }
    }
    for (y, out_row) in (y0..y1).zip(out.chunks_exact_mut(w * out_stride)) {
        // Horizontal running sum of the column sums, consumed chunk by chunk.
        let mut acc = [0.0f32; K];
        for c in &col[..(r + 1).min(w)] {
            for k in 0..K {
                acc[k] += c[k];
            }
        }
        for xs in (0..w).step_by(CHUNK) {
            let xe = (xs + CHUNK).min(w);
            for x in xs..xe {
                win[x - xs] = acc;
                if x + r + 1 < w {
                    let c = &col[x + r + 1];
                    for k in 0..K {
                        acc[k] += c[k];
                    }
                }
                if x >= r {
                    let c = &col[x - r];
                    for k in 0..K {
                        acc[k] -= c[k];
                    }
                }
            }
            pass.consume(xs, y, &win[..xe - xs], &mut out_row[xs * out_stride..xe * out_stride]);
        }
        // Slide the window down: add row y + r + 1, remove row y - r.
        if y + 1 < y1 {
            let (enter, leave) = (y + r + 1 < h, y >= r);
            if enter && leave {
                // Both rows in one read-modify-write of the column sums (same rounding as
                // adding then subtracting in two sweeps: `(c + q_in) - q_out`).
                for (x, c) in col.iter_mut().enumerate() {
                    let qi = pass.quantities(x, y + r + 1);
                    let qo = pass.quantities(x, y - r);
                    for k in 0..K {
                        c[k] = (c[k] + qi[k]) - qo[k];
                    }
                }
            } else if enter {
                for (x, c) in col.iter_mut().enumerate() {
                    let q = pass.quantities(x, y + r + 1);
                    for k in 0..K {
                        c[k] += q[k];
                    }
                }
            } else if leave {
                for (x, c) in col.iter_mut().enumerate() {
                    let q = pass.quantities(x, y - r);
                    for k in 0..K {
                        c[k] -= q[k];
                    }
                }
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn band_avx2<const K: usize, B: BoxPass<K>>(
    w: usize,
    h: usize,
    r: usize,
    y0: usize,
    out: &mut [f32],
    out_stride: usize,
    pass: &B,
) {
    band::<K, B>(w, h, r, y0, out, out_stride, pass)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn band_avx512<const K: usize, B: BoxPass<K>>(
    w: usize,
    h: usize,
    r: usize,
    y0: usize,
    out: &mut [f32],
    out_stride: usize,
    pass: &B,
) {
    band::<K, B>(w, h, r, y0, out, out_stride, pass)
}

/// Calls `pass.consume(y, sums, out_row)` for every row `y`, where `sums[x][k]` is the sum
/// of quantity `k` over the window of radius `r` around `(x, y)` clipped to the `w x h`
/// image, and `pass.produce(y, row)` fills `row[x]` with the quantities of pixel `(x, y)`.
/// `out` has `out_stride` values per pixel; `out_row` is row `y` of it.
pub(crate) fn box_sums<const K: usize, B: BoxPass<K>>(
    w: usize,
    h: usize,
    r: usize,
    out: &mut [f32],
    out_stride: usize,
    pass: &B,
) {
    assert_eq!(out.len(), w * h * out_stride, "box_sums: output size");
    if w == 0 || h == 0 {
        return;
    }
    let rows = band_rows(h, r);
    let isa = crate::simd::isa();
    out.par_chunks_mut(rows * w * out_stride).enumerate().for_each(|(b, chunk)| {
        #[cfg(target_arch = "x86_64")]
        match isa {
            // SAFETY: `isa()` reports Avx512 / Avx2 only when those features were detected.
            Isa::Avx512 => return unsafe { band_avx512::<K, B>(w, h, r, b * rows, chunk, out_stride, pass) },
            Isa::Avx2 => return unsafe { band_avx2::<K, B>(w, h, r, b * rows, chunk, out_stride, pass) },
            Isa::Base => {}
        }
        let _ = isa;
        band::<K, B>(w, h, r, b * rows, chunk, out_stride, pass)
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The O(N) running sums against direct O(r^2) window sums on random data.
    #[test]
    fn box_sums_match_direct_window_sums() {
        let mut state = 12345u64;
        let mut rnd = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 40) as f32) / (1u64 << 24) as f32
        };
        for &(w, h, r) in &[(13, 7, 2), (40, 150, 5), (9, 11, 20), (1, 1, 3), (70, 200, 0), (100, 131, 33)] {
            let data: Vec<[f32; 2]> = (0..w * h).map(|_| [rnd(), rnd() * 10.0 - 5.0]).collect();
            struct Copy<'a>(&'a [[f32; 2]], usize);
            impl BoxPass<2> for Copy<'_> {
                fn quantities(&self, x: usize, y: usize) -> [f32; 2] {
                    self.0[y * self.1 + x]
                }
                fn consume(&self, _: usize, _: usize, sums: &[[f32; 2]], out_row: &mut [f32]) {
                    for (o, s) in out_row.chunks_exact_mut(2).zip(sums) {
                        o.copy_from_slice(s);
                    }
                }
            }
            let mut out = vec![0.0f32; w * h * 2];
            box_sums::<2, _>(w, h, r, &mut out, 2, &Copy(&data, w));
            for y in 0..h {
                for x in 0..w {
                    let mut s = [0.0f64; 2];
                    for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                        for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                            s[0] += data[yy * w + xx][0] as f64;
                            s[1] += data[yy * w + xx][1] as f64;
                        }
                    }
                    let n = ((y + r + 1).min(h) - y.saturating_sub(r))
                        * ((x + r + 1).min(w) - x.saturating_sub(r));
                    for k in 0..2 {
                        let got = out[(y * w + x) * 2 + k] as f64;
                        let tol = 1e-4 * n as f64 * 5.0;
                        assert!((got - s[k]).abs() < tol, "{w}x{h} r={r} ({x},{y}) k={k}: {got} vs {}", s[k]);
                    }
                }
            }
        }
    }

    /// The band split does not follow the thread count, so the sums are bit-identical on
    /// 1, 2 and 3 threads (here several bands: h = 300, r = 5 gives 64-row bands).
    #[test]
    fn box_sums_bit_identical_across_thread_counts() {
        let (w, h, r) = (37, 300, 5);
        let data: Vec<[f32; 1]> = (0..w * h).map(|i| [((i * 7919) % 1000) as f32 * 0.001 + 0.1]).collect();
        struct Copy<'a>(&'a [[f32; 1]], usize);
        impl BoxPass<1> for Copy<'_> {
            fn quantities(&self, x: usize, y: usize) -> [f32; 1] {
                self.0[y * self.1 + x]
            }
            fn consume(&self, _: usize, _: usize, sums: &[[f32; 1]], out_row: &mut [f32]) {
                for (o, s) in out_row.iter_mut().zip(sums) {
                    *o = s[0];
                }
            }
        }
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let mut out = vec![0.0f32; w * h];
            pool.install(|| box_sums::<1, _>(w, h, r, &mut out, 1, &Copy(&data, w)));
            out.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        };
        let one = run(1);
        assert_eq!(one, run(2));
        assert_eq!(one, run(3));
    }
}
