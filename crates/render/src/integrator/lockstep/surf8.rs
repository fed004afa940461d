//! The hit records of eight lanes ([`Surf8`]) and [`from_hits`], the lane version of
//! [`SurfaceInteraction::from_hit`].

use super::LockstepContext;
use crate::integrator::lanes::{
    bits, columns, from_bits, lookup_u32, mask_of, mask_words, per_lane, select, F8, LANES, M8, U8, V8,
};
use crate::surface::{gamma, SurfaceInteraction, OFFSET_FLOOR, OFFSET_SAFETY, TRI_FLOATS};
use filtrace_accel::HitPacket;
use filtrace_core::{Vec2, Vec3};

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

/// [`SurfaceInteraction::from_hit`] for the lanes of `hits`, in lanes: the triangle
/// records are loaded as rows and transposed; on meshes with vertex normals or uvs the
/// corner values are gathered per lane and interpolated in lanes ([`vertex_attributes`]).
/// Returns the records and the lanes with a usable hit (a hit on a degenerate triangle
/// counts as a miss, as in the scalar `PathContext::intersect`).
#[inline(always)]
pub(super) fn from_hits<const A: bool>(
    lc: &LockstepContext,
    dir: &V8<A>,
    hits: &HitPacket,
    s: &mut Surf8<A>,
) -> M8<A> {
    let ctx = &lc.ctx;
    s.instance = hits.instance;
    s.prim = hits.prim;
    // The uvs of a mesh without vertex uvs are the barycentrics (`vertex_attributes`
    // overwrites the lanes of meshes with uvs).
    s.uv = [hits.u, hits.v];
    if hits.mask == 0 {
        return M8::none();
    }
    // Rows of the lanes' triangle records (row 0 for the lanes without a hit: read, unused)
    // and the lanes on meshes with vertex attributes, by table lookups.
    let t = lc.tables.instance_rows();
    let inst = U8::<A>::from_array(hits.instance);
    let in_mask = mask_words(from_bits::<A>(hits.mask));
    let rows = lookup_u32(&t.first, inst).wrapping_add(U8::from_array(hits.prim)).and(in_mask);
    let rows = rows.to_array();
    let attributes = bits(mask_of(lookup_u32(&t.attributes, inst).and(in_mask)));
    let start = per_lane(|i| rows[i] as usize * TRI_FLOATS);
    // The records as lanes: words 0..8 and 6..14 of each row, transposed (the rows lie in
    // the table: every hit indexes a record).
    let words = ctx.geometry.tri_words();
    let a = columns::<A>(words, &start).expect("triangle rows in the table");
    let b = columns::<A>(words, &start.map(|s| s + 6)).expect("triangle rows in the table");
    let (p0, p1, p2) = (V8::new(a[0], a[1], a[2]), V8::new(a[3], a[4], a[5]), V8::new(a[6], a[7], b[2]));
    let (n, scale) = (V8::new(b[3], b[4], b[5]), b[6]);
    // Word 13 of a row: the material's bits.
    s.material = b[7].to_bits().to_array();
    let (b1, b2) = (F8::from_array(hits.u), F8::from_array(hits.v));
    let b0 = F8::splat(1.0) - b1 - b2;
    s.p = p0 * b0 + p1 * b1 + p2 * b2;
    s.err = scale * F8::splat(gamma(7) * OFFSET_SAFETY) + F8::splat(OFFSET_FLOOR);
    let dir_len = dir.length();
    s.wo = *dir * (F8::splat(-1.0) / dir_len);
    let d = n.dot(s.wo);
    s.front_face = d.gt(F8::splat(0.0));
    // The shading normal: interpolated where the mesh has vertex normals, else the
    // winding normal; in the winding normal's hemisphere.
    let n_s = if attributes != 0 { vertex_attributes(lc, hits, attributes, [b0, b1, b2], n, s) } else { n };
    let n_s = V8::select(n_s.dot(n).lt(F8::splat(0.0)), -n_s, n_s);
    // `facing`: both normals to the side of `wo`.
    let flip = d.lt(F8::splat(0.0));
    s.n_winding = n;
    s.n_g = V8::select(flip, -n, n);
    s.n_s = V8::select(flip, -n_s, n_s);
    s.t = F8::from_array(hits.t) * dir_len;
    from_bits::<A>(hits.mask) & !n.is_zero()
}

