//! Cache point placement (Georgiev et al. 2012; thesis 5.1.2): screen samples
//! back-projected through the G-buffer onto the visible surfaces.
//!
//! The screen is cut into about `count` equal cells and one jittered pixel is taken per
//! cell (stratified rather than the thesis's plain uniform samples: fewer gaps for the
//! same count); a cell whose tries all hit background gives nothing, and the shortfall is
//! made up with distinct surface pixels drawn uniformly at random. Deterministic in `seed`.
//!
//! The G-buffer is asked pixel by pixel ([`ScreenSurfaces`]): the renderer traces only
//! the pixels tried (about `count` primary rays instead of one per pixel). The top-up
//! draws by rejection (uniform pixels, background and taken ones refused), and asks for
//! the mask of the whole screen only when that takes too many draws (a screen with
//! almost no surface left).

use super::CachePoint;
use filtrace_core::rng::SplitMix64;
use filtrace_core::Vec3;

/// Tries per cell before giving it up to the top-up pass.
const TRIES_PER_CELL: usize = 4;

/// Rejection draws the top-up may spend per missing point before it traces the whole
/// mask instead: enough while a thirtieth or more of the untaken pixels are surface.
const TOP_UP_DRAWS_PER_POINT: usize = 32;

/// What the placement knows of a pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Pixel {
    /// Not asked yet (or asked and found to be surface, but not taken).
    Unknown,
    Taken,
    /// Asked: no surface through its centre.
    Background,
}

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
    let mut state = vec![Pixel::Unknown; pixels];
    let mut points = Vec::with_capacity(count);
    for (x0, x1, y0, y1) in strata(width, height, count) {
        for _ in 0..TRIES_PER_CELL {
            let x = x0 + ((rng.next_f32() * (x1 - x0) as f32) as usize).min(x1 - x0 - 1);
            let y = y0 + ((rng.next_f32() * (y1 - y0) as f32) as usize).min(y1 - y0 - 1);
            if try_pixel(view, y * width + x, &mut state, &mut points) {
                break;
            }
        }
    }
    top_up(view, count, &mut rng, &mut state, &mut points);
    points
}

