//! `filtrace render --integrator vpl`: the many-light renderer (filtrace-vpl, the thesis's
//! importance caching) as the renderer's integrator, in the path tracer's progressive
//! passes (`--pass-spp`; the `optimized` sampler learns after each), with its Ctrl-C
//! behaviour: a render stopped once every pixel has a sample writes what it has (each
//! pixel a prefix of its samples) and exits with 130. Writes the usual EXR (colour, the
//! G-buffer AOVs, so the filters can run on it, and the motion layers) plus a
//! `cache_distance` layer (d-distance of each pixel's surface to the closest cache point,
//! the thesis's Figure 27) and the PNG; prints a summary with the milliseconds per stage.
//!
//! [`VplRun`] renders one frame; `sequence` uses it for `--frames` with one integrator
//! carried from frame to frame, so that the `optimized` parameters carry over, and writes
//! their state after each frame so that `--resume` continues exactly
//! (filtrace_vpl::vpls::state).

use super::render_args::CommonArgs;
use super::render_output::{render_attributes, write_outputs, Written};
use super::render_plain::render_passes;
use super::render_session::{progress_bar, spinner, test_hook, CtrlC, Interrupted};
use anyhow::Context;
use filtrace_core::Image;
use filtrace_render::Renderer;
use filtrace_vpl::cache::{CacheParams, SamplerKind, DEFAULT_FAINT_SHARE, MAX_NEIGHBOURS};
use filtrace_vpl::vpls::seam::frame_memory;
use filtrace_vpl::vpls::seam::resume_vpl_integrator;
use filtrace_vpl::vpls::{
    collect_frame, frame_vpl_seed, use_vpl_integrator, GeometryBound, VplFrame, VplIntegrator, VplParams,
    VplReport, VplSettings, VplState,
};
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

/// `--integrator` values.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum IntegratorArg {
    /// Path tracing (next-event estimation + MIS).
    #[default]
    Path,
    /// Virtual point lights with an importance cache.
    Vpl,
}

/// Most VPLs and most cache points an option may ask for (`render`, `bench vpl`; the
/// experiment specs' limit too): beyond it the cache alone needs terabytes.
pub const MAX_COUNT: i64 = 1_000_000;

/// Options of the VPL integrator.
#[derive(clap::Args, Debug, Clone)]
pub struct VplArgs {
    /// Which integrator renders the image.
    #[arg(long, value_enum, default_value_t = IntegratorArg::Path)]
    pub integrator: IntegratorArg,
    /// Number of VPLs (one eighth of them on the lights), as the thesis: 2048.
    #[arg(long, default_value_t = 2048, value_parser = clap::value_parser!(u32).range(1..=MAX_COUNT))]
    pub vpls: u32,
    /// VPL sampler: uniform, alpha-max, balance, balance-cv or optimized.
    #[arg(long, default_value = "optimized", value_parser = parse_sampler)]
    pub vpl_sampler: SamplerKind,
    /// Cache points placed through the G-buffer.
    #[arg(long, default_value_t = 2048, value_parser = clap::value_parser!(u32).range(1..=MAX_COUNT))]
    pub cache_points: u32,
    /// Records interpolated per shading point (M).
    #[arg(long, default_value_t = 2, value_parser = parse_neighbours)]
    pub cache_neighbours: usize,
    /// The faintest VPLs of a cache record, carrying together at most this share of its
    /// unoccluded light, count as visible without a shadow ray (0: every ray traced, as
    /// the thesis). Shapes only a sampling distribution: no bias.
    #[arg(long, default_value_t = DEFAULT_FAINT_SHARE, allow_negative_numbers = true, value_parser = parse_faint_share)]
    pub cache_faint_share: f32,
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

/// The faint share, in `[0, 1)`, checked as a usage error.
pub fn parse_faint_share(s: &str) -> Result<f32, String> {
    let v = super::args::finite_f32(s)?;
    if (0.0..1.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("cache faint share {v} (expected in [0, 1))"))
    }
}

