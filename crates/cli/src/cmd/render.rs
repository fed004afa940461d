//! `filtrace render`: load a scene, path trace it progressively in passes, write one
//! multi-layer EXR (colour + AOVs) and a tonemapped PNG beside it, print a summary.
//!
//! Ctrl-C ([`CtrlC`]) during loading or the BVH build exits at once, writing nothing.
//! During the passes it stops them within a sample's time; if every pixel has a sample,
//! what was rendered is written (each pixel the mean of its own samples `0..n`, an unbiased
//! estimate; the counts are the `samples` layer, and the header says how many were asked
//! for, the fewest done and that Ctrl-C cut it short), else nothing. Either way the command
//! exits with code 130. A second Ctrl-C exits at once.
//!
//! The filtered pipeline and adaptive sampling (`--adaptive`, and `--filter` once
//! `render_filtered::FilterArgs` has it) are run by `render_filtered`; this module
//! provides the common options ([`CommonArgs`]) and the writers ([`write_outputs`]) both use.

use super::render_filtered::{AdaptiveArgs, FilterArgs};
use anyhow::Context;
use filtrace_core::Image;
use filtrace_io::{ExrImage, TonemapParams};
use filtrace_render::film::Aovs;
use filtrace_render::renderer::progressive_passes;
use filtrace_render::{Film, RenderSettings, Renderer};
use serde::Serialize;
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Samples per pixel without `--spp` (with `--adaptive`, the budget is used instead).
pub const DEFAULT_SPP: u32 = 64;

/// Largest accepted image side (same as the renderer's limit).
pub const MAX_SIDE: u32 = filtrace_render::renderer::MAX_SIDE;

/// Options every rendering command shares (also read by `render_filtered::run`).
#[derive(clap::Args, Debug, Clone)]
pub struct CommonArgs {
    /// Built-in scene name (`cornell`) or a scene file (.toml, .obj, .gltf/.glb, .ply).
    #[arg(default_value = "cornell")]
    pub scene: String,
    /// Samples per pixel [default: 64; with --adaptive: the --budget-spp].
    #[arg(long, value_name = "N")]
    pub spp: Option<u32>,
    /// Resolution as WIDTHxHEIGHT, each side 1..=32768.
    #[arg(long, default_value = "512x512", value_parser = parse_resolution)]
    pub res: Resolution,
    /// Maximum path depth, Mitsuba's convention: 1 = emitters only, 2 = direct light,
    /// -1 = unbounded.
    #[arg(long, default_value_t = 8, allow_negative_numbers = true)]
    pub max_depth: i32,
    /// Seed of the sampler (the image is a deterministic function of it).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub threads: Option<u32>,
    /// Output EXR (default: filtrace-out/<scene>.exr); the PNG is written beside it.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print one JSON object instead of the human summary.
    #[arg(long)]
    pub json: bool,
    /// Most samples per pixel added by one progressive pass (default: spp/16, at least 1);
    /// passes start at 1 sample and double up to it.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub passes_spp: Option<u32>,
    /// PNG exposure in stops (a finite number).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true, value_parser = super::args::finite_f32)]
    pub exposure: f32,
    /// PNG with a filmic curve instead of the plain sRGB clamp.
    #[arg(long)]
    pub filmic: bool,
    /// How the path tracer walks its paths: one at a time (`scalar`) or 8 in SIMD lockstep
    /// (`lockstep`). The image is bit-identical; only the speed differs. Default: the
    /// renderer's default.
    #[arg(long, value_enum)]
    pub trace: Option<TraceArg>,
    /// Do not light a bare mesh file (.obj, .ply, .gltf/.glb) that has no light of its own
    /// by the default sky and sun (docs/scenes.md); it then renders black, with a warning.
    #[arg(long)]
    pub no_default_light: bool,
}

/// `--trace` values (filtrace_render::TraceMode).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum TraceArg {
    Scalar,
    Lockstep,
}

impl TraceArg {
    pub fn mode(self) -> filtrace_render::TraceMode {
        match self {
            TraceArg::Scalar => filtrace_render::TraceMode::Scalar,
            TraceArg::Lockstep => filtrace_render::TraceMode::Lockstep,
        }
    }
}

