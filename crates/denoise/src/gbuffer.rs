//! Guide buffers (the visible-surface record of each pixel) and their planar, sanitised form.
//!
//! A [`GBuffer`] holds interleaved [`Image`]s as renderers write them. Filters convert colour
//! and guides once to planes (one `Vec<f32>` per channel) so that inner loops run over
//! contiguous `f32` rows, and sanitise them there:
//! - a pixel whose normal is zero (or non-finite) is *background*; filters never mix
//!   background and surface pixels. So is a pixel whose depth or position (when given) is
//!   non-finite or at least [`FAR_BACKGROUND`] away: Cycles writes depth `1e10` where rays
//!   escape, also on edge pixels whose (pixel-filtered) normal is set;
//! - a non-finite colour value (or one of [`COLOR_LIMIT`] or more) marks the pixel *invalid*: it never contributes to a
//!   neighbour, and its own output is rebuilt from valid neighbours (0 when there are none).

use crate::error::DenoiseError;
use crate::pool::Buf;
use filtrace_core::Image;
use rayon::prelude::*;

/// Pixels per parallel work item of the per-pixel conversions.
const PAR_CHUNK: usize = 16 * 1024;

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
    /// points' box; depth: the [`DEPTH_SCALE_PERCENTILE`] of the surface depths), from
    /// surface pixels only (see [`surface_at`]).
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
        match self.scene_scale {
            Some(s) => crate::error::require_positive("scene_scale", s),
            None => Ok(()),
        }
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

/// Colour values of this magnitude or more are invalid, as non-finite ones are: no radiance
/// is that large, and sums of a few of them would overflow f32 (`3e38` everywhere gave a
/// black image).
pub const COLOR_LIMIT: f32 = 1e30;

/// A colour value the filters use: finite and below [`COLOR_LIMIT`] in magnitude.
#[inline]
pub fn is_valid_color(v: f32) -> bool {
    v.abs() < COLOR_LIMIT // false for NaN and infinities too
}

/// Depths and position coordinates of this magnitude or more are background (or garbage),
/// not surfaces: Cycles writes `1e10` for escaped rays, other renderers `f32::MAX` or
/// infinity. No scene is modelled at 1e9 units (a million kilometres in metres).
pub const FAR_BACKGROUND: f32 = 1e9;

/// A depth or position value a surface can have: finite and below [`FAR_BACKGROUND`].
#[inline]
pub fn is_valid_distance(v: f32) -> bool {
    v.abs() < FAR_BACKGROUND // false for NaN and infinities too
}

/// Whether pixel `i` of `g` is a surface: its normal is set ([`is_surface`]) and its depth
/// and position, when given, are valid ([`is_valid_distance`]).
#[inline]
pub fn surface_at(g: &GBuffer, i: usize) -> bool {
    is_surface(&g.normal.data()[3 * i..3 * i + 3])
        && g.depth.as_ref().is_none_or(|d| is_valid_distance(d.data()[i]))
        && g.position
            .as_ref()
            .is_none_or(|p| p.data()[3 * i..3 * i + 3].iter().all(|v| is_valid_distance(*v)))
}

/// The depth scale is this percentile of the surface pixels' depths, not their maximum: a
/// few far pixels (a distant object, a missed background) must not shrink every depth to
/// ~0 and so switch the depth term off.
pub const DEPTH_SCALE_PERCENTILE: f64 = 0.99;

/// Scaled guide values are clamped to this magnitude: a user's tiny `scene_scale` then never
/// makes them infinite (the filters subtract and square them).
pub(crate) const GUIDE_LIMIT: f32 = 1e6;

/// The depth scale of `g` (its `scene_scale` when set, else [`DEPTH_SCALE_PERCENTILE`] of
/// `|depth|` over surface pixels; 1 when there is none or it is 0).
pub(crate) fn depth_scale(g: &GBuffer, depth: &Image) -> f32 {
    if let Some(s) = g.scene_scale {
        return s;
    }
    let mut d: Vec<f32> =
        (0..depth.pixel_count()).filter(|&i| surface_at(g, i)).map(|i| depth.data()[i].abs()).collect();
    if d.is_empty() {
        return 1.0;
    }
    let k = ((d.len() - 1) as f64 * DEPTH_SCALE_PERCENTILE).round() as usize;
    let (_, v, _) = d.select_nth_unstable_by(k, f32::total_cmp);
    if *v > 0.0 {
        *v
    } else {
        1.0
    }
}

