//! The VPL set as the importance cache sees it: what a record needs to know about each
//! VPL to build its four distributions (thesis 4.2.5, Georgiev et al. 2012, section 4).
//!
//! The cache never shades pixels itself: the integrator evaluates the drawn VPLs with
//! visibility and combines them as the [`super::SamplePlan`] says. The cache only
//! evaluates every VPL at every record, through this trait.

use super::{CachePoint, FaintCut};
use filtrace_core::{luminance, Rgb, Vec3};

/// The VPLs, seen from a cache record. Implemented by the `vpls` module (and by small
/// synthetic sets in the tests).
///
/// All contributions are the radiance a VPL sends towards the camera through the
/// record's surface, `E_VPL · f(x_VPL → x0 → x−1) · G(x0 ↔ x_VPL)` (thesis eq. 9), with
/// `x0` the record's point and `x−1` the camera (the record knows its pixel, from which
/// the implementation finds the material and the outgoing direction).
pub trait VplSet: Sync {
    /// Number of VPLs N; VPL indices are `0..N`.
    fn vpl_count(&self) -> usize;

    /// `E f G` without visibility: the unoccluded contribution E²_VPL.
    fn unoccluded(&self, vpl: usize, site: &CachePoint) -> Rgb;

    /// Visibility V(x0 ↔ x_VPL): true when the segment is free. The full contribution
    /// E¹_VPL is `unoccluded · V`.
    fn visible(&self, vpl: usize, site: &CachePoint) -> bool;

    /// The bounded contribution E³_VPL: `E f` times the relaxed geometry term
    /// `cos θ0_min cos θVPL_min / r²_min` over the record's neighbourhood, receivers in
    /// the ball of `region.radius` around it whose normals deviate from the record's by up
    /// to `region.normal_cone` (see [`relaxed_geometry_term`]). Must be > 0 wherever some
    /// receiver of the neighbourhood can receive light from the VPL.
    fn bounded(&self, vpl: usize, site: &CachePoint, region: &Region) -> Rgb;

    /// Evaluates every VPL at one record into `out`. The default calls the three methods
    /// per VPL and casts a visibility ray only where the unoccluded contribution is
    /// positive and not faint (the faintest VPLs, carrying at most `faint_share` of the
    /// record's unoccluded light, count as visible: [`FaintCut`]). Override it to trace
    /// the record's visibility rays as a packet: they share the record's point as origin.
    fn evaluate_record(&self, site: &CachePoint, region: &Region, faint_share: f32, out: &mut RecordValues) {
        evaluate_each_vpl(self, site, region, faint_share, out);
    }
}

/// The neighbourhood a record's bounded distribution E³ covers: the ball of `radius`
/// around the record (the distance to the farthest of its M nearest records) and the
/// receivers' normals within `normal_cone` radians of the record's (the largest angle to
/// those records' normals).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Region {
    pub radius: f32,
    pub normal_cone: f32,
}

/// [`VplSet::evaluate_record`] one VPL and one visibility ray at a time (the unoccluded
/// contributions first: the faint cut needs their total): the default, and the reference
/// that packet implementations are tested against (same values, bit for bit).
pub fn evaluate_each_vpl<S: VplSet + ?Sized>(
    set: &S,
    site: &CachePoint,
    region: &Region,
    faint_share: f32,
    out: &mut RecordValues,
) {
    let n = set.vpl_count();
    out.clear(n);
    let unoccluded: Vec<Rgb> = (0..n).map(|j| set.unoccluded(j, site)).collect();
    let luminances: Vec<f32> = unoccluded.iter().map(|&c| luminance(c).max(0.0)).collect();
    let faint = FaintCut::new(&luminances, faint_share);
    for (j, &unoccluded) in unoccluded.iter().enumerate() {
        let visible = luminances[j] > 0.0
            && if faint.is_faint(luminances[j]) {
                out.rays.faint += 1;
                true
            } else {
                out.rays.traced += 1;
                set.visible(j, site)
            };
        let full = if visible { unoccluded } else { Rgb::ZERO };
        out.set(j, full, unoccluded, set.bounded(j, site, region));
    }
}

