//! `filtrace render`: load a scene, path trace it progressively in passes, write one
//! multi-layer EXR (colour + AOVs) and a tonemapped PNG beside it, print a summary.
//!
//! Ctrl-C stops the passes at the next tile; what was rendered is written (every pixel's
//! sample count is exact, so the image is an unbiased mean of fewer samples) and the
//! command exits with code 130. A second Ctrl-C exits at once.
//!
//! The filtered pipeline and adaptive sampling (`--adaptive`, and `--filter` once
//! `render_filtered::FilterArgs` has it) are run by `render_filtered`; this module
//! provides the common options ([`CommonArgs`]) and the writers ([`write_outputs`]) both use.

use super::render_filtered::{AdaptiveArgs, FilterArgs};
use anyhow::Context;
use filtrace_core::Image;
use filtrace_io::{ExrImage, TonemapParams};
use filtrace_render::film::Aovs;
use filtrace_render::{RenderSettings, Renderer};
use serde::Serialize;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

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
    /// Samples per pixel added per progressive pass (default: spp/16, at least 1).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub passes_spp: Option<u32>,
    /// PNG exposure in stops.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub exposure: f32,
    /// PNG with a filmic curve instead of the plain sRGB clamp.
    #[arg(long)]
    pub filmic: bool,
    /// How the path tracer walks its paths: one at a time (`scalar`) or 8 in SIMD lockstep
    /// (`lockstep`). The image is bit-identical; only the speed differs. Default: the
    /// renderer's default.
    #[arg(long, value_enum)]
    pub trace: Option<TraceArg>,
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

    /// [`CommonArgs::output_path`], checked before any work: it must end in `.exr` and its
    /// folder is created now, so that a long render never fails at the end for want of a
    /// place to write.
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

    /// Samples per pixel per pass.
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

/// A cancel flag that Ctrl-C sets; a second Ctrl-C exits the process at once (130).
pub fn install_ctrlc() -> Arc<AtomicBool> {
    let cancel = Arc::new(AtomicBool::new(false));
    let flag = cancel.clone();
    // Fails only if a handler is already installed (then Ctrl-C keeps its default).
    let _ = ctrlc::set_handler(move || {
        if flag.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        eprintln!("\nCtrl-C: stopping after the current tiles and writing what was rendered (Ctrl-C again to abort)");
    });
    cancel
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
/// `position`, `depth`, `variance`, then `extra` layers as `(name, channel names, image)`)
/// and the tonemapped PNG of `png_image` (the colour if `None`) beside it, creating the
/// folder.
pub fn write_outputs(
    exr_path: &Path,
    aovs: &Aovs,
    extra: &[(&str, &[&str], &Image)],
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
    // First, so that a Ctrl-C during loading also stops cleanly.
    let cancel = install_ctrlc();

    let t0 = Instant::now();
    let scene =
        filtrace_scene::load_scene(&c.scene).with_context(|| format!("cannot load scene '{}'", c.scene))?;
    let load_s = t0.elapsed().as_secs_f64();
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

    let pixels = settings.width as u64 * settings.height as u64;
    let bar = progress_bar(pixels * settings.spp as u64, &format!("rendering {}", c.scene_name()));
    let mut film = filtrace_render::Film::try_new(settings.width as usize, settings.height as usize)?;
    let step = c.pass_spp();
    let t1 = Instant::now();
    let mut first = 0u32;
    while first < settings.spp && !cancel.load(Ordering::SeqCst) {
        let count = step.min(settings.spp - first);
        let on_tile = |n: usize| bar.inc(n as u64 * count as u64);
        pool.install(|| renderer.render_pass_with_progress(&mut film, first, count, &cancel, &on_tile));
        first += count;
    }
    let render_s = t1.elapsed().as_secs_f64();
    bar.finish_and_clear();
    let cancelled = cancel.load(Ordering::SeqCst);

    let aovs = film.try_aovs()?;
    let written = write_outputs(&out, &aovs, &[], None, &c.tonemap())?;
    let samples = film.total_samples();
    let mean = aovs.color.mean();
    let summary = Summary {
        scene: c.scene.clone(),
        res: c.res.to_string(),
        width: settings.width,
        height: settings.height,
        spp: settings.spp,
        spp_done: film.min_samples(),
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
    if c.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        print_summary(&summary, written.png_nonfinite);
    }
    if cancelled {
        eprintln!(
            "cancelled: wrote what was rendered ({} to {} of {} spp per pixel, {:.2} on average) to {}",
            summary.spp_done,
            film.pixels().iter().map(|p| p.samples).max().unwrap_or(0),
            settings.spp,
            samples as f64 / pixels as f64,
            written.exr.display()
        );
        return Err(Interrupted.into());
    }
    Ok(())
}

fn print_summary(s: &Summary, png_nonfinite: usize) {
    println!(
        "{}: {} at {} spp, max depth {}, seed {}, {} threads",
        s.scene, s.res, s.spp_done, s.max_depth, s.seed, s.threads
    );
    println!(
        "  {} triangles ({} degenerate skipped); load {:.3} s, build {:.3} s, render {:.3} s ({:.2} M samples/s)",
        s.triangles,
        s.degenerate_triangles_skipped,
        s.load_s,
        s.build_s,
        s.render_s,
        s.samples_per_s / 1e6
    );
    println!("  mean linear RGB {:.6} {:.6} {:.6}", s.mean_rgb[0], s.mean_rgb[1], s.mean_rgb[2]);
    if s.nonfinite_samples > 0 {
        println!("  warning: {} non-finite samples were dropped", s.nonfinite_samples);
    }
    if png_nonfinite > 0 {
        println!("  warning: {png_nonfinite} non-finite values written as 0 in the PNG");
    }
    println!("  wrote {} and {}", s.output.display(), s.png.display());
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
