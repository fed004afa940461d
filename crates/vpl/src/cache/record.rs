//! Cache records and the cache itself: per record the four distributions over the VPLs
//! (thesis 4.2.5) with their cumulative sums, built per record in parallel.

use super::optimize::RecordParams;
use super::sampler::SamplerSetup;
use super::search::{KdTree, Neighbours};
use super::{CacheParams, CachePoint, RecordValues, Region, Technique, VisibilityRays, VplSet, TECHNIQUES};
use filtrace_core::{luminance, Rgb, Vec3};
use rayon::prelude::*;

/// Neighbourhood radius of a record with no other record, as a fraction of the scene
/// diagonal.
const LONE_RECORD_RADIUS: f32 = 0.05;

/// One importance record: its point, neighbourhood and distributions.
#[derive(Clone, Debug)]
pub struct CacheRecord {
    pub point: CachePoint,
    /// Radius of the ball the bounded distribution E³ covers: the distance to the
    /// farthest of the record's M nearest other records (its region of influence).
    pub radius: f32,
    /// Largest angle between the record's normal and those M neighbours' normals (the
    /// receiver's normal slack of E³).
    pub normal_cone: f32,
    /// E¹, E², E³ (luminance) as CDFs; E⁴ (uniform) needs no table.
    distributions: [VplCdf; 3],
    /// RGB sums over the VPLs of E¹, E², E³; the uniform slot repeats E²'s (its control
    /// variate's scale: E⁴ = 1 carries no radiance of its own).
    totals: [Rgb; TECHNIQUES],
    /// The visibility rays its evaluation traced and the faint VPLs it did without.
    pub rays: VisibilityRays,
}

impl CacheRecord {
    /// A record from its evaluated values.
    pub fn new(point: CachePoint, radius: f32, normal_cone: f32, values: &RecordValues) -> Self {
        let t = values.totals;
        CacheRecord {
            point,
            radius,
            normal_cone,
            distributions: VplCdf::three([&values.full, &values.unoccluded, &values.bounded]),
            totals: [t[0], t[1], t[2], t[1]],
            rays: values.rays,
        }
    }

    /// Number of VPLs the record covers.
    #[inline]
    pub fn vpl_count(&self) -> usize {
        self.distributions[0].count()
    }

    /// `p_t(j)`: probability that distribution `t` draws VPL `j` (the CDF's step, so it
    /// is exactly what [`CacheRecord::sample`] does; uniform when a table is all zero).
    #[inline]
    pub fn pmf(&self, t: Technique, j: usize) -> f32 {
        match t {
            Technique::Uniform => {
                let n = self.vpl_count();
                if j < n {
                    1.0 / n as f32
                } else {
                    0.0
                }
            }
            _ => self.distributions[t as usize].pmf(j),
        }
    }

    /// `p_t(j)` of every technique at once, indexed by `Technique as usize` (the same
    /// values as [`CacheRecord::pmf`]): a shading point reads one VPL's pmfs per record
    /// in one call instead of one dispatch per technique.
    #[inline]
    pub fn pmfs(&self, j: usize) -> [f32; TECHNIQUES] {
        let [full, unoccluded, bounded] = self.cdf_pmfs(j);
        [full, unoccluded, bounded, self.pmf(Technique::Uniform, j)]
    }

    /// `p_t(j)` of E¹, E², E³ (the CDFs' steps: [`CacheRecord::pmf`]'s values); E⁴'s
    /// is `1 / vpl_count()` at every `j` below the count.
    #[inline]
    pub fn cdf_pmfs(&self, j: usize) -> [f32; 3] {
        let [full, unoccluded, bounded] = &self.distributions;
        [full.pmf(j), unoccluded.pmf(j), bounded.pmf(j)]
    }

    /// Draws a VPL from distribution `t` with `u` in `[0, 1)` (binary search of the CDF).
    #[inline]
    pub fn sample(&self, t: Technique, u: f32) -> usize {
        match t {
            Technique::Uniform => {
                let n = self.vpl_count();
                ((u * n as f32) as usize).min(n.saturating_sub(1))
            }
            _ => self.distributions[t as usize].sample(u),
        }
    }

