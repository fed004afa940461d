//! The files of a sequence: their names, what each frame's EXR header says about how it was
//! rendered, and whether a frame already on disk is finished (for `--resume`).
//!
//! Frame `N` of `--out DIR/NAME.exr` is `DIR/NAME.NNNN.exr` and `DIR/NAME.NNNN.png` (at
//! least four digits, more for frames from 10000 on); the preview animation is
//! `DIR/NAME.preview.png`.

use std::path::{Path, PathBuf};

/// Header attribute holding the frame number.
pub const FRAME_ATTRIBUTE: &str = "filtrace:frame";
/// Header attribute holding everything that decides a frame's pixels but the frame number.
pub const SETTINGS_ATTRIBUTE: &str = "filtrace:settings";
/// Header attribute holding the frame's time in seconds on the animation's clock.
pub const TIME_ATTRIBUTE: &str = "filtrace:time";

/// `DIR/NAME.exr` -> `DIR/NAME.NNNN.exr`.
pub fn frame_path(out: &Path, frame: u64) -> PathBuf {
    let stem = out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "frame".into());
    out.with_file_name(format!("{stem}.{frame:04}.exr"))
}

/// `DIR/NAME.exr` -> `DIR/NAME.preview.png`.
pub fn preview_path(out: &Path) -> PathBuf {
    let stem = out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "frame".into());
    out.with_file_name(format!("{stem}.preview.png"))
}

/// What a finished frame's EXR must say to be kept by `--resume`.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameStamp {
    pub frame: u64,
    pub time_s: f64,
    pub width: u32,
    pub height: u32,
    /// Scene, samples, depth, seed and method, as one line (`SETTINGS_ATTRIBUTE`).
    pub settings: String,
}

impl FrameStamp {
    /// The header attributes written with the frame.
    pub fn attributes(&self) -> Vec<(&'static str, String)> {
        vec![
            (FRAME_ATTRIBUTE, self.frame.to_string()),
            (TIME_ATTRIBUTE, self.time_s.to_string()),
            (SETTINGS_ATTRIBUTE, self.settings.clone()),
        ]
    }

    /// `Ok` when the frame at `exr` (and the PNG beside it) is on disk, whole and was
    /// rendered to the end with these settings; else why it must be rendered again.
    pub fn check_finished(&self, exr: &Path) -> Result<(), String> {
        if !exr.exists() {
            return Err("not on disk".into());
        }
        let image = filtrace_io::read_exr(exr).map_err(|e| format!("unreadable ({e})"))?;
        let attribute = |name: &str| image.attribute(name).unwrap_or("(none)").to_string();
        if (image.width(), image.height()) != (self.width as usize, self.height as usize) {
            return Err(format!("{}x{}, not {}x{}", image.width(), image.height(), self.width, self.height));
        }
        if attribute("filtrace:cancelled") != "false" {
            return Err("cut short by Ctrl-C".into());
        }
        if attribute(FRAME_ATTRIBUTE) != self.frame.to_string() {
            return Err(format!("holds frame {}", attribute(FRAME_ATTRIBUTE)));
        }
        if attribute(SETTINGS_ATTRIBUTE) != self.settings {
            return Err(format!("rendered with other settings ({})", attribute(SETTINGS_ATTRIBUTE)));
        }
        let png = exr.with_extension("png");
        let (size, _) =
            super::preview::read_rgb8(&png).map_err(|e| format!("its PNG is unreadable ({e})"))?;
        if size != (self.width, self.height) {
            return Err(format!("its PNG is {}x{}", size.0, size.1));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_names_are_numbered_beside_the_output() {
        let out = Path::new("dir/shot.exr");
        assert_eq!(frame_path(out, 7), Path::new("dir/shot.0007.exr"));
        assert_eq!(frame_path(out, 12345), Path::new("dir/shot.12345.exr"));
        assert_eq!(frame_path(Path::new("a.b.exr"), 0), Path::new("a.b.0000.exr"));
        assert_eq!(preview_path(out), Path::new("dir/shot.preview.png"));
    }
}
