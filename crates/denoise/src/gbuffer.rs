//! Guide buffers (the visible-surface record of each pixel) and their planar, sanitised form.
//!
//! A [`GBuffer`] holds interleaved [`Image`]s as renderers write them. Filters convert colour
//! and guides once to planes (one `Vec<f32>` per channel) so that inner loops run over
//! contiguous `f32` rows, and sanitise them there:
//! - a pixel whose normal is zero (or non-finite) is *background*; filters never mix
//!   background and surface pixels;
//! - a non-finite colour value marks the pixel *invalid*: it never contributes to a
//!   neighbour, and its own output is rebuilt from valid neighbours (0 when there are none).

use crate::error::DenoiseError;
use filtrace_core::Image;

/// The guide images of one frame, all of the colour image's size.
#[derive(Clone, Debug)]
pub struct GBuffer {
    /// World-space shading normal, 3 channels; a zero-length normal means "no surface".
    pub normal: Image,
    /// World-space position of the visible surface, 3 channels.
    pub position: Option<Image>,
    /// Camera distance (or view depth) of the visible surface, 1 channel.
    pub depth: Option<Image>,
    /// Diffuse reflectance of the visible surface, 3 channels (for demodulation).
    pub albedo: Option<Image>,
    /// Length that positions and depths are divided by to make them unitless, e.g. the
    /// scene's bounding-box diagonal. Give a constant per scene so the filter is stable over
    /// frames; `None` estimates it from this frame (position: diagonal of the surface
    /// points' box; depth: largest surface depth).
    pub scene_scale: Option<f32>,
}

impl GBuffer {
    /// A G-buffer with only normals.
    pub fn new(normal: Image) -> Self {
        Self { normal, position: None, depth: None, albedo: None, scene_scale: None }
    }
    pub fn with_position(mut self, position: Image) -> Self {
        self.position = Some(position);
        self
    }
    pub fn with_depth(mut self, depth: Image) -> Self {
        self.depth = Some(depth);
        self
    }
    pub fn with_albedo(mut self, albedo: Image) -> Self {
        self.albedo = Some(albedo);
        self
    }
    pub fn with_scene_scale(mut self, scale: f32) -> Self {
        self.scene_scale = Some(scale);
        self
    }

    /// Checks channel counts and that every buffer is `width x height`.
    pub fn validate(&self, width: usize, height: usize) -> Result<(), DenoiseError> {
        let check = |name: &'static str, im: &Image, ch: usize, expected: &'static str| {
            if im.channels() != ch {
                return Err(DenoiseError::ChannelCount { buffer: name, expected, found: im.channels() });
            }
            if im.width() != width || im.height() != height {
                return Err(DenoiseError::SizeMismatch {
                    buffer: name,
                    expected: (width, height),
                    found: (im.width(), im.height()),
                });
            }
            Ok(())
        };
        check("normal", &self.normal, 3, "3")?;
        if let Some(p) = &self.position {
            check("position", p, 3, "3")?;
        }
        if let Some(d) = &self.depth {
            check("depth", d, 1, "1")?;
        }
        if let Some(a) = &self.albedo {
            check("albedo", a, 3, "3")?;
        }
        if let Some(s) = self.scene_scale {
            if !(s.is_finite() && s > 0.0) {
                return Err(crate::error::invalid("scene_scale", format!("must be finite and > 0, got {s}")));
            }
        }
        Ok(())
    }

    /// Number of background pixels (zero-length or non-finite normal).
    pub fn background_count(&self) -> usize {
        self.normal.data().chunks_exact(3).filter(|n| !is_surface(n)).count()
    }
}

/// A pixel is a surface when its normal is finite and not (near) zero.
#[inline]
pub(crate) fn is_surface(n: &[f32]) -> bool {
    let l2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
    l2.is_finite() && l2 > 1e-12
}

/// Checks that `color` is a 3-channel image with at least one pixel... or empty.
pub(crate) fn check_color(color: &Image) -> Result<(), DenoiseError> {
    if color.channels() != 3 {
        return Err(DenoiseError::ChannelCount { buffer: "colour", expected: "3", found: color.channels() });
    }
    Ok(())
}

/// Three planes of `w * h` values.
pub(crate) type Planes3 = [Vec<f32>; 3];

