//! The layers (AOVs) the viewer can show and save: one table, [`LAYERS`], one line per
//! layer. A renderer fills a [`LayerSet`] with the layers it has, by name; the selector
//! lists every line of the table and greys out what the current frame lacks. A new AOV
//! is one line here plus its producer's `insert`.

use filtrace_core::Image;
use filtrace_io::{Tonemap, TonemapParams};

use crate::srgb8::encode;

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
    /// A screen-space offset in pixels (X, Y): the flow colour wheel, hue for the direction
    /// and saturation for the length over the layer's 99th percentile; still pixels white.
    Motion,
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

/// Every layer the viewer knows, in selector order (keys 1-9 and 0 pick the first ten).
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
    LayerDesc { name: "motion", display: Display::Motion, channels: &["X", "Y"] },
    LayerDesc { name: "cache_distance", display: Display::Normalized, channels: &["Y"] },
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
    /// Layers the renderer had but that were not copied out (a moving frame keeps only the
    /// layers shown): the selector offers them, and the next frame has them.
    not_kept: Vec<&'static str>,
}

impl LayerSet {
    pub fn new(width: usize, height: usize) -> Self {
        Self { width, height, layers: Vec::new(), not_kept: Vec::new() }
    }

    /// Inserts the layer `name` made by `image` when `keep(name)`, else only notes that the
    /// renderer has it (no copy of its pixels).
    pub fn offer(&mut self, name: &'static str, keep: &dyn Fn(&str) -> bool, image: impl FnOnce() -> Image) {
        if keep(name) {
            self.insert(name, image());
        } else {
            self.not_kept.push(name);
        }
    }