    /// The table of distribution `t` (`None` for uniform).
    pub fn distribution(&self, t: Technique) -> Option<&VplCdf> {
        (t != Technique::Uniform).then(|| &self.distributions[t as usize])
    }

    /// `T_t`: RGB total of distribution `t` over the VPLs (the control variate's
    /// integral at β = 1).
    #[inline]
    pub fn total(&self, t: Technique) -> Rgb {
        self.totals[t as usize]
    }

    /// `L_t = luminance(T_t)`.
    #[inline]
    pub fn luminance_total(&self, t: Technique) -> f32 {
        luminance(self.totals[t as usize])
    }
}

/// Cells per block of [`VplCdf`]'s coarse index: a draw reads the index (2048 VPLs: 64
/// values, 4 cache lines, shared by all draws from the record) and one block of 32 CDF
/// values (2 lines) instead of a binary search over the whole table (~7 cold lines).
pub(crate) const CDF_BLOCK: usize = 32;

/// A weight as the distributions count it: non-finite and negative ones are 0.
#[inline]
fn sanitised(w: f32) -> f32 {
    if w.is_finite() && w > 0.0 {
        w
    } else {
        0.0
    }
}

/// A discrete distribution over the VPLs: the CDF of `filtrace_core`'s `Distribution1D`,
/// built with the same arithmetic (f64 sums, so the same `f32` values) and sampled with
/// the same rule (the partition point of `cdf[1..] <= u`, zero cells skipped), so pmfs and
/// draws are identical (`vpl_cdf_equals_distribution1d`); only the search differs: the
/// last value of each block of `CDF_BLOCK` cells is kept as a coarse index.
#[derive(Clone, Debug, Default)]
pub struct VplCdf {
    /// `cdf[i]` = probability of cells `< i`; `cdf[n] = 1`; length `n + 1`.
    cdf: Vec<f32>,
    /// `cdf[min((b + 1) B, n)]`, the upper bound of block `b`'s last cell.
    coarse: Vec<f32>,
    /// Sum of the sanitised weights.
    total: f32,
}

impl VplCdf {
    /// The distribution of `weights` (non-finite and negative ones count as 0; all zero:
    /// uniform).
    pub fn new(weights: &[f32]) -> Self {
        let [cdf] = Self::several([weights]);
        cdf
    }

    /// The three distributions of a record (E¹, E², E³).
    pub fn three(weights: [&[f32]; 3]) -> [Self; 3] {
        Self::several(weights)
    }

    /// [`VplCdf::new`] of each list: `filtrace_core`'s `normalized_cdf` of the sanitised
    /// weights, the same arithmetic in the same order (so the same bits), without the
    /// sanitised copy and without a `push` per cell; one scratch of running sums for all.
    fn several<const K: usize>(weights: [&[f32]; K]) -> [Self; K] {
        let longest = weights.iter().map(|w| w.len()).max().unwrap_or(0);
        let mut running = vec![0.0f64; longest];
        weights.map(|w| VplCdf::from_running_sums(w, &mut running[..w.len()]))
    }

    /// `normalized_cdf`'s loop in three passes over `running` (as long as `weights`): the
    /// sanitised weights as `f64` (vectorised), their running sums (in order: the last
    /// is its total, the same additions in the same order), then the divisions,
    /// independent per cell (vectorised). The same values as one pass
    /// (`vpl_cdf_equals_distribution1d`).
    fn from_running_sums(weights: &[f32], running: &mut [f64]) -> Self {
        let n = weights.len();
        for (r, &w) in running.iter_mut().zip(weights) {
            *r = sanitised(w) as f64;
        }
        // `f64`'s `Sum` start value (what `normalized_cdf` sums an empty list to; adding
        // to it changes nothing else).
        let mut acc: f64 = std::iter::empty::<f64>().sum();
        for r in running.iter_mut() {
            acc += *r;
            *r = acc;
        }
        let total64 = acc;
        let mut cdf = vec![0.0f32; n + 1];
        if total64 > 0.0 && total64.is_finite() {
            for (c, &a) in cdf[1..].iter_mut().zip(&*running) {
                *c = (a / total64) as f32;
            }
        } else {
            for (i, c) in cdf.iter_mut().enumerate().skip(1) {
                *c = i as f32 / n as f32;
            }
        }
        if n > 0 {
            cdf[n] = 1.0;
        }
        let total = if total64.is_finite() { total64 as f32 } else { 0.0 };
        let coarse = (0..n.div_ceil(CDF_BLOCK)).map(|b| cdf[((b + 1) * CDF_BLOCK).min(n)]).collect();
        VplCdf { cdf, coarse, total }
    }

