//! Geometry-aware lookup of the filtered indirect light (Bauszat et al. 2011, §3.2, eqs. 3-5).
//!
//! Only the first sample of a pixel (the *guide ray*, through the pixel centre) estimates
//! indirect light. Every further eye ray of the pixel takes its indirect light from the
//! filtered indirect map at the one of the four neighbouring guide rays whose hit point is
//! most similar to its own:
//!
//! ```text
//! s_i   = s_n,i * s_d,i                                   i in 0..3      (3)
//! s_n,i = 1 - ||N_a - N_i||^2 / max_j ||N_a - N_j||^2                    (4)
//! s_d,i = 1 - |D_a - D_i|     / max_j |D_a - D_j|                        (5)
//! ```
//!
//! `N_a`, `D_a` are the normal and depth of the additional eye ray, `N_i`, `D_i` those of the
//! neighbouring guide rays. The similarity needs no thresholds. Two cases the paper leaves
//! open are fixed here: a guide ray that hit nothing is never chosen, and when all
//! differences are zero (`max = 0`) the term is 1 for every guide (0/0 read as "no
//! difference"). Ties go to the first candidate in the order of [`neighbour_guides`], which
//! lists the sample's own pixel first.

use filtrace_core::{Vec2, Vec3};

/// Normal and depth at the first hit of an eye ray: the geometry the lookup compares.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HitGeometry {
    /// Unit world-space shading normal (facing the camera).
    pub normal: Vec3,
    /// Distance from the camera along the eye ray.
    pub depth: f32,
}

/// The guide-ray geometry of a whole frame, one entry per pixel (row-major, row 0 on top).
/// `None` where the guide ray escaped the scene.
#[derive(Clone, Debug, Default)]
pub struct GuideGeometry {
    pub width: usize,
    pub height: usize,
    pub hits: Vec<Option<HitGeometry>>,
}

impl GuideGeometry {
    pub fn new(width: usize, height: usize) -> Self {
        Self { width, height, hits: vec![None; width * height] }
    }

    /// Resizes (keeping the allocation when possible) and clears every entry.
    pub fn reset(&mut self, width: usize, height: usize) {
        self.width = width;
        self.height = height;
        self.hits.clear();
        self.hits.resize(width * height, None);
    }
}

/// Pixel indices of the (up to) four guide rays around film position `film` (continuous
/// pixel coordinates: pixel `(x, y)` covers `[x, x+1) x [y, y+1)`, its centre is at
/// `(x + 0.5, y + 0.5)`). The pixel containing `film` comes first. At the image border the
/// neighbourhood is clamped, so fewer than four distinct pixels may be returned.
pub fn neighbour_guides(film: Vec2, width: usize, height: usize) -> ([usize; 4], usize) {
    debug_assert!(width > 0 && height > 0);
    let clamp_x = |v: f32| (v.max(0.0) as usize).min(width - 1);
    let clamp_y = |v: f32| (v.max(0.0) as usize).min(height - 1);
    // The guide centres bracketing the sample: floor(p - 0.5) and the next one.
    let x0 = clamp_x((film.x - 0.5).floor());
    let x1 = clamp_x((film.x - 0.5).floor() + 1.0);
    let y0 = clamp_y((film.y - 0.5).floor());
    let y1 = clamp_y((film.y - 0.5).floor() + 1.0);
    let own = clamp_y(film.y.floor()) * width + clamp_x(film.x.floor());
    let mut out = [own; 4];
    let mut n = 1;
    for (x, y) in [(x0, y0), (x1, y0), (x0, y1), (x1, y1)] {
        let i = y * width + x;
        if !out[..n].contains(&i) {
            out[n] = i;
            n += 1;
        }
    }
    (out, n)
}

/// Similarities `s_i` (eq. 3) of the candidate guides to hit `a`; `None` for guides that
/// hit nothing. The reference form of eqs. 3-5, written as in the paper.
pub fn similarities(a: &HitGeometry, guides: &[Option<HitGeometry>]) -> Vec<Option<f32>> {
    let dn = |g: &HitGeometry| (a.normal - g.normal).length_squared();
    let dd = |g: &HitGeometry| (a.depth - g.depth).abs();
    let max_n = guides.iter().flatten().map(dn).fold(0.0f32, f32::max);
    let max_d = guides.iter().flatten().map(dd).fold(0.0f32, f32::max);
    // 0/0: every guide equals the sample in this attribute.
    let term = |d: f32, max: f32| if max > 0.0 { 1.0 - d / max } else { 1.0 };
    guides.iter().map(|g| g.as_ref().map(|g| term(dn(g), max_n) * term(dd(g), max_d))).collect()
}

