//! The frame as the window shows it: the chosen layer in display colour, or in split view
//! the chosen layer left of the split and the second layer right of it. Done on the worker
//! (tone mapping a 512x512 frame costs milliseconds the UI thread should not spend).

use eframe::egui::{Color32, ColorImage};

use crate::layers::{layer, to_rgb8, LayerSet};
use crate::settings::DisplayChoice;

/// The composed image and the names of the layers asked for that `layers` lacks (shown
/// black, and named in the overlay).
pub fn compose(layers: &LayerSet, d: &DisplayChoice) -> (ColorImage, Vec<&'static str>) {
    let (w, h) = (layers.width, layers.height);
    let mut missing = Vec::new();
    let mut rgb = |name: &'static str| -> Vec<u8> {
        match (layer(name), layers.get(name)) {
            (Some(desc), Some(image)) => to_rgb8(image, desc.display, &d.tonemap()),
            _ => {
                missing.push(name);
                vec![0; w * h * 3]
            }
        }
    };
    let left = rgb(d.layer);
    let right = if d.split && d.split_layer != d.layer { Some(rgb(d.split_layer)) } else { None };
    let split_x = split_column(w, d.split_at);
    let pixels = (0..w * h)
        .map(|i| {
            let src = match &right {
                Some(r) if i % w >= split_x => r,
                _ => &left,
            };
            Color32::from_rgb(src[3 * i], src[3 * i + 1], src[3 * i + 2])
        })
        .collect();
    (ColorImage::new([w, h], pixels), missing)
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
