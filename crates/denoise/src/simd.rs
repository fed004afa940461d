//! Vectorisation helpers: a branch-free `exp(-x)` that auto-vectorises, and runtime dispatch
//! of hot row loops to an AVX2 build of the same generic code.
//!
//! The hot loops are written once as `#[inline(always)]` generic functions over planar
//! `f32` slices; [`dispatch!`] calls them through a `#[target_feature(enable = "avx2,fma")]`
//! wrapper when the CPU has AVX2 (8 lanes), else through the baseline (SSE2, 4 lanes) build.
//! [`with_isa`] narrows the build on one thread, so tests check every build on any machine.

/// `exp(-x)` for `x >= 0` (clamped to `[0, 87]`), relative error below 5e-6 (for large `x`
/// dominated by the f32 rounding of `x * log2(e)`; below 3e-7 for `x < 1`).
///
/// Range reduction `2^t = 2^round(t) * 2^f` with `f` in `[-0.5, 0.5]` by the `1.5 * 2^23`
/// rounding trick (SSE2 has no `floor`), then a degree-6 Taylor polynomial of `2^f`.
#[inline(always)]
pub fn exp_neg(x: f32) -> f32 {
    exp_neg_g::<false>(x)
}

/// `a * b + c`, fused (one rounding) when `F`: only for builds with hardware FMA (the
/// `#[target_feature(enable = "fma")]` paths), where `f32::mul_add` is one instruction.
#[inline(always)]
pub fn madd<const F: bool>(a: f32, b: f32, c: f32) -> f32 {
    if F {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// [`exp_neg`] with the polynomial evaluated by fused multiply-adds when `F` (half the
/// dependent-latency chain; differs from `exp_neg` by a rounding or two, same error bounds,
/// tested).
#[inline(always)]
pub fn exp_neg_g<const F: bool>(x: f32) -> f32 {
    const MAGIC: f32 = 12_582_912.0; // 1.5 * 2^23: adding it rounds to an integer
    let x = x.clamp(0.0, 87.0);
    let t = x * -std::f32::consts::LOG2_E;
    let tm = t + MAGIC;
    let r = tm - MAGIC;
    let f = t - r;
    let i = (tm.to_bits() as i32).wrapping_sub(MAGIC.to_bits() as i32);
    let scale = f32::from_bits(((i + 127) << 23) as u32);
    let p = if F {
        let p = madd::<F>(f, 1.540_353e-4, 0.001_333_355);
        let p = madd::<F>(f, p, 0.009_618_129);
        let p = madd::<F>(f, p, 0.055_504_11);
        let p = madd::<F>(f, p, 0.240_226_5);
        let p = madd::<F>(f, p, std::f32::consts::LN_2);
        madd::<F>(f, p, 1.0)
    } else {
        1.0 + f
            * (std::f32::consts::LN_2
                + f * (0.240_226_5
                    + f * (0.055_504_11 + f * (0.009_618_129 + f * (0.001_333_355 + f * 1.540_353e-4)))))
    };
    p * scale
}

/// `2^(log2_h - x log2(e)) = h exp(-x)` for `x >= 0`: [`exp_neg_g`] with a constant factor
/// `h = 2^log2_h` (`h <= 1`) folded into the exponent, one multiply fewer per weight.
/// Relative error below 5e-6 against `h exp(-x)` (tested), as `exp_neg`.
///
/// Values below [`SCALED_EXP_MIN_LOG2`] (`2^-100`, about 8e-31) are exactly 0: a weight
/// that small changes no normalised sum, and flushing it keeps the products `w c` out of
/// the subnormal range, whose arithmetic is microcoded and slow (the coarse À-Trous levels,
/// where `w_rt`'s exponent is large, would hit it: docs/perf-filters.md).
#[inline(always)]
// `!(t >= min)` on purpose: one comparison that is also true for NaN.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
pub fn scaled_exp_neg<const F: bool>(x: f32, log2_h: f32) -> f32 {
    const MAGIC: f32 = 12_582_912.0; // 1.5 * 2^23: adding it rounds to an integer
    let t = madd::<F>(x, -std::f32::consts::LOG2_E, log2_h);
    // One comparison for both: false for NaN.
    if !(t >= SCALED_EXP_MIN_LOG2) {
        return 0.0;
    }
    let tm = t + MAGIC;
    let r = tm - MAGIC;
    let f = t - r;
    let i = (tm.to_bits() as i32).wrapping_sub(MAGIC.to_bits() as i32);
    let scale = f32::from_bits(((i + 127) << 23) as u32);
    // 2^f on [-1/2, 1/2], degree 5, fitted to the relative error (Lawson iterations): 1.9e-7
    // relative in f32, one multiply-add less than the degree-6 polynomial of `exp_neg_g`
    // (12 evaluations per pixel and À-Trous level).
    let p = madd::<F>(f, 0.001_326_47, 0.009_671_51);
    let p = madd::<F>(f, p, 0.055_507_34);
    let p = madd::<F>(f, p, 0.240_222_42);
    // 0.693_146_98 (a fitted value 3 ulp from ln 2), written by its bits for clippy.
    let p = madd::<F>(f, p, f32::from_bits(0x3f317215));
    madd::<F>(f, p, 1.0) * scale
}

/// `log2` of the smallest non-zero value of [`scaled_exp_neg`].
pub const SCALED_EXP_MIN_LOG2: f32 = -100.0;

/// The instruction set the hot loops run with (detected once per process by
/// [`filtrace_core::cpu`]).
pub use filtrace_core::cpu::Isa;

/// The instruction set the hot loops run with: the widest this CPU runs, narrowed on the
/// calling thread by [`with_isa`]. Every filter reads it once, on the calling thread,
/// before it hands rows to worker threads.
#[inline]
pub fn isa() -> Isa {
    let cpu = cpu_isa();
    match ISA_CAP.with(|c| c.get()) {
        Some(cap) if cap.lanes() < cpu.lanes() => cap,
        _ => cpu,
    }
}

/// The widest instruction set of the hot loops this CPU runs ([`filtrace_core::cpu::isa`]).
#[inline]
pub fn cpu_isa() -> Isa {
    filtrace_core::cpu::isa()
}

thread_local! {
    static ISA_CAP: std::cell::Cell<Option<Isa>> = const { std::cell::Cell::new(None) };
}

/// Runs `f` with the filters' builds narrowed to at most `cap` on this thread (a wider `cap`
/// than the CPU runs changes nothing: never unsafe). For tests and benchmarks that compare
/// the builds on one machine; the previous cap is restored afterwards, also on a panic.
pub fn with_isa<R>(cap: Isa, f: impl FnOnce() -> R) -> R {
    struct Restore(Option<Isa>);
    impl Drop for Restore {
        fn drop(&mut self) {
            ISA_CAP.with(|c| c.set(self.0));
        }
    }
    let _restore = Restore(ISA_CAP.with(|c| c.replace(Some(cap))));
    f()
}

/// True when the AVX2 build of the hot loops may run on this CPU.
#[inline]
pub fn has_avx2() -> bool {
    cpu_isa().has_avx2()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_neg_fma_matches_std_exp() {
        let mut worst = 0.0f64;
        for k in 0..=200_000 {
            let x = k as f32 * (87.0 / 200_000.0);
            let exact = (-(x as f64)).exp();
            worst = worst.max(((exp_neg_g::<true>(x) as f64 - exact) / exact).abs());
        }
        assert!(worst < 5e-6, "worst relative error {worst}");
        for k in 0..=10_000 {
            let x = k as f32 * 1e-4;
            let exact = (-(x as f64)).exp();
            assert!(((exp_neg_g::<true>(x) as f64 - exact) / exact).abs() < 3e-7, "x = {x}");
        }
        assert_eq!(exp_neg_g::<true>(0.0), 1.0);
    }

    #[test]
    fn scaled_exp_neg_matches_std_exp() {
        // Every B3 kernel product h = b_x b_y (1/256 .. 9/64), and 1.
        let b3 = crate::kernel::B3_SPLINE;
        for h in b3.iter().flat_map(|a| b3.iter().map(move |b| a * b)).chain([1.0]) {
            let l = h.log2();
            for fma in [false, true] {
                let mut worst = 0.0f64;
                for k in 0..=100_000 {
                    let x = k as f32 * (80.0 / 100_000.0);
                    let exact = h as f64 * (-(x as f64)).exp();
                    let got = if fma { scaled_exp_neg::<true>(x, l) } else { scaled_exp_neg::<false>(x, l) };
                    if exact.log2() < SCALED_EXP_MIN_LOG2 as f64 - 1e-3 {
                        assert_eq!(got, 0.0, "h = {h}, x = {x}: below 2^-100 flushes to 0");
                    } else if exact.log2() > SCALED_EXP_MIN_LOG2 as f64 + 1e-3 {
                        worst = worst.max(((got as f64 - exact) / exact).abs());
                    }
                }
                assert!(worst < 5e-6, "h = {h}, fma {fma}: worst relative error {worst}");
            }
            assert_eq!(scaled_exp_neg::<false>(f32::INFINITY, l), 0.0);
            assert_eq!(scaled_exp_neg::<true>(0.0, 0.0), 1.0);
        }
    }

    #[test]
    fn exp_neg_matches_std_exp() {
        let mut worst = 0.0f64;
        for k in 0..=200_000 {
            let x = k as f32 * (87.0 / 200_000.0);
            let exact = (-(x as f64)).exp();
            let rel = ((exp_neg(x) as f64 - exact) / exact).abs();
            worst = worst.max(rel);
        }
        assert!(worst < 5e-6, "worst relative error {worst}");
        for k in 0..=10_000 {
            let x = k as f32 * 1e-4;
            let exact = (-(x as f64)).exp();
            assert!(((exp_neg(x) as f64 - exact) / exact).abs() < 3e-7, "x = {x}");
        }
        assert_eq!(exp_neg(0.0), 1.0);
        assert!(exp_neg(1e30) > 0.0 && exp_neg(1e30) < 1e-37);
        assert_eq!(exp_neg(-5.0), 1.0, "negative arguments clamp to 0");
    }
}
