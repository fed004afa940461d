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
        let (l, r) = row.split_at_mut(split_x);
        map_span(left.as_ref(), y * w, l);
        map_span(right.as_ref().and_then(|r| r.as_ref()), y * w + split_x, r);
    });
    (ColorImage::new([w, h], pixels), missing)
}

/// Maps the pixels `first..first + out.len()` of `src`'s image into `out` (left black when
/// the layer is missing).
fn map_span(src: Option<&(PixelMap, &Image)>, first: usize, out: &mut [Color32]) {
    let Some((map, image)) = src else { return };
    let c = image.channels().max(1);
    let data = &image.data()[first * c..(first + out.len()) * c];
    for (px, o) in data.chunks_exact(c).zip(out) {
        let [r, g, b] = map.map(px);
        *o = Color32::from_rgb(r, g, b);
    }
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

    /// The display stage of a 512x512 colour frame: the earlier path (the PNG writer's
    /// `tonemap_srgb8`, then a `Color32` per pixel, on one thread) against `compose` on one
    /// thread and on the pool. Prints; asserts only that both give the same pixels.
    #[test]
    #[ignore = "timing: prints the display stage's cost; run with --ignored --nocapture"]
    fn display_stage_timing() {
        let (w, h) = (512, 512);
        let data = (0..w * h * 3).map(|i| ((i as f32 * 0.618_034).fract()).powi(2) * 1.5).collect();
        let mut set = LayerSet::new(w, h);
        set.insert("colour", Image::from_vec(w, h, 3, data).unwrap());
        let d = DisplayChoice::default();
        let time = |f: &dyn Fn() -> ColorImage| {
            let t = std::time::Instant::now();
            let mut img = f();
            for _ in 0..9 {
                img = f();
            }
            (t.elapsed().as_secs_f64() * 100.0, img)
        };
        let earlier = || {
            let (rgb, _) = filtrace_io::tonemap_srgb8(set.get("colour").unwrap(), &d.tonemap());
            let px = rgb.chunks_exact(3).map(|c| Color32::from_rgb(c[0], c[1], c[2])).collect();
            ColorImage::new([w, h], px)
        };
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let (ms_earlier, a) = time(&earlier);
        let (ms_one, b) = time(&|| one.install(|| compose(&set, &d).0));
        let (ms_pool, c) = time(&|| compose(&set, &d).0);
        assert!(a.pixels == b.pixels && b.pixels == c.pixels);
        eprintln!(
            "display 512x512 (ms per frame): earlier {ms_earlier:.2}, compose 1 thread {ms_one:.2}, compose {} threads {ms_pool:.2}",
            rayon::current_num_threads()
        );
    }
}
