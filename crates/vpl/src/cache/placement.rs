//! Cache point placement (Georgiev et al. 2012; thesis 5.1.2): screen samples
//! back-projected through the G-buffer onto the visible surfaces.
//!
//! The screen is cut into about `count` equal cells and one jittered pixel is taken per
//! cell (stratified rather than the thesis's plain uniform samples: fewer gaps for the
//! same count); a cell whose tries all hit background gives nothing, and the shortfall is
//! made up with distinct surface pixels drawn at random. Deterministic in `seed`.

use super::CachePoint;
use filtrace_core::rng::SplitMix64;
use filtrace_core::Vec3;

/// Tries per cell before giving it up to the top-up pass.
const TRIES_PER_CELL: usize = 4;

/// The G-buffer as the placement needs it: per pixel (row-major) the visible surface's
/// world position and normal; a zero or non-finite normal, or a non-finite position,
/// means "no surface" (the convention of `filtrace_denoise::GBuffer`).
#[derive(Clone, Copy, Debug)]
pub struct GBufferView<'a> {
    pub width: usize,
    pub height: usize,
    pub positions: &'a [Vec3],
    pub normals: &'a [Vec3],
}

impl GBufferView<'_> {
    fn is_surface(&self, pixel: usize) -> bool {
        let (p, n) = (self.positions[pixel], self.normals[pixel]);
        p.is_finite() && n.is_finite() && n.length_squared() > 0.0
    }

    fn point(&self, pixel: usize) -> CachePoint {
        CachePoint {
            position: self.positions[pixel],
            normal: self.normals[pixel].normalize(),
            pixel: pixel as u32,
        }
    }
}

/// Places up to `count` cache points (fewer only when the image has fewer surface
/// pixels). Fails when the slices do not match `width × height`.
pub fn place_cache_points(view: &GBufferView, count: usize, seed: u64) -> Result<Vec<CachePoint>, String> {
    let pixels = view.width * view.height;
    if view.positions.len() != pixels || view.normals.len() != pixels {
        return Err(format!(
            "cache placement: G-buffer of {}x{} needs {pixels} positions and normals, got {} and {}",
            view.width,
            view.height,
            view.positions.len(),
            view.normals.len()
        ));
    }
    if count == 0 || pixels == 0 {
        return Ok(Vec::new());
    }
    let mut rng = SplitMix64::new(seed ^ 0x6361_6368_655f_7074);
    let mut taken = vec![false; pixels];
    let mut points = Vec::with_capacity(count);
    for (x0, x1, y0, y1) in strata(view.width, view.height, count) {
        for _ in 0..TRIES_PER_CELL {
            let x = x0 + ((rng.next_f32() * (x1 - x0) as f32) as usize).min(x1 - x0 - 1);
            let y = y0 + ((rng.next_f32() * (y1 - y0) as f32) as usize).min(y1 - y0 - 1);
            let pixel = y * view.width + x;
            if view.is_surface(pixel) && !taken[pixel] {
                taken[pixel] = true;
                points.push(view.point(pixel));
                break;
            }
        }
    }
    top_up(view, count, &mut rng, &mut taken, &mut points);
    Ok(points)
}

/// About `count` cells `(x0, x1, y0, y1)` (half-open, non-empty) tiling the image, in
/// rows of roughly square cells.
fn strata(width: usize, height: usize, count: usize) -> Vec<(usize, usize, usize, usize)> {
    let aspect = width as f64 / height as f64;
    let nx = ((count as f64 * aspect).sqrt().round() as usize).clamp(1, width);
    let ny = count.div_ceil(nx).clamp(1, height);
    let mut cells = Vec::with_capacity(nx * ny);
    for j in 0..ny {
        for i in 0..nx {
            let (x0, x1) = (i * width / nx, (i + 1) * width / nx);
            let (y0, y1) = (j * height / ny, (j + 1) * height / ny);
            if x1 > x0 && y1 > y0 && cells.len() < count {
                cells.push((x0, x1, y0, y1));
            }
        }
    }
    cells
}

/// Adds distinct random surface pixels until `count` points or no surface pixel is left.
fn top_up(
    view: &GBufferView,
    count: usize,
    rng: &mut SplitMix64,
    taken: &mut [bool],
    points: &mut Vec<CachePoint>,
) {
    if points.len() >= count {
        return;
    }
    let mut free: Vec<usize> = (0..taken.len()).filter(|&p| !taken[p] && view.is_surface(p)).collect();
    while points.len() < count && !free.is_empty() {
        let k = ((rng.next_f32() * free.len() as f32) as usize).min(free.len() - 1);
        let pixel = free.swap_remove(k);
        taken[pixel] = true;
        points.push(view.point(pixel));
    }
}
