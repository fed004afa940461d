//! `filtrace render --integrator vpl`: the many-light renderer (filtrace-vpl, the thesis's
//! importance caching) as the renderer's integrator, in the path tracer's progressive
//! passes (`--pass-spp`; the `optimized` sampler learns after each), with its Ctrl-C
//! behaviour: a render stopped once every pixel has a sample writes what it has (each
//! pixel a prefix of its samples) and exits with 130. Writes the usual EXR (colour and the G-buffer AOVs, so the filters
//! can run on it) plus a `cache_distance` layer (d-distance of each pixel's surface to the
//! closest cache point, the thesis's Figure 27) and the PNG; prints a summary with the
//! milliseconds per stage.

use super::render_args::CommonArgs;
use super::render_output::{render_attributes, write_outputs, Written};
use super::render_session::{progress_bar, test_hook, CtrlC, Interrupted};
use anyhow::Context;
use filtrace_render::renderer::progressive_passes;
use filtrace_render::Renderer;
use filtrace_vpl::cache::{CacheParams, SamplerKind};
use filtrace_vpl::vpls::{
    collect_frame, use_vpl_integrator, GeometryBound, VplFrame, VplIntegrator, VplParams, VplSettings,
};
use std::io::Write;
use std::sync::atomic::Ordering;
use std::time::Instant;

/// `--integrator` values.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum IntegratorArg {
    /// Path tracing (next-event estimation + MIS).
    #[default]
    Path,
    /// Virtual point lights with an importance cache.
    Vpl,
}

/// Options of the VPL integrator.
#[derive(clap::Args, Debug, Clone)]
pub struct VplArgs {
    /// Which integrator renders the image.
    #[arg(long, value_enum, default_value_t = IntegratorArg::Path)]
    pub integrator: IntegratorArg,
    /// Number of VPLs (one eighth of them on the lights), as the thesis: 2048.
    #[arg(long, default_value_t = 2048, value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    pub vpls: u32,
    /// VPL sampler: uniform, alpha-max, balance, balance-cv or optimized.
    #[arg(long, default_value = "optimized", value_parser = parse_sampler)]
    pub vpl_sampler: SamplerKind,
    /// Cache points placed through the G-buffer.
    #[arg(long, default_value_t = 2048, value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    pub cache_points: u32,
    /// Records interpolated per shading point (M).
    #[arg(long, default_value_t = 2)]
    pub cache_neighbours: usize,
    /// Every VPL with exact visibility at every sample (the ground truth).
    #[arg(long)]
    pub ground_truth: bool,
    /// Bound the geometry term's 1/r² below this distance, as a fraction of the scene's
    /// bounding radius (thesis 4.2.3; darkens short-range light; default off: unbiased).
    #[arg(long, allow_negative_numbers = true, value_parser = super::args::finite_f32)]
    pub vpl_clamp: Option<f32>,
}

fn parse_sampler(s: &str) -> Result<SamplerKind, String> {
    s.parse()
}

impl VplArgs {
    pub fn enabled(&self) -> bool {
        self.integrator == IntegratorArg::Vpl
    }

    /// The integrator's settings; `radius` is the scene's bounding radius. The VPLs' seed
    /// follows the render's `--seed` (and the frame number) inside the integrator.
    pub fn settings(&self, radius: f32) -> anyhow::Result<VplSettings> {
        let mut vpls = VplParams::with_count(self.vpls as usize);
        if let Some(c) = self.vpl_clamp {
            vpls.bound = GeometryBound::MinDistance(c * radius);
        }
        let cache = CacheParams {
            cache_points: self.cache_points as usize,
            neighbours: self.cache_neighbours,
            ..CacheParams::default()
        };
        let s = VplSettings { vpls, sampler: self.vpl_sampler, cache, ground_truth: self.ground_truth };
        s.vpls.validate().map_err(|e| anyhow::anyhow!("--vpls/--vpl-clamp: {e}"))?;
        s.cache.validate().map_err(|e| anyhow::anyhow!("--cache-points/--cache-neighbours: {e}"))?;
        Ok(s)
    }
}

