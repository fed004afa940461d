//! Texture loading shared by the loaders: image files decoded with the `image` crate and
//! converted from sRGB to linear colour, each file loaded once per scene.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use filtrace_core::Rgb;

use crate::types::{Texture, TextureId};

/// The sRGB transfer function inverted (IEC 61966-2-1): encoded value in [0, 1] to linear.
#[inline]
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Builds a linear texture from 8-bit sRGB RGB texels, row 0 at the top.
pub fn texture_from_srgb8(name: &str, width: u32, height: u32, rgb8: &[u8], channels: usize) -> Texture {
    let lut: Vec<f32> = (0..256).map(|i| srgb_to_linear(i as f32 / 255.0)).collect();
    let texels = rgb8
        .chunks_exact(channels)
        .map(|p| match channels {
            1 | 2 => Rgb::splat(lut[p[0] as usize]),
            _ => Rgb::new(lut[p[0] as usize], lut[p[1] as usize], lut[p[2] as usize]),
        })
        .collect();
    Texture { name: name.to_string(), width, height, texels }
}

/// Decodes an image file (PNG or JPEG) into a linear texture.
pub fn load_texture(path: &Path) -> Result<Texture, String> {
    let img = image::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let name = path.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let rgb = img.to_rgb32f();
    let (width, height) = rgb.dimensions();
    if width == 0 || height == 0 {
        return Err(format!("{}: empty image", path.display()));
    }
    let texels =
        rgb.pixels().map(|p| Rgb::new(srgb_to_linear(p[0]), srgb_to_linear(p[1]), srgb_to_linear(p[2])));
    Ok(Texture { name, width, height, texels: texels.collect() })
}

/// Loads each texture file once; ids index the final `Scene::textures`.
#[derive(Default)]
pub(crate) struct TextureCache {
    by_path: HashMap<PathBuf, TextureId>,
    textures: Vec<Texture>,
}

impl TextureCache {
    pub(crate) fn load(&mut self, path: &Path) -> Result<TextureId, String> {
        if let Some(&id) = self.by_path.get(path) {
            return Ok(id);
        }
        let t = load_texture(path)?;
        let id = self.textures.len() as TextureId;
        self.textures.push(t);
        self.by_path.insert(path.to_path_buf(), id);
        Ok(id)
    }

    pub(crate) fn into_textures(self) -> Vec<Texture> {
        self.textures
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_decoding_matches_the_standard() {
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
        // 0.5 encoded is 0.214041 linear (IEC 61966-2-1).
        assert!((srgb_to_linear(0.5) - 0.214_041).abs() < 1e-5);
        // Continuous at the break point.
        assert!((0.04045f32 / 12.92 - ((0.04045f32 + 0.055) / 1.055).powf(2.4)).abs() < 1e-6);
    }
}
