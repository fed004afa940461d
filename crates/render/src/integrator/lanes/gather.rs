//! Lanes from and to memory: eight-word loads, stream compaction ([`compress_store`]),
//! row transposes ([`columns`]) and eight-entry table lookups ([`lookup8`], [`alias_pick8`]).

use super::{per_lane, raw_from_i, raw_to_i, select, Raw, F8, LANES, M8, U8};
#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// Row `m`: the indices of the lanes set in `m`, in order, then the others (stream
/// compaction by one `vpermps`, [`compress_store`]).
static COMPRESS: [[u32; LANES]; 256] = compress_table();

const fn compress_table() -> [[u32; LANES]; 256] {
    let mut t = [[0u32; LANES]; 256];
    let mut m = 0;
    while m < 256 {
        let (mut j, mut i) = (0, 0);
        while i < LANES {
            if (m >> i) & 1 == 1 {
                t[m][j] = i as u32;
                j += 1;
            }
            i += 1;
        }
        i = 0;
        while i < LANES {
            if (m >> i) & 1 == 0 {
                t[m][j] = i as u32;
                j += 1;
            }
            i += 1;
        }
        m += 1;
    }
    t
}

/// The lanes of `v` set in `keep` moved to the front in lane order, the others after them
/// (one `vpermps` with AVX2).
#[inline(always)]
fn compress<const A: bool>(v: Raw, keep: u8) -> Raw {
    let idx = &COMPRESS[keep as usize];
    avx_or!(A, _mm256_permutevar8x32_ps(v, _mm256_loadu_si256(idx.as_ptr() as *const __m256i)), {
        let a = raw_to_i(v);
        raw_from_i(per_lane(|j| a[idx[j] as usize]))
    })
}

/// Stores the lanes of `v` set in `keep` at `dst[at..]`, packed in lane order; the words
/// up to `dst[at + 8]` after them are overwritten with the other lanes. `dst` may be the
/// slice `v` was loaded from (`at` at most the lane's old index: the stream compaction of
/// [`super::pool`]).
#[inline(always)]
pub fn compress_store<const A: bool>(v: F8<A>, keep: u8, dst: &mut [f32], at: usize) {
    let dst: &mut [f32; LANES] = (&mut dst[at..at + LANES]).try_into().expect("eight words");
    *dst = F8::<A>(compress::<A>(v.0, keep)).to_array();
}

/// [`compress_store`] of `u32` lanes.
#[inline(always)]
pub fn compress_store_u32<const A: bool>(v: U8<A>, keep: u8, dst: &mut [u32], at: usize) {
    let dst: &mut [u32; LANES] = (&mut dst[at..at + LANES]).try_into().expect("eight words");
    *dst = U8::<A>(compress::<A>(v.0, keep)).to_array();
}

/// `src[at..at + 8]` as lanes.
#[inline(always)]
pub fn load8<const A: bool>(src: &[f32], at: usize) -> F8<A> {
    F8::from_array(src[at..at + LANES].try_into().expect("eight words"))
}

/// `src[at..at + 8]` as `u32` lanes.
#[inline(always)]
pub fn load8_u32<const A: bool>(src: &[u32], at: usize) -> U8<A> {
    U8::from_array(src[at..at + LANES].try_into().expect("eight words"))
}

/// The mask as `u32` words (`u32::MAX` / 0; [`mask_of`] is the inverse).
#[inline(always)]
pub fn mask_words<const A: bool>(m: M8<A>) -> U8<A> {
    U8(m.0)
}

