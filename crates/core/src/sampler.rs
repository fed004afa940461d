//! Deterministic low-discrepancy sampler: Owen-scrambled Sobol (0,2)-sequence pairs with
//! hash-based nested uniform scrambling and per-dimension-pair index shuffling
//! (Burley 2020, "Practical Hash-based Owen Scrambling", JCGT 9(4), listings 1-6).
//!
//! Every value is a pure function of `(pixel, sample index, dimension, seed)`: there is no
//! state shared between pixels, so an image is bit-identical whatever the thread count or
//! the tile order.
//!
//! How a value is made (Burley 2020, sec. 4-5):
//! 1. The dimensions are consumed in pairs (`next_2d`) or singly (`next_1d`); each call uses
//!    a fresh *dimension slot* `d`.
//! 2. A 32-bit seed per (pixel, slot, user seed) is hashed.
//! 3. The sample index is shuffled by a nested uniform scramble of its bits (which
//!    permutes every aligned block of `2^k` indices among itself), so that the pairs of
//!    different slots are decorrelated ("padding" the 2D Sobol pairs across dimensions).
//! 4. The first two Sobol dimensions (van der Corput and its (0,2) partner) are evaluated at
//!    the shuffled index and each is Owen-scrambled with its own seed.
//!
//! The first `2^k` samples of one pair therefore form a (0,k,2)-net: each of the `2^k`
//! elementary intervals of every shape `2^-a x 2^-(k-a)` holds exactly one point.
//!
//! ```
//! use filtrace_core::sampler::Sampler;
//! let mut s = Sampler::new(3, 7, 0, 42);
//! let u = s.next_2d();
//! assert!((0.0..1.0).contains(&u.x) && (0.0..1.0).contains(&u.y));
//! // Same key, same value.
//! assert_eq!(Sampler::new(3, 7, 0, 42).next_2d(), u);
//! ```

use glam::Vec2;

/// Generator matrix columns of Sobol dimension 1 (dimension 0 is the bit reversal of the
/// index). Column `i` is `v_i = v_{i-1} ^ (v_{i-1} >> 1)` with `v_0 = 2^31` (the Pascal
/// matrix mod 2).
const SOBOL_DIM1: [u32; 32] = {
    let mut v = [0u32; 32];
    v[0] = 1 << 31;
    let mut i = 1;
    while i < 32 {
        v[i] = v[i - 1] ^ (v[i - 1] >> 1);
        i += 1;
    }
    v
};

/// Largest `f32` below one; values are clamped to it so that `u < 1` always holds.
pub const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// Sobol dimension 0 (van der Corput radical inverse in base 2) as a 0.32 fixed-point value.
#[inline]
pub fn sobol_dim0(index: u32) -> u32 {
    index.reverse_bits()
}

/// Byte tables of a map linear over GF(2) with generator columns `cols`: `t[k][b]` is the
/// XOR of the columns selected by byte `k` of an index holding the value `b`, so four
/// lookups replace a loop over 32 bits.
const fn byte_tables(cols: [u32; 32]) -> [[u32; 256]; 4] {
    let mut t = [[0u32; 256]; 4];
    let mut k = 0;
    while k < 4 {
        let mut b = 0;
        while b < 256 {
            let mut x = 0u32;
            let mut bit = 0;
            while bit < 8 {
                if b & (1 << bit) != 0 {
                    x ^= cols[8 * k + bit];
                }
                bit += 1;
            }
            t[k][b] = x;
            b += 1;
        }
        k += 1;
    }
    t
}

/// Byte tables of Sobol dimension 1 (the shuffled indices use all 32 bits): the sampler's
/// share of the Cornell box profile fell from 33% to under 2% (perf, docs/perf-render.md).
const SOBOL_DIM1_BYTES: [[u32; 256]; 4] = byte_tables(SOBOL_DIM1);

