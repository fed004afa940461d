//! The files of a sequence: their names, what each frame's EXR header says about how it was
//! rendered, and whether a frame already on disk is finished (for `--resume`).
//!
//! Frame `N` of `--out DIR/NAME.exr` is `DIR/NAME.NNNN.exr` and `DIR/NAME.NNNN.png` (at
//! least four digits, more for frames from 10000 on); the preview animation is
//! `DIR/NAME.preview.png`.
//!
//! A sequence whose integrator carries state from frame to frame (`--integrator vpl` with
//! `optimized`) writes that state after each finished frame beside it,
//! `DIR/NAME.NNNN.vpl-state.json` ([`StateFile`]: the frame's stamp and the
//! `filtrace_vpl::vpls::VplState`), atomically: a failed write leaves the file that was
//! there. `--resume` then keeps the finished frames from the first one on, up to the last
//! whose state can be read ([`resume_carried`]); every later frame is rendered from that
//! state, so the files are those of an uninterrupted run.

use filtrace_vpl::vpls::VplState;
use serde::{Deserialize, Serialize};
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

/// `DIR/NAME.NNNN.exr` -> `DIR/NAME.NNNN.vpl-state.json`: the integrator's state after
/// that frame.
pub fn state_path(frame_exr: &Path) -> PathBuf {
    frame_exr.with_extension("vpl-state.json")
}

/// A state file: the stamp of the frame after which the state was taken, and the state.
#[derive(Serialize, Deserialize)]
pub struct StateFile {
    pub frame: u64,
    pub width: u32,
    pub height: u32,
    /// The frame's [`SETTINGS_ATTRIBUTE`].
    pub settings: String,
    pub state: VplState,
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

    /// Writes `state`, taken after this frame, to `path` through a temporary file renamed
    /// over it when complete ([`filtrace_io::write_atomic`]): on any error the file that
    /// was at `path` keeps its bytes.
    pub fn write_state(&self, path: &Path, state: &VplState) -> anyhow::Result<()> {
        let file = StateFile {
            frame: self.frame,
            width: self.width,
            height: self.height,
            settings: self.settings.clone(),
            state: state.clone(),
        };
        let bytes = serde_json::to_vec(&file)?;
        let fail = super::render_session::test_failure(&format!("state {}", self.frame));
        filtrace_io::write_atomic(path, |w| {
            if fail {
                w.write_all(&bytes[..bytes.len() / 2])?;
                return Err(std::io::Error::other("test hook FILTRACE_TEST_FAIL"));
            }
            w.write_all(&bytes)
        })?;
        Ok(())
    }

    /// The state taken after this frame, from `path`; else why it cannot be used (missing,
    /// unreadable, another version, or written for another frame or other settings).
    pub fn read_state(&self, path: &Path) -> Result<VplState, String> {
        let text = match std::fs::read_to_string(path) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Err("is not on disk".into()),
            Err(e) => return Err(format!("cannot be read ({e})")),
            Ok(text) => text,
        };
        let file: StateFile = serde_json::from_str(&text).map_err(|e| format!("is corrupt ({e})"))?;
        file.state.check().map_err(|e| format!("cannot be used: {e}"))?;
        if file.frame != self.frame {
            return Err(format!("holds the state after frame {}", file.frame));
        }
        if (file.width, file.height) != (self.width, self.height) || file.settings != self.settings {
            let (w, h, s) = (file.width, file.height, &file.settings);
            return Err(format!("was written with other settings ({w}x{h}, {s})"));
        }
        Ok(file.state)
    }
}

/// What `--resume` keeps of a sequence whose integrator carries state: the first `kept`
/// frames, and the state the next frame starts from (`None`: the first frame is rendered,
/// from scratch).
pub struct Resumed {
    pub kept: usize,
    pub state: Option<VplState>,
    /// Why frames that were finished on disk are rendered again (a state missing, corrupt
    /// or from other settings), one line each.
    pub notes: Vec<String>,
}