/// Checks that `color` is a 3-channel image with at least one pixel... or empty.
pub(crate) fn check_color(color: &Image) -> Result<(), DenoiseError> {
    if color.channels() != 3 {
        return Err(DenoiseError::ChannelCount { buffer: "colour", expected: "3", found: color.channels() });
    }
    Ok(())
}

/// Three planes of `w * h` values.
pub(crate) type Planes3 = [Buf; 3];

/// Splits an interleaved 3-channel image into planes, replacing non-finite values by 0.
/// Returns the planes and a validity plane (1 where all three values were finite).
pub(crate) fn to_planes(im: &Image) -> (Planes3, Buf) {
    to_planes_strided(im, im.width())
}

/// [`to_planes`] into planes of `stride >= width` values per row (padding: 0, invalid).
pub(crate) fn to_planes_strided(im: &Image, stride: usize) -> (Planes3, Buf) {
    let n = stride * im.height();
    let mut p = [Buf::uninit(n), Buf::uninit(n), Buf::uninit(n)];
    let mut valid = Buf::uninit(n);
    split_planes(im, stride, &mut p, Some(&mut valid));
    (p, valid)
}

/// [`to_planes_strided`] without the validity plane when every value is finite (the usual
/// case: `None`, and 8 MB less to write and scan at 1080p); when some value is not, the
/// planes and the validity plane of [`to_planes_strided`].
pub(crate) fn to_planes_valid(im: &Image, stride: usize) -> (Planes3, Option<Buf>) {
    let n = stride * im.height();
    let mut p = [Buf::uninit(n), Buf::uninit(n), Buf::uninit(n)];
    if split_planes(im, stride, &mut p, None) {
        let (p, valid) = to_planes_strided(im, stride);
        (p, Some(valid))
    } else {
        (p, None)
    }
}

/// Writes the planes of `im` (non-finite pixels as 0; rows padded with 0 to `stride`) and,
/// when given, its validity plane (1 where all three values are finite); returns whether
/// some pixel was not finite.
fn split_planes(im: &Image, stride: usize, p: &mut Planes3, valid: Option<&mut Buf>) -> bool {
    let (w, h) = (im.width(), im.height());
    debug_assert!(stride >= w);
    if stride * h == 0 {
        return false;
    }
    let [p0, p1, p2] = p;
    // One work item per PAR_CHUNK pixels (whole rows).
    let rows = (PAR_CHUNK / w.max(1)).max(1);
    let chunk = rows * stride;
    let items = p0
        .par_chunks_mut(chunk)
        .zip(p1.par_chunks_mut(chunk))
        .zip(p2.par_chunks_mut(chunk))
        .zip(im.data().par_chunks(3 * w * rows));
    match valid {
        Some(valid) => items
            .zip(valid.par_chunks_mut(chunk))
            .map(|((((a, b), c), src), v)| split_rows::<true>(src, w, stride, [a, b, c], v))
            .reduce(|| false, |x, y| x || y),
        None => items
            .map(|(((a, b), c), src)| split_rows::<false>(src, w, stride, [a, b, c], &mut []))
            .reduce(|| false, |x, y| x || y),
    }
}

/// [`split_planes`] for the rows of one work item; `v` (the validity rows) is written only
/// when `VALID` (a constant, so that the loop without it stays as tight as before).
#[inline(always)]
fn split_rows<const VALID: bool>(
    src: &[f32],
    w: usize,
    stride: usize,
    [a, b, c]: [&mut [f32]; 3],
    v: &mut [f32],
) -> bool {
    let mut bad = false;
    for (r, src) in src.chunks_exact(3 * w).enumerate() {
        let o = r * stride;
        for (i, px) in src.chunks_exact(3).enumerate() {
            let ok = is_valid_color(px[0]) && is_valid_color(px[1]) && is_valid_color(px[2]);
            bad |= !ok;
            a[o + i] = if ok { px[0] } else { 0.0 };
            b[o + i] = if ok { px[1] } else { 0.0 };
            c[o + i] = if ok { px[2] } else { 0.0 };
            if VALID {
                v[o + i] = if ok { 1.0 } else { 0.0 };
            }
        }
        for pl in [&mut *a, &mut *b, &mut *c] {
            pl[o + w..o + stride].fill(0.0);
        }
        if VALID {
            v[o + w..o + stride].fill(0.0);
        }
    }
    bad
}

/// Interleaves three planes into `out` (3 channels, same pixel count).
pub(crate) fn from_planes(p: &Planes3, out: &mut Image) {
    from_planes_strided(p, out.width(), out)
}