/// M, checked as a usage error (the integrator's own check would exit 1 after parsing).
fn parse_neighbours(s: &str) -> Result<usize, String> {
    let m: usize = s.parse().map_err(|_| format!("{s:?} is not a whole number"))?;
    if (1..=MAX_NEIGHBOURS).contains(&m) {
        Ok(m)
    } else {
        Err(format!("cache neighbours M = {m} (expected 1..={MAX_NEIGHBOURS})"))
    }
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
            let d = c * radius;
            if !(d.is_finite() && d > 0.0) {
                anyhow::bail!(
                    "--vpl-clamp {c:?}: times the scene's bounding radius {radius:?} it gives the distance \
                     {d:?} (expected a finite value > 0)"
                );
            }
            vpls.bound = GeometryBound::MinDistance(d);
        }
        let cache = CacheParams {
            cache_points: self.cache_points as usize,
            neighbours: self.cache_neighbours,
            faint_share: self.cache_faint_share,
            ..CacheParams::default()
        };
        let s = VplSettings { vpls, sampler: self.vpl_sampler, cache, ground_truth: self.ground_truth };
        s.vpls.validate().map_err(|e| anyhow::anyhow!("--vpls/--vpl-clamp: {e}"))?;
        s.cache.validate().map_err(|e| anyhow::anyhow!("--cache-points/--cache-neighbours: {e}"))?;
        Ok(s)
    }

    /// Whether the integrator carries state from frame to frame (`optimized`): a frame of
    /// a sequence then depends on the frames before it, and `--resume` needs their state.
    pub fn carries_state(&self) -> bool {
        self.enabled() && self.vpl_sampler == SamplerKind::Optimized && !self.ground_truth
    }

    /// Everything but the frame that decides a frame's pixels, for a sequence's header:
    /// the pass size too, since `optimized` learns after each pass.
    pub fn stamp(&self, pass_spp: u32) -> String {
        let sampler = if self.ground_truth { "exhaustive" } else { self.vpl_sampler.name() };
        format!(
            "vpl sampler={sampler} vpls={} cache_points={} neighbours={} faint_share={} clamp={:?} \
             passes_spp={pass_spp}",
            self.vpls, self.cache_points, self.cache_neighbours, self.cache_faint_share, self.vpl_clamp
        )
    }

    /// Refuses a frame whose film, outputs and integrator buffers ([`frame_memory`]) do
    /// not fit in memory: called before the scene is loaded.
    pub fn check_memory(&self, c: &CommonArgs) -> anyhow::Result<()> {
        let s = c.settings()?;
        // The scene's radius only scales --vpl-clamp, which costs no memory.
        let vs = self.settings(1.0)?;
        check_frame_memory(s.width, s.height, &vs, c.thread_count(), c.pass_spp())
    }
}

/// Refuses a `width x height` VPL frame of `settings` on `threads` threads in passes of at
/// most `max_pass` samples whose film, outputs and integrator buffers ([`frame_memory`])
/// do not fit in memory, before anything is allocated (`render`, `bench vpl`, `experiment`).
pub fn check_frame_memory(
    width: u32,
    height: u32,
    settings: &VplSettings,
    threads: usize,
    max_pass: u32,
) -> anyhow::Result<()> {
    let vpl = frame_memory(width, height, settings, threads, max_pass);
    let needs = filtrace_render::memory::plain_render(width, height).with_all(&vpl);
    let needs = needs.with_hint(
        "Lower --res, --vpls or --cache-points (the cache holds three distributions over the \
         VPLs per cache point), or for `optimized` the samples per pass (`render --passes-spp`: it \
         keeps every sample of a pass); set FILTRACE_MEMORY_LIMIT=bytes to test with another limit",
    );
    filtrace_render::memory::check(&needs).map_err(anyhow::Error::msg)
}

/// What stays the same from frame to frame of a VPL render; the integrator itself lives
/// in the renderer, set once and prepared by every frame update.
pub struct VplRun<'a> {
    pub c: &'a CommonArgs,
    pub settings: VplSettings,
    pub pool: &'a rayon::ThreadPool,
    pub cancel: &'a AtomicBool,
    /// The state of the frame before the first one rendered (a resumed sequence), handed
    /// to the integrator when it is set.
    pub carried: Option<VplState>,
}

/// The JSON summary of one VPL frame (`--json`).
#[derive(Serialize)]
pub struct Summary {
    scene: String,
    res: String,
    spp: u32,
    spp_done: u32,
    spp_max: u32,
    seed: u64,
    /// The seed the frame's VPLs were drawn with ([`frame_vpl_seed`]).
    vpl_seed: u64,
    threads: usize,
    integrator: &'static str,
    sampler: &'static str,
    vpls: usize,
    light_paths: usize,
    cache_records: usize,
    /// The cache's visibility rays, and the faint VPLs its records took as visible
    /// without one (`--cache-faint-share`).
    cache_rays: u64,
    cache_faint_vpls: u64,
    vpl_generation_ms: f64,
    cache_ms: f64,
    shading_ms: f64,
    optimisation_ms: f64,
    /// `optimized`: passes the optimiser learnt from in this frame, and the records its
    /// last step moved.
    optimised_passes: u32,
    records_stepped: usize,
    mean_rgb: [f64; 3],
    output: PathBuf,
    png: PathBuf,
    nonfinite_samples: u64,
    pub cancelled: bool,
    /// The scene loader's warnings (no light, default light, ...), as the path tracer's
    /// summary lists them.
    load_warnings: Vec<String>,
}