/// A record's visibility decisions: rays traced, and faint VPLs taken as visible
/// without one (summed over records by [`super::ImportanceCache::visibility_rays`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct VisibilityRays {
    pub traced: u64,
    pub faint: u64,
}

impl std::ops::Add for VisibilityRays {
    type Output = VisibilityRays;
    fn add(self, o: VisibilityRays) -> VisibilityRays {
        VisibilityRays { traced: self.traced + o.traced, faint: self.faint + o.faint }
    }
}

/// One record's per-VPL importance values (luminances) and the RGB totals of the three
/// non-uniform distributions, as [`VplSet::evaluate_record`] fills them.
#[derive(Clone, Debug, Default)]
pub struct RecordValues {
    /// Luminance of the full contribution E¹ per VPL.
    pub full: Vec<f32>,
    /// Luminance of the unoccluded contribution E² per VPL.
    pub unoccluded: Vec<f32>,
    /// Luminance of the bounded contribution E³ per VPL.
    pub bounded: Vec<f32>,
    /// RGB sums over the VPLs of E¹, E², E³ (their colours colour the control variates).
    pub totals: [Rgb; 3],
    /// The record's visibility rays, and the faint VPLs that went without one.
    pub rays: VisibilityRays,
    /// Scratch of packet implementations, kept to reuse its memory: per VPL the RGB
    /// unoccluded and bounded contributions (a column per channel), and the visibility
    /// found by the packets.
    pub(crate) rgb: RgbColumns,
    pub(crate) visible: Vec<bool>,
}

impl RecordValues {
    /// Resets to `n` zero entries.
    pub fn clear(&mut self, n: usize) {
        for v in [&mut self.full, &mut self.unoccluded, &mut self.bounded] {
            v.clear();
            v.resize(n, 0.0);
        }
        self.totals = [Rgb::ZERO; 3];
        self.rays = VisibilityRays::default();
    }

    /// `n` entries per list without zeroing those already there, and zero totals: for
    /// an evaluation that writes every entry (a zero fill per record cost as much as
    /// the CDFs' divisions).
    pub(crate) fn resize_for_overwrite(&mut self, n: usize) {
        for v in [&mut self.full, &mut self.unoccluded, &mut self.bounded] {
            v.resize(n, 0.0);
        }
        self.totals = [Rgb::ZERO; 3];
        self.rays = VisibilityRays::default();
    }

    /// Stores VPL `j`'s three contributions (RGB; the distributions keep luminance).
    #[inline]
    pub fn set(&mut self, j: usize, full: Rgb, unoccluded: Rgb, bounded: Rgb) {
        self.full[j] = luminance(full).max(0.0);
        self.unoccluded[j] = luminance(unoccluded).max(0.0);
        self.bounded[j] = luminance(bounded).max(0.0);
        self.totals[0] += full;
        self.totals[1] += unoccluded;
        self.totals[2] += bounded;
    }
}

/// Per VPL the unoccluded contribution E² and the bounded one E³ in RGB, as columns
/// (`c[k][j]`: channel `k` of VPL `j`), so that eight VPLs in a row are stored as blocks.
#[derive(Clone, Debug, Default)]
pub(crate) struct RgbColumns {
    pub c: [Vec<f32>; 3],
    pub b: [Vec<f32>; 3],
}

impl RgbColumns {
    /// `n` entries per column, those already there kept: for an evaluation that
    /// writes every entry.
    pub fn resize_for_overwrite(&mut self, n: usize) {
        for v in self.c.iter_mut().chain(&mut self.b) {
            v.resize(n, 0.0);
        }
    }

    /// VPL `j`'s E² and E³.
    #[inline]
    pub fn set(&mut self, j: usize, c: Rgb, b: Rgb) {
        for k in 0..3 {
            (self.c[k][j], self.b[k][j]) = (c[k], b[k]);
        }
    }
}

