//! Procedural G-buffers for tests and benchmarks: no scene, no renderer, just the
//! normal and position layers a renderer would write, with a known structure.

use filtrace_core::rng::SplitMix64;
use filtrace_core::{Image, Vec3};

/// A "grass" frame of `width x height`: sky (background, zero normal) in the top
/// quarter, a ground plane seen at a grazing angle below it, and `blades` thin
/// vertical blades 1-3 pixels wide with random heights, depths and tilted normals in
/// front of it. Returns `(normal, position)`, both 3-channel, world space (y up,
/// camera at the origin looking down +z).
pub fn grass_gbuffer(width: usize, height: usize, blades: usize, seed: u64) -> (Image, Image) {
    let mut normal = Image::new(width, height, 3);
    let mut position = Image::new(width, height, 3);
    let horizon = height / 4;
    // Depth of the closest surface written so far, for the blades' z-test.
    let mut depth = vec![f32::INFINITY; width * height];
    let (w, h) = (width.max(1) as f32, height.max(1) as f32);
    // Ground plane y = -1: the pixel row below the horizon at screen height v < 0
    // sees it at depth z = 1 / -v (pinhole with unit focal length).
    for y in horizon..height {
        let v = -((y - horizon) as f32 + 0.5) / h - 1e-3;
        let z = 1.0 / -v;
        for x in 0..width {
            let u = (x as f32 + 0.5) / w - 0.5;
            normal.set_rgb(x, y, Vec3::Y);
            position.set_rgb(x, y, Vec3::new(u * z, -1.0, z));
            depth[y * width + x] = z;
        }
    }
    let mut rng = SplitMix64(seed);
    for _ in 0..blades {
        let x0 = (rng.next_f32() * w) as usize;
        let bw = 1 + (rng.next_f32() * 3.0) as usize;
        let z = 1.5 + 8.0 * rng.next_f32();
        // Blade base sits on the ground at depth z; its top is 10-60% of the frame above.
        let base = horizon as f32 + h / z;
        let top = base - h * (0.1 + 0.5 * rng.next_f32());
        let tilt = rng.next_f32() * 2.0 - 1.0;
        let n = Vec3::new(tilt, 0.3 * rng.next_f32(), -1.0).normalize();
        for y in (top.max(0.0) as usize)..(base.min(h) as usize) {
            for x in x0..(x0 + bw).min(width) {
                let i = y * width + x;
                if z < depth[i] {
                    depth[i] = z;
                    let u = (x as f32 + 0.5) / w - 0.5;
                    let v = 0.5 - (y as f32 + 0.5) / h;
                    normal.set_rgb(x, y, n);
                    position.set_rgb(x, y, Vec3::new(u * z, v * z, z));
                }
            }
        }
    }
    (normal, position)
}
