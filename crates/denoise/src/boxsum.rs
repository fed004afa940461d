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
//! rows), the price of independence between bands.

use rayon::prelude::*;

/// Rows per parallel band: at least 64 (so the `2r+1` start-up rows stay a small share),
/// else about two bands per thread.
fn band_rows(h: usize) -> usize {
    let threads = rayon::current_num_threads().max(1);
    h.div_ceil(2 * threads).max(64)
}

#[inline(always)]
fn add_row<const K: usize>(col: &mut [[f32; K]], row: &[[f32; K]]) {
    for (c, r) in col.iter_mut().zip(row) {
        for k in 0..K {
            c[k] += r[k];
        }
    }
}

#[inline(always)]
fn sub_row<const K: usize>(col: &mut [[f32; K]], row: &[[f32; K]]) {
    for (c, r) in col.iter_mut().zip(row) {
        for k in 0..K {
            c[k] -= r[k];
        }
    }
}

/// `win[x] = sum of col[x-r ..= x+r]` clipped to the row.
#[inline(always)]
fn horizontal<const K: usize>(col: &[[f32; K]], r: usize, win: &mut [[f32; K]]) {
    let w = col.len();
    let mut acc = [0.0f32; K];
    for c in &col[..(r + 1).min(w)] {
        for k in 0..K {
            acc[k] += c[k];
        }
    }
    for x in 0..w {
        win[x] = acc;
        if x + r + 1 < w {
            for k in 0..K {
                acc[k] += col[x + r + 1][k];
            }
        }
        if x >= r {
            for k in 0..K {
                acc[k] -= col[x - r][k];
            }
        }
    }
}

/// The work of one band of rows `y0..y1`; `out` holds the band's rows (`out_stride` values
/// per pixel).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn band<const K: usize, P, C>(
    w: usize,
    h: usize,
    r: usize,
    y0: usize,
    out: &mut [f32],
    out_stride: usize,
    produce: &P,
    consume: &C,
) where
    P: Fn(usize, &mut [[f32; K]]),
    C: Fn(usize, &[[f32; K]], &mut [f32]),
{
    let rows = out.len() / (w * out_stride);
    let y1 = y0 + rows;
    let mut col = vec![[0.0f32; K]; w];
    let mut row = vec![[0.0f32; K]; w];
    let mut win = vec![[0.0f32; K]; w];
    for yy in y0.saturating_sub(r)..=(y0 + r).min(h - 1) {
        produce(yy, &mut row);
        add_row(&mut col, &row);
    }
    for (y, out_row) in (y0..y1).zip(out.chunks_exact_mut(w * out_stride)) {
        horizontal(&col, r, &mut win);
        consume(y, &win, out_row);
        if y + 1 < y1 {
            if y + r + 1 < h {
                produce(y + r + 1, &mut row);
                add_row(&mut col, &row);
            }
            if y >= r {
                produce(y - r, &mut row);
                sub_row(&mut col, &row);
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx2,fma")]
unsafe fn band_avx2<const K: usize, P, C>(
    w: usize,
    h: usize,
    r: usize,
    y0: usize,
    out: &mut [f32],
    out_stride: usize,
    produce: &P,
    consume: &C,
) where
    P: Fn(usize, &mut [[f32; K]]),
    C: Fn(usize, &[[f32; K]], &mut [f32]),
{
    band::<K, P, C>(w, h, r, y0, out, out_stride, produce, consume)
}

/// Calls `consume(y, sums, out_row)` for every row `y`, where `sums[x][k]` is the sum of
/// quantity `k` over the window of radius `r` around `(x, y)` clipped to the `w x h` image,
/// and `produce(y, row)` fills `row[x]` with the quantities of pixel `(x, y)`.
/// `out` has `out_stride` values per pixel; `out_row` is row `y` of it.
pub(crate) fn box_sums<const K: usize, P, C>(
    w: usize,
    h: usize,
    r: usize,
    out: &mut [f32],
    out_stride: usize,
    produce: P,
    consume: C,
) where
    P: Fn(usize, &mut [[f32; K]]) + Sync,
    C: Fn(usize, &[[f32; K]], &mut [f32]) + Sync,
{
    assert_eq!(out.len(), w * h * out_stride, "box_sums: output size");
    if w == 0 || h == 0 {
        return;
    }
    let rows = band_rows(h);
    let avx2 = crate::simd::has_avx2();
    out.par_chunks_mut(rows * w * out_stride).enumerate().for_each(|(b, chunk)| {
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            // SAFETY: `avx2` is true only when AVX2 and FMA were detected on this CPU.
            unsafe { band_avx2::<K, P, C>(w, h, r, b * rows, chunk, out_stride, &produce, &consume) };
            return;
        }
        let _ = avx2;
        band::<K, P, C>(w, h, r, b * rows, chunk, out_stride, &produce, &consume)
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
            let mut out = vec![0.0f32; w * h * 2];
            box_sums::<2, _, _>(
                w,
                h,
                r,
                &mut out,
                2,
                |y, row| row.copy_from_slice(&data[y * w..(y + 1) * w]),
                |_, sums, out_row| {
                    for (o, s) in out_row.chunks_exact_mut(2).zip(sums) {
                        o.copy_from_slice(s);
                    }
                },
            );
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
}