/// The relaxed geometry term of the bounded distribution E³ (thesis 4.2.5):
/// `cos θ0_min · cos θVPL_min / r²_min` for a receiver anywhere in the ball of `radius`
/// around `x0` whose normal deviates from `n0` by up to `normal_cone` radians.
///
/// - `r_min = max(r − radius, radius)`: the distance can shrink by the radius; below the
///   radius itself the bound stops growing (the same role as the clamp of thesis 4.2.3,
///   here only shaping a sampling distribution, so it biases nothing);
/// - the direction to the VPL turns by at most `δ = asin(min(radius / r, 1))` as the
///   receiver moves in the ball, so each angle shrinks by `δ` (the receiver's also by
///   `normal_cone`), clamped at 0;
/// - `n_vpl = None` is a VPL without a surface (point light): its cosine is 1.
pub fn relaxed_geometry_term(
    x0: Vec3,
    n0: Vec3,
    x_vpl: Vec3,
    n_vpl: Option<Vec3>,
    radius: f32,
    normal_cone: f32,
) -> f32 {
    let d = x_vpl - x0;
    let r = d.length();
    if !(r > 0.0) {
        return if radius > 0.0 { 1.0 / (radius * radius) } else { 0.0 };
    }
    let w = d / r;
    let delta = (radius / r).min(1.0).asin();
    let relaxed_cos = |cos_theta: f32, slack: f32| {
        let theta = cos_theta.clamp(-1.0, 1.0).acos();
        (theta - slack).max(0.0).cos().max(0.0)
    };
    let cos0 = relaxed_cos(n0.dot(w), delta + normal_cone);
    let cos_vpl = n_vpl.map_or(1.0, |n| relaxed_cos(n.dot(-w), delta));
    let r_min = (r - radius).max(radius).max(f32::MIN_POSITIVE.sqrt());
    cos0 * cos_vpl / (r_min * r_min)
}

/// [`relaxed_geometry_term`] without inverse trigonometric functions (the cache
/// evaluation calls it for every VPL at every record; the reference spends most of its
/// time in `acos`, `asin` and `cos`): with `sin δ = min(R / r, 1)`,
/// `cos δ = √(1 − sin² δ)`, the slack `s` (δ, plus the normal cone for the receiver) as
/// its cosine and sine, `θ ≤ s ⟺ cos θ ≥ cos s` and otherwise
/// `cos(θ − s) = cos θ cos s + sin θ sin s`. Equal to the reference up to rounding (the
/// test `fast_relaxed_term_matches_the_reference`: within 1e-4 of the largest value the
/// term can take at that distance); it only shapes the bounded sampling distribution, so
/// the rounding biases nothing.
pub fn relaxed_geometry_term_fast(
    x0: Vec3,
    n0: Vec3,
    x_vpl: Vec3,
    n_vpl: Option<Vec3>,
    radius: f32,
    normal_cone: f32,
) -> f32 {
    let d = x_vpl - x0;
    let r = d.length();
    if !(r > 0.0) {
        return if radius > 0.0 { 1.0 / (radius * radius) } else { 0.0 };
    }
    relaxed_geometry_term_towards(n0, d / r, r, n_vpl, radius, normal_cone)
}

/// [`relaxed_geometry_term_fast`] for a VPL at distance `r > 0` along the unit direction
/// `w` from the record (for callers that already have them).
#[inline]
pub fn relaxed_geometry_term_towards(
    n0: Vec3,
    w: Vec3,
    r: f32,
    n_vpl: Option<Vec3>,
    radius: f32,
    normal_cone: f32,
) -> f32 {
    RelaxedReceiver::new(n0, radius, normal_cone).towards(w, r, n_vpl)
}

/// The receiver's side of [`relaxed_geometry_term_towards`], prepared once per record:
/// the cache evaluates the term for every VPL at every record, and the normal cone's
/// sine and cosine cost as much as the rest of the term.
#[derive(Clone, Copy, Debug)]
pub struct RelaxedReceiver {
    n0: Vec3,
    radius: f32,
    /// `(sin, cos)` of the normal cone clamped to `[0, π]`; `None` for a cone of 0.
    cone: Option<(f32, f32)>,
}

