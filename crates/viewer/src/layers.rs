//! The layers (AOVs) the viewer can show and save: one table, [`LAYERS`], one line per
//! layer. A renderer fills a [`LayerSet`] with the layers it has, by name; the selector
//! lists every line of the table and greys out what the current frame lacks. A new AOV
//! (motion vectors, cache-point distance, ...) is one line here plus its producer's
//! `insert`.

use filtrace_core::Image;
use filtrace_io::TonemapParams;

/// How a layer becomes 8-bit display colour.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Display {
    /// Linear radiance: exposure, tone curve and sRGB encoding ([`filtrace_io::tonemap_srgb8`],
    /// the same bytes as `filtrace render`'s PNG).
    Radiance,
    /// A unit vector in [-1, 1] per channel (normals): `0.5 + 0.5 v`, no sRGB curve.
    Signed,
    /// Values scaled by the layer's 99th percentile per channel group (depth, position,
    /// variance): `v / p99`, clamped, no sRGB curve; negative values by their magnitude.
    Normalized,
    /// Already in [0, 1] (importance): shown as it is.
    Unit,
}

/// One selectable layer: its name (the EXR layer name too; `""` is the colour in an EXR)
/// and how it is displayed.
#[derive(Clone, Copy, Debug)]
pub struct LayerDesc {
    pub name: &'static str,
    pub display: Display,
    /// Channel names in the EXR.
    pub channels: &'static [&'static str],
}

const RGB: &[&str] = &["R", "G", "B"];
const XYZ: &[&str] = &["X", "Y", "Z"];

/// Every layer the viewer knows, in selector order (keys 1-9 pick the first nine).
pub const LAYERS: &[LayerDesc] = &[
    LayerDesc { name: "colour", display: Display::Radiance, channels: RGB },
    LayerDesc { name: "direct", display: Display::Radiance, channels: RGB },
    LayerDesc { name: "indirect", display: Display::Radiance, channels: RGB },
    LayerDesc { name: "albedo", display: Display::Radiance, channels: RGB },
    LayerDesc { name: "normal", display: Display::Signed, channels: XYZ },
    LayerDesc { name: "depth", display: Display::Normalized, channels: &["Z"] },
    LayerDesc { name: "position", display: Display::Normalized, channels: XYZ },
    LayerDesc { name: "variance", display: Display::Normalized, channels: RGB },
    LayerDesc { name: "importance", display: Display::Unit, channels: &["Y"] },
    LayerDesc { name: "noisy", display: Display::Radiance, channels: RGB },
];

/// The table entry of `name`.
pub fn layer(name: &str) -> Option<&'static LayerDesc> {
    LAYERS.iter().find(|l| l.name == name)
}

/// The layers of one frame, by name (all of one size).
#[derive(Clone, Debug, Default)]
pub struct LayerSet {
    pub width: usize,
    pub height: usize,
    layers: Vec<(&'static str, Image)>,
}

impl LayerSet {
    pub fn new(width: usize, height: usize) -> Self {
        Self { width, height, layers: Vec::new() }
    }

    /// Adds (or replaces) layer `name`; a name outside [`LAYERS`] or an image of another
    /// size is a programming error (debug assertion) and is dropped.
    pub fn insert(&mut self, name: &'static str, image: Image) {
        debug_assert!(layer(name).is_some(), "layer {name} is not in LAYERS");
        debug_assert!(image.width() == self.width && image.height() == self.height, "layer {name} size");
        if layer(name).is_none() || image.width() != self.width || image.height() != self.height {
            return;
        }
        self.layers.retain(|(n, _)| *n != name);
        self.layers.push((name, image));
    }

    pub fn get(&self, name: &str) -> Option<&Image> {
        self.layers.iter().find(|(n, _)| *n == name).map(|(_, i)| i)
    }

    pub fn has(&self, name: &str) -> bool {
        self.get(name).is_some()
    }

