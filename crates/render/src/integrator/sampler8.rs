//! The Owen-scrambled Sobol sampler of [`filtrace_core::sampler::Sampler`] evaluated for
//! eight sample keys at once on [`U8`] lanes, bit for bit (see the exactness note of
//! [`super::lanes`]).

use super::lanes::{F8, LANES, U8};

/// `hash_combine(seed, v)` lane-wise (`seed ^ (v + 0x9e3779b9 + (seed << 6) + (seed >> 2))`).
#[inline(always)]
fn hash_combine8<const A: bool>(seed: U8<A>, v: U8<A>) -> U8<A> {
    seed.xor(
        v.wrapping_add(U8::splat(0x9e37_79b9)).wrapping_add(seed.shl::<6>()).wrapping_add(seed.shr::<2>()),
    )
}

/// `hash_u32` lane-wise.
#[inline(always)]
fn hash_u32_8<const A: bool>(x: U8<A>) -> U8<A> {
    let x = x.xor(x.shr::<16>());
    let x = x.wrapping_mul(U8::splat(0x7feb_352d));
    let x = x.xor(x.shr::<15>());
    let x = x.wrapping_mul(U8::splat(0x846c_a68b));
    x.xor(x.shr::<16>())
}

/// `laine_karras_permutation` lane-wise.
#[inline(always)]
fn laine_karras8<const A: bool>(x: U8<A>, seed: U8<A>) -> U8<A> {
    let x = x.wrapping_add(seed);
    let x = x.xor(x.wrapping_mul(U8::splat(0x6c50_b47c)));
    let x = x.xor(x.wrapping_mul(U8::splat(0xb82f_1e52)));
    let x = x.xor(x.wrapping_mul(U8::splat(0xc7af_e638)));
    x.xor(x.wrapping_mul(U8::splat(0x8d22_f6e6)))
}

/// [`filtrace_core::sampler::Sampler`] for eight sample keys at once: lane `i` is the
/// sampler of pixel key `key[i]` (a [`Sampler::pixel_key`]) and the common sample index.
/// `next_2d(slot)` equals `Sampler::set_slot(slot); Sampler::next_2d()` of each lane, bit
/// for bit (same integer hashes, lane-wise: `vpmulld`, shifts and xors; bit reversals by
/// `vpshufb`; Sobol dimension 1 by five shift-and-xor steps, [`sobol_dim1_reversed8`]).
///
/// `AVX2 = true` (only inside code compiled for AVX2, such as the AVX2 tile loop) uses the
/// AVX2 instructions, `false` plain per-lane code.
///
/// [`Sampler::pixel_key`]: filtrace_core::sampler::Sampler::pixel_key
#[derive(Clone, Copy, Debug)]
pub struct Sampler8<const AVX2: bool> {
    pub key: U8<AVX2>,
    index_rev: u32,
}

/// [`filtrace_core::sampler::sobol_dim1_reversed`] of eight lanes, from the unreversed index `idx`
/// (`= i_rev.reverse_bits()`, which the `x` of `next_2d` needs anyway). Column `i` of Sobol
/// dimension 1 has bit `31 - j` set iff `C(i, j)` is odd, i.e. (Lucas) iff the bits of `j`
/// are a subset of those of `i`; so bit `j` of the reversed result is the XOR of the index
/// bits `i` that are supersets of `j`: the superset-sum transform over the 5-bit bit
/// positions, five shift-and-xor steps (the four byte-table gathers they replace are
/// microcoded on Zen 4).
#[inline(always)]
fn sobol_dim1_reversed8<const A: bool>(idx: U8<A>) -> U8<A> {
    let x = idx;
    let x = x.xor(x.shr::<1>().and(U8::splat(0x5555_5555)));
    let x = x.xor(x.shr::<2>().and(U8::splat(0x3333_3333)));
    let x = x.xor(x.shr::<4>().and(U8::splat(0x0f0f_0f0f)));
    let x = x.xor(x.shr::<8>().and(U8::splat(0x00ff_00ff)));
    x.xor(x.shr::<16>())
}

