//! Shared by the pipeline's integration tests (included with `#[path]`).

use filtrace_core::Image;
use filtrace_pipeline::Frame;

/// Every layer of a frame, bit for bit.
pub fn assert_frames_identical(a: &Frame, b: &Frame, what: &str) {
    let (a, b) = (&a.images, &b.images);
    let layers = [
        ("color", &a.color, &b.color),
        ("noisy", &a.noisy, &b.noisy),
        ("direct", &a.direct, &b.direct),
        ("indirect", &a.indirect, &b.indirect),
        ("filtered_indirect", &a.filtered_indirect, &b.filtered_indirect),
        ("indirect_map", &a.indirect_map, &b.indirect_map),
        ("filtered_map", &a.filtered_map, &b.filtered_map),
        ("normal", &a.guide.normal, &b.guide.normal),
        ("albedo", &a.guide.albedo, &b.guide.albedo),
        ("position", &a.guide.position, &b.guide.position),
        ("depth", &a.guide.depth, &b.guide.depth),
        ("coverage", &a.guide.coverage, &b.guide.coverage),
    ];
    for (name, x, y) in layers {
        assert!(x.same_size(y), "{what}: {name} sizes differ");
        let bits = |i: &Image| i.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let (bx, by) = (bits(x), bits(y));
        if let Some(k) = bx.iter().zip(&by).position(|(p, q)| p != q) {
            panic!("{what}: {name}[{k}] differs: {} vs {}", x.data()[k], y.data()[k]);
        }
    }
}