/// Eight-word rows of a table as lanes: `out[j]` lane `i` is `table[start[i] + j]`. With
/// AVX2 one unaligned load per row and an 8 x 8 transpose (`vunpcklps`/`vunpckhps`,
/// `vshufps`, `vperm2f128`: 24 shuffles) instead of 64 scalar loads and stores, or eight
/// gathers (slower on the development machine, see docs/perf-render.md). `None` when a
/// row does not lie in `table`.
#[inline(always)]
pub fn columns<const A: bool>(table: &[f32], start: &[usize; LANES]) -> Option<[F8<A>; 8]> {
    if start.iter().any(|&s| s > table.len() || table.len() - s < 8) {
        return None;
    }
    #[cfg(target_arch = "x86_64")]
    if A {
        // SAFETY: AVX (see `avx_or!`); every row `start[i]..start[i] + 8` is in `table`
        // (checked above).
        unsafe {
            let p = table.as_ptr();
            let r: [__m256; LANES] = [
                _mm256_loadu_ps(p.add(start[0])),
                _mm256_loadu_ps(p.add(start[1])),
                _mm256_loadu_ps(p.add(start[2])),
                _mm256_loadu_ps(p.add(start[3])),
                _mm256_loadu_ps(p.add(start[4])),
                _mm256_loadu_ps(p.add(start[5])),
                _mm256_loadu_ps(p.add(start[6])),
                _mm256_loadu_ps(p.add(start[7])),
            ];
            let t0 = _mm256_unpacklo_ps(r[0], r[1]);
            let t1 = _mm256_unpackhi_ps(r[0], r[1]);
            let t2 = _mm256_unpacklo_ps(r[2], r[3]);
            let t3 = _mm256_unpackhi_ps(r[2], r[3]);
            let t4 = _mm256_unpacklo_ps(r[4], r[5]);
            let t5 = _mm256_unpackhi_ps(r[4], r[5]);
            let t6 = _mm256_unpacklo_ps(r[6], r[7]);
            let t7 = _mm256_unpackhi_ps(r[6], r[7]);
            let u0 = _mm256_shuffle_ps::<0x44>(t0, t2);
            let u1 = _mm256_shuffle_ps::<0xee>(t0, t2);
            let u2 = _mm256_shuffle_ps::<0x44>(t1, t3);
            let u3 = _mm256_shuffle_ps::<0xee>(t1, t3);
            let u4 = _mm256_shuffle_ps::<0x44>(t4, t6);
            let u5 = _mm256_shuffle_ps::<0xee>(t4, t6);
            let u6 = _mm256_shuffle_ps::<0x44>(t5, t7);
            let u7 = _mm256_shuffle_ps::<0xee>(t5, t7);
            return Some([
                F8(_mm256_permute2f128_ps::<0x20>(u0, u4)),
                F8(_mm256_permute2f128_ps::<0x20>(u1, u5)),
                F8(_mm256_permute2f128_ps::<0x20>(u2, u6)),
                F8(_mm256_permute2f128_ps::<0x20>(u3, u7)),
                F8(_mm256_permute2f128_ps::<0x31>(u0, u4)),
                F8(_mm256_permute2f128_ps::<0x31>(u1, u5)),
                F8(_mm256_permute2f128_ps::<0x31>(u2, u6)),
                F8(_mm256_permute2f128_ps::<0x31>(u3, u7)),
            ]);
        }
    }
    let mut out = [F8::splat(0.0); 8];
    for (j, c) in out.iter_mut().enumerate() {
        *c = F8::from_array(per_lane(|i| table[start[i] + j]));
    }
    Some(out)
}

/// `table[idx[i]]` for an eight-entry table (`idx` below 8): one `vpermps` with AVX2.
#[inline(always)]
pub fn lookup8<const A: bool>(table: &[f32; LANES], idx: U8<A>) -> F8<A> {
    avx_or!(A, F8(_mm256_permutevar8x32_ps(_mm256_loadu_ps(table.as_ptr()), _mm256_castps_si256(idx.0))), {
        let i = idx.to_array();
        F8::from_array(per_lane(|k| table[i[k] as usize & 7]))
    })
}

/// [`lookup8`] of a table of `u32` words.
#[inline(always)]
pub fn lookup8_u32<const A: bool>(table: &[u32; LANES], idx: U8<A>) -> U8<A> {
    avx_or!(
        A,
        U8(_mm256_castsi256_ps(_mm256_permutevar8x32_epi32(
            _mm256_loadu_si256(table.as_ptr() as *const __m256i),
            _mm256_castps_si256(idx.0)
        ))),
        {
            let i = idx.to_array();
            U8::from_array(per_lane(|k| table[i[k] as usize & 7]))
        }
    )
}

/// `table[min(idx[i], table.len() - 1)]` per lane: one `vgatherdps` with AVX2 (for
/// tables of more than eight entries; [`lookup8`] for eight). `table` must not be empty.
#[inline(always)]
pub fn gather<const A: bool>(table: &[f32], idx: U8<A>) -> F8<A> {
    assert!(!table.is_empty() && table.len() <= i32::MAX as usize, "gather: table of {} words", table.len());
    let last = U8::<A>::splat((table.len() - 1) as u32);
    let idx = idx.min(last);
    // SAFETY (AVX2 branch): every index is at most `table.len() - 1` (clamped above).
    avx_or!(A, F8(_mm256_i32gather_ps::<4>(table.as_ptr(), _mm256_castps_si256(idx.0))), {
        let i = idx.to_array();
        F8::from_array(per_lane(|k| table[i[k] as usize]))
    })
}

