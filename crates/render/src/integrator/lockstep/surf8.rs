//! The hit records of eight lanes ([`Surf8`]) and [`from_hits`], the lane version of
//! [`SurfaceInteraction::from_hit`].

use super::LockstepContext;
use crate::integrator::lanes::{
    bits, columns, from_bits, lookup8_u32, mask_words, per_lane, select, F8, LANES, M8, U8, V8,
};
use crate::surface::{gamma, SurfaceInteraction, OFFSET_FLOOR, OFFSET_SAFETY, TRI_FLOATS};
use filtrace_accel::{Hit, HitPacket};
use filtrace_core::{Ray, Vec2, Vec3};

/// The hit records of eight lanes, structure of arrays (a [`SurfaceInteraction`] per lane).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Surf8<const A: bool> {
    pub(super) p: V8<A>,
    /// `p_error` (the same value in all three components).
    pub(super) err: F8<A>,
    pub(super) n_g: V8<A>,
    pub(super) n_s: V8<A>,
    pub(super) n_winding: V8<A>,
    pub(super) front_face: M8<A>,
    pub(super) wo: V8<A>,
    /// `u` and `v` rows.
    pub(super) uv: [[f32; LANES]; 2],
    pub(super) material: [u32; LANES],
    pub(super) instance: [u32; LANES],
    pub(super) prim: [u32; LANES],
    pub(super) t: F8<A>,
}

impl<const A: bool> Surf8<A> {
    /// Lane `i` as a [`SurfaceInteraction`] (for the per-lane scalar code).
    #[inline(always)]
    pub(super) fn lane(&self, i: usize) -> SurfaceInteraction {
        SurfaceInteraction {
            p: self.p.lane(i),
            p_error: Vec3::splat(self.err.lane(i)),
            n_g: self.n_g.lane(i),
            n_s: self.n_s.lane(i),
            n_winding: self.n_winding.lane(i),
            front_face: self.front_face.get(i),
            wo: self.wo.lane(i),
            uv: Vec2::new(self.uv[0][i], self.uv[1][i]),
            material: self.material[i],
            instance: self.instance[i],
            prim: self.prim[i],
            t: self.t.lane(i),
        }
    }

    #[inline(always)]
    pub(super) fn set_lane(&mut self, i: usize, si: &SurfaceInteraction) {
        self.p.set_lane(i, si.p);
        self.err.set_lane(i, si.p_error.x);
        self.n_g.set_lane(i, si.n_g);
        self.n_s.set_lane(i, si.n_s);
        self.n_winding.set_lane(i, si.n_winding);
        self.front_face.set(i, si.front_face);
        self.wo.set_lane(i, si.wo);
        (self.uv[0][i], self.uv[1][i]) = (si.uv.x, si.uv.y);
        self.material[i] = si.material;
        self.instance[i] = si.instance;
        self.prim[i] = si.prim;
        self.t.set_lane(i, si.t);
    }

    /// [`SurfaceInteraction::offset_origin`] in lanes: `p` pushed along `n_g` to the side
    /// of `w` by `|n_g| . p_error`.
    #[inline(always)]
    pub(super) fn offset_origin(&self, w: V8<A>) -> V8<A> {
        let a = self.n_g.abs();
        let d = a.x * self.err + a.y * self.err + a.z * self.err;
        let below = w.dot(self.n_g).lt(F8::splat(0.0));
        let s = select(below, -d, d);
        self.p + self.n_g * s
    }
}

/// Iterates over the set lanes of `m`.
#[inline(always)]
pub(super) fn lanes_of<const A: bool>(m: M8<A>) -> impl Iterator<Item = usize> {
    let mut b = bits(m) as u32;
    std::iter::from_fn(move || {
        if b == 0 {
            return None;
        }
        let i = b.trailing_zeros() as usize;
        b &= b - 1;
        Some(i)
    })
}