    /// The layers present, in [`LAYERS`] order.
    pub fn iter(&self) -> impl Iterator<Item = (&'static LayerDesc, &Image)> {
        LAYERS.iter().filter_map(|d| self.get(d.name).map(|i| (d, i)))
    }
}

/// `image` as 8-bit RGB for display, by `display` (a 1-channel layer is shown grey).
pub fn to_rgb8(image: &Image, display: Display, tonemap: &TonemapParams) -> Vec<u8> {
    let n = image.pixel_count();
    let c = image.channels();
    let grey_or_rgb = |f: &dyn Fn(usize, f32) -> f32| -> Vec<u8> {
        let mut out = Vec::with_capacity(n * 3);
        for px in image.data().chunks_exact(c) {
            for k in 0..3 {
                let ch = if c >= 3 { k } else { 0 };
                out.push((f(ch, px[ch]).clamp(0.0, 1.0) * 255.0).round() as u8);
            }
        }
        out
    };
    match display {
        Display::Radiance if c == 3 => filtrace_io::tonemap_srgb8(image, tonemap).0,
        Display::Radiance => grey_or_rgb(&|_, v| tonemap.display(v)),
        Display::Signed => grey_or_rgb(&|_, v| if v.is_finite() { 0.5 + 0.5 * v } else { 0.0 }),
        Display::Unit => grey_or_rgb(&|_, v| if v.is_finite() { v } else { 0.0 }),
        Display::Normalized => {
            let scale = percentile_magnitude(image, 0.99);
            grey_or_rgb(&|_, v| if v.is_finite() { v.abs() / scale } else { 0.0 })
        }
    }
}

/// The `q`-quantile of the finite magnitudes of `image` (1 when there are none or it is 0).
fn percentile_magnitude(image: &Image, q: f64) -> f32 {
    let mut v: Vec<f32> = image.data().iter().filter(|v| v.is_finite()).map(|v| v.abs()).collect();
    if v.is_empty() {
        return 1.0;
    }
    let k = ((v.len() - 1) as f64 * q).round() as usize;
    let (_, p, _) = v.select_nth_unstable_by(k, f32::total_cmp);
    if *p > 0.0 {
        *p
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_the_set_keeps_table_order() {
        for (i, a) in LAYERS.iter().enumerate() {
            assert!(LAYERS[i + 1..].iter().all(|b| b.name != a.name), "{}", a.name);
        }
        let mut set = LayerSet::new(2, 1);
        set.insert("normal", Image::filled(2, 1, 3, 0.0));
        set.insert("colour", Image::filled(2, 1, 3, 1.0));
        set.insert("colour", Image::filled(2, 1, 3, 0.5));
        let names: Vec<_> = set.iter().map(|(d, _)| d.name).collect();
        assert_eq!(names, ["colour", "normal"]);
        assert_eq!(set.get("colour").unwrap().data()[0], 0.5);
        assert!(!set.has("depth"));
    }

    #[test]
    fn display_mappings() {
        let t = TonemapParams::srgb_clamp();
        let img = Image::from_vec(2, 1, 3, vec![-1.0, 0.0, 1.0, 0.5, 0.5, 0.5]).unwrap();
        assert_eq!(to_rgb8(&img, Display::Signed, &t), [0, 128, 255, 191, 191, 191]);
        // Radiance is exactly the PNG writer's bytes.
        assert_eq!(to_rgb8(&img, Display::Radiance, &t), filtrace_io::tonemap_srgb8(&img, &t).0);
        let depth = Image::from_vec(4, 1, 1, vec![0.0, 1.0, 2.0, f32::NAN]).unwrap();
        assert_eq!(
            to_rgb8(&depth, Display::Normalized, &t),
            [0, 0, 0, 128, 128, 128, 255, 255, 255, 0, 0, 0]
        );
        let unit = Image::from_vec(1, 1, 1, vec![0.25]).unwrap();
        assert_eq!(to_rgb8(&unit, Display::Unit, &t), [64, 64, 64]);
    }
}
