//! Sampling-rate computation (Bauszat et al. 2011, §4.2): a fixed per-frame sample
//! budget is apportioned over the pixels in proportion to their importance.
//!
//! With `s = budget - minSamples · numPixels` distributable samples (eq. 8), pixel
//! `p` with quota `q_p` (its importance) gets
//! `n_p = minSamples + ⌊s · q_p / t⌋` (eq. 7), `t = Σ q`. That is the first step of
//! the largest-remainder (Hamilton / Hare-Niemeyer) method; the paper stops there and
//! loses up to `numPixels - 1` samples to rounding ([`Mode::Paper`]). filtrace by
//! default finishes the method ([`Mode::Exact`]): the `R = s - Σ⌊·⌋` leftover samples
//! go to the `R` pixels with the largest remainders, found with a linear-time
//! selection (a remainder histogram, then `select_nth_unstable` within one bin) instead
//! of a sort, so a frame uses exactly its budget.
//!
//! Documented behaviour:
//! * `budget < minSamples · numPixels` is an error; `budget == minSamples · numPixels`
//!   gives every pixel exactly `minSamples`.
//! * NaN, infinite or negative importance is an error (never silently spread).
//! * All importance zero (`t = 0`: a flat frame, or all background) is treated as all
//!   importance equal: the budget is spread uniformly.
//! * Ties between equal remainders are broken by the larger importance, then by a
//!   fixed hash of the pixel index (so leftover samples of a uniform frame are spread
//!   over the image, not packed into its first rows). The result is a pure function of
//!   its input: deterministic, and independent of thread count.
//! * Monotone: a pixel with strictly larger importance never gets fewer samples.
//! * `minSamples = 0` is allowed; pixels may then get 0 samples.

use crate::AdaptiveError;
use filtrace_core::Image;
use rayon::prelude::*;
use std::cmp::Ordering;

/// How the rounding remainder of eq. 7 is handled.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Mode {
    /// Largest-remainder method: the frame's total equals the budget exactly.
    #[default]
    Exact,
    /// The paper's eq. 7 only: the total never exceeds the budget and falls short by
    /// less than the number of pixels.
    Paper,
}

/// Per-pixel sample counts of a frame, row-major.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SampleCounts {
    width: usize,
    height: usize,
    counts: Vec<u32>,
    total: u64,
}

impl SampleCounts {
    /// Wraps per-pixel counts. Returns `None` when the length is not `width * height`.
    pub fn from_vec(width: usize, height: usize, counts: Vec<u32>) -> Option<Self> {
        (counts.len() == width * height).then(|| {
            let total = counts.iter().map(|&c| c as u64).sum();
            Self { width, height, counts, total }
        })
    }

    /// `spp` samples in every pixel: the uniform baseline.
    pub fn uniform(width: usize, height: usize, spp: u32) -> Self {
        Self::from_vec(width, height, vec![spp; width * height]).expect("length matches")
    }

    pub fn width(&self) -> usize {
        self.width
    }
    pub fn height(&self) -> usize {
        self.height
    }
    /// Samples of each pixel, row-major.
    pub fn counts(&self) -> &[u32] {
        &self.counts
    }
    /// Sum of all counts.
    pub fn total(&self) -> u64 {
        self.total
    }
    pub fn min(&self) -> u32 {
        self.counts.iter().copied().min().unwrap_or(0)
    }
    pub fn max(&self) -> u32 {
        self.counts.iter().copied().max().unwrap_or(0)
    }

    /// The counts as a 1-channel image, to be written next to the render.
    pub fn to_image(&self) -> Image {
        let data = self.counts.iter().map(|&c| c as f32).collect();
        Image::from_vec(self.width, self.height, 1, data).expect("length matches")
    }
}

