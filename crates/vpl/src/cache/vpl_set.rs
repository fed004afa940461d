//! The VPL set as the importance cache sees it: what a record needs to know about each
//! VPL to build its four distributions (thesis 4.2.5, Georgiev et al. 2012, section 4).
//!
//! The cache never shades pixels itself: the integrator evaluates the drawn VPLs with
//! visibility and combines them as the [`super::SamplePlan`] says. The cache only
//! evaluates every VPL at every record, through this trait.

use super::CachePoint;
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
    /// `cos θ0_min cos θVPL_min / r²_min` over the ball of `radius` around the record
    /// (see [`relaxed_geometry_term`]). Must be > 0 wherever some point of the
    /// neighbourhood can receive light from the VPL.
    fn bounded(&self, vpl: usize, site: &CachePoint, radius: f32) -> Rgb;

    /// Evaluates every VPL at one record into `out` (already sized to `vpl_count()`).
    /// The default calls the three methods per VPL and casts a visibility ray only where
    /// the unoccluded contribution is positive. Override it to trace the record's
    /// visibility rays as a packet: they share the record's point as origin.
    fn evaluate_record(&self, site: &CachePoint, radius: f32, out: &mut RecordValues) {
        out.clear(self.vpl_count());
        for j in 0..self.vpl_count() {
            let unoccluded = self.unoccluded(j, site);
            let visible = luminance(unoccluded) > 0.0 && self.visible(j, site);
            let full = if visible { unoccluded } else { Rgb::ZERO };
            out.set(j, full, unoccluded, self.bounded(j, site, radius));
        }
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
}

impl RecordValues {
    /// Resets to `n` zero entries.
    pub fn clear(&mut self, n: usize) {
        for v in [&mut self.full, &mut self.unoccluded, &mut self.bounded] {
            v.clear();
            v.resize(n, 0.0);
        }
        self.totals = [Rgb::ZERO; 3];
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