impl RelaxedReceiver {
    /// A receiver at normal `n0` standing for the ball of `radius` and the normal cone.
    #[inline]
    pub fn new(n0: Vec3, radius: f32, normal_cone: f32) -> Self {
        let cone = (normal_cone != 0.0).then(|| normal_cone.clamp(0.0, std::f32::consts::PI).sin_cos());
        RelaxedReceiver { n0, radius, cone }
    }

    /// The ball's radius and the normal cone's `(sin, cos)` (`None` for a cone of 0), for
    /// the eight-lane version of [`RelaxedReceiver::towards`] (`vpls/soa.rs`).
    #[inline]
    pub fn radius_and_cone(&self) -> (f32, Option<(f32, f32)>) {
        (self.radius, self.cone)
    }

    /// The relaxed term towards a VPL at distance `r > 0` along the unit direction `w`.
    #[inline]
    pub fn towards(&self, w: Vec3, r: f32, n_vpl: Option<Vec3>) -> f32 {
        let radius = self.radius;
        let sin_delta = (radius / r).min(1.0);
        let cos_delta = (1.0 - sin_delta * sin_delta).max(0.0).sqrt();
        let delta = Slack { cos: cos_delta, sin: sin_delta, at_least_pi: false };
        let receiver = match self.cone {
            Some((sin_c, cos_c)) => delta.widened(sin_c, cos_c),
            None => delta,
        };
        let cos0 = receiver.relax(self.n0.dot(w));
        let cos_vpl = n_vpl.map_or(1.0, |n| delta.relax(n.dot(-w)));
        let r_min = (r - radius).max(radius).max(f32::MIN_POSITIVE.sqrt());
        cos0 * cos_vpl / (r_min * r_min)
    }
}

/// An angle `s ∈ [0, π]` as its cosine and sine, or "at least π".
#[derive(Clone, Copy)]
struct Slack {
    cos: f32,
    sin: f32,
    at_least_pi: bool,
}

impl Slack {
    /// `s + cone` for the angle `cone ∈ [0, π]` given as its sine and cosine (angle sum;
    /// `s + cone ≥ π ⟺ cos cone ≤ −cos s`).
    #[inline]
    fn widened(self, sin_c: f32, cos_c: f32) -> Slack {
        Slack {
            cos: self.cos * cos_c - self.sin * sin_c,
            sin: self.sin * cos_c + self.cos * sin_c,
            at_least_pi: self.at_least_pi || cos_c <= -self.cos,
        }
    }

    /// `max(cos(max(θ − s, 0)), 0)` for `θ = acos(cos_theta)`.
    #[inline]
    fn relax(self, cos_theta: f32) -> f32 {
        let c = cos_theta.clamp(-1.0, 1.0);
        if self.at_least_pi || c >= self.cos {
            return 1.0;
        }
        (c * self.cos + (1.0 - c * c).max(0.0).sqrt() * self.sin).max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use filtrace_core::rng::SplitMix64;

    /// The trigonometry-free term equals the reference within 1e-4 of the largest value
    /// it can take at that distance (`1 / r_min²`), over random configurations: radii
    /// below and above the distance, normal cones from 0 to π, VPLs with and without a
    /// surface.
    #[test]
    fn fast_relaxed_term_matches_the_reference() {
        let mut rng = SplitMix64::new(4);
        for i in 0..200_000 {
            let x0 = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            let x1 = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            let (n0, n1) = (rng.unit_vector(), (i % 4 != 0).then(|| rng.unit_vector()));
            let radius = rng.range(0.0, 1.5).powi(2);
            let cone = if i % 3 == 0 { 0.0 } else { rng.range(0.0, std::f32::consts::PI) };
            let reference = relaxed_geometry_term(x0, n0, x1, n1, radius, cone);
            let fast = relaxed_geometry_term_fast(x0, n0, x1, n1, radius, cone);
            let r_min = ((x1 - x0).length() - radius).max(radius).max(f32::MIN_POSITIVE.sqrt());
            let scale = 1.0 / (r_min * r_min);
            assert!(
                (fast - reference).abs() <= 1e-4 * scale,
                "case {i}: fast {fast} vs reference {reference} (scale {scale})"
            );
        }
    }
}
