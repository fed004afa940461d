//! `filtrace view`: the interactive viewer (`filtrace-viewer`): progressive path tracing
//! when still, the 1-spp filtered pipeline while moving, every AOV, saves, reload.
//!
//! Headless: `--frames N --screenshot out.png` renders N still frames in the window, saves
//! the image area as PNG and exits (what the window tests under Xvfb use).

use std::io::Write;
use std::path::PathBuf;

use filtrace_pipeline::FilterChoice;
use filtrace_viewer::settings::StillRenderer;
use filtrace_viewer::{layers, ViewerOptions};

use super::render::{parse_resolution, Resolution};

/// `filtrace view` options.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// Built-in scene name (`cornell`) or a scene file (.toml, .obj, .gltf/.glb, .ply);
    /// a file is loaded again when it changes on disk.
    #[arg(default_value = "cornell")]
    pub scene: String,
    /// Render resolution as WIDTHxHEIGHT (the still image's; moving frames adapt below it).
    #[arg(long, default_value = "512x512", value_parser = parse_resolution)]
    pub res: Resolution,
    /// Start camera as eye,target,up,fov: 10 numbers `ex,ey,ez,tx,ty,tz,ux,uy,uz,fov`
    /// (default: the scene's camera).
    #[arg(long, value_parser = filtrace_viewer::camera::parse_camera, allow_hyphen_values = true)]
    pub camera: Option<filtrace_scene::Camera>,
    /// Samples per pixel added by each still frame.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub spp_per_frame: u32,
    /// Stop accumulating at this many samples per pixel.
    #[arg(long, default_value_t = 4096, value_parser = clap::value_parser!(u32).range(1..))]
    pub max_spp: u32,
    /// Maximum path depth, Mitsuba's convention (1 = emitters only, 2 = direct light,
    /// -1 = unbounded).
    #[arg(long, default_value_t = 8, allow_negative_numbers = true, value_parser = parse_depth)]
    pub max_depth: i32,
    /// Sampler seed (the still image is `filtrace render --seed`'s).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Render threads (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub threads: Option<u32>,
    /// Headless: render this many still frames, then (with --screenshot) save the image
    /// area and exit.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub frames: Option<u32>,
    /// PNG to save the image area to after --frames.
    #[arg(long, requires = "frames")]
    pub screenshot: Option<PathBuf>,
    /// The --screenshot holds the whole window (panel, overlay), not only the image.
    #[arg(long, requires = "screenshot")]
    pub screenshot_window: bool,
    /// Filter while moving.
    #[arg(long, default_value = "guided", value_parser = ["guided", "atrous", "bilateral", "none"])]
    pub filter: String,
    /// Frame rate the moving frames' resolution adapts to (a low value keeps the full
    /// resolution, for measuring).
    #[arg(long, default_value_t = 12.0, value_parser = super::args::positive_f32)]
    pub target_fps: f32,
    /// Adaptive sampling of the moving frames (and the importance layer).
    #[arg(long)]
    pub adaptive: bool,
    /// Layer shown at start.
    #[arg(long, default_value = "colour", value_parser = parse_layer)]
    pub layer: &'static str,
    /// Folder for saves (F2) and screenshots (F12).
    #[arg(long, default_value = "filtrace-out")]
    pub out_dir: PathBuf,
    /// Print one line per shown frame on stderr (kind, samples, size, layer, camera).
    #[arg(long)]
    pub log_frames: bool,
    /// Start with the overlay hidden (O toggles it).
    #[arg(long)]
    pub no_overlay: bool,
    /// Do not light a bare mesh file without lights by the default sky and sun.
    #[arg(long)]
    pub no_default_light: bool,
    /// Animation frame shown at start (the still image is `filtrace render --frame N`'s).
    #[arg(long, value_name = "N", value_parser = super::sequence::parse_frame)]
    pub frame: Option<u64>,
    /// Start the animation playing (Space plays and pauses).
    #[arg(long)]
    pub play: bool,
    /// Renderer of the still image: progressive path tracing, or the many-light renderer
    /// (one frame of --spp-per-frame samples, as `filtrace render --integrator vpl`).
    #[arg(long, default_value = "path", value_parser = ["path", "vpl"])]
    pub integrator: String,
}

fn parse_depth(s: &str) -> Result<i32, String> {
    let d: i32 = s.trim().parse().map_err(|_| format!("'{s}' is not a whole number"))?;
    if d == 0 || d < -1 {
        return Err(format!("max depth {d} is invalid (use -1 for unbounded or a depth >= 1)"));
    }
    Ok(d)
}

fn parse_layer(s: &str) -> Result<&'static str, String> {
    let s = if s == "color" { "colour" } else { s };
    layers::layer(s).map(|l| l.name).ok_or_else(|| {
        let names: Vec<_> = layers::LAYERS.iter().map(|l| l.name).collect();
        format!("unknown layer '{s}' (layers: {})", names.join(", "))
    })
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let mut o = ViewerOptions::new(&a.scene);
    o.width = a.res.width;
    o.height = a.res.height;
    o.camera = a.camera;
    o.spp_per_frame = a.spp_per_frame;
    o.max_spp = a.max_spp;
    o.max_depth = a.max_depth;
    o.seed = a.seed;
    if let Some(t) = a.threads {
        o.threads = t as usize;
    }
    o.frames = a.frames;
    o.screenshot = a.screenshot;
    o.screenshot_window = a.screenshot_window;
    o.filter = FilterChoice::named(&a.filter);
    o.adaptive = a.adaptive;
    o.target_fps = a.target_fps;
    o.layer = a.layer;
    o.out_dir = a.out_dir;
    o.log_frames = a.log_frames;
    o.no_overlay = a.no_overlay;
    o.default_light = !a.no_default_light;
    o.frame = a.frame.map(|f| f as i64);
    o.play = a.play;
    o.still = match a.integrator.as_str() {
        "vpl" => StillRenderer::Vpl,
        _ => StillRenderer::PathTracer,
    };
    let outcome = filtrace_viewer::run(o).map_err(anyhow::Error::msg)?;
    let camera = outcome.camera.as_ref().map(filtrace_viewer::camera::format_camera).unwrap_or_default();
    // The summary goes to stderr: stdout stays free for tools.
    let mut err = std::io::stderr();
    let moving = match outcome.moving_frames {
        0 => "no moving frames".to_string(),
        n => {
            let stages: Vec<String> =
                outcome.moving_stages.iter().map(|(s, ms)| format!("{s} {ms:.1}")).collect();
            format!(
                "{n} moving frames, mean {:.1} ms ({:.1} fps), shown {:.1} fps, mean {:.0} pixels, stages (mean ms) {}",
                outcome.moving_mean_ms,
                1000.0 / outcome.moving_mean_ms.max(1e-9),
                outcome.moving_shown_fps,
                outcome.moving_mean_pixels,
                stages.join(", ")
            )
        }
    };
    writeln!(
        err,
        "filtrace view: closed; camera {camera}; longest UI frame while rendering {:.1} ms (mean {:.1}) over {} frames; {moving}",
        outcome.max_ui_frame_ms, outcome.mean_ui_frame_ms, outcome.ui_frames_while_rendering
    )?;
    if let Some(e) = outcome.load_error {
        anyhow::bail!("{e}");
    }
    if let Some(e) = outcome.error {
        anyhow::bail!("{e}");
    }
    Ok(())
}