/// `--resume` of a sequence of `stamps` (in order) whose frames depend on the state of the
/// frame before: the finished frames from the first one on are kept up to the last whose
/// state can be read; each frame whose state cannot is rendered again from the state of
/// the one before it (or from scratch at the first frame), with a note saying why.
pub fn resume_carried(stamps: &[FrameStamp], out: &Path) -> Resumed {
    let finished = |s: &FrameStamp| s.check_finished(&frame_path(out, s.frame)).is_ok();
    let mut kept = stamps.iter().take_while(|s| finished(s)).count();
    let mut notes = Vec::new();
    while kept > 0 && kept < stamps.len() {
        let last = &stamps[kept - 1];
        let path = state_path(&frame_path(out, last.frame));
        match last.read_state(&path) {
            Ok(state) => return Resumed { kept, state: Some(state), notes },
            Err(why) => notes.push(format!(
                "frame {} is rendered again: the state the next frame continues from, {}, {why}",
                last.frame,
                path.display()
            )),
        }
        kept -= 1;
    }
    Resumed { kept, state: None, notes }
}

/// Which frames `--resume` keeps: every finished one, or, when each frame continues the
/// state of the one before (`carries`), the finished ones from the first on up to the last
/// whose state can be read ([`resume_carried`], whose notes go to stderr), with the state
/// the next frame continues from.
pub fn keep_on_resume(
    stamps: Vec<FrameStamp>,
    out: &Path,
    resume: bool,
    carries: bool,
) -> (Vec<(FrameStamp, bool)>, Option<VplState>) {
    if resume && carries {
        let resumed = resume_carried(&stamps, out);
        resumed.notes.iter().for_each(|n| eprintln!("note: {n}"));
        let frames = stamps.into_iter().enumerate().map(|(i, s)| (s, i < resumed.kept)).collect();
        return (frames, resumed.state);
    }
    let keep = |s: &FrameStamp| resume && s.check_finished(&frame_path(out, s.frame)).is_ok();
    let frames = stamps
        .into_iter()
        .map(|s| {
            let k = keep(&s);
            (s, k)
        })
        .collect();
    (frames, None)
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
        assert_eq!(state_path(&frame_path(out, 7)), Path::new("dir/shot.0007.vpl-state.json"));
    }

    /// A state file reads back as written, for its own frame and settings only; a corrupt
    /// one says so.
    #[test]
    fn a_state_file_reads_back_for_its_frame_and_settings_only() {
        let dir = std::env::temp_dir().join(format!("filtrace-state-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("s.0003.vpl-state.json");
        let stamp =
            FrameStamp { frame: 3, time_s: 0.0, width: 4, height: 2, settings: "scene=a seed=0".into() };
        let state = VplState {
            version: filtrace_vpl::vpls::STATE_VERSION,
            settings: "VplSettings".into(),
            lambda: 0.1f32 as f64,
            records: Vec::new(),
        };
        assert_eq!(stamp.read_state(&path).unwrap_err(), "is not on disk");
        stamp.write_state(&path, &state).unwrap();
        assert_eq!(stamp.read_state(&path).unwrap(), state);
        let next = FrameStamp { frame: 4, ..stamp.clone() };
        assert!(next.read_state(&path).unwrap_err().contains("after frame 3"));
        let other = FrameStamp { settings: "scene=a seed=1".into(), ..stamp.clone() };
        assert!(other.read_state(&path).unwrap_err().contains("other settings"));
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::write(&path, &text[..text.len() - 3]).unwrap();
        assert!(stamp.read_state(&path).unwrap_err().contains("is corrupt"));
        let version = format!("\"version\":{}", filtrace_vpl::vpls::STATE_VERSION);
        std::fs::write(&path, text.replace(&version, "\"version\":99")).unwrap();
        assert!(stamp.read_state(&path).unwrap_err().contains("state version 99"));
        std::fs::remove_dir_all(&dir).ok();
    }
}