/// Takes `pixel` when it is an untaken surface pixel (true); marks it background when
/// it is one, so that no later draw traces it again.
fn try_pixel(
    view: &impl ScreenSurfaces,
    pixel: usize,
    state: &mut [Pixel],
    points: &mut Vec<CachePoint>,
) -> bool {
    if state[pixel] != Pixel::Unknown {
        return false;
    }
    match point(view, pixel) {
        Some(p) => {
            state[pixel] = Pixel::Taken;
            points.push(p);
            true
        }
        None => {
            state[pixel] = Pixel::Background;
            false
        }
    }
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

/// Uniform in `0..n` (`n > 0`; Lemire's multiply: a bias of `n / 2⁶⁴`).
#[inline]
fn below(rng: &mut SplitMix64, n: usize) -> usize {
    ((rng.next_u64() as u128 * n as u128) >> 64) as usize
}

/// Adds distinct surface pixels, each uniform over the untaken surface pixels, until
/// `count` points or no surface pixel is left. Rejection: a uniform pixel, refused when
/// taken or background (traced once, then remembered), accepts each untaken surface
/// pixel with the same probability, so it draws without replacement exactly as a list of
/// the free surface pixels would. After `TOP_UP_DRAWS_PER_POINT` draws per missing point
/// the rest is drawn from that list (the mask of the whole screen): the same
/// distribution for what is left, and an end however little surface there is.
fn top_up(
    view: &impl ScreenSurfaces,
    count: usize,
    rng: &mut SplitMix64,
    state: &mut [Pixel],
    points: &mut Vec<CachePoint>,
) {
    let missing = count.saturating_sub(points.len());
    for _ in 0..missing.saturating_mul(TOP_UP_DRAWS_PER_POINT) {
        if points.len() >= count {
            return;
        }
        try_pixel(view, below(rng, state.len()), state, points);
    }
    if points.len() >= count {
        return;
    }
    let mask = view.surface_mask();
    let mut free: Vec<usize> = (0..state.len()).filter(|&p| state[p] == Pixel::Unknown && mask[p]).collect();
    while points.len() < count && !free.is_empty() {
        let pixel = free.swap_remove(below(rng, free.len()));
        state[pixel] = Pixel::Taken;
        points.extend(point(view, pixel));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use filtrace_core::stats::{chi2_sf, chi2_statistic};
    use std::cell::Cell;

    /// A `w × h` screen whose surface pixels are those `surface(x, y)` says, and which
    /// counts the pixels and masks asked for.
    struct Screen {
        w: usize,
        h: usize,
        surface: Vec<bool>,
        asked: Cell<usize>,
        masks: Cell<usize>,
    }

    impl Screen {
        fn new(w: usize, h: usize, surface: impl Fn(usize, usize) -> bool) -> Self {
            let surface = (0..w * h).map(|p| surface(p % w, p / w)).collect();
            Screen { w, h, surface, asked: Cell::new(0), masks: Cell::new(0) }
        }
    }

    impl ScreenSurfaces for Screen {
        fn size(&self) -> (usize, usize) {
            (self.w, self.h)
        }

        fn surface(&self, pixel: usize) -> Option<(Vec3, Vec3)> {
            self.asked.set(self.asked.get() + 1);
            self.surface[pixel].then(|| (Vec3::new(pixel as f32, 0.0, 1.0), Vec3::Z))
        }

        fn surface_mask(&self) -> Vec<bool> {
            self.masks.set(self.masks.get() + 1);
            self.surface.clone()
        }
    }

    /// How often each pixel is drawn by `trials` top-ups of `draws` points each, from a
    /// state where every pixel `taken` says is taken; the χ² p-value of those counts
    /// against the same count for every free surface pixel (and none elsewhere).
    fn top_up_uniformity(screen: &Screen, taken: impl Fn(usize) -> bool, draws: usize, trials: usize) -> f64 {
        let pixels = screen.w * screen.h;
        let mut counts = vec![0.0f64; pixels];
        for trial in 0..trials {
            let mut rng = SplitMix64::new(trial as u64);
            let mut state: Vec<Pixel> =
                (0..pixels).map(|p| if taken(p) { Pixel::Taken } else { Pixel::Unknown }).collect();
            let mut points = Vec::new();
            top_up(screen, draws, &mut rng, &mut state, &mut points);
            assert_eq!(points.len(), draws, "trial {trial}");
            for p in &points {
                counts[p.pixel as usize] += 1.0;
            }
        }
        let free: Vec<bool> = (0..pixels).map(|p| screen.surface[p] && !taken(p)).collect();
        let per_pixel = (draws * trials) as f64 / free.iter().filter(|&&f| f).count() as f64;
        let expected: Vec<f64> = free.iter().map(|&f| if f { per_pixel } else { 0.0 }).collect();
        let (stat, dof) = chi2_statistic(&counts, &expected, 5.0).expect("no draw off the free surface");
        chi2_sf(stat, dof as f64)
    }

    /// The rejection draws: uniform over the free surface pixels (taken and background
    /// ones never drawn), without the whole-screen mask.
    #[test]
    fn top_up_draws_uniformly_over_free_surface_pixels() {
        let screen = Screen::new(16, 12, |x, y| (x * 7 + y * 3) % 5 != 0 && x < 13);
        let p = top_up_uniformity(&screen, |p| p % 9 == 0, 4, 6000);
        assert!(p > 1e-3, "p = {p:.2e}");
        assert_eq!(screen.masks.get(), 0, "enough surface: no mask");
    }

    /// Almost no surface: the draws give up and read the mask, still uniform.
    #[test]
    fn top_up_on_a_nearly_empty_screen_falls_back_to_the_mask_uniformly() {
        let screen = Screen::new(64, 64, |x, y| x % 17 == 3 && y % 23 == 5);
        let p = top_up_uniformity(&screen, |_| false, 1, 4000);
        assert!(p > 1e-3, "p = {p:.2e}");
        assert!(screen.masks.get() > 3000, "mostly the mask: {}", screen.masks.get());
    }

    /// Whole cells of background: the top-up traces about the pixels it needs, not the
    /// screen, and the points stay distinct surface pixels, the same for the same seed.
    #[test]
    fn top_up_traces_few_pixels_where_cells_see_background() {
        let screen = Screen::new(64, 64, |x, _| x >= 32);
        let points = place_on_surfaces(&screen, 256, 5);
        assert_eq!(points.len(), 256);
        let mut seen = std::collections::HashSet::new();
        assert!(points.iter().all(|p| screen.surface[p.pixel as usize] && seen.insert(p.pixel)));
        assert_eq!(screen.masks.get(), 0);
        assert!(screen.asked.get() < 64 * 64 / 3, "{} pixels traced", screen.asked.get());
        assert_eq!(points, place_on_surfaces(&screen, 256, 5), "same seed, same points");
    }

    /// A screen with a handful of surface pixels: every one is found, and it ends.
    #[test]
    fn almost_no_surface_ends_with_every_surface_pixel() {
        let screen = Screen::new(64, 64, |x, y| (x, y) == (0, 0) || (x, y) == (63, 63) || (x, y) == (31, 7));
        for count in [1, 3, 4, 1000] {
            let points = place_on_surfaces(&screen, count, 11);
            assert_eq!(points.len(), count.min(3), "count {count}");
            let mut pixels: Vec<u32> = points.iter().map(|p| p.pixel).collect();
            pixels.sort_unstable();
            pixels.dedup();
            assert_eq!(pixels.len(), points.len(), "distinct");
        }
        let none = Screen::new(64, 64, |_, _| false);
        assert!(place_on_surfaces(&none, 100, 0).is_empty());
    }
}