/// `filtrace render` options.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    #[command(flatten)]
    pub common: CommonArgs,
    #[command(flatten)]
    pub filter: FilterArgs,
    #[command(flatten)]
    pub adaptive: AdaptiveArgs,
    #[command(flatten)]
    pub vpl: super::render_vpl::VplArgs,
}

/// An image size parsed from `WxH`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Resolution {
    pub width: u32,
    pub height: u32,
}

impl std::fmt::Display for Resolution {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}", self.width, self.height)
    }
}

/// Parses `WxH` (also `W*H`), each side in 1..=32768.
pub fn parse_resolution(s: &str) -> Result<Resolution, String> {
    let malformed = || format!("'{s}' is not a resolution: expected WIDTHxHEIGHT, e.g. 512x512");
    let (w, h) = s.trim().split_once(['x', 'X', '*']).ok_or_else(malformed)?;
    let side = |v: &str| v.trim().parse::<u64>().map_err(|_| malformed());
    let (w, h) = (side(w)?, side(h)?);
    if w == 0 || h == 0 {
        return Err(format!("resolution {w}x{h} has no pixels: both sides must be at least 1"));
    }
    if w > MAX_SIDE as u64 || h > MAX_SIDE as u64 {
        return Err(format!("resolution {w}x{h} is too large: at most {MAX_SIDE} per side"));
    }
    Ok(Resolution { width: w as u32, height: h as u32 })
}

impl CommonArgs {
    /// Loads the scene argument with the load options these flags select.
    pub fn load_scene(&self) -> Result<filtrace_scene::Scene, filtrace_scene::SceneError> {
        let options = filtrace_scene::LoadOptions { default_light: !self.no_default_light };
        filtrace_scene::load_scene_with(&self.scene, &options)
    }

    /// The renderer settings these options select (validated).
    pub fn settings(&self) -> anyhow::Result<RenderSettings> {
        let s = RenderSettings {
            width: self.res.width,
            height: self.res.height,
            spp: self.spp(),
            max_depth: self.max_depth,
            seed: self.seed,
        };
        s.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
        Ok(s)
    }

    /// `--spp`, or [`DEFAULT_SPP`].
    pub fn spp(&self) -> u32 {
        self.spp.unwrap_or(DEFAULT_SPP)
    }

    /// A short name for the scene: the built-in name or the file stem.
    pub fn scene_name(&self) -> String {
        let p = Path::new(&self.scene);
        match p.extension() {
            Some(_) => p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or("scene".into()),
            None => p.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or("scene".into()),
        }
    }

    /// The EXR path: `--out`, or `filtrace-out/<scene>.exr`.
    pub fn output_path(&self) -> PathBuf {
        self.out
            .clone()
            .unwrap_or_else(|| PathBuf::from("filtrace-out").join(format!("{}.exr", self.scene_name())))
    }

    /// [`CommonArgs::output_path`], checked before any work: it must end in `.exr`, its
    /// folder is created now, and the EXR and the PNG beside it must be writable
    /// ([`filtrace_io::check_writable`]), so that a long render never fails at the end for
    /// want of a place to write.
    pub fn prepare_output(&self) -> anyhow::Result<PathBuf> {
        let out = self.output_path();
        let is_exr = out.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("exr"));
        if !is_exr {
            anyhow::bail!(
                "--out {}: the output must be an .exr file (the PNG is written beside it)",
                out.display()
            );
        }
        if out.is_dir() {
            anyhow::bail!("--out {}: is a folder, expected an .exr file name", out.display());
        }
        if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create output folder {}", dir.display()))?;
        }
        for path in [out.clone(), out.with_extension("png")] {
            filtrace_io::check_writable(&path).context("the output cannot be written (see --out)")?;
        }
        Ok(out)
    }

    pub fn thread_count(&self) -> usize {
        self.threads
            .map(|t| t as usize)
            .unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1))
    }

    /// A rayon pool of [`CommonArgs::thread_count`] threads.
    pub fn thread_pool(&self) -> anyhow::Result<rayon::ThreadPool> {
        rayon::ThreadPoolBuilder::new()
            .num_threads(self.thread_count())
            .build()
            .context("cannot start the worker threads")
    }

    pub fn tonemap(&self) -> TonemapParams {
        let base = if self.filmic { TonemapParams::filmic() } else { TonemapParams::srgb_clamp() };
        TonemapParams { exposure: self.exposure, ..base }
    }

    /// Most samples per pixel per pass.
    pub fn pass_spp(&self) -> u32 {
        self.passes_spp.unwrap_or((self.spp() / 16).max(1)).min(self.spp().max(1))
    }
}