/// [`from_planes`] from planes of `stride` values per row.
pub(crate) fn from_planes_strided(p: &Planes3, stride: usize, out: &mut Image) {
    let w = out.width();
    if w == 0 {
        return;
    }
    let rows = (PAR_CHUNK / w).max(1);
    out.data_mut().par_chunks_mut(3 * w * rows).enumerate().for_each(|(k, dst)| {
        for (r, dst) in dst.chunks_exact_mut(3 * w).enumerate() {
            let o = (k * rows + r) * stride;
            for (i, px) in dst.chunks_exact_mut(3).enumerate() {
                px[0] = p[0][o + i];
                px[1] = p[1][o + i];
                px[2] = p[2][o + i];
            }
        }
    });
}

/// The sanitised planar guides the filters run on.
pub(crate) struct Guides {
    pub width: usize,
    pub height: usize,
    /// Values per row of every plane (`width` unless built by [`Guides::new_strided`]).
    pub stride: usize,
    /// Unit normals (zero on background).
    pub normal: Planes3,
    /// Positions divided by the scene scale, or `[depth / scale, 0, 0]` when only depth is
    /// given; `None` when neither is.
    pub position: Option<Planes3>,
    /// 1 on surface pixels, 0 on background.
    pub surface: Buf,
}

impl Guides {
    /// Errors when a position weight (`sigma_position`) is asked for but neither a position
    /// nor a depth buffer was given.
    pub fn require_position(&self, sigma_position: Option<f32>) -> Result<(), DenoiseError> {
        if sigma_position.is_some() && self.position.is_none() {
            return Err(DenoiseError::MissingGuide {
                buffer: "position (or depth)",
                needed_by: "sigma_position",
            });
        }
        Ok(())
    }

    pub fn new(g: &GBuffer, width: usize, height: usize) -> Result<Self, DenoiseError> {
        Self::new_strided(g, width, height, width)
    }

    /// [`Guides::new`] with planes of `stride >= width` values per row; the padding columns
    /// are background (normal 0, surface 0, position 0). The depth is read only when it
    /// stands in for an absent position (no filter here reads it otherwise: the guided
    /// filter converts its own inputs).
    pub fn new_strided(
        g: &GBuffer,
        width: usize,
        height: usize,
        stride: usize,
    ) -> Result<Self, DenoiseError> {
        g.validate(width, height)?;
        debug_assert!(stride >= width);
        let (mut normal, mut surface) = unit_normal_planes(g, width, height, stride);
        // Invalid depths and positions make background too (see `surface_at`).
        if g.depth.is_some() || g.position.is_some() {
            clear_far_surfaces(g, width, stride, &mut normal, &mut surface);
        }
        let position = match &g.position {
            Some(p) => Some(position_planes(g, p, width, height, stride)),
            // The depth plane is only needed as the position.
            None => g.depth.as_ref().map(|d| {
                let n = stride * height;
                [depth_plane(g, d, width, height, stride), Buf::zeros(n), Buf::zeros(n)]
            }),
        };
        Ok(Self { width, height, stride, normal, position, surface })
    }
}

/// Whole image rows per parallel work item of the guide conversions (about [`PAR_CHUNK`]
/// pixels).
fn rows_per_item(width: usize) -> usize {
    (PAR_CHUNK / width.max(1)).max(1)
}

/// A scaled guide value clamped to [`GUIDE_LIMIT`].
fn limit(v: f32) -> f32 {
    v.clamp(-GUIDE_LIMIT, GUIDE_LIMIT)
}

/// The unit normals of `g` in planes of `stride` values per row, and the surface plane (1
/// where the normal is set, [`is_surface`]); background and padding are 0.
fn unit_normal_planes(g: &GBuffer, width: usize, height: usize, stride: usize) -> (Planes3, Buf) {
    let n = stride * height;
    let w = width.max(1);
    let rows = rows_per_item(width);
    let mut normal = [Buf::uninit(n), Buf::uninit(n), Buf::uninit(n)];
    let mut surface = Buf::uninit(n);
    if n == 0 {
        return (normal, surface);
    }
    let [n0, n1, n2] = &mut normal;
    n0.par_chunks_mut(rows * stride)
        .zip(n1.par_chunks_mut(rows * stride))
        .zip(n2.par_chunks_mut(rows * stride))
        .zip(surface.par_chunks_mut(rows * stride))
        .zip(g.normal.data().par_chunks(3 * w * rows))
        .for_each(|((((a, b), c), s), src)| {
            for (r, src) in src.chunks_exact(3 * w).enumerate() {
                let o = r * stride;
                for (i, px) in src.chunks_exact(3).enumerate() {
                    let ok = is_surface(px);
                    let inv =
                        if ok { 1.0 / (px[0] * px[0] + px[1] * px[1] + px[2] * px[2]).sqrt() } else { 0.0 };
                    a[o + i] = px[0] * inv;
                    b[o + i] = px[1] * inv;
                    c[o + i] = px[2] * inv;
                    s[o + i] = if ok { 1.0 } else { 0.0 };
                }
                for pl in [&mut *a, &mut *b, &mut *c, &mut *s] {
                    pl[o + width..o + stride].fill(0.0);
                }
            }
        });
    (normal, surface)
}

