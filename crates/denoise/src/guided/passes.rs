//! The two box passes of the guided filter: window statistics to per-window coefficients
//! (pass 1), and the coefficients averaged over the windows covering each pixel (pass 2).

use super::inputs::{Inputs, P_COLOR, P_MASK, P_SURFACE};
use super::solve::solve_lanes;
use crate::stripbox::{vadd, vecs_mut, vmul, vsub, StripPass, S, V};

pub(super) struct Pass1<'a, const D: usize> {
    pub(super) inputs: &'a Inputs<D>,
    pub(super) eps: [f32; D],
    /// Per position, 1 on the lanes inside the image: windows centred on padding are empty.
    pub(super) inside: &'a [V],
}

/// The inputs of 16 pixels that the pass-1 quantities are products of.
struct Px<const D: usize> {
    m: V,
    /// `m I_a` (m is 0 or 1, so `(m I_a)(m I_b) = m I_a I_b`).
    i: [V; D],
    p: [V; 3],
}

impl<const D: usize> Px<D> {
    #[inline(always)]
    fn load(inp: &Inputs<D>, y: usize, j: usize) -> Self {
        // Loops into zeroed arrays rather than `array::from_fn`, which was compiled out of line.
        let mut px = Self::zero();
        px.m = inp.get(D + P_MASK, y, j);
        for a in 0..D {
            px.i[a] = vmul(px.m, inp.get(a, y, j));
        }
        for c in 0..3 {
            px.p[c] = inp.get(D + P_COLOR + c, y, j);
        }
        px
    }

    /// A row outside the image: contributes nothing.
    #[inline(always)]
    fn zero() -> Self {
        Self { m: [0.0; S], i: [[0.0; S]; D], p: [[0.0; S]; 3] }
    }
}

impl<const D: usize, const K1: usize> StripPass<K1> for Pass1<'_, D> {
    /// Adds / subtracts `m, m I, m I I^T, m p, m I p` of 16 pixels, in the order of [`super::k1`].
    /// (Written out without closures: a closure per quantity was compiled out of line,
    /// without the AVX-512 features.) A missing row is taken as zeros:
    /// `(c + q) - 0 = c + q` and `(c + 0) - q = c - q` exactly.
    #[inline(always)]
    fn update(&self, j: usize, y_add: Option<usize>, y_sub: Option<usize>, col: &mut [V; K1]) {
        if y_add.is_none() && y_sub.is_none() {
            return;
        }
        let inp = self.inputs;
        // (`match`, not `map_or_else`: its closure was compiled out of line.)
        let a = match y_add {
            Some(y) => Px::load(inp, y, j),
            None => Px::zero(),
        };
        let s = match y_sub {
            Some(y) => Px::load(inp, y, j),
            None => Px::zero(),
        };
        let mut k = 0;
        macro_rules! upd {
            ($qa:expr, $qs:expr) => {{
                col[k] = vsub(vadd(col[k], $qa), $qs);
                k += 1;
            }};
        }
        upd!(a.m, s.m);
        for t in 0..D {
            upd!(a.i[t], s.i[t]);
        }
        for t in 0..D {
            for u in t..D {
                upd!(vmul(a.i[t], a.i[u]), vmul(s.i[t], s.i[u]));
            }
        }
        for c in 0..3 {
            upd!(vmul(a.m, a.p[c]), vmul(s.m, s.p[c]));
        }
        for t in 0..D {
            for c in 0..3 {
                upd!(vmul(a.i[t], a.p[c]), vmul(s.i[t], s.p[c]));
            }
        }
        debug_assert_eq!(k, K1);
    }

    #[inline(always)]
    fn consume(&self, _y: usize, j: usize, sums: &[V; K1], out_row: &mut [f32]) {
        let k2 = 4 + 3 * D;
        let o = vecs_mut(&mut out_row[j * k2 * S..(j + 1) * k2 * S]);
        solve_lanes::<D, K1>(sums, &self.eps, &self.inside[j], o);
    }
}

pub(super) struct Pass2<'a, const D: usize, const K2: usize> {
    pub(super) inputs: &'a Inputs<D>,
    pub(super) coef: &'a [f32],
    /// Values per coefficient row.
    pub(super) row: usize,
    /// Per channel, `[min, max]` of the fit pixels' colours: outputs are clamped to it.
    pub(super) range: [[f32; 2]; 3],
}

impl<const D: usize, const K2: usize> StripPass<K2> for Pass2<'_, D, K2> {
    #[inline(always)]
    fn update(&self, j: usize, y_add: Option<usize>, y_sub: Option<usize>, col: &mut [V; K2]) {
        let coef = |y: usize| &self.coef[y * self.row + j * K2 * S..][..K2 * S];
        let c = col.as_flattened_mut();
        // Flat loops over the K2 * S values (see `stripbox::add`).
        match (y_add, y_sub) {
            (Some(a), Some(s)) => {
                for (c, (a, s)) in c.iter_mut().zip(coef(a).iter().zip(coef(s))) {
                    *c = (*c + a) - s;
                }
            }
            (Some(a), None) => c.iter_mut().zip(coef(a)).for_each(|(c, a)| *c += a),
            (None, Some(s)) => c.iter_mut().zip(coef(s)).for_each(|(c, s)| *c -= s),
            (None, None) => {}
        }
    }

    /// `q_i = mean(a) . I_i + mean(b)` over the windows that hold fit pixels, clamped to the
    /// fit range; background (or an isolated invalid pixel) passes the sanitised input
    /// through.
    #[inline(always)]
    fn consume(&self, y: usize, j: usize, s: &[V; K2], out_row: &mut [f32]) {
        let inp = self.inputs;
        let st = &inp.st;
        let n = s[0];
        let surface = inp.get(D + P_SURFACE, y, j);
        let fit: [bool; S] = std::array::from_fn(|l| surface[l] > 0.0 && n[l] > 0.5);
        let inv: V = std::array::from_fn(|l| 1.0 / if fit[l] { n[l] } else { 1.0 });
        let mut guide = [[0.0f32; S]; D];
        for a in 0..D {
            guide[a] = inp.get(a, y, j);
        }
        let mut q = [[0.0f32; S]; 3];
        for c in 0..3 {
            let p = inp.get(D + P_COLOR + c, y, j);
            let mut v = s[1 + 3 * D + c];
            for a in 0..D {
                v = vadd(v, vmul(s[1 + a * 3 + c], guide[a]));
            }
            let v = vmul(v, inv);
            let [lo, hi] = self.range[c];
            // (`max(lo).min(hi)` maps NaN to `hi`; `!is_finite` catches it first.)
            let v: V = v.map(|v| if v.is_finite() { v.max(lo).min(hi) } else { f32::NAN });
            q[c] = std::array::from_fn(|l| if fit[l] && !v[l].is_nan() { v[l] } else { p[l] });
        }
        for l in 0..st.lanes_in_image(j) {
            let x = l * st.len + j;
            for c in 0..3 {
                out_row[3 * x + c] = q[c][l];
            }
        }
    }
}
