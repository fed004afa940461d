//! The images an experiment writes beside its report: tonemapped PNGs, zoomed crops and
//! false-colour error maps. Kept apart from [`crate::report`] (which reads the results)
//! so that [`crate::experiment`] can write them while it runs.

use std::path::Path;

use filtrace_core::{Image, Vec3};

/// Writes a tonemapped sRGB PNG (clamped, no exposure change).
pub fn write_png(path: &Path, img: &Image) -> Result<(), String> {
    filtrace_io::write_image(path, img).map(|_| ()).map_err(|e| format!("{}: {e}", path.display()))
}

/// Crop `[x, y, w, h]` (clamped to the image), enlarged by the integer factor that makes
/// it at least 128 pixels wide (nearest neighbour: pixels stay visible).
pub fn zoomed_crop(img: &Image, [x, y, w, h]: [u32; 4]) -> Image {
    let (x, y) =
        ((x as usize).min(img.width().saturating_sub(1)), (y as usize).min(img.height().saturating_sub(1)));
    let w = (w as usize).min(img.width() - x).max(1);
    let h = (h as usize).min(img.height() - y).max(1);
    let f = (128 / w).max(1);
    let mut out = Image::new(w * f, h * f, img.channels());
    for oy in 0..h * f {
        for ox in 0..w * f {
            out.pixel_mut(ox, oy).copy_from_slice(img.pixel(x + ox / f, y + oy / f));
        }
    }
    out
}

/// False colour of a 1-channel error map on a log scale from 1e-4 to 1e1 (black, blue,
/// red, yellow, white); non-finite values are magenta.
pub fn error_map_colours(err: &Image) -> Image {
    let mut out = Image::new(err.width(), err.height(), 3);
    for (i, &e) in err.data().iter().step_by(err.channels().max(1)).enumerate() {
        let c = if !e.is_finite() {
            Vec3::new(1.0, 0.0, 1.0)
        } else {
            let t = ((e.max(1e-12).log10() + 4.0) / 5.0).clamp(0.0, 1.0);
            let stops = [
                Vec3::ZERO,
                Vec3::new(0.1, 0.1, 0.8),
                Vec3::new(0.9, 0.1, 0.1),
                Vec3::new(1.0, 0.9, 0.1),
                Vec3::ONE,
            ];
            let s = t * 4.0;
            let k = (s.floor() as usize).min(3);
            stops[k].lerp(stops[k + 1], s - k as f32)
        };
        out.data_mut()[i * 3..i * 3 + 3].copy_from_slice(&c.to_array());
    }
    out
}

/// Writes an error map as a false-colour PNG (see [`error_map_colours`]).
pub fn write_error_map(path: &Path, err: &Image) -> Result<(), String> {
    write_png(path, &error_map_colours(err))
}