impl Summary {
    /// Milliseconds per stage, for the human line.
    pub fn stages(&self) -> String {
        format!(
            "VPLs {:.1} ms, cache {:.1} ms, shading {:.1} ms, optimisation {:.1} ms",
            self.vpl_generation_ms, self.cache_ms, self.shading_ms, self.optimisation_ms
        )
    }
}

impl VplRun<'_> {
    /// What a frame's progress display says while its VPLs (and importance cache, where
    /// the sampler reads one) are built.
    pub fn preparing_message(&self) -> String {
        let vs = &self.settings;
        if !vs.ground_truth && vs.sampler.needs_cache() {
            format!(
                "building {} VPLs and an importance cache of {} records",
                vs.vpls.count, vs.cache.cache_points
            )
        } else {
            format!("building {} VPLs", vs.vpls.count)
        }
    }

    /// Brings `renderer` to render `frame` with the VPL integrator: a still scene, which
    /// the sequence does not move, is moved to the frame number here so that its VPLs
    /// follow it too ([`frame_vpl_seed`]); the integrator is set the first time (which
    /// prepares it) and then kept, so every later frame update prepares the same one and
    /// the `optimized` parameters carry over (thesis 5.2.2); with [`VplRun::carried`], the
    /// first frame continues from that state as if the frame before had been rendered.
    pub fn prepare(&mut self, renderer: &mut Renderer, frame: i64) -> anyhow::Result<()> {
        if renderer.frame().index != frame {
            self.pool.install(|| renderer.prepare_frame(frame)).with_context(|| format!("frame {frame}"))?;
        }
        if renderer.integrator_as::<VplIntegrator>().is_none() {
            let (settings, carried) = (&self.settings, self.carried.take());
            self.pool
                .install(|| match &carried {
                    Some(state) => resume_vpl_integrator(renderer, settings, state),
                    None => use_vpl_integrator(renderer, settings),
                })
                .map_err(|e| anyhow::anyhow!("frame {frame}: {e}"))?;
        }
        Ok(())
    }

    /// What the integrator carries into the next frame (`None` when nothing:
    /// [`VplArgs::carries_state`]).
    pub fn state(&self, renderer: &Renderer) -> Option<VplState> {
        renderer.integrator_as::<VplIntegrator>().and_then(VplIntegrator::state)
    }

    /// Renders the prepared frame in progressive passes and writes it to `out` (header:
    /// the render's attributes, then `stamp`), the samples counted on `bar`. `None` when
    /// Ctrl-C stopped it before every pixel had a sample: then nothing is written.
    pub fn render_frame(
        &self,
        renderer: &Renderer,
        out: &Path,
        stamp: &[(&str, String)],
        bar: &indicatif::ProgressBar,
    ) -> anyhow::Result<Option<Summary>> {
        let integrator = renderer
            .integrator_as::<VplIntegrator>()
            .context("the VPL integrator was not set (VplRun::prepare)")?;
        let (film, render_s) = render_passes(renderer, self.pool, self.c, self.cancel, bar);
        let cancelled = self.cancel.load(Ordering::SeqCst);
        if cancelled && film.pixels_without_samples() > 0 {
            return Ok(None);
        }
        let frame = self.pool.install(|| collect_frame(film, integrator, render_s * 1e3, cancelled));
        let written = write_frame(self.c, out, renderer, &frame, stamp)?;
        Ok(Some(self.summary(renderer, &frame, &integrator.report(), written)))
    }

    fn summary(
        &self,
        renderer: &Renderer,
        frame: &VplFrame,
        report: &VplReport,
        written: Written,
    ) -> Summary {
        let settings = renderer.settings();
        let mean = frame.film.aovs().color.mean();
        let t = frame.times;
        let vs = &self.settings;
        Summary {
            scene: self.c.scene.clone(),
            res: self.c.res.to_string(),
            spp: settings.spp,
            spp_done: frame.film.min_samples(),
            spp_max: frame.film.max_samples(),
            seed: settings.seed,
            vpl_seed: frame_vpl_seed(vs.vpls.seed, settings.seed, renderer.frame().index),
            threads: self.pool.current_num_threads(),
            integrator: "vpl",
            sampler: if vs.ground_truth { "exhaustive" } else { vs.sampler.name() },
            vpls: frame.vpls.len(),
            light_paths: frame.vpls.light_paths,
            cache_records: frame.cache_records,
            cache_rays: frame.cache_rays.traced,
            cache_faint_vpls: frame.cache_rays.faint,
            vpl_generation_ms: t.vpl_generation_ms,
            cache_ms: t.cache_ms,
            shading_ms: t.shading_ms,
            optimisation_ms: t.optimisation_ms,
            optimised_passes: report.optimised_passes,
            records_stepped: report.last_step.stepped,
            mean_rgb: [mean[0], mean[1], mean[2]],
            output: written.exr,
            png: written.png,
            nonfinite_samples: frame.film.dropped_samples(),
            cancelled: frame.cancelled,
            load_warnings: Vec::new(),
        }
    }
}