/// [`gather`] of a table of `u32` words.
#[inline(always)]
pub fn gather_u32<const A: bool>(table: &[u32], idx: U8<A>) -> U8<A> {
    assert!(!table.is_empty() && table.len() <= i32::MAX as usize, "gather: table of {} words", table.len());
    let last = U8::<A>::splat((table.len() - 1) as u32);
    let idx = idx.min(last);
    // SAFETY (AVX2 branch): every index is at most `table.len() - 1` (clamped above).
    avx_or!(
        A,
        U8(_mm256_castsi256_ps(_mm256_i32gather_epi32::<4>(
            table.as_ptr() as *const i32,
            _mm256_castps_si256(idx.0)
        ))),
        {
            let i = idx.to_array();
            U8::from_array(per_lane(|k| table[i[k] as usize]))
        }
    )
}

/// `table[idx[i]]` for a table of any length (indices in range): [`lookup8`] (one
/// `vpermps`) for exactly eight entries, else [`gather`].
#[inline(always)]
pub fn lookup<const A: bool>(table: &[f32], idx: U8<A>) -> F8<A> {
    match <&[f32; LANES]>::try_from(table) {
        Ok(t) => lookup8(t, idx),
        Err(_) => gather(table, idx),
    }
}

/// [`lookup`] of a table of `u32` words.
#[inline(always)]
pub fn lookup_u32<const A: bool>(table: &[u32], idx: U8<A>) -> U8<A> {
    match <&[u32; LANES]>::try_from(table) {
        Ok(t) => lookup8_u32(t, idx),
        Err(_) => gather_u32(table, idx),
    }
}

/// Lanes of `m` whose word is not zero (words `u32::MAX` / 0, as [`lookup8_u32`] of a
/// mask table returns them).
#[inline(always)]
pub fn mask_of<const A: bool>(m: U8<A>) -> M8<A> {
    avx_or!(
        A,
        M8(_mm256_castsi256_ps(_mm256_xor_si256(
            _mm256_cmpeq_epi32(_mm256_castps_si256(m.0), _mm256_setzero_si256()),
            _mm256_set1_epi32(-1)
        ))),
        {
            let a = m.to_array();
            M8(raw_from_i(per_lane(|i| -((a[i] != 0) as i32))))
        }
    )
}

/// `(x as usize).min(n - 1)` per lane for `x < 2^31` and `1 <= n < 2^31` (truncation, NaN
/// and negatives to 0).
#[inline(always)]
pub fn trunc_below<const A: bool>(x: F8<A>, n: u32) -> U8<A> {
    avx_or!(
        A,
        {
            let t = _mm256_cvttps_epi32(x.0);
            let t = _mm256_max_epi32(
                _mm256_min_epi32(t, _mm256_set1_epi32(n as i32 - 1)),
                _mm256_setzero_si256(),
            );
            U8(_mm256_castsi256_ps(t))
        },
        {
            let xa = x.to_array();
            U8::from_array(per_lane(|k| (xa[k] as usize).min(n as usize - 1) as u32))
        }
    )
}

/// `AliasTable::sample(u)` in lanes for a table of `n` cells, `1 <= n <= 8`, given by its
/// `q`, `alias` and `pmf` words (`SmallLights`): `x = u * n`, `i = min(x as usize, n - 1)`,
/// `f = x - i as f32`, `k = f < q[i] ? i : alias[i]` (the scalar operations, so the same
/// cell), returned with `pmf[k]`. With AVX2 three `vpermps`, no per-lane code.
#[inline(always)]
pub fn alias_pick8<const A: bool>(
    u: F8<A>,
    n: u32,
    q: &[f32; LANES],
    alias: &[u32; LANES],
    pmf: &[f32; LANES],
) -> (U8<A>, F8<A>) {
    debug_assert!((1..=8).contains(&n));
    let x = u * F8::splat(n as f32);
    let i = trunc_below(x, n);
    let i_f = i.to_f32();
    let f = x - i_f;
    let keep = f.lt(lookup8(q, i));
    let al = lookup8_u32(alias, i);
    let k = U8(select(keep, F8(i.0), F8(al.0)).0);
    (k, lookup8(pmf, k))
}