/// Splits an interleaved 3-channel image into planes, replacing non-finite values by 0.
/// Returns the planes and a validity plane (1 where all three values were finite).
pub(crate) fn to_planes(im: &Image) -> (Planes3, Vec<f32>) {
    let n = im.pixel_count();
    let mut p = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
    let mut valid = vec![1.0; n];
    for (i, px) in im.data().chunks_exact(3).enumerate() {
        if px.iter().all(|v| v.is_finite()) {
            p[0][i] = px[0];
            p[1][i] = px[1];
            p[2][i] = px[2];
        } else {
            valid[i] = 0.0;
        }
    }
    (p, valid)
}

/// Interleaves three planes into `out` (3 channels, same pixel count).
pub(crate) fn from_planes(p: &Planes3, out: &mut Image) {
    for (i, px) in out.data_mut().chunks_exact_mut(3).enumerate() {
        px[0] = p[0][i];
        px[1] = p[1][i];
        px[2] = p[2][i];
    }
}

/// The sanitised planar guides the filters run on.
pub(crate) struct Guides {
    pub width: usize,
    pub height: usize,
    /// Unit normals (zero on background).
    pub normal: Planes3,
    /// Positions divided by the scene scale, or `[depth / scale, 0, 0]` when only depth is
    /// given; `None` when neither is.
    pub position: Option<Planes3>,
    /// Depth divided by the depth scale (about `[0, 1]`), when depth is given.
    pub depth: Option<Vec<f32>>,
    /// 1 on surface pixels, 0 on background.
    pub surface: Vec<f32>,
}

impl Guides {
    pub fn new(g: &GBuffer, width: usize, height: usize) -> Result<Self, DenoiseError> {
        g.validate(width, height)?;
        let n = width * height;
        let mut normal = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
        let mut surface = vec![0.0; n];
        for (i, px) in g.normal.data().chunks_exact(3).enumerate() {
            if is_surface(px) {
                let inv = 1.0 / (px[0] * px[0] + px[1] * px[1] + px[2] * px[2]).sqrt();
                normal[0][i] = px[0] * inv;
                normal[1][i] = px[1] * inv;
                normal[2][i] = px[2] * inv;
                surface[i] = 1.0;
            }
        }
        let depth = g.depth.as_ref().map(|d| {
            let scale = g.scene_scale.unwrap_or_else(|| {
                let m = d
                    .data()
                    .iter()
                    .zip(&surface)
                    .filter(|(v, s)| **s > 0.0 && v.is_finite())
                    .fold(0.0f32, |m, (v, _)| m.max(v.abs()));
                if m > 0.0 {
                    m
                } else {
                    1.0
                }
            });
            d.data()
                .iter()
                .zip(&surface)
                .map(|(v, s)| if *s > 0.0 && v.is_finite() { v / scale } else { 0.0 })
                .collect::<Vec<f32>>()
        });
        let position = if let Some(p) = &g.position {
            let scale = g.scene_scale.unwrap_or_else(|| {
                let mut lo = [f32::INFINITY; 3];
                let mut hi = [f32::NEG_INFINITY; 3];
                for (px, s) in p.data().chunks_exact(3).zip(&surface) {
                    if *s > 0.0 && px.iter().all(|v| v.is_finite()) {
                        for k in 0..3 {
                            lo[k] = lo[k].min(px[k]);
                            hi[k] = hi[k].max(px[k]);
                        }
                    }
                }
                let d2: f32 = (0..3).map(|k| (hi[k] - lo[k]).max(0.0).powi(2)).sum();
                let d = d2.sqrt();
                if d.is_finite() && d > 0.0 {
                    d
                } else {
                    1.0
                }
            });
            let mut planes = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
            for (i, px) in p.data().chunks_exact(3).enumerate() {
                // Background keeps its (finite) positions: it is only ever compared with
                // background.
                if px.iter().all(|v| v.is_finite()) {
                    for k in 0..3 {
                        planes[k][i] = px[k] / scale;
                    }
                }
            }
            Some(planes)
        } else {
            depth.as_ref().map(|d| [d.clone(), vec![0.0; n], vec![0.0; n]])
        };
        Ok(Self { width, height, normal, position, depth, surface })
    }
}
