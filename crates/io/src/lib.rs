//! # filtrace-io
//!
//! Reading and writing the images filtrace exchanges with the outside world:
//!
//! - [`write_exr`]: ONE multi-layer float32 OpenEXR per render: colour as `R,G,B` and the
//!   AOV layers `direct.R/G/B`, `indirect.R/G/B`, `albedo.R/G/B`, `normal.X/Y/Z`,
//!   `position.X/Y/Z`, `depth.Z`, `variance.R/G/B`, plus any extra named layer
//!   (`filtered.R/G/B`, `importance.Y`, ...). Built with [`ExrImage::insert`].
//! - [`read_exr`]: any scan-line or tiled EXR (single or multi-part; f16, f32 and u32
//!   samples all become f32) into an [`ExrImage`] of named channels, with
//!   [`ExrImage::layer`] looking layers up through the alias table in [`aliases`], so
//!   that AOV files from Blender (`ViewLayer.Combined.R`, `ViewLayer.Denoising Albedo.R`)
//!   or Mitsuba 3 (`nn.X`, `dd.Y`, `depth.T`) are understood.
//! - [`write_png`]: tonemapped 8-bit sRGB PNG (exposure, plain clamp by default, optional
//!   filmic curve). Non-finite values are written as 0 and counted, never smeared.
//! - [`write_image`]: a single image (an error map, a filtered frame) as EXR or PNG by
//!   file extension.
//! - [`write_atomic`]: how every output file of filtrace is written (a temporary file
//!   renamed into place when complete: a failed write never destroys the old file), and
//!   [`check_writable`], the same checks made before a long computation.
//!
//! ```
//! use filtrace_core::Image;
//! use filtrace_io::{ExrImage, read_exr, write_exr};
//! let dir = std::env::temp_dir().join(format!("filtrace-io-doctest-{}", std::process::id()));
//! std::fs::create_dir_all(&dir).unwrap();
//! let path = dir.join("frame.exr");
//! let color = Image::filled(4, 2, 3, 0.5);
//! let depth = Image::filled(4, 2, 1, 3.0);
//! let mut exr = ExrImage::new(4, 2);
//! exr.insert("", &["R", "G", "B"], &color).unwrap();
//! exr.insert("depth", &["Z"], &depth).unwrap();
//! write_exr(&path, &exr).unwrap();
//! let back = read_exr(&path).unwrap();
//! assert_eq!(back.layer(&["color"]).unwrap(), color);
//! assert_eq!(back.layer(&["depth"]).unwrap(), depth);
//! # std::fs::remove_dir_all(&dir).ok();
//! ```

pub mod aliases;
mod atomic;
mod error;
mod exr_io;
mod png_io;

pub use atomic::{check_writable, write_atomic};
pub use error::IoError;
pub use exr_io::{read_exr, write_exr, ExrImage};
pub use png_io::{srgb_eotf, srgb_oetf, tonemap_srgb8, write_png, PngReport, Tonemap, TonemapParams};

use filtrace_core::Image;
use std::path::Path;

/// Writes one image by file extension: `.exr` as float32 EXR (channels named by count:
/// 1 → `Y`, 3 → `R,G,B`, 4 → `R,G,B,A`, otherwise `C0, C1, ...`), `.png` as tonemapped sRGB
/// with [`TonemapParams::default`]. Returns the number of non-finite values met (written as
/// they are into an EXR, as 0 into a PNG).
pub fn write_image(path: impl AsRef<Path>, image: &Image) -> Result<usize, IoError> {
    let path = path.as_ref();
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    match ext.as_str() {
        "exr" => {
            let names = default_channel_names(image.channels());
            let names: Vec<&str> = names.iter().map(String::as_str).collect();
            let mut exr = ExrImage::new(image.width(), image.height());
            exr.insert("", &names, image)?;
            write_exr(path, &exr)?;
            Ok(image.count_non_finite())
        }
        "png" => Ok(write_png(path, image, &TonemapParams::default())?.nonfinite),
        _ => Err(IoError::UnsupportedFormat { path: path.to_path_buf() }),
    }
}

/// Channel names used for an image of `n` channels written on its own.
pub fn default_channel_names(n: usize) -> Vec<String> {
    match n {
        1 => vec!["Y".into()],
        3 => vec!["R".into(), "G".into(), "B".into()],
        4 => vec!["R".into(), "G".into(), "B".into(), "A".into()],
        _ => (0..n).map(|i| format!("C{i}")).collect(),
    }
}