/// Byte tables of the map `i_rev -> reverse(sobol_dim1(reverse(i_rev)))` (also linear over
/// GF(2): column `j` is column `31 - j` of dimension 1, reversed), so that the sampler can
/// work on bit-reversed indices and skip two reversals. Public for samplers that look them
/// up with SIMD gathers (the render crate's 8-lane sampler).
pub static SOBOL_DIM1_REV_TABLES: [[u32; 256]; 4] = {
    let mut cols = [0u32; 32];
    let mut j = 0;
    while j < 32 {
        cols[j] = SOBOL_DIM1[31 - j].reverse_bits();
        j += 1;
    }
    byte_tables(cols)
};

/// `reverse(sobol_dim1(reverse(i_rev)))` by four table lookups (public for samplers that
/// evaluate several sample keys at once, e.g. the render crate's 8-lane sampler).
#[inline]
pub fn sobol_dim1_reversed(i_rev: u32) -> u32 {
    SOBOL_DIM1_REV_TABLES[0][(i_rev & 0xff) as usize]
        ^ SOBOL_DIM1_REV_TABLES[1][((i_rev >> 8) & 0xff) as usize]
        ^ SOBOL_DIM1_REV_TABLES[2][((i_rev >> 16) & 0xff) as usize]
        ^ SOBOL_DIM1_REV_TABLES[3][(i_rev >> 24) as usize]
}

/// Sobol dimension 1 as a 0.32 fixed-point value.
#[inline]
pub fn sobol_dim1(index: u32) -> u32 {
    SOBOL_DIM1_BYTES[0][(index & 0xff) as usize]
        ^ SOBOL_DIM1_BYTES[1][((index >> 8) & 0xff) as usize]
        ^ SOBOL_DIM1_BYTES[2][((index >> 16) & 0xff) as usize]
        ^ SOBOL_DIM1_BYTES[3][(index >> 24) as usize]
}

/// Sobol dimension 1 by the definition (one generator column per set index bit), the naive
/// reference for [`sobol_dim1`].
pub fn sobol_dim1_naive(index: u32) -> u32 {
    (0..32).filter(|&bit| index & (1 << bit) != 0).fold(0, |x, bit| x ^ SOBOL_DIM1[bit])
}

/// Laine-Karras style hash permutation: bit `i` of the result depends only on bits `<= i`
/// of `x` (Burley 2020, listing 3, with the improved constants of its sec. 5).
#[inline]
pub fn laine_karras_permutation(mut x: u32, seed: u32) -> u32 {
    x = x.wrapping_add(seed);
    x ^= x.wrapping_mul(0x6c50_b47c);
    x ^= x.wrapping_mul(0xb82f_1e52);
    x ^= x.wrapping_mul(0xc7af_e638);
    x ^= x.wrapping_mul(0x8d22_f6e6);
    x
}

/// Nested uniform (Owen) scramble of a 0.32 fixed-point value: each bit is flipped by a
/// hash of the more significant bits (Burley 2020, listing 4).
#[inline]
pub fn nested_uniform_scramble(x: u32, seed: u32) -> u32 {
    laine_karras_permutation(x.reverse_bits(), seed).reverse_bits()
}

/// A well-mixing 32-bit hash (the "lowbias32" finaliser of Chris Wellons' hash prospector).
#[inline]
pub fn hash_u32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// Combines a hash with a new value (boost's `hash_combine`, Burley 2020, listing 6).
#[inline]
pub fn hash_combine(seed: u32, v: u32) -> u32 {
    seed ^ v.wrapping_add(0x9e37_79b9).wrapping_add(seed << 6).wrapping_add(seed >> 2)
}