    /// Names of every layer the renderer had for this frame, kept or not.
    pub fn available(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.layers.iter().map(|(n, _)| *n).chain(self.not_kept.iter().copied())
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

/// How one frame's layer becomes display RGB, pixel by pixel: built once per frame (the
/// percentile a normalized or motion layer is scaled by is found here), then applied to
/// each pixel on any thread ([`crate::display::compose`] maps rows in parallel).
#[derive(Clone, Copy, Debug)]
pub struct PixelMap {
    display: Display,
    tonemap: TonemapParams,
    channels: usize,
    /// Normalized: the 99th percentile of the magnitudes; motion: of the offsets' lengths.
    scale: f32,
    /// `2^exposure`, once per frame rather than per value.
    gain: f32,
}

impl PixelMap {
    pub fn new(image: &Image, display: Display, tonemap: &TonemapParams) -> Self {
        let scale = match display {
            Display::Normalized => percentile(image.data().iter().map(|v| v.abs()), 0.99),
            Display::Motion => {
                percentile(image.data().chunks_exact(image.channels().max(1)).map(motion_length), 0.99)
            }
            _ => 1.0,
        };
        let gain = tonemap.exposure.exp2();
        Self { display, tonemap: *tonemap, channels: image.channels(), scale, gain }
    }

    /// [`TonemapParams::display`] with the exposure's gain computed once: the same
    /// arithmetic, so the same value (`display_mappings` holds it to the PNG writer's bytes).
    #[inline]
    fn display_value(&self, v: f32) -> f32 {
        if !v.is_finite() {
            return 0.0;
        }
        let x = (v * self.gain).max(0.0);
        let y = match self.tonemap.curve {
            Tonemap::Clamp => x,
            Tonemap::Filmic => (x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14),
        };
        y.clamp(0.0, 1.0)
    }

    /// Display RGB of one pixel's channels (a 1-channel layer is grey).
    #[inline]
    pub fn map(&self, px: &[f32]) -> [u8; 3] {
        let unit = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        let finite = |v: f32| if v.is_finite() { v } else { 0.0 };
        let pick = |k: usize| px[if self.channels >= 3 { k } else { 0 }];
        match self.display {
            // The PNG writer's bytes (filtrace_io::tonemap_srgb8), by table.
            Display::Radiance if self.channels == 3 => [0, 1, 2].map(|k| encode(self.display_value(px[k]))),
            Display::Radiance => [0, 1, 2].map(|k| unit(self.display_value(pick(k)))),
            Display::Signed => [0, 1, 2].map(|k| unit(0.5 + 0.5 * finite(pick(k)))),
            Display::Unit => [0, 1, 2].map(|k| unit(finite(pick(k)))),
            Display::Normalized => [0, 1, 2].map(|k| unit(finite(pick(k)).abs() / self.scale)),
            Display::Motion => flow_colour(px, self.scale),
        }
    }
}

/// `image` as 8-bit RGB for display, by `display` (a 1-channel layer is shown grey).
pub fn to_rgb8(image: &Image, display: Display, tonemap: &TonemapParams) -> Vec<u8> {
    let map = PixelMap::new(image, display, tonemap);
    image.data().chunks_exact(image.channels().max(1)).flat_map(|px| map.map(px)).collect()
}

/// Length of a motion offset (0 when not finite or not two channels).
fn motion_length(px: &[f32]) -> f32 {
    match px {
        [x, y, ..] if x.is_finite() && y.is_finite() => x.hypot(*y),
        _ => 0.0,
    }
}

/// The optical-flow colour wheel (as in the Middlebury flow benchmark): the hue is the
/// direction of the offset (right red, up yellow-green, left cyan, down blue-violet), the
/// saturation its length over `scale`; no motion is white. Not finite: black.
fn flow_colour(px: &[f32], scale: f32) -> [u8; 3] {
    let (x, y) = (px[0], px.get(1).copied().unwrap_or(0.0));
    if !(x.is_finite() && y.is_finite()) {
        return [0, 0, 0];
    }
    let s = (x.hypot(y) / scale).min(1.0);
    // Image y points down: up on screen is a positive angle.
    let turns = (-y).atan2(x).rem_euclid(std::f32::consts::TAU) / std::f32::consts::TAU;
    let h = turns * 6.0;
    // HSV to RGB with value 1 (the closed form of Wikipedia's "HSV to RGB alternative").
    let channel = |n: f32| {
        let k = (n + h) % 6.0;
        1.0 - s * k.min(4.0 - k).clamp(0.0, 1.0)
    };
    [5.0, 3.0, 1.0].map(|n| (channel(n) * 255.0).round() as u8)
}

/// The `q`-quantile of the finite `values` (1 when there are none or it is 0).
fn percentile(values: impl Iterator<Item = f32>, q: f64) -> f32 {
    let mut v: Vec<f32> = values.filter(|v| v.is_finite()).collect();
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
        // Radiance is exactly the PNG writer's bytes, whatever the value, exposure and curve.
        let mut values: Vec<f32> =
            (0..3000).map(|i| (i as f32 * 0.618).fract().powi(3) * 4.0 - 0.1).collect();
        values.extend([f32::NAN, f32::INFINITY, -f32::INFINITY, 1e-9, 0.0031308, 1.0, 3e38]);
        values.truncate(values.len() / 3 * 3);
        let hdr = Image::from_vec(values.len() / 3, 1, 3, values).unwrap();
        for exposure in [0.0, -1.5, 2.0] {
            for (_, preset) in TonemapParams::presets() {
                let tm = TonemapParams { exposure, ..preset };
                assert_eq!(to_rgb8(&hdr, Display::Radiance, &tm), filtrace_io::tonemap_srgb8(&hdr, &tm).0);
            }
        }
        let depth = Image::from_vec(4, 1, 1, vec![0.0, 1.0, 2.0, f32::NAN]).unwrap();
        assert_eq!(
            to_rgb8(&depth, Display::Normalized, &t),
            [0, 0, 0, 128, 128, 128, 255, 255, 255, 0, 0, 0]
        );
        let unit = Image::from_vec(1, 1, 1, vec![0.25]).unwrap();
        assert_eq!(to_rgb8(&unit, Display::Unit, &t), [64, 64, 64]);
    }

    #[test]
    fn motion_is_the_flow_colour_wheel() {
        let t = TonemapParams::srgb_clamp();
        // Right, up (negative image y), left, down, none; the longest sets the scale.
        let m = Image::from_vec(5, 1, 2, vec![2.0, 0.0, 0.0, -2.0, -2.0, 0.0, 0.0, 2.0, 0.0, 0.0]).unwrap();
        let rgb = to_rgb8(&m, Display::Motion, &t);
        assert_eq!(&rgb[0..3], [255, 0, 0], "right: red");
        assert_eq!(&rgb[3..6], [128, 255, 0], "up: a quarter turn on");
        assert_eq!(&rgb[6..9], [0, 255, 255], "left: cyan");
        assert_eq!(&rgb[9..12], [128, 0, 255], "down: three quarters");
        assert_eq!(&rgb[12..15], [255, 255, 255], "no motion: white");
        let half = Image::from_vec(2, 1, 2, vec![1.0, 0.0, 2.0, 0.0]).unwrap();
        assert_eq!(
            &to_rgb8(&half, Display::Motion, &t)[0..3],
            [255, 128, 128],
            "half the scale: half saturated"
        );
    }
}