/// The guide (pixel index) whose indirect light an additional eye ray at film position
/// `film` with hit `a` takes: the most similar of the four neighbouring guide rays
/// (eqs. 3-5). `None` when none of them hit anything.
#[inline]
pub fn most_similar_guide(guides: &GuideGeometry, film: Vec2, a: &HitGeometry) -> Option<usize> {
    let (cand, n) = neighbour_guides(film, guides.width, guides.height);
    let cand = &cand[..n];
    // Same as `similarities`, without allocating: two passes over at most four guides.
    let mut max_n = 0.0f32;
    let mut max_d = 0.0f32;
    for &i in cand {
        if let Some(g) = &guides.hits[i] {
            max_n = max_n.max((a.normal - g.normal).length_squared());
            max_d = max_d.max((a.depth - g.depth).abs());
        }
    }
    let mut best: Option<(usize, f32)> = None;
    for &i in cand {
        if let Some(g) = &guides.hits[i] {
            let s_n = if max_n > 0.0 { 1.0 - (a.normal - g.normal).length_squared() / max_n } else { 1.0 };
            let s_d = if max_d > 0.0 { 1.0 - (a.depth - g.depth).abs() / max_d } else { 1.0 };
            let s = s_n * s_d;
            if best.is_none_or(|(_, b)| s > b) {
                best = Some((i, s));
            }
        }
    }
    best.map(|(i, _)| i)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hit(n: Vec3, d: f32) -> Option<HitGeometry> {
        Some(HitGeometry { normal: n.normalize(), depth: d })
    }

    /// A 2x2 frame; the sample sits at the shared corner of the four pixels, inside pixel 0.
    fn frame(h: [Option<HitGeometry>; 4]) -> GuideGeometry {
        GuideGeometry { width: 2, height: 2, hits: h.to_vec() }
    }
    const CORNER: Vec2 = Vec2::new(0.9, 0.9);

    #[test]
    fn neighbours_bracket_the_sample_and_own_pixel_comes_first() {
        // Sample in pixel (3, 2) of a 8x8 frame, upper-left quadrant: guides (2..3, 1..2).
        let (c, n) = neighbour_guides(Vec2::new(3.2, 2.3), 8, 8);
        assert_eq!(n, 4);
        assert_eq!(c[0], 2 * 8 + 3);
        let mut s = c.to_vec();
        s.sort();
        assert_eq!(s, vec![8 + 2, 8 + 3, 2 * 8 + 2, 2 * 8 + 3]);
        // Lower-right quadrant: guides (3..4, 2..3).
        let (c, _) = neighbour_guides(Vec2::new(3.7, 2.9), 8, 8);
        let mut s = c.to_vec();
        s.sort();
        assert_eq!(s, vec![2 * 8 + 3, 2 * 8 + 4, 3 * 8 + 3, 3 * 8 + 4]);
        // Corner of the image: clamped to one pixel.
        assert_eq!(neighbour_guides(Vec2::new(0.1, 0.2), 8, 8), ([0; 4], 1));
        assert_eq!(neighbour_guides(Vec2::new(7.99, 7.99), 8, 8).1, 1);
        // 1x1 image.
        assert_eq!(neighbour_guides(Vec2::new(0.7, 0.3), 1, 1).1, 1);
    }

    #[test]
    fn picks_the_guide_with_the_most_similar_normal() {
        let a = HitGeometry { normal: Vec3::Y, depth: 5.0 };
        let g = frame([
            hit(Vec3::X, 5.0),
            hit(Vec3::Z, 5.0),
            hit(Vec3::new(0.1, 1.0, 0.0), 5.0),
            hit(-Vec3::Y, 5.0),
        ]);
        assert_eq!(most_similar_guide(&g, CORNER, &a), Some(2));
    }

    #[test]
    fn picks_the_guide_with_the_most_similar_depth() {
        let a = HitGeometry { normal: Vec3::Z, depth: 3.0 };
        let g = frame([hit(Vec3::Z, 9.0), hit(Vec3::Z, 3.2), hit(Vec3::Z, 2.5), hit(Vec3::Z, 1.0)]);
        assert_eq!(most_similar_guide(&g, CORNER, &a), Some(1));
    }

    #[test]
    fn normal_and_depth_multiply() {
        // Guide 1 has the right normal but the worst depth (s = 1 * 0 = 0); guide 2 is
        // second best in both (s = 0.5 * 0.75 > 0); guide 0 has the best depth but the worst normal.
        let a = HitGeometry { normal: Vec3::Z, depth: 10.0 };
        let g = frame([
            hit(-Vec3::Z, 10.0),                 // dn = 4 (max), dd = 0
            hit(Vec3::Z, 14.0),                  // dn = 0, dd = 4 (max)
            hit(Vec3::new(1.0, 0.0, 1.0), 11.0), // dn = 2 - sqrt2 ~ 0.59, dd = 1
            hit(Vec3::X, 12.0),                  // dn = 2, dd = 2
        ]);
        let s = similarities(&a, &g.hits);
        assert_eq!(s[0], Some(0.0));
        assert_eq!(s[1], Some(0.0));
        assert!(s[2].unwrap() > s[3].unwrap());
        assert_eq!(most_similar_guide(&g, CORNER, &a), Some(2));
    }

    #[test]
    fn guides_that_missed_are_never_picked() {
        let a = HitGeometry { normal: Vec3::Z, depth: 1.0 };
        let g = frame([None, None, hit(-Vec3::Z, 100.0), None]);
        assert_eq!(most_similar_guide(&g, CORNER, &a), Some(2));
        let g = frame([None, None, None, None]);
        assert_eq!(most_similar_guide(&g, CORNER, &a), None);
    }

    #[test]
    fn identical_guides_resolve_to_the_own_pixel() {
        let a = HitGeometry { normal: Vec3::Z, depth: 1.0 };
        let g = frame([hit(Vec3::Z, 2.0); 4]);
        // Sample inside pixel 3 (lower right), near the centre of the 2x2 frame.
        assert_eq!(most_similar_guide(&g, Vec2::new(1.1, 1.1), &a), Some(3));
        assert_eq!(most_similar_guide(&g, Vec2::new(0.9, 1.1), &a), Some(2));
    }

    #[test]
    fn an_exact_match_always_wins_and_the_fast_form_agrees_with_eqs_3_to_5() {
        // Deterministic pseudo-random 2x2 neighbourhoods.
        let mut state = 0x9e3779b97f4a7c15u64;
        let mut rnd = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 40) as f32) / (1u64 << 24) as f32
        };
        for case in 0..2000 {
            let mut hits = [None; 4];
            for h in hits.iter_mut() {
                if rnd() > 0.15 {
                    let n = Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5);
                    *h = if n.length() > 1e-3 { hit(n, 1.0 + 10.0 * rnd()) } else { None };
                }
            }
            let film = Vec2::new(0.55 + 0.9 * rnd(), 0.55 + 0.9 * rnd());
            let mut a =
                HitGeometry { normal: Vec3::new(rnd() - 0.5, 0.3, rnd()).normalize(), depth: 10.0 * rnd() };
            let exact = case % 3 == 0 && hits[case % 4].is_some();
            if exact {
                a = hits[case % 4].unwrap();
            }
            let g = frame(hits);
            let (cand, n) = neighbour_guides(film, 2, 2);
            let cands: Vec<_> = cand[..n].iter().map(|&i| g.hits[i]).collect();
            let s = similarities(&a, &cands);
            let best = most_similar_guide(&g, film, &a);
            // Naive argmax of the paper's formula (first maximum wins).
            let mut naive: Option<(usize, f32)> = None;
            for (k, si) in s.iter().enumerate() {
                if let Some(si) = si {
                    assert!((0.0..=1.0).contains(si), "similarity {si} out of [0, 1]");
                    if naive.is_none_or(|(_, b)| *si > b) {
                        naive = Some((cand[k], *si));
                    }
                }
            }
            assert_eq!(best, naive.map(|(i, _)| i), "case {case}");
            if exact {
                let b = best.unwrap();
                assert_eq!(g.hits[b].unwrap(), a, "case {case}: an identical guide must win");
            }
        }
    }
}