/// Renders `c.scene` with the VPL integrator in progressive passes and writes the outputs.
pub fn run(c: &CommonArgs, v: &VplArgs) -> anyhow::Result<()> {
    let settings = c.settings()?;
    // Until the passes start, Ctrl-C exits at once and writes nothing.
    let ctrlc = CtrlC::install();
    let scene = c.load_scene().with_context(|| format!("cannot load scene '{}'", c.scene))?;
    test_hook("loaded", ctrlc.flag());
    let out = c.prepare_output()?;
    let pool = c.thread_pool()?;
    let mut renderer =
        pool.install(|| Renderer::new(scene, settings.clone())).map_err(|e| anyhow::anyhow!("{e}"))?;
    let vs = v.settings(renderer.lights().scene_radius())?;
    // The integrator's `prepare`: VPLs, G-buffer and importance cache of the frame.
    pool.install(|| use_vpl_integrator(&mut renderer, &vs)).map_err(|e| anyhow::anyhow!("{e}"))?;
    test_hook("built", ctrlc.flag());
    ctrlc.arm();
    test_hook("rendering", ctrlc.flag());
    let cancel = ctrlc.flag();
    let pixels = settings.width as u64 * settings.height as u64;
    let bar = progress_bar(pixels * settings.spp as u64, &format!("rendering {} (vpl)", c.scene_name()));
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
    let cancelled = ctrlc.is_set();
    if cancelled && film.pixels_without_samples() > 0 {
        eprintln!(
            "cancelled before every pixel had a sample: nothing written ({} left as it was)",
            out.display()
        );
        return Err(Interrupted.into());
    }
    let integrator = renderer.integrator_as::<VplIntegrator>().expect("the VPL integrator was set");
    let frame =
        pool.install(|| collect_frame(film, integrator, start.elapsed().as_secs_f64() * 1e3, cancelled));
    let written = write_frame(c, &out, &frame, settings.spp)?;
    print_summary(c, &vs, &frame, &written, settings.spp)?;
    if cancelled {
        eprintln!(
            "cancelled: wrote what was rendered ({} to {} of {} spp per pixel) to {}",
            frame.film.min_samples(),
            frame.film.max_samples(),
            settings.spp,
            written.exr.display()
        );
        return Err(Interrupted.into());
    }
    Ok(())
}

/// The EXR (colour, AOVs, per-pixel sample counts, cache distance) and the PNG.
fn write_frame(c: &CommonArgs, out: &std::path::Path, frame: &VplFrame, spp: u32) -> anyhow::Result<Written> {
    let aovs = frame.film.try_aovs()?;
    let counts = frame.film.sample_counts();
    let attributes = render_attributes(spp, frame.film.min_samples(), frame.cancelled);
    let extra: [(&str, &[&str], &filtrace_core::Image); 2] =
        [("samples", &["Y"], &counts), ("cache_distance", &["Y"], &frame.cache_distance)];
    write_outputs(out, &aovs, &extra, &attributes, None, &c.tonemap())
}

/// The JSON object (`--json`) or the line of text.
fn print_summary(
    c: &CommonArgs,
    vs: &VplSettings,
    frame: &VplFrame,
    written: &Written,
    spp: u32,
) -> anyhow::Result<()> {
    let mean = frame.film.aovs().color.mean();
    let t = frame.times;
    let sampler = if vs.ground_truth { "exhaustive" } else { vs.sampler.name() };
    let summary = serde_json::json!({
        "scene": c.scene, "res": c.res.to_string(), "spp": spp, "spp_done": frame.film.min_samples(),
        "seed": c.settings()?.seed, "integrator": "vpl", "sampler": sampler, "vpls": frame.vpls.len(),
        "light_paths": frame.vpls.light_paths, "cache_records": frame.cache_records,
        "vpl_generation_ms": t.vpl_generation_ms, "cache_ms": t.cache_ms,
        "shading_ms": t.shading_ms, "optimisation_ms": t.optimisation_ms,
        "mean_rgb": [mean[0], mean[1], mean[2]], "output": written.exr, "png": written.png,
        "nonfinite_samples": frame.film.dropped_samples(), "cancelled": frame.cancelled,
    });
    let mut o = super::output::stdout();
    if c.json {
        writeln!(o, "{summary}")?;
    } else {
        writeln!(
            o,
            "rendered {} with {} VPLs ({sampler}, {} cache records) at {} spp: VPLs {:.1} ms, cache {:.1} ms, shading {:.1} ms, optimisation {:.1} ms\nwrote {}",
            c.scene, frame.vpls.len(), frame.cache_records, frame.film.min_samples(),
            t.vpl_generation_ms, t.cache_ms, t.shading_ms, t.optimisation_ms, written.exr.display()
        )?;
    }
    Ok(())
}