/// 0.32 fixed point to a float in `[0, 1)` (the top 24 bits, exactly representable: the
/// largest value is `(2^24 - 1) / 2^24 = ONE_MINUS_EPSILON`, so no clamp is needed).
#[inline]
pub fn to_unit_float(x: u32) -> f32 {
    (x >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// The shuffled, Owen-scrambled Sobol pair of `index` for the given 32-bit `seed`
/// (Burley 2020, listing 5), as 0.32 fixed-point values. This is the readable reference;
/// [`Sampler`] computes the same bits with fewer bit reversals.
#[inline]
pub fn shuffled_scrambled_sobol_2d(index: u32, seed: u32) -> (u32, u32) {
    let i = nested_uniform_scramble(index, seed);
    let x = nested_uniform_scramble(sobol_dim0(i), hash_combine(seed, 0));
    let y = nested_uniform_scramble(sobol_dim1(i), hash_combine(seed, 1));
    (x, y)
}

/// Per-sample sampler state: the key `(pixel, sample index, seed)` and the next dimension
/// slot. Cheap to create; make one per (pixel, sample).
#[derive(Clone, Debug)]
pub struct Sampler {
    /// Hash of (pixel, seed); slots are combined into it.
    key: u32,
    index: u32,
    /// `index.reverse_bits()`, computed once.
    index_rev: u32,
    slot: u32,
}

impl Sampler {
    /// The sampler for sample `index` of pixel `(px, py)` under the user `seed`.
    #[inline]
    pub fn new(px: u32, py: u32, index: u32, seed: u64) -> Self {
        Self::from_pixel_key(Self::pixel_key(px, py, seed), index)
    }

    /// The hash of `(pixel, seed)` that every sample of the pixel shares (five hashes):
    /// renderers compute it once per pixel and make each sample's sampler with
    /// [`Sampler::from_pixel_key`].
    #[inline]
    pub fn pixel_key(px: u32, py: u32, seed: u64) -> u32 {
        let s = hash_u32(seed as u32 ^ hash_u32((seed >> 32) as u32 ^ 0x5bd1_e995));
        hash_u32(hash_combine(hash_combine(s, hash_u32(px)), hash_u32(py ^ 0x27d4_eb2f)))
    }

    /// The sampler of sample `index` of the pixel whose [`Sampler::pixel_key`] is `key`;
    /// equal to `Sampler::new(px, py, index, seed)`.
    #[inline]
    pub fn from_pixel_key(key: u32, index: u32) -> Self {
        Self { key, index, index_rev: index.reverse_bits(), slot: 0 }
    }

    /// The sample index within the pixel.
    #[inline]
    pub fn index(&self) -> u32 {
        self.index
    }

    /// Jumps to dimension slot `slot` (integrators use this to give each bounce a fixed set
    /// of slots whatever branches were taken before).
    #[inline]
    pub fn set_slot(&mut self, slot: u32) {
        self.slot = slot;
    }

    /// The next dimension slot that will be consumed.
    #[inline]
    pub fn slot(&self) -> u32 {
        self.slot
    }

    #[inline]
    fn slot_seed(&mut self) -> u32 {
        let seed = hash_u32(hash_combine(self.key, self.slot));
        self.slot += 1;
        seed
    }

    /// A 2D sample in `[0, 1)^2`; the first `2^k` indices of one slot are a (0,k,2)-net.
    ///
    /// Bit-identical to [`shuffled_scrambled_sobol_2d`] with the slot's seed, rewritten on
    /// reversed indices: with `nus(v, s) = rev(LK(rev(v), s))` and `sobol_dim0 = rev`,
    /// the reversed shuffled index is `i_rev = LK(rev(index), s)`, `x = rev(LK(rev(i_rev),
    /// s0))` and `y = rev(LK(rev(sobol_dim1(rev(i_rev))), s1))` (the inner map by table).
    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        let seed = self.slot_seed();
        let i_rev = laine_karras_permutation(self.index_rev, seed);
        let x = laine_karras_permutation(i_rev.reverse_bits(), hash_combine(seed, 0)).reverse_bits();
        let y = laine_karras_permutation(sobol_dim1_reversed(i_rev), hash_combine(seed, 1)).reverse_bits();
        Vec2::new(to_unit_float(x), to_unit_float(y))
    }

    /// A 1D sample in `[0, 1)`; the first `2^k` indices of one slot are stratified in `2^k`
    /// equal intervals (one Owen-scrambled van der Corput dimension; equal to the `x` of
    /// `next_2d` on the same slot).
    #[inline]
    pub fn next_1d(&mut self) -> f32 {
        let seed = self.slot_seed();
        let i_rev = laine_karras_permutation(self.index_rev, seed);
        to_unit_float(laine_karras_permutation(i_rev.reverse_bits(), hash_combine(seed, 0)).reverse_bits())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_in_unit_interval() {
        for px in 0..8 {
            for i in 0..256 {
                let mut s = Sampler::new(px, px * 3, i, 7);
                for _ in 0..8 {
                    let u = s.next_2d();
                    assert!((0.0..1.0).contains(&u.x) && (0.0..1.0).contains(&u.y), "{u}");
                    let v = s.next_1d();
                    assert!((0.0..1.0).contains(&v), "{v}");
                }
            }
        }
        assert!(to_unit_float(u32::MAX) < 1.0);
        assert_eq!(to_unit_float(u32::MAX), ONE_MINUS_EPSILON);
    }

    #[test]
    fn sobol_dim1_matches_known_prefix() {
        // Sobol dimension 2 in natural (not Gray-code) index order.
        let expect = [0.0, 0.5, 0.75, 0.25, 0.625, 0.125, 0.375, 0.875];
        for (i, e) in expect.iter().enumerate() {
            assert_eq!(sobol_dim1(i as u32) as f64 / 4294967296.0, *e, "index {i}");
        }
    }

    /// The sampler's reversed-domain arithmetic gives the bits of Burley's listing.
    #[test]
    fn fast_sampler_matches_reference_listing() {
        for index in (0..2000u32).chain([u32::MAX, 1 << 31, 123_456_789]) {
            let mut s = Sampler::new(17, 4, index, 5);
            s.set_slot(6);
            let seed = hash_u32(hash_combine(s.key, 6));
            let (x, y) = shuffled_scrambled_sobol_2d(index, seed);
            assert_eq!(s.next_2d(), Vec2::new(to_unit_float(x), to_unit_float(y)), "index {index}");
            s.set_slot(6);
            assert_eq!(s.next_1d(), to_unit_float(x));
        }
    }

    #[test]
    fn table_sobol_matches_naive() {
        let mut x = 0x1234_5678u32;
        for i in 0..100_000u32 {
            x = hash_u32(x ^ i);
            assert_eq!(sobol_dim1(x), sobol_dim1_naive(x));
            assert_eq!(sobol_dim1(i), sobol_dim1_naive(i));
        }
    }

    /// The first 2^k samples of every pair are a (0,k,2)-net: every elementary interval
    /// `2^-a x 2^-(k-a)` holds exactly one point.
    #[test]
    fn first_power_of_two_samples_are_a_0k2_net() {
        for k in [2u32, 4, 6, 8] {
            let n = 1u32 << k;
            for (px, slot) in [(0u32, 0u32), (5, 1), (17, 3), (123, 9)] {
                let pts: Vec<Vec2> = (0..n)
                    .map(|i| {
                        let mut s = Sampler::new(px, 2 * px + 1, i, 99);
                        s.set_slot(slot);
                        s.next_2d()
                    })
                    .collect();
                for a in 0..=k {
                    let (nx, ny) = (1u32 << a, 1u32 << (k - a));
                    let mut cells = vec![0u32; n as usize];
                    for p in &pts {
                        let cx = (p.x * nx as f32) as u32;
                        let cy = (p.y * ny as f32) as u32;
                        cells[(cy * nx + cx) as usize] += 1;
                    }
                    assert!(cells.iter().all(|&c| c == 1), "k={k} a={a} px={px} slot={slot}");
                }
                // 1D slots are stratified too.
                let mut strata = vec![0u32; n as usize];
                for i in 0..n {
                    let mut s = Sampler::new(px, 0, i, 99);
                    s.set_slot(slot);
                    strata[(s.next_1d() * n as f32) as usize] += 1;
                }
                assert!(strata.iter().all(|&c| c == 1), "1D k={k}");
            }
        }
    }

    #[test]
    fn pixel_key_gives_the_same_sampler() {
        for (px, py, i, seed) in [(0u32, 0u32, 0u32, 0u64), (17, 4, 9, 5), (511, 3, 1 << 20, u64::MAX)] {
            let mut a = Sampler::new(px, py, i, seed);
            let mut b = Sampler::from_pixel_key(Sampler::pixel_key(px, py, seed), i);
            assert_eq!((a.next_2d(), a.next_1d()), (b.next_2d(), b.next_1d()));
        }
    }

    #[test]
    fn deterministic_and_seed_dependent() {
        let draw = |seed| {
            let mut s = Sampler::new(10, 20, 5, seed);
            (s.next_2d(), s.next_1d(), s.next_2d())
        };
        assert_eq!(draw(1), draw(1));
        assert_ne!(draw(1), draw(2));
        // Seeds differing only in the high 32 bits differ too.
        assert_ne!(draw(1), draw(1 | (1 << 40)));
    }

    /// Samples of neighbouring pixels (and of different slots of one pixel) are
    /// uncorrelated: the sample correlation of the first values over many pixels is ~0.
    #[test]
    fn pixels_and_dimensions_are_decorrelated() {
        let n = 4096usize;
        let mut a = Vec::with_capacity(n);
        let mut b = Vec::with_capacity(n);
        let mut c = Vec::with_capacity(n);
        for p in 0..n as u32 {
            let (x, y) = (p % 64, p / 64);
            let mut s0 = Sampler::new(x, y, 0, 3);
            let u0 = s0.next_2d();
            let u1 = s0.next_2d();
            let mut s1 = Sampler::new(x + 1, y, 0, 3);
            a.push(u0.x as f64);
            b.push(s1.next_2d().x as f64);
            c.push(u1.x as f64);
        }
        let corr = |x: &[f64], y: &[f64]| {
            let mx = x.iter().sum::<f64>() / n as f64;
            let my = y.iter().sum::<f64>() / n as f64;
            let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
            let sxx: f64 = x.iter().map(|a| (a - mx).powi(2)).sum();
            let syy: f64 = y.iter().map(|b| (b - my).powi(2)).sum();
            sxy / (sxx * syy).sqrt()
        };
        // Under independence the correlation is ~N(0, 1/n): 5 sigma = 5/64 = 0.078.
        assert!(corr(&a, &b).abs() < 0.078, "neighbour pixels {}", corr(&a, &b));
        assert!(corr(&a, &c).abs() < 0.078, "slots {}", corr(&a, &c));
        // And the first sample over pixels is uniform: mean 0.5 within 5 sigma.
        let m = a.iter().sum::<f64>() / n as f64;
        assert!((m - 0.5).abs() < 5.0 * (1.0 / 12.0f64 / n as f64).sqrt(), "mean {m}");
    }

    /// Monte Carlo integration with the sampler converges faster than 1/sqrt(N): integrate a
    /// smooth function with 256 samples per pixel and check the error over many pixels is
    /// far below the random-sampling standard error.
    #[test]
    fn integrates_smooth_function_better_than_random() {
        let f = |u: Vec2| (u.x * u.y).sin() + u.x * u.x; // integral = 0.239811742 + 1/3
        let exact = 0.239_811_742_f64 + 1.0 / 3.0;
        let mut err2 = 0.0f64;
        let pixels = 64u32;
        for p in 0..pixels {
            let mut sum = 0.0f64;
            for i in 0..256 {
                let mut s = Sampler::new(p, 0, i, 11);
                s.set_slot(2);
                sum += f(s.next_2d()) as f64;
            }
            err2 += (sum / 256.0 - exact).powi(2);
        }
        let rmse = (err2 / pixels as f64).sqrt();
        // Random sampling: sigma(f) ~ 0.33 -> std error ~0.02 at 256 samples.
        assert!(rmse < 0.002, "rmse {rmse}");
    }
}
