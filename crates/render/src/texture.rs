//! Texture lookup: bilinear filtering with wrap-around (repeat) addressing.
//!
//! Convention: texture coordinates follow glTF/OBJ with `v` flipped relative to memory:
//! row 0 of [`Texture::texels`] is the *top* of the image, which is `v = 1`; `v = 0` is
//! the bottom row. Texel centres sit at `((x + 0.5) / w, 1 − (y + 0.5) / h)`.
//! Both coordinates wrap (`u = 1.25` reads like `u = 0.25`), and bilinear weights blend
//! across the seam.
//!
//! Bad input never panics: an unknown texture id, an empty texture or a texel buffer of
//! the wrong size evaluates to the texturable's `factor` alone (as if the texture were
//! white); non-finite `uv` reads as `(0, 0)`.
//!
//! Reference: pbrt-v4 section 10.4.3 (image texture lookups, bilinear filtering) and the
//! glTF 2.0 specification (texture coordinate origin at the image's top-left).

use filtrace_core::{Rgb, Vec2};
use filtrace_scene::{Texturable, Texture};

/// Bilinear, wrapping lookup of `tex` at `uv`. Returns white for a malformed texture.
#[inline]
pub fn bilinear(tex: &Texture, uv: Vec2) -> Rgb {
    let (w, h) = (tex.width as usize, tex.height as usize);
    if w == 0 || h == 0 || tex.texels.len() != w * h {
        return Rgb::ONE;
    }
    let u = if uv.x.is_finite() { uv.x } else { 0.0 };
    let v = if uv.y.is_finite() { uv.y } else { 0.0 };
    // Continuous texel coordinates with texel centres at integer + 0.5.
    let x = u * w as f32 - 0.5;
    let y = (1.0 - v) * h as f32 - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let wrap = |i: f32, n: usize| -> usize { (i as i64).rem_euclid(n as i64) as usize };
    let (xa, xb) = (wrap(x0, w), wrap(x0 + 1.0, w));
    let (ya, yb) = (wrap(y0, h), wrap(y0 + 1.0, h));
    let t = |x: usize, y: usize| tex.texels[y * w + x];
    (t(xa, ya) * (1.0 - fx) + t(xb, ya) * fx) * (1.0 - fy) + (t(xa, yb) * (1.0 - fx) + t(xb, yb) * fx) * fy
}

/// Value of a constant-or-textured colour at `uv` (texture × factor).
#[inline]
pub fn eval_texturable(t: &Texturable, textures: &[Texture], uv: Vec2) -> Rgb {
    match t {
        Texturable::Constant(c) => *c,
        Texturable::Texture { texture, factor } => match textures.get(*texture as usize) {
            Some(tex) => bilinear(tex, uv) * *factor,
            None => *factor,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 2x2 texture: top row red, green; bottom row blue, white.
    fn tiny() -> Texture {
        Texture { name: "tiny".into(), width: 2, height: 2, texels: vec![Rgb::X, Rgb::Y, Rgb::Z, Rgb::ONE] }
    }

    fn close(a: Rgb, b: Rgb) -> bool {
        (a - b).abs().max_element() < 1e-5
    }

    #[test]
    fn texel_centres_and_v_flip() {
        let t = tiny();
        // Texel centres: top-left (u=.25, v=.75) is red; bottom-left (u=.25, v=.25) blue.
        assert!(close(bilinear(&t, Vec2::new(0.25, 0.75)), Rgb::X));
        assert!(close(bilinear(&t, Vec2::new(0.75, 0.75)), Rgb::Y));
        assert!(close(bilinear(&t, Vec2::new(0.25, 0.25)), Rgb::Z));
        assert!(close(bilinear(&t, Vec2::new(0.75, 0.25)), Rgb::ONE));
    }

    #[test]
    fn bilinear_blend_and_wrap() {
        let t = tiny();
        // Centre of the texture: average of all four.
        let avg = (Rgb::X + Rgb::Y + Rgb::Z + Rgb::ONE) / 4.0;
        assert!(close(bilinear(&t, Vec2::new(0.5, 0.5)), avg));
        // Halfway between red and green along u on the top row.
        assert!(close(bilinear(&t, Vec2::new(0.5, 0.75)), (Rgb::X + Rgb::Y) / 2.0));
        // u = 0 lies between the right column (wrapped) and the left one.
        assert!(close(bilinear(&t, Vec2::new(0.0, 0.75)), (Rgb::X + Rgb::Y) / 2.0));
        // Periodic in both directions.
        for uv in [Vec2::new(0.1, 0.3), Vec2::new(0.9, 0.05)] {
            assert!(close(bilinear(&t, uv), bilinear(&t, uv + Vec2::new(3.0, -2.0))));
        }
    }

    #[test]
    fn texturable_and_bad_input() {
        let t = tiny();
        let texs = vec![t];
        let c = Texturable::Constant(Rgb::new(0.1, 0.2, 0.3));
        assert_eq!(eval_texturable(&c, &texs, Vec2::ZERO), Rgb::new(0.1, 0.2, 0.3));
        let tx = Texturable::Texture { texture: 0, factor: Rgb::splat(0.5) };
        assert!(close(eval_texturable(&tx, &texs, Vec2::new(0.25, 0.75)), Rgb::new(0.5, 0.0, 0.0)));
        let missing = Texturable::Texture { texture: 7, factor: Rgb::splat(0.5) };
        assert_eq!(eval_texturable(&missing, &texs, Vec2::ZERO), Rgb::splat(0.5));
        let broken = Texture { name: "b".into(), width: 3, height: 3, texels: vec![Rgb::ONE] };
        assert_eq!(bilinear(&broken, Vec2::ZERO), Rgb::ONE);
        assert!(bilinear(&texs[0], Vec2::new(f32::NAN, f32::INFINITY)).is_finite());
    }
}