/// What a frame cut short by Ctrl-C holds.
pub fn cancelled_note(s: &Summary) -> String {
    format!(
        "cancelled: wrote what was rendered ({} to {} of {} spp per pixel; per pixel in the 'samples' layer) to {}",
        s.spp_done,
        s.spp_max,
        s.spp,
        s.output.display()
    )
}

/// Renders `c.scene` with the VPL integrator in progressive passes and writes the outputs.
pub fn run(c: &CommonArgs, v: &VplArgs) -> anyhow::Result<()> {
    let settings = c.settings()?;
    v.check_memory(c)?;
    // Until the passes start, Ctrl-C exits at once and writes nothing.
    let ctrlc = CtrlC::install();
    let scene = c.load_scene().with_context(|| format!("cannot load scene '{}'", c.scene))?;
    let load_warnings = scene.stats.warnings.clone();
    test_hook("loaded", ctrlc.flag());
    let out = c.prepare_output()?;
    if !c.json {
        load_warnings.iter().for_each(|w| eprintln!("warning: {w}"));
    }
    let pool = c.thread_pool()?;
    let mut renderer =
        pool.install(|| Renderer::new(scene, settings.clone())).map_err(|e| anyhow::anyhow!("{e}"))?;
    let vs = v.settings(renderer.lights().scene_radius())?;
    let mut run = VplRun { c, settings: vs, pool: &pool, cancel: ctrlc.flag(), carried: None };
    // The integrator's `prepare`: VPLs, G-buffer and importance cache of the frame.
    let frame = renderer.frame().index;
    let preparing = spinner(&run.preparing_message());
    run.prepare(&mut renderer, frame)?;
    preparing.finish_and_clear();
    test_hook("built", ctrlc.flag());
    ctrlc.arm();
    test_hook("rendering", ctrlc.flag());
    let pixels = settings.width as u64 * settings.height as u64;
    let bar = progress_bar(pixels * settings.spp as u64, &format!("rendering {} (vpl)", c.scene_name()));
    let Some(mut summary) = run.render_frame(&renderer, &out, &[], &bar)? else {
        eprintln!(
            "cancelled before every pixel had a sample: nothing written ({} left as it was)",
            out.display()
        );
        return Err(Interrupted.into());
    };
    summary.load_warnings = load_warnings;
    print_summary(c, &summary)?;
    if summary.cancelled {
        eprintln!("{}", cancelled_note(&summary));
        return Err(Interrupted.into());
    }
    Ok(())
}

/// The EXR (colour, AOVs, per-pixel sample counts, cache distance, motion) and the PNG.
fn write_frame(
    c: &CommonArgs,
    out: &Path,
    renderer: &Renderer,
    frame: &VplFrame,
    stamp: &[(&str, String)],
) -> anyhow::Result<Written> {
    let aovs = frame.film.try_aovs()?;
    let counts = frame.film.sample_counts();
    let mut attributes =
        render_attributes(renderer.settings().spp, frame.film.min_samples(), frame.cancelled);
    attributes.extend(stamp.iter().cloned());
    let motion = renderer.motion_aov();
    let extra: Vec<(&str, &[&str], &Image)> =
        [("samples", &["Y"][..], &counts), ("cache_distance", &["Y"][..], &frame.cache_distance)]
            .into_iter()
            .chain(motion.layers())
            .collect();
    write_outputs(out, &aovs, &extra, &attributes, None, &c.tonemap())
}

/// The JSON object (`--json`) or the line of text.
fn print_summary(c: &CommonArgs, s: &Summary) -> anyhow::Result<()> {
    let mut o = super::output::stdout();
    if c.json {
        writeln!(o, "{}", serde_json::to_string(s)?)?;
    } else {
        writeln!(
            o,
            "rendered {} with {} VPLs ({}, {} cache records) at {} spp: {}\nwrote {}",
            s.scene,
            s.vpls,
            s.sampler,
            s.cache_records,
            s.spp_done,
            s.stages(),
            s.output.display()
        )?;
    }
    Ok(())
}