/// [`SurfaceInteraction::from_hit`] for the lanes of `hits`: in lanes for meshes without
/// vertex normals and uvs, else the scalar function. Returns the records and the lanes
/// with a usable hit (a hit on a degenerate triangle counts as a miss, as in the scalar
/// `PathContext::intersect`).
#[inline(always)]
pub(super) fn from_hits<const A: bool>(
    lc: &LockstepContext,
    dir: &V8<A>,
    hits: &HitPacket,
    s: &mut Surf8<A>,
) -> M8<A> {
    let ctx = &lc.ctx;
    // Per-lane loads into plain arrays, then one vector load each (setting lanes of a
    // vector value one by one goes through memory every time).
    // Rows of the plain lanes' triangle records (row 0 for the other lanes: read, unused).
    let mut start = [0usize; LANES];
    let mut plain = 0u8;
    let mut scalar_ok = 0u8;
    let mut scalar = [None; LANES];
    s.instance = hits.instance;
    s.prim = hits.prim;
    // The uvs of a mesh without vertex uvs are the barycentrics (the scalar lanes'
    // records overwrite theirs below).
    s.uv = [hits.u, hits.v];
    if let Some(first_tri) = lc.tables.plain_first_tris() {
        // Every instance plain: the rows by one table lookup, the materials from the rows.
        plain = hits.mask;
        let rows = lookup8_u32(first_tri, U8::<A>::from_array(hits.instance))
            .wrapping_add(U8::from_array(hits.prim))
            .and(mask_words(from_bits::<A>(plain)))
            .to_array();
        start = per_lane(|i| rows[i] as usize * TRI_FLOATS);
    } else {
        let mut b = hits.mask as u32;
        while b != 0 {
            let i = b.trailing_zeros() as usize;
            b &= b - 1;
            match ctx.geometry.plain_row(hits.instance[i], hits.prim[i]) {
                Some(row) => {
                    plain |= 1 << i;
                    start[i] = row * TRI_FLOATS;
                }
                None => {
                    let h = Hit {
                        t: hits.t[i],
                        u: hits.u[i],
                        v: hits.v[i],
                        instance: hits.instance[i],
                        prim: hits.prim[i],
                    };
                    let ray = Ray::new(Vec3::ZERO, dir.lane(i));
                    scalar[i] = SurfaceInteraction::from_hit(ctx.scene, ctx.geometry, &ray, &h);
                    if scalar[i].is_some() {
                        scalar_ok |= 1 << i;
                    }
                }
            }
        }
    }
    // The records as lanes: words 0..8 and 6..14 of each row, transposed (a row lies in
    // the table: `plain_row` indexed the record).
    let (p0, p1, p2, n, scale, material) = if plain != 0 {
        let words = ctx.geometry.tri_words();
        let a = columns::<A>(words, &start).expect("triangle rows in the table");
        let b = columns::<A>(words, &start.map(|s| s + 6)).expect("triangle rows in the table");
        (
            V8::new(a[0], a[1], a[2]),
            V8::new(a[3], a[4], a[5]),
            V8::new(a[6], a[7], b[2]),
            V8::new(b[3], b[4], b[5]),
            b[6],
            b[7].to_bits(),
        )
    } else {
        (V8::default(), V8::default(), V8::default(), V8::default(), F8::default(), U8::default())
    };
    // Word 13 of a row: the material's bits (the scalar lanes' records overwrite theirs).
    s.material = material.to_array();
    // The lane version of `from_hit` (mesh without normals and uvs: n_s = n_g = winding).
    let (b1, b2) = (F8::from_array(hits.u), F8::from_array(hits.v));
    let b0 = F8::splat(1.0) - b1 - b2;
    s.p = p0 * b0 + p1 * b1 + p2 * b2;
    s.err = scale * F8::splat(gamma(7) * OFFSET_SAFETY) + F8::splat(OFFSET_FLOOR);
    let dir_len = dir.length();
    s.wo = *dir * (F8::splat(-1.0) / dir_len);
    let d = n.dot(s.wo);
    s.front_face = d.gt(F8::splat(0.0));
    // `n_s . n_winding < 0` never holds here (n_s = n_winding, unit length); `facing`:
    let flip = d.lt(F8::splat(0.0));
    s.n_winding = n;
    s.n_g = V8::select(flip, -n, n);
    s.n_s = s.n_g;
    s.t = F8::from_array(hits.t) * dir_len;
    let ok_plain = from_bits::<A>(plain) & !n.is_zero();
    let mut b = scalar_ok as u32;
    while b != 0 {
        let i = b.trailing_zeros() as usize;
        b &= b - 1;
        if let Some(si) = &scalar[i] {
            s.set_lane(i, si);
        }
    }
    ok_plain | from_bits(scalar_ok)
}