/// Returned (as an error) after a cancelled command has written its output: `main`
/// exits with code 130.
#[derive(Debug)]
pub struct Interrupted;

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "interrupted by Ctrl-C (partial result written)")
    }
}

impl std::error::Error for Interrupted {}

/// Ctrl-C of the rendering commands. Until [`CtrlC::arm`] there is nothing to keep, and
/// loading and the BVH build cannot stop midway: Ctrl-C exits at once (code 130) and
/// writes nothing. Once armed, Ctrl-C sets [`CtrlC::flag`], which the render polls; the
/// command then writes what is complete and exits with 130. A second Ctrl-C exits at once.
pub struct CtrlC {
    flag: Arc<AtomicBool>,
    armed: Arc<AtomicBool>,
}

impl CtrlC {
    /// Installs the handler (if one is installed already, as in unit tests running several
    /// commands, Ctrl-C keeps that one and this flag is never set).
    pub fn install() -> Self {
        let (flag, armed) = (Arc::new(AtomicBool::new(false)), Arc::new(AtomicBool::new(false)));
        let (f, a) = (flag.clone(), armed.clone());
        let _ = ctrlc::set_handler(move || {
            if f.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            if !a.load(Ordering::SeqCst) {
                eprintln!("\nCtrl-C: stopped before any sample was taken; nothing written");
                std::process::exit(130);
            }
            eprintln!("\nCtrl-C: stopping and writing what is complete (Ctrl-C again to abort)");
        });
        CtrlC { flag, armed }
    }

    /// The render starts: from now on Ctrl-C sets the flag instead of exiting.
    pub fn arm(&self) {
        self.armed.store(true, Ordering::SeqCst);
    }

    pub fn flag(&self) -> &Arc<AtomicBool> {
        &self.flag
    }

    pub fn is_set(&self) -> bool {
        self.flag.load(Ordering::SeqCst)
    }
}

