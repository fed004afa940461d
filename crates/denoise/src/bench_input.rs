//! The synthetic input of `filtrace bench filters` and the `filter_time` example: shaped like
//! a few-spp render (noisy colour with fireflies, a box-like G-buffer with normal, position
//! and depth edges), deterministic. The filters' cost does not depend on the content.

use crate::{GBuffer, Image};

/// A noisy colour image and a G-buffer of a few boxes in a room (normal, position, depth
/// discontinuities), deterministic.
pub fn synthetic_input(w: usize, h: usize) -> (Image, GBuffer) {
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut rnd = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let (mut c, mut n, mut p, mut d) = (
        Vec::with_capacity(w * h * 3),
        Vec::with_capacity(w * h * 3),
        Vec::with_capacity(w * h * 3),
        Vec::with_capacity(w * h),
    );
    for y in 0..h {
        for x in 0..w {
            let (u, v) = (x as f32 / w as f32, y as f32 / h as f32);
            let in_box = (0.2..0.45).contains(&u) && (0.4..0.9).contains(&v);
            let (normal, depth) = if in_box {
                ([0.0, 0.0, -1.0], 0.6)
            } else if u < 0.1 {
                ([1.0, 0.0, 0.0], 0.8 + u)
            } else if v > 0.9 {
                ([0.0, 1.0, 0.0], 0.8 + (1.0 - v))
            } else {
                ([0.0, 0.0, -1.0], 1.0)
            };
            n.extend_from_slice(&normal);
            p.extend_from_slice(&[u, 1.0 - v, depth]);
            d.push(depth);
            let base = 0.3 + 0.5 * u;
            for _ in 0..3 {
                let r = rnd();
                // Exponential-tailed noise with occasional fireflies, like a few-spp render.
                c.push(base * (-(1.0 - r).max(1e-6).ln()) * if rnd() < 0.001 { 50.0 } else { 1.0 });
            }
        }
    }
    let im = |ch, v| Image::from_vec(w, h, ch, v).expect("sizes match");
    let g = GBuffer::new(im(3, n)).with_position(im(3, p)).with_depth(im(1, d)).with_scene_scale(1.5);
    (im(3, c), g)
}