/// Fixed scramble of a pixel index (a 32-bit integer hash, "lowbias32" by C. Wellons):
/// the last tie-breaker between equal remainders.
#[inline]
fn tie_hash(i: u32) -> u32 {
    let mut x = i;
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// One pixel's standing in the largest-remainder ranking.
#[derive(Clone, Copy, Debug)]
struct Rank {
    frac: f64,
    q: f32,
    hash: u32,
    pixel: u32,
}

/// Ranking for the leftover samples: larger remainder first, then larger importance,
/// then the hash, then the index (a strict total order, so any selection algorithm
/// picks the same pixels).
#[inline]
fn rank_order(a: &Rank, b: &Rank) -> Ordering {
    b.frac.total_cmp(&a.frac).then(b.q.total_cmp(&a.q)).then(a.hash.cmp(&b.hash)).then(a.pixel.cmp(&b.pixel))
}

/// Validated input of eq. 7: quotas (importance, or all ones when `t = 0`), `s` and `t`.
struct Quotas {
    q: Vec<f32>,
    s: u64,
    t: f64,
}

/// Fixed-size chunks summed in parallel, then in order: deterministic for any thread count.
const SUM_CHUNK: usize = 4096;

fn quotas(importance: &Image, budget: u64, min_spp: u32) -> Result<Quotas, AdaptiveError> {
    if importance.channels() != 1 {
        return Err(AdaptiveError::Channels {
            layer: "importance",
            expected: 1,
            found: importance.channels(),
        });
    }
    let n = importance.pixel_count();
    if n == 0 {
        return Err(AdaptiveError::EmptyImage);
    }
    if n > u32::MAX as usize {
        return Err(AdaptiveError::Overflow);
    }
    let minimum = (min_spp as u64).checked_mul(n as u64).ok_or(AdaptiveError::Overflow)?;
    if budget < minimum {
        return Err(AdaptiveError::BudgetBelowMinimum { budget, min_spp, pixels: n });
    }
    // eq. 8
    let s = budget - minimum;
    let data = importance.data();
    if let Some((pixel, &value)) = data.iter().enumerate().find(|(_, v)| !(v.is_finite() && **v >= 0.0)) {
        return Err(AdaptiveError::InvalidImportance { pixel, value });
    }
    let partial: Vec<f64> =
        data.par_chunks(SUM_CHUNK).map(|c| c.iter().map(|&v| v as f64).sum::<f64>()).collect();
    let t: f64 = partial.iter().sum();
    if t > 0.0 {
        Ok(Quotas { q: data.to_vec(), s, t })
    } else {
        Ok(Quotas { q: vec![1.0; n], s, t: n as f64 })
    }
}

/// `⌊s·q/t⌋` (eq. 7) and the remainder, in f64.
#[inline]
fn quota(s: u64, q: f32, t: f64) -> (u64, f64) {
    let exact = s as f64 * q as f64 / t;
    let fl = exact.floor();
    (fl as u64, exact - fl)
}

/// Apportions `budget` samples over the pixels of `importance` (1 channel, values
/// finite and `>= 0`), at least `min_spp` each (see module docs).
///
/// ```
/// use filtrace_adaptive::{apportion, Mode};
/// use filtrace_core::Image;
/// let imp = Image::from_vec(3, 1, 1, vec![0.0, 0.25, 0.75]).unwrap();
/// let c = apportion(&imp, 12, 1, Mode::Exact).unwrap();
/// assert_eq!(c.counts(), &[1, 3, 8]); // 1 + 9·{0, 1/4, 3/4} = 1, 3.25, 7.75 -> leftover to 7.75
/// assert_eq!(c.total(), 12);
/// ```
pub fn apportion(
    importance: &Image,
    budget: u64,
    min_spp: u32,
    mode: Mode,
) -> Result<SampleCounts, AdaptiveError> {
    let Quotas { q, s, t } = quotas(importance, budget, min_spp)?;
    // eq. 7, first step of the largest-remainder method, in parallel.
    let mut floors: Vec<u64> = q.par_iter().map(|&q| quota(s, q, t).0).collect();
    let assigned: u64 = floors.par_chunks(SUM_CHUNK).map(|c| c.iter().sum::<u64>()).sum();
    let pixels = q.len() as u64;
    match assigned.cmp(&s) {
        Ordering::Greater => {
            // Only float rounding in s·q/t can make Σ⌊·⌋ exceed s (by a few samples);
            // take them back from the smallest remainders so the budget is never exceeded.
            let mut excess = assigned - s;
            let mut ranks = ranks(&q, s, t);
            ranks.sort_unstable_by(|a, b| rank_order(b, a));
            for r in ranks {
                if excess == 0 {
                    break;
                }
                if floors[r.pixel as usize] > 0 {
                    floors[r.pixel as usize] -= 1;
                    excess -= 1;
                }
            }
        }
        Ordering::Less if mode == Mode::Exact => {
            let mut left = s - assigned;
            // Normally left < pixels; a whole round each is only a float-rounding guard.
            let rounds = left / pixels;
            if rounds > 0 {
                floors.par_iter_mut().for_each(|f| *f += rounds);
                left -= rounds * pixels;
            }
            if left > 0 {
                add_largest_remainders(&q, s, t, left as usize, &mut floors);
            }
        }
        _ => {}
    }
    finish(importance, floors, min_spp)
}

/// Bins of the remainder histogram in [`largest_remainders`].
const FRAC_BINS: usize = 1 << 16;

/// Adds one sample to each of the `k` pixels first in [`rank_order`], without sorting or
/// selecting over all pixels: a histogram of the remainders (in `[0, 1)`, 2^16 bins) finds
/// the bin holding the k-th largest; every pixel in a higher bin gets its sample in one
/// vectorisable pass, and only the pixels of that bin (about `N / 2^16` unless many quotas
/// are equal) are ranked in full for the places left. Selecting over all ranks instead
/// cost 3x the paper's rounding (bench adaptive, 1024x768); this costs about 1.5x.
fn add_largest_remainders(q: &[f32], s: u64, t: f64, k: usize, floors: &mut [u64]) {
    debug_assert!(k > 0 && k <= q.len());
    const CHUNK: usize = 1 << 16;
    let bins: Vec<u16> = q
        .par_iter()
        .map(|&q| ((quota(s, q, t).1 * FRAC_BINS as f64) as usize).min(FRAC_BINS - 1) as u16)
        .collect();
    let hist = bins
        .par_chunks(CHUNK)
        .map(|c| {
            let mut h = vec![0u32; FRAC_BINS];
            for &b in c {
                h[b as usize] += 1;
            }
            h
        })
        .reduce_with(|mut a, b| {
            a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
            a
        })
        .unwrap_or_default();
    // The bin where the count from the top reaches k.
    let (mut above, mut cut) = (0usize, 0u16);
    for b in (0..FRAC_BINS).rev() {
        if above + hist[b] as usize >= k {
            cut = b as u16;
            break;
        }
        above += hist[b] as usize;
    }
    floors.par_chunks_mut(CHUNK).zip(bins.par_chunks(CHUNK)).for_each(|(f, b)| {
        for (f, &b) in f.iter_mut().zip(b) {
            *f += (b > cut) as u64;
        }
    });
    let mut ties: Vec<Rank> = bins
        .par_chunks(CHUNK)
        .enumerate()
        .flat_map_iter(|(c, b)| {
            b.iter().enumerate().filter(move |(_, &b)| b == cut).map(move |(j, _)| {
                let i = c * CHUNK + j;
                Rank { frac: quota(s, q[i], t).1, q: q[i], hash: tie_hash(i as u32), pixel: i as u32 }
            })
        })
        .collect();
    let need = k - above;
    debug_assert!(need >= 1 && need <= ties.len());
    ties.select_nth_unstable_by(need - 1, rank_order);
    for r in &ties[..need] {
        floors[r.pixel as usize] += 1;
    }
}

fn ranks(q: &[f32], s: u64, t: f64) -> Vec<Rank> {
    q.par_iter()
        .enumerate()
        .map(|(i, &q)| Rank { frac: quota(s, q, t).1, q, hash: tie_hash(i as u32), pixel: i as u32 })
        .collect()
}

fn finish(importance: &Image, floors: Vec<u64>, min_spp: u32) -> Result<SampleCounts, AdaptiveError> {
    let counts = floors
        .into_iter()
        .map(|f| u32::try_from(f + min_spp as u64).map_err(|_| AdaptiveError::Overflow))
        .collect::<Result<Vec<u32>, _>>()?;
    Ok(SampleCounts::from_vec(importance.width(), importance.height(), counts).expect("length matches"))
}

/// Reference implementation of [`apportion`]: sequential, with a full sort of the
/// remainders (what the paper calls too costly on a GPU). For tests.
pub fn apportion_naive(
    importance: &Image,
    budget: u64,
    min_spp: u32,
    mode: Mode,
) -> Result<SampleCounts, AdaptiveError> {
    let Quotas { q, s, t } = quotas(importance, budget, min_spp)?;
    let mut floors: Vec<u64> = q.iter().map(|&q| quota(s, q, t).0).collect();
    let mut ranks = ranks(&q, s, t);
    ranks.sort_by(rank_order);
    let mut assigned: u64 = floors.iter().sum();
    // Rounding guard, as in `apportion`.
    for r in ranks.iter().rev() {
        if assigned <= s {
            break;
        }
        if floors[r.pixel as usize] > 0 {
            floors[r.pixel as usize] -= 1;
            assigned -= 1;
        }
    }
    if mode == Mode::Exact {
        for r in ranks.iter().cycle() {
            if assigned >= s {
                break;
            }
            floors[r.pixel as usize] += 1;
            assigned += 1;
        }
    }
    finish(importance, floors, min_spp)
}