/// The vertex attributes of the lanes `lanes` (meshes with vertex normals or uvs), as
/// [`SurfaceInteraction::from_hit`] computes them: the corners' normals and the instance's
/// normal transform gathered per lane, then `normalize_or_zero(M (b0 n0 + b1 n1 + b2 n2))`
/// in lanes (glam's operations in glam's order); the uvs per lane into `s.uv`. Returns the
/// shading normals (the winding normal `n` where the mesh has none, or where the
/// interpolated one is zero or not finite), not yet moved into `n`'s hemisphere.
#[inline(always)]
fn vertex_attributes<const A: bool>(
    lc: &LockstepContext,
    hits: &HitPacket,
    lanes: u8,
    [b0, b1, b2]: [F8<A>; 3],
    n: V8<A>,
    s: &mut Surf8<A>,
) -> V8<A> {
    let ctx = &lc.ctx;
    // Per lane: corner normals `[corner][axis]` and the columns of the normal transform.
    let mut corners = [[[0.0f32; LANES]; 3]; 3];
    let mut xf = [[[0.0f32; LANES]; 3]; 3];
    let mut with_normals = 0u8;
    for i in lanes_of(from_bits::<A>(lanes)) {
        let va = ctx.geometry.vertex_attributes(ctx.scene, hits.instance[i]);
        let idx = va.mesh.indices[hits.prim[i] as usize].map(|k| k as usize);
        if va.has_normals {
            with_normals |= 1 << i;
            for (c, &k) in idx.iter().enumerate() {
                let v = va.mesh.normals[k];
                (corners[c][0][i], corners[c][1][i], corners[c][2][i]) = (v.x, v.y, v.z);
            }
            for (col, axis) in
                xf.iter_mut().zip([va.normal_xf.x_axis, va.normal_xf.y_axis, va.normal_xf.z_axis])
            {
                (col[0][i], col[1][i], col[2][i]) = (axis.x, axis.y, axis.z);
            }
        }
        if va.has_uvs {
            let uvs = &va.mesh.uvs;
            let uv = b0.lane(i) * uvs[idx[0]] + b1.lane(i) * uvs[idx[1]] + b2.lane(i) * uvs[idx[2]];
            (s.uv[0][i], s.uv[1][i]) = (uv.x, uv.y);
        }
    }
    if with_normals == 0 {
        return n;
    }
    // (No closures here: they would not inherit the caller's AVX2.)
    let (c0, c1, c2) =
        (V8::from_arrays(&corners[0]), V8::from_arrays(&corners[1]), V8::from_arrays(&corners[2]));
    let interpolated: V8<A> = c0 * b0 + c1 * b1 + c2 * b2;
    // `Mat3A * Vec3`: `(x_axis n.x + y_axis n.y) + z_axis n.z`.
    let (x_axis, y_axis, z_axis) =
        (V8::from_arrays(&xf[0]), V8::from_arrays(&xf[1]), V8::from_arrays(&xf[2]));
    let m: V8<A> = x_axis * interpolated.x + y_axis * interpolated.y + z_axis * interpolated.z;
    // `normalize_or_zero`: `m * (1 / length)` when that reciprocal is finite and positive.
    let rcp = F8::splat(1.0) / m.length();
    let normalizable = rcp.is_finite() & rcp.gt(F8::splat(0.0));
    let n_i = V8::select(normalizable, m * rcp, V8::default());
    let usable = from_bits::<A>(with_normals) & n_i.is_finite() & !n_i.is_zero();
    V8::select(usable, n_i, n)
}