    /// Number of cells.
    #[inline]
    pub fn count(&self) -> usize {
        self.cdf.len().saturating_sub(1)
    }

    /// Bytes of its tables (the frame's memory estimate is checked against it).
    pub fn heap_bytes(&self) -> usize {
        (self.cdf.capacity() + self.coarse.capacity()) * size_of::<f32>()
    }

    /// Sum of the sanitised weights; 0 for a degenerate distribution.
    #[inline]
    pub fn total(&self) -> f32 {
        self.total
    }

    /// Probability of cell `i` (0 outside `0..count()`).
    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        // One bounds check: `i + 1 < cdf.len()` is `i < count()`.
        match self.cdf.get(i..).and_then(|c| c.get(..2)) {
            Some(&[below, above]) => above - below,
            _ => 0.0,
        }
    }

    /// The cell of `u ∈ [0, 1)`: largest `i` with `cdf[i] <= u`, zero cells skipped.
    #[inline]
    pub fn sample(&self, u: f32) -> usize {
        let n = self.count();
        if n == 0 {
            return 0;
        }
        // The partition point of `cdf[1..=n] <= u` (the CDF is non-decreasing): whole
        // blocks from the coarse index, then the cells of one block.
        let block = self.coarse.partition_point(|&c| c <= u);
        let start = block * CDF_BLOCK;
        let end = (start + CDF_BLOCK).min(n);
        let i = start + self.cdf[1 + start.min(n)..1 + end].partition_point(|&c| c <= u);
        let mut i = i.min(n - 1);
        // Zero-pmf cells can only be reached at exact boundaries; step to a live cell.
        while i > 0 && self.cdf[i + 1] - self.cdf[i] <= 0.0 {
            i -= 1;
        }
        while i + 1 < n && self.cdf[i + 1] - self.cdf[i] <= 0.0 {
            i += 1;
        }
        i
    }
}

/// The importance cache of one frame: records, their search tree, the `optimized`
/// sampler's per-record parameters, and the configuration they were built with.
#[derive(Clone, Debug)]
pub struct ImportanceCache {
    pub(crate) records: Vec<CacheRecord>,
    pub(crate) params: Vec<RecordParams>,
    pub(crate) tree: KdTree,
    pub(crate) config: CacheParams,
    pub(crate) vpl_count: usize,
    /// What the samplers read of `config` per shading point.
    pub(crate) setup: SamplerSetup,
}

impl ImportanceCache {
    /// A cache without records: every sampler falls back to `uniform`.
    pub fn empty(vpl_count: usize, config: &CacheParams) -> Self {
        ImportanceCache::from_parts(Vec::new(), Vec::new(), KdTree::default(), config, vpl_count)
    }

