//! The SIMD instruction sets of this CPU, detected once per process.
//!
//! Every crate's fast paths ask [`isa`] (never `is_x86_feature_detected!` directly), so
//! one detection decides them all: the BVH kernels (`filtrace_accel::Simd`), the
//! filters' row loops (`filtrace_denoise::simd`, which may narrow it per thread for
//! tests) and the lockstep tracer's lane code (`filtrace_render`). Each fast path is
//! bit-identical to its baseline build, so the level changes only the speed.

use std::sync::OnceLock;

/// An instruction-set level, narrowest first: a CPU that runs a level runs every lower
/// one (`Isa::Avx2 < Isa::Avx512`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Isa {
    /// The baseline build: SSE2 on x86-64, portable code elsewhere.
    Base,
    /// AVX2 and FMA (8 f32 lanes, 16 vector registers).
    Avx2,
    /// AVX-512F and AVX-512VL on top of AVX2 and FMA (16 lanes, or 8 lanes with 32
    /// vector registers and mask registers).
    Avx512,
}

/// The widest level this CPU runs, detected on the first call.
#[inline]
pub fn isa() -> Isa {
    static ISA: OnceLock<Isa> = OnceLock::new();
    *ISA.get_or_init(detect)
}

#[cfg(target_arch = "x86_64")]
fn detect() -> Isa {
    use std::arch::is_x86_feature_detected as has;
    if !(has!("avx2") && has!("fma")) {
        Isa::Base
    } else if has!("avx512f") && has!("avx512vl") {
        Isa::Avx512
    } else {
        Isa::Avx2
    }
}

#[cfg(not(target_arch = "x86_64"))]
fn detect() -> Isa {
    Isa::Base
}

impl Isa {
    /// True when code built for AVX2 and FMA may run (`#[target_feature(enable =
    /// "avx2,fma")]`).
    #[inline]
    pub fn has_avx2(self) -> bool {
        self >= Isa::Avx2
    }

    /// True when code built for AVX-512F and AVX-512VL (and AVX2, FMA) may run.
    #[inline]
    pub fn has_avx512(self) -> bool {
        self >= Isa::Avx512
    }

    /// f32 lanes of one full-width vector.
    pub fn lanes(self) -> usize {
        match self {
            Isa::Base => 4,
            Isa::Avx2 => 8,
            Isa::Avx512 => 16,
        }
    }

    /// Every level this CPU runs, widest first (tests run each against the baseline).
    pub fn supported() -> Vec<Isa> {
        [Isa::Avx512, Isa::Avx2, Isa::Base].into_iter().filter(|&i| i <= isa()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cached level is what the CPU reports, and the levels nest.
    #[test]
    fn detected_once_and_levels_nest() {
        let first = isa();
        assert_eq!(isa(), first);
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            assert_eq!(first.has_avx2(), has!("avx2") && has!("fma"));
            assert_eq!(first.has_avx512(), first.has_avx2() && has!("avx512f") && has!("avx512vl"));
        }
        assert!(Isa::Base < Isa::Avx2 && Isa::Avx2 < Isa::Avx512);
        let s = Isa::supported();
        assert_eq!((s[0], *s.last().unwrap()), (first, Isa::Base));
        assert!(s.windows(2).all(|w| w[0] > w[1] && w[0].lanes() > w[1].lanes()));
    }
}
