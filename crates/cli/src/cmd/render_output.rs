//! The files of a plain render: one multi-layer EXR (colour + AOVs) with its header
//! attributes, and the tonemapped PNG beside it.

use anyhow::Context;
use filtrace_core::Image;
use filtrace_io::{ExrImage, TonemapParams};
use filtrace_render::film::Aovs;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The EXR header attributes of a render: samples per pixel asked for, done (the fewest of
/// any pixel) and whether Ctrl-C stopped it.
pub fn render_attributes(spp_requested: u32, spp_done: u32, cancelled: bool) -> Vec<(&'static str, String)> {
    vec![
        ("filtrace:spp_requested", spp_requested.to_string()),
        ("filtrace:spp_done", spp_done.to_string()),
        ("filtrace:cancelled", cancelled.to_string()),
    ]
}

/// The paths written by [`write_outputs`].
#[derive(Clone, Debug, Serialize)]
pub struct Written {
    pub exr: PathBuf,
    pub png: PathBuf,
    /// Non-finite colour values (written as they are to the EXR, as 0 to the PNG).
    pub png_nonfinite: usize,
}

/// Writes the multi-layer EXR (`R,G,B`, `direct`, `indirect`, `albedo`, `normal`,
/// `position`, `depth`, `variance`, then `extra` layers as `(name, channel names, image)`;
/// header text `attributes`) and the tonemapped PNG of `png_image` (the colour if `None`)
/// beside it, creating the folder.
pub fn write_outputs(
    exr_path: &Path,
    aovs: &Aovs,
    extra: &[(&str, &[&str], &Image)],
    attributes: &[(&str, String)],
    png_image: Option<&Image>,
    tonemap: &TonemapParams,
) -> anyhow::Result<Written> {
    if let Some(dir) = exr_path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create folder {}", dir.display()))?;
    }
    const RGB: &[&str] = &["R", "G", "B"];
    const XYZ: &[&str] = &["X", "Y", "Z"];
    let mut exr = ExrImage::new(aovs.width, aovs.height);
    let layers: [(&str, &[&str], &Image); 8] = [
        ("", RGB, &aovs.color),
        ("direct", RGB, &aovs.direct),
        ("indirect", RGB, &aovs.indirect),
        ("albedo", RGB, &aovs.albedo),
        ("normal", XYZ, &aovs.normal),
        ("position", XYZ, &aovs.position),
        ("depth", &["Z"], &aovs.depth),
        ("variance", RGB, &aovs.variance),
    ];
    for (name, channels, image) in layers.iter().chain(extra.iter()) {
        exr.insert(name, channels, image)?;
    }
    for (name, value) in attributes {
        exr.set_attribute(name, value)?;
    }
    filtrace_io::write_exr(exr_path, &exr)?;
    let png = exr_path.with_extension("png");
    let report = filtrace_io::write_png(&png, png_image.unwrap_or(&aovs.color), tonemap)?;
    Ok(Written { exr: exr_path.to_path_buf(), png, png_nonfinite: report.nonfinite })
}
