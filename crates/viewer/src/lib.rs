//! # filtrace-viewer
//!
//! `filtrace view`: a window on the renderer (egui/eframe on OpenGL through glow; under
//! Xvfb it runs on Mesa's software OpenGL). Rendering happens on a worker thread with its
//! own rayon pool ([`worker`]); the UI thread only turns input into a camera, posts jobs and
//! shows the newest finished frame, so it never waits for a render.
//!
//! - While the camera moves: the 1-spp filtered pipeline of Bauszat et al. 2011 (guided
//!   filter by default; À-Trous, bilateral, none), at a resolution that adapts to the
//!   target frame rate ([`worker::adapt_scale`]).
//! - When still: progressive path tracing, `spp_per_frame` samples per frame, converging to
//!   `filtrace render`'s image (bit for bit the same film after the same samples).
//! - Every AOV at hand ([`layers::LAYERS`]), split view, overlay with fps and per-stage
//!   milliseconds, EXR (all layers) and PNG saves, reload of the scene file when it changes.
//!
//! Modules: [`camera`] (camera moves), [`input`] (window input to moves and actions),
//! [`engine`] (the frames of one scene), [`worker`] (the render thread), [`layers`] and
//! [`display`] (AOVs to display colour), [`scene_watch`] (loading and reloading), [`save`],
//! [`settings`], [`timeline`] (animation frame, playback, camera track), and the window:
//! `app`, `panel`, `overlay`, `stats`.

pub mod camera;
pub mod display;
pub mod engine;
pub mod input;
pub mod layers;
pub mod save;
pub mod scene_watch;
pub mod settings;
mod srgb8;
pub mod timeline;
pub mod worker;

mod app;
mod overlay;
mod panel;
mod stats;

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use filtrace_pipeline::FilterChoice;
use filtrace_scene::Camera;

/// Everything `filtrace view` is started with.
#[derive(Clone, Debug)]
pub struct ViewerOptions {
    /// Built-in scene name or scene file.
    pub scene: String,
    pub width: u32,
    pub height: u32,
    /// Start camera (default: the scene's).
    pub camera: Option<Camera>,
    pub spp_per_frame: u32,
    /// Accumulation stops here (with `frames`: `frames * spp_per_frame`).
    pub max_spp: u32,
    pub max_depth: i32,
    pub seed: u64,
    /// Render threads.
    pub threads: usize,
    /// Headless: close after this many still frames (taking `screenshot` first).
    pub frames: Option<u32>,
    pub screenshot: Option<PathBuf>,
    /// The screenshot holds the whole window (panel and overlay), not only the image.
    pub screenshot_window: bool,
    /// Layer shown at start (a name of [`layers::LAYERS`]).
    pub layer: &'static str,
    /// Filter of the moving frames.
    pub filter: FilterChoice,
    /// Frame rate the moving frames' resolution adapts to.
    pub target_fps: f32,
    pub adaptive: bool,
    /// Folder of saves and screenshots taken with keys.
    pub out_dir: PathBuf,
    /// Print one line per shown frame on stderr.
    pub log_frames: bool,
    pub no_overlay: bool,
    /// Light bare mesh files by the default sky and sun.
    pub default_light: bool,
    /// Animation frame shown at start (default: the first).
    pub frame: Option<i64>,
    /// Start the animation playing.
    pub play: bool,
    /// The still image's renderer.
    pub still: settings::StillRenderer,
}

impl ViewerOptions {
    /// Defaults for `scene`: 512x512, 1 spp per frame, guided filter while moving.
    pub fn new(scene: &str) -> Self {
        Self {
            scene: scene.to_string(),
            width: 512,
            height: 512,
            camera: None,
            spp_per_frame: 1,
            max_spp: 4096,
            max_depth: 8,
            seed: 0,
            threads: std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
            frames: None,
            screenshot: None,
            screenshot_window: false,
            layer: "colour",
            filter: FilterChoice::named(settings::FILTERS[0]),
            target_fps: 12.0,
            adaptive: false,
            out_dir: PathBuf::from("filtrace-out"),
            log_frames: false,
            no_overlay: false,
            default_light: true,
            frame: None,
            play: false,
            still: settings::StillRenderer::PathTracer,
        }
    }

    /// The sample count accumulation stops at.
    pub fn max_spp(&self) -> u32 {
        match self.frames {
            Some(n) => n.max(1).saturating_mul(self.spp_per_frame.max(1)),
            None => self.max_spp.max(1),
        }
    }

    /// Built-in name or file stem, for file names.
    pub fn scene_name(&self) -> String {
        let p = Path::new(&self.scene);
        p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "scene".into())
    }

    pub(crate) fn scene_is_file(&self) -> bool {
        !filtrace_scene::builtin_names().contains(&self.scene.as_str())
    }
}

/// How the window ended.
#[derive(Clone, Debug, Default)]
pub struct ViewerOutcome {
    /// The camera when the window closed.
    pub camera: Option<Camera>,
    /// Longest UI frame (ms) while a render ran, and how many such frames there were.
    pub max_ui_frame_ms: f64,
    pub mean_ui_frame_ms: f64,
    pub ui_frames_while_rendering: u64,
    /// Moving frames shown, their mean render time (ms) and mean pixel count.
    pub moving_frames: u64,
    pub moving_mean_ms: f64,
    pub moving_mean_pixels: f64,
    /// Mean milliseconds of each stage of the moving frames (render stages, then
    /// `display`: tone mapping into the texture's pixels).
    pub moving_stages: Vec<(&'static str, f64)>,
    /// Moving frames shown per second, wall clock from the first to the last.
    pub moving_shown_fps: f64,
    /// The scene never loaded: why.
    pub load_error: Option<String>,
    /// A screenshot could not be written.
    pub error: Option<String>,
}

/// Opens the window and runs until it is closed (Escape, the window manager, or the end of
/// a headless run). Errors: no window could be opened.
pub fn run(options: ViewerOptions) -> Result<ViewerOutcome, String> {
    let outcome = Arc::new(Mutex::new(ViewerOutcome::default()));
    let size = [app::PANEL_WIDTH + options.width as f32 + 16.0, (options.height as f32 + 16.0).max(560.0)];
    let native = eframe::NativeOptions {
        viewport: eframe::egui::ViewportBuilder::default()
            .with_title(format!("filtrace view - {}", options.scene))
            .with_app_id("filtrace-view")
            .with_inner_size(size),
        renderer: eframe::Renderer::Glow,
        ..Default::default()
    };
    let out = outcome.clone();
    eframe::run_native(
        "filtrace view",
        native,
        Box::new(move |cc| {
            let app = app::ViewerApp::new(cc, options, out)?;
            Ok(Box::new(app))
        }),
    )
    .map_err(|e| format!("cannot open the viewer window: {e}"))?;
    let o = outcome.lock().unwrap_or_else(|p| p.into_inner()).clone();
    Ok(o)
}
