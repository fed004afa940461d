//! The frame as the window shows it: the chosen layer in display colour, or in split view
//! the chosen layer left of the split and the second layer right of it. Done on the worker,
//! rows in parallel on its pool, straight into the RGBA8 pixels the texture takes (tone
//! mapping a 512x512 frame costs milliseconds the UI thread should not spend).

use eframe::egui::{Color32, ColorImage};
use filtrace_core::Image;
use rayon::prelude::*;

use crate::layers::{layer, LayerSet, PixelMap};
use crate::settings::DisplayChoice;

/// The composed image and the names of the layers asked for that `layers` lacks (shown
/// black, and named in the overlay).
pub fn compose(layers: &LayerSet, d: &DisplayChoice) -> (ColorImage, Vec<&'static str>) {
    let (w, h) = (layers.width, layers.height);
    let tonemap = d.tonemap();
    let mut missing = Vec::new();
    let mut side = |name: &'static str| match (layer(name), layers.get(name)) {
        (Some(desc), Some(image)) => Some((PixelMap::new(image, desc.display, &tonemap), image)),
        _ => {
            missing.push(name);
            None
        }
    };
    let left = side(d.layer);
    // `Some(None)`: a split whose right layer is missing (black).
    let right = (d.split && d.split_layer != d.layer).then(|| side(d.split_layer));
    let split_x = if right.is_some() { split_column(w, d.split_at) } else { w };
    let mut pixels = vec![Color32::BLACK; w * h];
    pixels.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, row)| {
        for (x, out) in row.iter_mut().enumerate() {
            let src = if x >= split_x { right.as_ref().and_then(|r| r.as_ref()) } else { left.as_ref() };
            if let Some((map, image)) = src {
                *out = rgb(map, image, y * w + x);
            }
        }
    });
    (ColorImage::new([w, h], pixels), missing)
}

#[inline]
fn rgb(map: &PixelMap, image: &Image, i: usize) -> Color32 {
    let c = image.channels();
    let [r, g, b] = map.map(&image.data()[i * c..(i + 1) * c]);
    Color32::from_rgb(r, g, b)
}

/// The first column of the right part of a split at `fraction` of `width`.
pub fn split_column(width: usize, fraction: f32) -> usize {
    ((width as f32 * fraction.clamp(0.0, 1.0)).round() as usize).min(width)
}

#[cfg(test)]
mod tests {
    use super::*;
    use filtrace_core::Image;

    #[test]
    fn split_view_shows_one_layer_each_side_and_names_missing_layers() {
        let mut set = LayerSet::new(4, 1);
        set.insert("colour", Image::filled(4, 1, 3, 1.0));
        set.insert("normal", Image::filled(4, 1, 3, -1.0));
        let d =
            DisplayChoice { split: true, split_layer: "normal", split_at: 0.5, ..DisplayChoice::default() };
        let (img, missing) = compose(&set, &d);
        let row: Vec<u8> = img.pixels.iter().map(|c| c.r()).collect();
        assert_eq!(row, [255, 255, 0, 0]);
        assert!(missing.is_empty());
        let d = DisplayChoice { layer: "variance", ..DisplayChoice::default() };
        let (img, missing) = compose(&set, &d);
        assert_eq!(missing, ["variance"]);
        assert!(img.pixels.iter().all(|c| *c == Color32::BLACK));
    }
}