    /// Evaluates every VPL at every point (per record in parallel; the result does not
    /// depend on the thread count) and builds the distributions. `scene_diagonal` is D
    /// of λ = `lambda_scale` · D. `previous`: the last frame's cache, whose optimised
    /// parameters are interpolated at the new records (M nearest, same weights as
    /// shading; a record at distance 0 of an old one copies it); without it the
    /// parameters start a priori.
    pub fn build(
        vpls: &impl VplSet,
        points: Vec<CachePoint>,
        scene_diagonal: f32,
        config: &CacheParams,
        previous: Option<&ImportanceCache>,
    ) -> Result<Self, String> {
        config.validate()?;
        if !(scene_diagonal.is_finite() && scene_diagonal > 0.0) {
            return Err(format!(
                "importance cache: scene diagonal {scene_diagonal} (expected finite and > 0)"
            ));
        }
        let lambda = config.lambda_scale * scene_diagonal;
        let positions: Vec<Vec3> = points.iter().map(|p| p.position).collect();
        let normals: Vec<Vec3> = points.iter().map(|p| p.normal).collect();
        let tree = KdTree::new(&positions, &normals, lambda);
        let vpl_count = vpls.vpl_count();
        let records: Vec<CacheRecord> = points
            .par_iter()
            .enumerate()
            .map_init(RecordValues::default, |values, (i, &point)| {
                let region = neighbourhood(&tree, &points, i, config.neighbours, scene_diagonal);
                vpls.evaluate_record(&point, &region, config.faint_share, values);
                CacheRecord::new(point, region.radius, region.normal_cone, values)
            })
            .collect();
        let mut cache = ImportanceCache::from_parts(records, Vec::new(), tree, config, vpl_count);
        cache.params = cache.initial_params(previous);
        Ok(cache)
    }

    /// The cache of these parts (`params` one per record or empty).
    pub(crate) fn from_parts(
        records: Vec<CacheRecord>,
        params: Vec<RecordParams>,
        tree: KdTree,
        config: &CacheParams,
        vpl_count: usize,
    ) -> Self {
        let setup = SamplerSetup::new(config);
        ImportanceCache { records, params, tree, config: config.clone(), vpl_count, setup }
    }

    /// A priori parameters, or those of `previous` interpolated at each record.
    fn initial_params(&self, previous: Option<&ImportanceCache>) -> Vec<RecordParams> {
        let prior = RecordParams::prior(&self.config);
        self.records
            .iter()
            .map(|r| match previous {
                Some(prev) if !prev.records.is_empty() => {
                    let nb = prev.neighbours(r.point.position, r.point.normal);
                    let nearest = nb.iter().next();
                    match nearest {
                        // A record that stayed put keeps its parameters exactly.
                        Some((l, _)) if nb.closest_distance() == Some(0.0) => prev.params[l],
                        _ => RecordParams::blend(nb.iter().map(|(l, w)| (&prev.params[l], w))),
                    }
                }
                _ => prior,
            })
            .collect()
    }

    /// The records.
    pub fn records(&self) -> &[CacheRecord] {
        &self.records
    }

    /// The visibility rays of every record's evaluation, and the faint VPLs taken as
    /// visible without one.
    pub fn visibility_rays(&self) -> VisibilityRays {
        self.records.iter().map(|r| r.rays).fold(VisibilityRays::default(), |a, b| a + b)
    }

    /// The `optimized` sampler's parameters, one per record.
    pub fn params(&self) -> &[RecordParams] {
        &self.params
    }

    /// Replaces the parameters (e.g. to carry them over unchanged records).
    pub fn set_params(&mut self, params: Vec<RecordParams>) -> Result<(), String> {
        if params.len() != self.records.len() {
            return Err(format!(
                "importance cache: {} parameter sets for {} records",
                params.len(),
                self.records.len()
            ));
        }
        self.params = params;
        Ok(())
    }

    /// The configuration the cache was built with.
    pub fn config(&self) -> &CacheParams {
        &self.config
    }

    /// Number of VPLs.
    pub fn vpl_count(&self) -> usize {
        self.vpl_count
    }

    /// λ of the search distance.
    pub fn lambda(&self) -> f32 {
        self.tree.lambda()
    }

    /// The M nearest records of a shading point, with their interpolation weights
    /// (empty when the cache has no records).
    pub fn neighbours(&self, position: Vec3, normal: Vec3) -> Neighbours {
        let m = self.config.neighbours;
        Neighbours::from_nearest(self.tree.nearest(position, normal, m + 1).as_slice(), m)
    }
}

