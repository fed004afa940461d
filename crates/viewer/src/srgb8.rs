//! 8-bit sRGB encoding of display values by table. `(srgb_oetf(y) * 255 + 0.5) as u8` (the
//! PNG writer's expression, [`filtrace_io::tonemap_srgb8`]) is a step function of `y` with
//! 255 steps: their thresholds are found once, by bisection over the f32 values in [0, 1],
//! and an encoding is then a binary search of 8 comparisons instead of a `powf`, giving the
//! same byte for every input because the expression is monotone in `y` (tested).

use std::sync::OnceLock;

use filtrace_io::srgb_oetf;

/// The PNG writer's encoding of a display value.
#[inline]
fn reference(y: f32) -> u8 {
    (srgb_oetf(y) * 255.0 + 0.5) as u8
}

/// `t[k]`: the smallest f32 `y` in [0, 1] that encodes to `k` or more (`t[0] = 0`).
fn thresholds() -> &'static [f32; 256] {
    static TABLE: OnceLock<[f32; 256]> = OnceLock::new();
    TABLE.get_or_init(|| {
        let mut t = [0.0f32; 256];
        for (k, slot) in t.iter_mut().enumerate().skip(1) {
            // Non-negative f32s are ordered as their bits: bisect the bits, keeping
            // reference(lo) < k <= reference(hi).
            let (mut lo, mut hi) = (0u32, 1.0f32.to_bits());
            while hi - lo > 1 {
                let mid = lo + (hi - lo) / 2;
                if reference(f32::from_bits(mid)) as usize >= k {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            *slot = f32::from_bits(hi);
        }
        t
    })
}

/// `(srgb_oetf(y) * 255 + 0.5) as u8` for a display value `y` in [0, 1] (as
/// [`filtrace_io::TonemapParams::display`] gives).
#[inline]
pub fn encode(y: f32) -> u8 {
    let t = thresholds();
    // The largest k with t[k] <= y.
    let mut k = 0;
    for step in [128, 64, 32, 16, 8, 4, 2, 1] {
        if t[k + step] <= y {
            k += step;
        }
    }
    k as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every 61st f32 of [0, 1] and every f32 within 256 ulps of a step: the table gives the
    /// PNG writer's byte.
    #[test]
    fn the_table_encodes_as_the_png_writer() {
        let one = 1.0f32.to_bits();
        let check = |bits: u32| {
            let y = f32::from_bits(bits);
            assert_eq!(encode(y), reference(y), "y = {y:e} (bits {bits:#x})");
        };
        (0..=one).step_by(61).for_each(check);
        for &t in &thresholds()[1..] {
            let b = t.to_bits();
            (b.saturating_sub(256)..=(b + 256).min(one)).for_each(check);
        }
        check(one);
        assert_eq!((encode(0.0), encode(1.0)), (0, 255));
    }
}
