//! The plain path-traced render of `filtrace render` (no filter, uniform sampling): the
//! progressive passes of one frame, then one multi-layer EXR (colour + AOVs) and a
//! tonemapped PNG beside it, and a summary.
//!
//! Ctrl-C ([`CtrlC`]) during loading or the BVH build exits at once, writing nothing.
//! During the passes it stops them within a sample's time; if every pixel has a sample,
//! what was rendered is written (each pixel the mean of its own samples `0..n`, an unbiased
//! estimate; the counts are the `samples` layer, and the header says how many were asked
//! for, the fewest done and that Ctrl-C cut it short), else nothing. Either way the command
//! exits with code 130. A second Ctrl-C exits at once.

use anyhow::Context;
use filtrace_core::Image;
use filtrace_render::renderer::progressive_passes;
use filtrace_render::{Film, Renderer};
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use super::render_args::CommonArgs;
use super::render_output::{render_attributes, write_outputs};
use super::render_session::{check_memory, progress_bar, test_hook, CtrlC, Interrupted};

/// What loading the scene took and left; reported with every frame.
#[derive(Clone, Debug, Serialize)]
pub struct LoadReport {
    pub load_s: f64,
    pub load_warnings: Vec<String>,
    pub degenerate_triangles_skipped: usize,
}

impl LoadReport {
    pub fn of(scene: &filtrace_scene::Scene, load_s: f64) -> Self {
        LoadReport {
            load_s,
            load_warnings: scene.stats.warnings.clone(),
            degenerate_triangles_skipped: scene.stats.degenerate_triangles_skipped,
        }
    }
}

/// The JSON summary of `filtrace render --json` (one frame's).
#[derive(Serialize)]
pub struct Summary {
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
    #[serde(flatten)]
    load: LoadReport,
    build_s: f64,
    render_s: f64,
    samples: u64,
    samples_per_s: f64,
    mean_rgb: [f64; 3],
    output: PathBuf,
    png: PathBuf,
    pub cancelled: bool,
    /// Samples dropped by the film because they were not finite.
    nonfinite_samples: u64,
    /// Non-finite colour values written as 0 to the PNG (not in the JSON).
    #[serde(skip)]
    png_nonfinite: usize,
}

/// What stays the same from frame to frame of a plain render.
pub struct PlainRun<'a> {
    pub c: &'a CommonArgs,
    pub pool: &'a rayon::ThreadPool,
    pub cancel: &'a AtomicBool,
    pub load: &'a LoadReport,
}

impl PlainRun<'_> {
    /// Renders one frame with `renderer` and writes it to `out` (header: the render's
    /// attributes, then `stamp`), the samples counted on `bar`. `None` when Ctrl-C stopped
    /// it before every pixel had a sample: then nothing is written.
    pub fn render_frame(
        &self,
        renderer: &Renderer,
        out: &Path,
        stamp: &[(&str, String)],
        bar: &indicatif::ProgressBar,
    ) -> anyhow::Result<Option<Summary>> {
        let (film, render_s) = render_passes(renderer, self.pool, self.c, self.cancel, bar);
        let cancelled = self.cancel.load(Ordering::SeqCst);
        if cancelled && film.pixels_without_samples() > 0 {
            return Ok(None);
        }
        let settings = renderer.settings();
        let aovs = film.try_aovs()?;
        let counts = film.sample_counts();
        let mut attributes = render_attributes(settings.spp, film.min_samples(), cancelled);
        attributes.extend(stamp.iter().cloned());
        let tonemap = self.c.tonemap();
        let motion = renderer.motion_aov();
        let extra: Vec<(&str, &[&str], &Image)> =
            [("samples", &["Y"][..], &counts)].into_iter().chain(motion.layers()).collect();
        let written = write_outputs(out, &aovs, &extra, &attributes, None, &tonemap)?;
        let samples = film.total_samples();
        let mean = aovs.color.mean();
        Ok(Some(Summary {
            scene: self.c.scene.clone(),
            res: self.c.res.to_string(),
            width: settings.width,
            height: settings.height,
            spp: settings.spp,
            spp_done: film.min_samples(),
            spp_max: film.max_samples(),
            max_depth: settings.max_depth,
            seed: settings.seed,
            threads: self.pool.current_num_threads(),
            triangles: renderer.triangle_count(),
            load: self.load.clone(),
            build_s: renderer.build_seconds(),
            render_s,
            samples,
            samples_per_s: samples as f64 / render_s.max(1e-9),
            mean_rgb: [mean[0], mean[1], mean[2]],
            output: written.exr,
            png: written.png,
            cancelled,
            nonfinite_samples: film.dropped_samples(),
            png_nonfinite: written.png_nonfinite,
        }))
    }
}