/// Radius and normal cone of record `i`: over its M nearest other records, the largest
/// distance and the largest normal angle.
fn neighbourhood(tree: &KdTree, points: &[CachePoint], i: usize, m: usize, diagonal: f32) -> Region {
    let p = points[i];
    let nearest = tree.nearest(p.position, p.normal, m + 1);
    let (mut radius, mut cone, mut found) = (0.0f32, 0.0f32, false);
    for &(_, id) in nearest.as_slice().iter().filter(|&&(_, id)| id as usize != i).take(m) {
        let q = points[id as usize];
        radius = radius.max((q.position - p.position).length());
        cone = cone.max(p.normal.dot(q.normal).clamp(-1.0, 1.0).acos());
        found = true;
    }
    if found {
        Region { radius, normal_cone: cone }
    } else {
        Region { radius: LONE_RECORD_RADIUS * diagonal, normal_cone: 0.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::VplCdf;
    use filtrace_core::rng::SplitMix64;
    use filtrace_core::sampling::Distribution1D;

    /// Same pmfs, totals and draws as `Distribution1D` (bit for bit), on weights with
    /// zero runs, bad values, all zeros, one cell and sizes around the block length,
    /// for random `u` and for `u` on the CDF's own values.
    #[test]
    fn vpl_cdf_equals_distribution1d() {
        let mut rng = SplitMix64::new(8);
        for &n in &[0usize, 1, 2, 31, 32, 33, 64, 100, 2048, 2053] {
            for case in 0..4 {
                let weights: Vec<f32> = (0..n)
                    .map(|i| match case {
                        0 => rng.range(0.0, 1.0),
                        1 if (i / 7) % 3 == 0 => 0.0,
                        1 => rng.range(0.0, 10.0).powi(3),
                        2 if i % 11 == 0 => f32::NAN,
                        2 => -rng.range(0.0, 1.0) * (i % 2) as f32,
                        _ => 0.0,
                    })
                    .collect();
                let (fast, reference) = (VplCdf::new(&weights), Distribution1D::new(&weights));
                assert_eq!(
                    (fast.count(), fast.total().to_bits()),
                    (reference.count(), reference.total().to_bits())
                );
                let mut us: Vec<f32> = (0..2000).map(|_| rng.next_f32()).collect();
                us.extend(fast.cdf.iter().copied().filter(|&c| c < 1.0));
                us.push(0.0);
                for j in 0..n + 2 {
                    assert_eq!(
                        fast.pmf(j).to_bits(),
                        reference.pmf(j).to_bits(),
                        "n {n}, case {case}, cell {j}"
                    );
                }
                for u in us {
                    let expected = if n == 0 { 0 } else { reference.sample_discrete(u).0 };
                    assert_eq!(fast.sample(u), expected, "n {n}, case {case}, u {u}");
                }
            }
        }
    }

    /// A record's three CDFs built together are the three built alone, bit for bit
    /// (lists with zeros, bad values, all zero), and `new`'s are `Distribution1D`'s (above).
    #[test]
    fn three_cdfs_at_once_equal_three_alone() {
        let mut rng = SplitMix64::new(9);
        for &n in &[0usize, 1, 33, 2048] {
            let lists: [Vec<f32>; 3] = [
                (0..n).map(|_| rng.range(0.0, 1.0)).collect(),
                (0..n).map(|i| if i % 5 == 0 { f32::INFINITY } else { rng.range(-1.0, 1.0) }).collect(),
                vec![0.0; n],
            ];
            let together = VplCdf::three([&lists[0], &lists[1], &lists[2]]);
            for (k, list) in lists.iter().enumerate() {
                let alone = VplCdf::new(list);
                let bits = |c: &VplCdf| {
                    (
                        c.cdf.iter().chain(&c.coarse).map(|x| x.to_bits()).collect::<Vec<_>>(),
                        c.total.to_bits(),
                    )
                };
                assert_eq!(bits(&together[k]), bits(&alone), "n {n}, list {k}");
            }
        }
    }
}