/// Test hook for `tests/cancel.rs`: when the environment has `FILTRACE_TEST_PAUSE`, each
/// stage of a render prints `filtrace-test: STAGE` on stderr, and the stage the variable
/// names then waits up to 10 s (less if `cancel` is set), so that a test can send SIGINT at
/// a known point. Stages: `loaded`, `built`, `rendering`, and `pass N` after each pass of
/// the plain render (N samples per pixel done).
pub fn test_hook(stage: &str, cancel: &AtomicBool) {
    let Some(pause) = std::env::var_os("FILTRACE_TEST_PAUSE") else { return };
    eprintln!("filtrace-test: {stage}");
    if pause == stage {
        let until = Instant::now() + Duration::from_secs(10);
        while Instant::now() < until && !cancel.load(Ordering::SeqCst) {
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

/// The EXR header attributes of a render: samples per pixel asked for, done (the fewest of
/// any pixel) and whether Ctrl-C stopped it.
pub fn render_attributes(spp_requested: u32, spp_done: u32, cancelled: bool) -> Vec<(&'static str, String)> {
    vec![
        ("filtrace:spp_requested", spp_requested.to_string()),
        ("filtrace:spp_done", spp_done.to_string()),
        ("filtrace:cancelled", cancelled.to_string()),
    ]
}

/// A progress bar on stderr when it is a terminal, hidden otherwise.
pub fn progress_bar(total: u64, what: &str) -> indicatif::ProgressBar {
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(total);
    let style = indicatif::ProgressStyle::with_template(
        "{msg} [{elapsed_precise}] {wide_bar} {percent:>3}% (eta {eta})",
    )
    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar());
    bar.set_style(style);
    bar.set_message(what.to_string());
    bar
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

/// The JSON summary of `filtrace render --json`.
#[derive(Serialize)]
struct Summary {
    scene: String,
    res: String,
    width: u32,
    height: u32,
    spp: u32,
    /// Smallest per-pixel sample count reached (less than `spp` when cancelled).
    spp_done: u32,
    /// Largest per-pixel sample count (between `spp_done` and twice it when cancelled).
    spp_max: u32,
    max_depth: i32,
    seed: u64,
    threads: usize,
    triangles: usize,
    load_s: f64,
    build_s: f64,
    render_s: f64,
    samples: u64,
    samples_per_s: f64,
    mean_rgb: [f64; 3],
    output: PathBuf,
    png: PathBuf,
    cancelled: bool,
    load_warnings: Vec<String>,
    degenerate_triangles_skipped: usize,
    /// Samples dropped by the film because they were not finite.
    nonfinite_samples: u64,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.vpl.enabled() {
        return super::render_vpl::run(&args.common, &args.vpl);
    }
    // The filtered pipeline (and adaptive sampling, which drives it) lives in
    // `render_filtered` (pipeline engineer).
    if args.filter.enabled() || args.adaptive.adaptive {
        return super::render_filtered::run(&args.common, &args.filter, &args.adaptive);
    }
    run_plain(&args.common)
}

/// The plain path-traced render (no filter, uniform sampling).
pub fn run_plain(c: &CommonArgs) -> anyhow::Result<()> {
    let settings = c.settings()?;
    super::render_filtered::check_memory(filtrace_render::memory::plain_render(
        settings.width,
        settings.height,
    ))?;
    // First: until the render starts, Ctrl-C exits at once and writes nothing.
    let ctrlc = CtrlC::install();

    let t0 = Instant::now();
    let scene = c.load_scene().with_context(|| format!("cannot load scene '{}'", c.scene))?;
    let load_s = t0.elapsed().as_secs_f64();
    test_hook("loaded", ctrlc.flag());
    let out = c.prepare_output()?;
    let load_warnings = scene.stats.warnings.clone();
    let degenerate = scene.stats.degenerate_triangles_skipped;
    if !c.json {
        for w in &load_warnings {
            eprintln!("warning: {w}");
        }
    }

    let pool = c.thread_pool()?;
    let threads = pool.current_num_threads();
    let mut renderer =
        pool.install(|| Renderer::new(scene, settings.clone())).map_err(|e| anyhow::anyhow!("{e}"))?;
    if let Some(t) = c.trace {
        renderer = renderer.with_trace_mode(t.mode());
    }
    test_hook("built", ctrlc.flag());

    ctrlc.arm();
    test_hook("rendering", ctrlc.flag());
    let (film, render_s) = render_passes(&renderer, &pool, c, ctrlc.flag());
    let cancelled = ctrlc.is_set();
    if cancelled && film.pixels_without_samples() > 0 {
        eprintln!(
            "cancelled before every pixel had a sample: nothing written ({} left as it was)",
            out.display()
        );
        return Err(Interrupted.into());
    }

    let aovs = film.try_aovs()?;
    let counts = film.sample_counts();
    let attributes = render_attributes(settings.spp, film.min_samples(), cancelled);
    let written =
        write_outputs(&out, &aovs, &[("samples", &["Y"], &counts)], &attributes, None, &c.tonemap())?;
    let samples = film.total_samples();
    let mean = aovs.color.mean();
    let summary = Summary {
        scene: c.scene.clone(),
        res: c.res.to_string(),
        width: settings.width,
        height: settings.height,
        spp: settings.spp,
        spp_done: film.min_samples(),
        spp_max: film.max_samples(),
        max_depth: settings.max_depth,
        seed: settings.seed,
        threads,
        triangles: renderer.triangle_count(),
        load_s,
        build_s: renderer.build_seconds(),
        render_s,
        samples,
        samples_per_s: samples as f64 / render_s.max(1e-9),
        mean_rgb: [mean[0], mean[1], mean[2]],
        output: written.exr.clone(),
        png: written.png.clone(),
        cancelled,
        load_warnings,
        degenerate_triangles_skipped: degenerate,
        nonfinite_samples: film.dropped_samples(),
    };
    let mut out = super::output::stdout();
    if c.json {
        writeln!(out, "{}", serde_json::to_string(&summary)?)?;
    } else {
        print_summary(&mut out, &summary, written.png_nonfinite)?;
    }
    if cancelled {
        eprintln!(
            "cancelled: wrote what was rendered ({} to {} of {} spp per pixel, {:.2} on average; per pixel in the 'samples' layer) to {}",
            summary.spp_done,
            summary.spp_max,
            settings.spp,
            samples as f64 / (settings.width as f64 * settings.height as f64),
            written.exr.display()
        );
        return Err(Interrupted.into());
    }
    Ok(())
}

/// The progressive passes ([`progressive_passes`]) of `c` until done or `cancel`; returns
/// the film and the seconds spent.
fn render_passes(
    renderer: &Renderer,
    pool: &rayon::ThreadPool,
    c: &CommonArgs,
    cancel: &AtomicBool,
) -> (Film, f64) {
    let settings = renderer.settings();
    let pixels = settings.width as u64 * settings.height as u64;
    let bar = progress_bar(pixels * settings.spp as u64, &format!("rendering {}", c.scene_name()));
    let mut film = renderer.new_film();
    let start = Instant::now();
    for (first, count) in progressive_passes(settings.spp, c.pass_spp()) {
        let on_tile = |n: usize| bar.inc(n as u64 * count as u64);
        if cancel.load(Ordering::SeqCst)
            || !pool.install(|| renderer.render_pass_with_progress(&mut film, first, count, cancel, &on_tile))
        {
            break;
        }
        test_hook(&format!("pass {}", first + count), cancel);
    }
    bar.finish_and_clear();
    (film, start.elapsed().as_secs_f64())
}

fn print_summary(out: &mut impl Write, s: &Summary, png_nonfinite: usize) -> std::io::Result<()> {
    writeln!(
        out,
        "{}: {} at {} spp, max depth {}, seed {}, {} threads",
        s.scene, s.res, s.spp_done, s.max_depth, s.seed, s.threads
    )?;
    writeln!(
        out,
        "  {} triangles ({} degenerate skipped); load {:.3} s, build {:.3} s, render {:.3} s ({:.2} M samples/s)",
        s.triangles,
        s.degenerate_triangles_skipped,
        s.load_s,
        s.build_s,
        s.render_s,
        s.samples_per_s / 1e6
    )?;
    writeln!(out, "  mean linear RGB {:.6} {:.6} {:.6}", s.mean_rgb[0], s.mean_rgb[1], s.mean_rgb[2])?;
    if s.nonfinite_samples > 0 {
        writeln!(out, "  warning: {} non-finite samples were dropped", s.nonfinite_samples)?;
    }
    if png_nonfinite > 0 {
        writeln!(out, "  warning: {png_nonfinite} non-finite values written as 0 in the PNG")?;
    }
    writeln!(out, "  wrote {} and {}", s.output.display(), s.png.display())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resolution_parsing() {
        assert_eq!(parse_resolution("640x480"), Ok(Resolution { width: 640, height: 480 }));
        assert_eq!(parse_resolution(" 32X16 "), Ok(Resolution { width: 32, height: 16 }));
        assert_eq!(parse_resolution("1x32768").unwrap().height, 32768);
        for bad in ["abc", "0x0", "10x0", "x10", "10x", "-5x10", "32769x1", "1.5x2", "99999999999999999999x1"]
        {
            let e = parse_resolution(bad).unwrap_err();
            assert!(!e.is_empty(), "{bad}");
        }
        assert!(parse_resolution("0x4").unwrap_err().contains("at least 1"));
        assert!(parse_resolution("40000x4").unwrap_err().contains("too large"));
        assert!(parse_resolution("abc").unwrap_err().contains("WIDTHxHEIGHT"));
    }
}