/// A renderer of `scene` at the settings of `c` (on `pool`'s threads).
pub fn build_renderer(
    scene: filtrace_scene::Scene,
    c: &CommonArgs,
    pool: &rayon::ThreadPool,
) -> anyhow::Result<Renderer> {
    let settings = c.settings()?;
    let mut renderer = pool.install(|| Renderer::new(scene, settings)).map_err(|e| anyhow::anyhow!("{e}"))?;
    if let Some(t) = c.trace {
        renderer = renderer.with_trace_mode(t.mode());
    }
    Ok(renderer)
}

/// `filtrace render` without a filter: one still frame.
pub fn run(c: &CommonArgs) -> anyhow::Result<()> {
    let settings = c.settings()?;
    check_memory(filtrace_render::memory::plain_render(settings.width, settings.height))?;
    // First: until the render starts, Ctrl-C exits at once and writes nothing.
    let ctrlc = CtrlC::install();
    let t0 = Instant::now();
    let scene = c.load_scene().with_context(|| format!("cannot load scene '{}'", c.scene))?;
    let load = LoadReport::of(&scene, t0.elapsed().as_secs_f64());
    test_hook("loaded", ctrlc.flag());
    let out = c.prepare_output()?;
    if !c.json {
        load.load_warnings.iter().for_each(|w| eprintln!("warning: {w}"));
    }
    let pool = c.thread_pool()?;
    let renderer = build_renderer(scene, c, &pool)?;
    test_hook("built", ctrlc.flag());
    ctrlc.arm();
    test_hook("rendering", ctrlc.flag());
    let run = PlainRun { c, pool: &pool, cancel: ctrlc.flag(), load: &load };
    let pixels = settings.width as u64 * settings.height as u64;
    let bar = progress_bar(pixels * settings.spp as u64, &format!("rendering {}", c.scene_name()));
    let Some(summary) = run.render_frame(&renderer, &out, &[], &bar)? else {
        eprintln!(
            "cancelled before every pixel had a sample: nothing written ({} left as it was)",
            out.display()
        );
        return Err(Interrupted.into());
    };
    let mut stdout = super::output::stdout();
    if c.json {
        writeln!(stdout, "{}", serde_json::to_string(&summary)?)?;
    } else {
        print_summary(&mut stdout, &summary)?;
    }
    if summary.cancelled {
        eprintln!("{}", cancelled_note(&summary));
        return Err(Interrupted.into());
    }
    Ok(())
}

/// What a frame cut short by Ctrl-C holds.
pub fn cancelled_note(s: &Summary) -> String {
    format!(
        "cancelled: wrote what was rendered ({} to {} of {} spp per pixel, {:.2} on average; per pixel in the 'samples' layer) to {}",
        s.spp_done,
        s.spp_max,
        s.spp,
        s.samples as f64 / (s.width as f64 * s.height as f64),
        s.output.display()
    )
}

/// The progressive passes ([`progressive_passes`]) of `c` until done or `cancel`, counted
/// on `bar` (its length set here); returns the film and the seconds spent.
pub fn render_passes(
    renderer: &Renderer,
    pool: &rayon::ThreadPool,
    c: &CommonArgs,
    cancel: &AtomicBool,
    bar: &indicatif::ProgressBar,
) -> (Film, f64) {
    let settings = renderer.settings();
    let pixels = settings.width as u64 * settings.height as u64;
    bar.reset();
    bar.set_length(pixels * settings.spp as u64);
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

pub fn print_summary(out: &mut impl Write, s: &Summary) -> std::io::Result<()> {
    writeln!(
        out,
        "{}: {} at {} spp, max depth {}, seed {}, {} threads",
        s.scene, s.res, s.spp_done, s.max_depth, s.seed, s.threads
    )?;
    writeln!(
        out,
        "  {} triangles ({} degenerate skipped); load {:.3} s, build {:.3} s, render {:.3} s ({:.2} M samples/s)",
        s.triangles,
        s.load.degenerate_triangles_skipped,
        s.load.load_s,
        s.build_s,
        s.render_s,
        s.samples_per_s / 1e6
    )?;
    writeln!(out, "  mean linear RGB {:.6} {:.6} {:.6}", s.mean_rgb[0], s.mean_rgb[1], s.mean_rgb[2])?;
    if s.nonfinite_samples > 0 {
        writeln!(out, "  warning: {} non-finite samples were dropped", s.nonfinite_samples)?;
    }
    if s.png_nonfinite > 0 {
        writeln!(out, "  warning: {} non-finite values written as 0 in the PNG", s.png_nonfinite)?;
    }
    writeln!(out, "  wrote {} and {}", s.output.display(), s.png.display())?;
    Ok(())
}
