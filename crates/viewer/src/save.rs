//! Writing what the viewer shows: the frame's layers as one multi-layer EXR (the colour as
//! `R,G,B`, every other layer under its name, as `filtrace render` writes them), the
//! displayed image as PNG, and window screenshots cropped to the image area. Every file
//! goes through `filtrace_io`'s atomic writes (a failed write leaves an old file intact).

use std::path::{Path, PathBuf};

use eframe::egui::{self, ColorImage};
use filtrace_io::ExrImage;

use crate::layers::LayerSet;

/// `dir/<stem>-NNN.<ext>` for the first NNN for which no `.exr`/`.png` of that name exists.
pub fn next_free(dir: &Path, stem: &str) -> PathBuf {
    (1..)
        .map(|n| dir.join(format!("{stem}-{n:03}")))
        .find(|p| !p.with_extension("exr").exists() && !p.with_extension("png").exists())
        .expect("some number is free")
}

/// Writes `layers` to `path` (EXR, the colour as `R,G,B`, other layers by name) with the
/// header attributes `attributes`.
pub fn write_layers_exr(path: &Path, layers: &LayerSet, attributes: &[(&str, String)]) -> Result<(), String> {
    let mut exr = ExrImage::new(layers.width, layers.height);
    for (desc, image) in layers.iter() {
        let name = if desc.name == "colour" { "" } else { desc.name };
        exr.insert(name, desc.channels, image).map_err(|e| e.to_string())?;
    }
    for (name, value) in attributes {
        exr.set_attribute(name, value).map_err(|e| e.to_string())?;
    }
    filtrace_io::write_exr(path, &exr).map_err(|e| e.to_string())
}

/// Writes an egui image as an 8-bit RGB PNG.
pub fn write_png(path: &Path, image: &ColorImage) -> Result<(), String> {
    let [w, h] = image.size;
    let rgb: Vec<u8> = image.pixels.iter().flat_map(|c| [c.r(), c.g(), c.b()]).collect();
    let buffer = image::RgbImage::from_raw(w as u32, h as u32, rgb).ok_or("image size mismatch")?;
    filtrace_io::write_atomic(path, |out| {
        let mut bytes = Vec::new();
        buffer
            .write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png)
            .map_err(std::io::Error::other)?;
        out.write_all(&bytes)
    })
    .map_err(|e| e.to_string())
}

/// The part of a window screenshot inside `rect` (in points; `pixels_per_point` converts),
/// clipped to the screenshot.
pub fn crop(shot: &ColorImage, rect: egui::Rect, pixels_per_point: f32) -> ColorImage {
    let [sw, sh] = shot.size;
    let px = |v: f32, max: usize| ((v * pixels_per_point).round().max(0.0) as usize).min(max);
    let (x0, y0) = (px(rect.min.x, sw), px(rect.min.y, sh));
    let (x1, y1) = (px(rect.max.x, sw), px(rect.max.y, sh));
    let (w, h) = (x1.saturating_sub(x0), y1.saturating_sub(y0));
    let pixels =
        (y0..y0 + h).flat_map(|y| shot.pixels[y * sw + x0..y * sw + x0 + w].iter().copied()).collect();
    ColorImage::new([w, h], pixels)
}

#[cfg(test)]
mod tests {
    use super::*;
    use egui::{pos2, Color32, Rect};
    use filtrace_core::Image;

    #[test]
    fn crop_takes_the_rect_in_physical_pixels() {
        let pixels = (0..16).map(|i| Color32::from_gray(i as u8)).collect();
        let shot = ColorImage::new([4, 4], pixels);
        let c = crop(&shot, Rect::from_min_max(pos2(1.0, 1.0), pos2(3.0, 2.0)), 1.0);
        assert_eq!(c.size, [2, 1]);
        assert_eq!(c.pixels, [Color32::from_gray(5), Color32::from_gray(6)]);
        let c = crop(&shot, Rect::from_min_max(pos2(0.5, 0.5), pos2(9.0, 9.0)), 2.0);
        assert_eq!(c.size, [3, 3]);
        assert_eq!(crop(&shot, Rect::EVERYTHING, 1.0), shot);
    }

    #[test]
    fn layers_and_png_are_written_and_read_back() {
        let dir = std::env::temp_dir().join(format!("filtrace-view-save-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut set = LayerSet::new(3, 2);
        set.insert("colour", Image::filled(3, 2, 3, 0.25));
        set.insert("depth", Image::filled(3, 2, 1, 7.0));
        let base = next_free(&dir, "v");
        assert!(base.ends_with("v-001"));
        write_layers_exr(&base.with_extension("exr"), &set, &[("filtrace:spp", "4".into())]).unwrap();
        let back = filtrace_io::read_exr(base.with_extension("exr")).unwrap();
        assert_eq!(back.layer(&["color"]).unwrap(), *set.get("colour").unwrap());
        assert_eq!(back.layer(&["depth"]).unwrap(), *set.get("depth").unwrap());
        assert_eq!(back.attribute("filtrace:spp"), Some("4"));
        let img = ColorImage::new([3, 2], vec![Color32::from_rgb(1, 2, 3); 6]);
        write_png(&base.with_extension("png"), &img).unwrap();
        let png = image::open(base.with_extension("png")).unwrap().to_rgb8();
        assert_eq!(png.get_pixel(2, 1).0, [1, 2, 3]);
        assert!(next_free(&dir, "v").ends_with("v-002"));
        std::fs::remove_dir_all(&dir).ok();
    }
}