/// Turns the surface pixels whose depth or position is invalid ([`surface_at`]) into
/// background: normal and surface 0.
fn clear_far_surfaces(g: &GBuffer, width: usize, stride: usize, normal: &mut Planes3, surface: &mut Buf) {
    if surface.is_empty() {
        return;
    }
    let [n0, n1, n2] = normal;
    n0.par_chunks_mut(stride)
        .zip(n1.par_chunks_mut(stride))
        .zip(n2.par_chunks_mut(stride))
        .zip(surface.par_chunks_mut(stride))
        .enumerate()
        .for_each(|(y, (((a, b), c), s))| {
            for x in 0..width {
                if s[x] != 0.0 && !surface_at(g, y * width + x) {
                    (a[x], b[x], c[x], s[x]) = (0.0, 0.0, 0.0, 0.0);
                }
            }
        });
}

/// The depth `d` divided by [`depth_scale`] (invalid depths 0) in a plane of `stride`
/// values per row.
fn depth_plane(g: &GBuffer, d: &Image, width: usize, height: usize, stride: usize) -> Buf {
    let scale = depth_scale(g, d);
    let mut b = Buf::uninit(stride * height);
    if !b.is_empty() {
        b.par_chunks_mut(stride).zip(d.data().par_chunks(width.max(1))).for_each(|(o, src)| {
            for (o, v) in o.iter_mut().zip(src) {
                *o = if is_valid_distance(*v) { limit(v / scale) } else { 0.0 };
            }
            o[width..].fill(0.0);
        });
    }
    b
}

/// The position scale of `g`: its `scene_scale` when set, else the diagonal of the surface
/// points' box (1 when that is 0 or not finite).
fn position_scale(g: &GBuffer, p: &Image) -> f32 {
    g.scene_scale.unwrap_or_else(|| {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for (i, px) in p.data().chunks_exact(3).enumerate() {
            if surface_at(g, i) {
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
    })
}

/// The positions `p` divided by [`position_scale`] (invalid ones 0) in planes of `stride`
/// values per row. Background keeps its (finite) positions: it is only ever compared with
/// background.
fn position_planes(g: &GBuffer, p: &Image, width: usize, height: usize, stride: usize) -> Planes3 {
    let n = stride * height;
    let (w, rows) = (width.max(1), rows_per_item(width));
    // A multiply per value instead of a division (3 divisions per pixel were ~2% of
    // À-Trous 5x3 at 1080p, perf).
    let inv_scale = 1.0 / position_scale(g, p);
    let mut planes = [Buf::uninit(n), Buf::uninit(n), Buf::uninit(n)];
    if n == 0 {
        return planes;
    }
    let [a, b, c] = &mut planes;
    a.par_chunks_mut(rows * stride)
        .zip(b.par_chunks_mut(rows * stride))
        .zip(c.par_chunks_mut(rows * stride))
        .zip(p.data().par_chunks(3 * w * rows))
        .for_each(|(((a, b), c), src)| {
            for (r, src) in src.chunks_exact(3 * w).enumerate() {
                let o = r * stride;
                for (i, px) in src.chunks_exact(3).enumerate() {
                    let ok = px.iter().all(|v| is_valid_distance(*v));
                    a[o + i] = if ok { limit(px[0] * inv_scale) } else { 0.0 };
                    b[o + i] = if ok { limit(px[1] * inv_scale) } else { 0.0 };
                    c[o + i] = if ok { limit(px[2] * inv_scale) } else { 0.0 };
                }
                for pl in [&mut *a, &mut *b, &mut *c] {
                    pl[o + width..o + stride].fill(0.0);
                }
            }
        });
    planes
}
