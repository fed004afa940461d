//! Cache point placement (Georgiev et al. 2012; thesis 5.1.2): screen samples
//! back-projected through the G-buffer onto the visible surfaces.
//!
//! The screen is cut into about `count` equal cells and one jittered pixel is taken per
//! cell (stratified rather than the thesis's plain uniform samples: fewer gaps for the
//! same count); a cell whose tries all hit background gives nothing, and the shortfall is
//! made up with distinct surface pixels drawn at random. Deterministic in `seed`.
//!
//! The G-buffer is asked pixel by pixel ([`ScreenSurfaces`]): the renderer traces only
//! the pixels tried (about `count` primary rays instead of one per pixel), and a whole
//! mask only when a top-up is needed.

use super::CachePoint;
use filtrace_core::rng::SplitMix64;
use filtrace_core::Vec3;

/// Tries per cell before giving it up to the top-up pass.
const TRIES_PER_CELL: usize = 4;

/// The visible surfaces of the screen as the placement asks for them.
pub trait ScreenSurfaces {
    /// Width and height in pixels.
    fn size(&self) -> (usize, usize);
    /// The world position and (not necessarily unit) normal seen through the pixel's
    /// centre (row-major index), `None` for background; a zero or non-finite normal or a
    /// non-finite position also means background ([`is_surface`]).
    fn surface(&self, pixel: usize) -> Option<(Vec3, Vec3)>;
    /// [`is_surface`] of every pixel (the top-up's); one `surface` per pixel unless an
    /// implementation does better (in parallel).
    fn surface_mask(&self) -> Vec<bool> {
        let (w, h) = self.size();
        (0..w * h).map(|p| is_surface(self.surface(p))).collect()
    }
}

/// Whether a G-buffer entry is a surface (the convention of `filtrace_denoise::GBuffer`).
#[inline]
pub fn is_surface(entry: Option<(Vec3, Vec3)>) -> bool {
    entry.is_some_and(|(p, n)| p.is_finite() && n.is_finite() && n.length_squared() > 0.0)
}

/// A G-buffer held in memory: per pixel (row-major) the visible surface's world position
/// and normal; a zero normal means "no surface".
#[derive(Clone, Copy, Debug)]
pub struct GBufferView<'a> {
    pub width: usize,
    pub height: usize,
    pub positions: &'a [Vec3],
    pub normals: &'a [Vec3],
}

impl GBufferView<'_> {
    /// Fails when the slices do not match `width × height`.
    fn check(&self) -> Result<(), String> {
        let pixels = self.width * self.height;
        if self.positions.len() != pixels || self.normals.len() != pixels {
            return Err(format!(
                "cache placement: G-buffer of {}x{} needs {pixels} positions and normals, got {} and {}",
                self.width,
                self.height,
                self.positions.len(),
                self.normals.len()
            ));
        }
        Ok(())
    }
}

impl ScreenSurfaces for GBufferView<'_> {
    fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    fn surface(&self, pixel: usize) -> Option<(Vec3, Vec3)> {
        Some((self.positions[pixel], self.normals[pixel]))
    }
}

/// Places up to `count` cache points (fewer only when the image has fewer surface
/// pixels). Fails when the slices do not match `width × height`.
pub fn place_cache_points(view: &GBufferView, count: usize, seed: u64) -> Result<Vec<CachePoint>, String> {
    view.check()?;
    Ok(place_on_surfaces(view, count, seed))
}

/// [`place_cache_points`] on any [`ScreenSurfaces`].
pub fn place_on_surfaces(view: &impl ScreenSurfaces, count: usize, seed: u64) -> Vec<CachePoint> {
    let (width, height) = view.size();
    let pixels = width * height;
    if count == 0 || pixels == 0 {
        return Vec::new();
    }
    let mut rng = SplitMix64::new(seed ^ 0x6361_6368_655f_7074);
    let mut taken = vec![false; pixels];
    let mut points = Vec::with_capacity(count);
    for (x0, x1, y0, y1) in strata(width, height, count) {
        for _ in 0..TRIES_PER_CELL {
            let x = x0 + ((rng.next_f32() * (x1 - x0) as f32) as usize).min(x1 - x0 - 1);
            let y = y0 + ((rng.next_f32() * (y1 - y0) as f32) as usize).min(y1 - y0 - 1);
            let pixel = y * width + x;
            if taken[pixel] {
                continue;
            }
            if let Some(point) = point(view, pixel) {
                taken[pixel] = true;
                points.push(point);
                break;
            }
        }
    }
    top_up(view, count, &mut rng, &mut taken, &mut points);
    points
}

/// The cache point of a surface pixel.
fn point(view: &impl ScreenSurfaces, pixel: usize) -> Option<CachePoint> {
    let entry = view.surface(pixel);
    let (position, normal) = entry.filter(|_| is_surface(entry))?;
    Some(CachePoint { position, normal: normal.normalize(), pixel: pixel as u32 })
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
    view: &impl ScreenSurfaces,
    count: usize,
    rng: &mut SplitMix64,
    taken: &mut [bool],
    points: &mut Vec<CachePoint>,
) {
    if points.len() >= count {
        return;
    }
    let mask = view.surface_mask();
    let mut free: Vec<usize> = (0..taken.len()).filter(|&p| !taken[p] && mask[p]).collect();
    while points.len() < count && !free.is_empty() {
        let k = ((rng.next_f32() * free.len() as f32) as usize).min(free.len() - 1);
        let pixel = free.swap_remove(k);
        taken[pixel] = true;
        points.extend(point(view, pixel));
    }
}