impl<const AVX2: bool> Sampler8<AVX2> {
    #[inline(always)]
    pub fn new(key: [u32; LANES], index: u32) -> Self {
        Self::from_keys(U8::from_array(key), index)
    }

    /// The samplers of the pixel keys `key` at sample `index`.
    #[inline(always)]
    pub fn from_keys(key: U8<AVX2>, index: u32) -> Self {
        Sampler8 { key, index_rev: index.reverse_bits() }
    }

    /// Per-lane seed of `slot` and the reversed shuffled index.
    #[inline(always)]
    fn seed_and_index(&self, slot: u32) -> (U8<AVX2>, U8<AVX2>) {
        let seed = hash_u32_8(hash_combine8(self.key, U8::splat(slot)));
        let i_rev = laine_karras8(U8::splat(self.index_rev), seed);
        (seed, i_rev)
    }

    /// The 2D sample of dimension slot `slot` of every lane.
    #[inline(always)]
    pub fn next_2d(&self, slot: u32) -> (F8<AVX2>, F8<AVX2>) {
        let (seed, i_rev) = self.seed_and_index(slot);
        let idx = i_rev.reverse_bits();
        let x = laine_karras8(idx, hash_combine8(seed, U8::splat(0))).reverse_bits();
        let d1 = sobol_dim1_reversed8(idx);
        let y = laine_karras8(d1, hash_combine8(seed, U8::splat(1))).reverse_bits();
        (x.to_unit(), y.to_unit())
    }

    /// The 1D sample of dimension slot `slot` of every lane (the `x` of `next_2d`).
    #[inline(always)]
    pub fn next_1d(&self, slot: u32) -> F8<AVX2> {
        let (seed, i_rev) = self.seed_and_index(slot);
        laine_karras8(i_rev.reverse_bits(), hash_combine8(seed, U8::splat(0))).reverse_bits().to_unit()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use filtrace_core::sampler::{sobol_dim1_reversed, Sampler};

    #[test]
    fn sampler8_matches_the_scalar_sampler() {
        let keys: [u32; LANES] = std::array::from_fn(|i| Sampler::pixel_key(i as u32 * 7, 3, 11));
        for index in [0u32, 1, 2, 5, 255, 1 << 20, u32::MAX] {
            let s8 = Sampler8::<false>::new(keys, index);
            #[cfg(target_arch = "x86_64")]
            let avx2 = filtrace_core::cpu::isa().has_avx2();
            #[cfg(not(target_arch = "x86_64"))]
            let avx2 = false;
            for slot in [0u32, 1, 4, 33] {
                let (x, y) = s8.next_2d(slot);
                let one = s8.next_1d(slot);
                if avx2 {
                    // The AVX2 version (called here outside AVX2 code: correct, just
                    // not inlined).
                    let (gx, gy) = Sampler8::<true>::new(keys, index).next_2d(slot);
                    assert_eq!((gx.to_array(), gy.to_array()), (x.to_array(), y.to_array()));
                }
                for (i, &key) in keys.iter().enumerate() {
                    let mut s = Sampler::from_pixel_key(key, index);
                    s.set_slot(slot);
                    let u = s.next_2d();
                    assert_eq!((x.lane(i).to_bits(), y.lane(i).to_bits()), (u.x.to_bits(), u.y.to_bits()));
                    s.set_slot(slot);
                    assert_eq!(one.lane(i).to_bits(), s.next_1d().to_bits());
                }
            }
        }
    }

    #[test]
    fn sobol_dim1_reversed8_matches_the_byte_tables() {
        let mut x = 0x1234_5678u32;
        let mut vals: Vec<u32> = vec![0, 1, u32::MAX, 1 << 31, 0x8000_0001];
        vals.extend((0..32).map(|b| 1u32 << b));
        for _ in 0..4096 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            vals.push(x);
        }
        for c in vals.chunks(LANES) {
            let r: [u32; LANES] = std::array::from_fn(|i| c.get(i).copied().unwrap_or(7));
            let got = sobol_dim1_reversed8(U8::<false>::from_array(r.map(u32::reverse_bits))).to_array();
            assert_eq!(got, r.map(sobol_dim1_reversed));
        }
    }
}
