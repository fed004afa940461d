//! Options of `filtrace render` for the filtered pipeline (Bauszat et al. 2011) and for
//! adaptive sampling; flattened into `render::Args`.
//!
//! `filtrace render --filter none|atrous|guided|bilateral --spp N --max-depth D` renders
//! with [`filtrace_pipeline::FilteredRenderer`]: one guide ray per pixel estimates the
//! indirect light, which is filtered; the further `N - 1` samples take it from the filtered
//! map by the geometry-aware lookup. It writes one EXR with the final image and the `noisy`,
//! `direct`, `indirect`, `filtered` (indirect) layers plus the guide G-buffer, a PNG beside
//! it, and prints the milliseconds of each stage.
//!
//! Ctrl-C (see `render_session::CtrlC`) during loading, the build or the guide rays writes nothing;
//! during the further samples, the frame is completed from the samples done (exactly the
//! frame of fewer samples per pixel, `filtrace_pipeline::pipeline`) and written, its header
//! saying how many. Either way the command exits with code 130.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::Context;
use filtrace_pipeline::adaptive::AdaptiveFrameError;
use filtrace_pipeline::{
    FilterChoice, FilteredRenderer, Frame, PipelineError, PipelineSettings, RenderSource,
};
use filtrace_render::Renderer;
use serde::Serialize;
use std::io::Write;

use super::render_args::{CommonArgs, DEFAULT_SPP};
use super::render_output::render_attributes;
use super::render_session::{check_memory, test_hook, CtrlC, Interrupted};

/// Reconstruction filter options of `filtrace render`.
#[derive(clap::Args, Debug, Clone)]
pub struct FilterArgs {
    /// Render with the filtered pipeline of Bauszat et al. 2011 and this filter for the
    /// indirect light (`none` = the pipeline unfiltered). Without it: plain path tracing.
    #[arg(long, value_parser = ["none", "atrous", "guided", "bilateral"])]
    pub filter: Option<String>,
    /// Named preset of the filter (atrous: paper, interactive, pure, color_only,
    /// color_normal; guided: paper, paper_wide, normal_only, grey; bilateral: reference,
    /// reference_wide, small). Default: the first (the paper's).
    #[arg(long, requires = "filter")]
    pub filter_preset: Option<String>,
    /// Window radius in pixels (guided, bilateral).
    #[arg(long, requires = "filter")]
    pub filter_radius: Option<u32>,
    /// Number of À-Trous levels.
    #[arg(long, requires = "filter")]
    pub filter_iterations: Option<u32>,
    /// Paths estimating the indirect light at each guide ray (Bauszat: 1; at least 1).
    #[arg(long, default_value_t = 1, requires = "filter", value_parser = clap::value_parser!(u32).range(1..))]
    pub indirect_paths: u32,
    /// Filter the direct light too (for comparison; the paper filters only the indirect).
    #[arg(long, requires = "filter")]
    pub filter_direct: bool,
    /// Filter the indirect radiance itself instead of radiance / albedo.
    #[arg(long, requires = "filter")]
    pub no_demodulate: bool,
}

impl FilterArgs {
    /// True when `filtrace render` should run the filtered pipeline.
    pub fn enabled(&self) -> bool {
        self.filter.is_some()
    }

    pub fn choice(&self) -> FilterChoice {
        FilterChoice {
            name: self.filter.clone().unwrap_or_else(|| "none".into()),
            preset: self.filter_preset.clone(),
            radius: self.filter_radius,
            iterations: self.filter_iterations,
        }
    }
}

/// A ready pipeline on a loaded scene (shared by `render`, `bench pipeline` and
/// `experiment`).
pub type Pipeline = FilteredRenderer<RenderSource, Box<dyn filtrace_pipeline::IndirectFilter>>;

/// Builds the pipeline for `scene` at `settings` with `filter`; `max_depth` in Mitsuba's
/// convention (3 = direct light and one indirect bounce).
pub fn build_pipeline(
    scene: filtrace_scene::Scene,
    settings: PipelineSettings,
    max_depth: i32,
    filter: &FilterChoice,
) -> anyhow::Result<Pipeline> {
    build_pipeline_traced(scene, settings, max_depth, filter, None)
}

/// [`build_pipeline`] whose source traces its batches as `trace` says (`--trace`; `None`:
/// the renderer's default, the lockstep tracer). The frame is the same bit for bit.
pub fn build_pipeline_traced(
    scene: filtrace_scene::Scene,
    settings: PipelineSettings,
    max_depth: i32,
    filter: &FilterChoice,
    trace: Option<filtrace_render::TraceMode>,
) -> anyhow::Result<Pipeline> {
    let rs = filtrace_render::RenderSettings {
        width: settings.width,
        height: settings.height,
        spp: settings.spp,
        max_depth,
        seed: settings.seed,
    };
    let mut renderer = Renderer::new(scene, rs).map_err(|e| anyhow::anyhow!("{e}"))?;
    if let Some(t) = trace {
        renderer = renderer.with_trace_mode(t);
    }
    let source = RenderSource::new(renderer);
    let f = filter.build(Some(source.scene_scale())).map_err(|e| anyhow::anyhow!("{e}"))?;
    FilteredRenderer::new(source, f, settings).map_err(|e| anyhow::anyhow!("{e}"))
}

/// The JSON summary of `filtrace render --filter/--adaptive --json` (one frame's).
#[derive(Serialize)]
pub struct Summary {
    scene: String,
    width: u32,
    height: u32,
    spp: u32,
    /// Eye samples per pixel in the frame (less than `spp` when cancelled).
    spp_done: u32,
    indirect_paths: u32,
    max_depth: i32,
    seed: u64,
    filter: String,
    threads: usize,
    load_s: f64,
    build_s: f64,
    timings: filtrace_pipeline::FrameTimings,
    lookup_failures: u64,
    /// Adaptive sampling: milliseconds of the G-buffer pass + importance map + apportionment.
    adaptive_plan_ms: Option<f64>,
    mean_rgb: [f64; 3],
    output: PathBuf,
    pub cancelled: bool,
}

/// The pipeline settings and filter these options select (checked), and the memory the
/// render will need checked against what there is: all before the scene is loaded.
pub fn pipeline_settings(
    common: &CommonArgs,
    filter: &FilterArgs,
    adaptive: &AdaptiveArgs,
) -> anyhow::Result<(PipelineSettings, FilterChoice)> {
    let settings = PipelineSettings {
        width: common.res.width,
        height: common.res.height,
        spp: adaptive.eye_spp(common.spp),
        indirect_paths: filter.indirect_paths,
        seed: common.seed,
        demodulate_albedo: !filter.no_demodulate,
        filter_direct: filter.filter_direct,
    };
    settings.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
    // `--adaptive` alone: the pipeline unfiltered, with adaptive indirect sample counts.
    let choice =
        FilterArgs { filter: filter.filter.clone().or_else(|| Some("none".into())), ..filter.clone() }
            .choice();
    choice.denoise_filter().map_err(|e| anyhow::anyhow!("{e}"))?;
    check_memory(filtrace_pipeline::memory::render_bytes(&settings, &choice.name, adaptive.adaptive))?;
    Ok((settings, choice))
}

/// What stays the same from frame to frame of a filtered render.
pub struct FilteredRun<'a> {
    pub common: &'a CommonArgs,
    pub adaptive: &'a AdaptiveArgs,
    pub pool: &'a rayon::ThreadPool,
    pub cancel: &'a AtomicBool,
    pub load_s: f64,
}

impl FilteredRun<'_> {
    /// Renders one frame with `pipeline` (its buffers kept for the next) and writes it to
    /// `out` (header: the render's attributes, then `stamp`). `None` when Ctrl-C stopped it
    /// before the guide rays were done: then nothing is written.
    pub fn render_frame(
        &self,
        pipeline: &mut Pipeline,
        out: &Path,
        stamp: &[(&str, String)],
    ) -> anyhow::Result<Option<Summary>> {
        // Adaptive sampling (Bauszat et al. 2011b, `filtrace_pipeline::adaptive`): a G-buffer
        // pre-pass of the guide rays, the importance map from its normals and positions, the
        // apportioned per-pixel indirect path counts, then the frame with those counts.
        let mut plan_ms = None;
        let mut adaptive_layers = None;
        // The frame stays in the pipeline (no copy: it is the biggest buffer of the command).
        let result = match self.adaptive.params() {
            None => self.pool.install(|| pipeline.render_frame().map(|_| ())),
            Some(params) => match self.pool.install(|| pipeline.render_frame_adaptive(&params)) {
                Ok((_, plan)) => {
                    plan_ms = Some(plan.prepass_ms + plan.plan_ms);
                    adaptive_layers = Some((plan.importance, plan.counts.to_image()));
                    Ok(())
                }
                Err(AdaptiveFrameError::Pipeline(e)) => Err(e),
                Err(e) => return Err(anyhow::anyhow!("{e}")),
            },
        };
        match result {
            Err(PipelineError::Cancelled) => return Ok(None),
            Err(e) => return Err(anyhow::anyhow!("{e}")),
            Ok(()) => {}
        }
        // The motion AOV of the frame's camera and instances, as a plain frame writes it
        // (`motion.X/Y`, `prev_depth.Z`, `prev_normal.X/Y/Z`; zero for a still frame).
        let motion = pipeline.source().renderer().motion_aov();
        let mut extra: Vec<(&str, &[&str], &filtrace_core::Image)> = match &adaptive_layers {
            Some((importance, counts)) => {
                vec![("importance", &["Y"], importance), ("indirect_paths", &["Y"], counts)]
            }
            None => vec![],
        };
        extra.extend(motion.layers());
        let frame = pipeline.last_frame();
        let settings = pipeline.settings();
        let cancelled = self.cancel.load(Ordering::SeqCst);
        let mut attributes = render_attributes(settings.spp, frame.spp_done, cancelled);
        attributes.extend(stamp.iter().cloned());
        write_frame(out, frame, &extra, &attributes, &self.common.tonemap())?;
        let m = frame.images.color.mean();
        Ok(Some(Summary {
            scene: self.common.scene.clone(),
            width: settings.width,
            height: settings.height,
            spp: settings.spp,
            spp_done: frame.spp_done,
            indirect_paths: settings.indirect_paths,
            max_depth: self.common.max_depth,
            seed: settings.seed,
            filter: pipeline.filter_mut().label(),
            threads: self.pool.current_num_threads(),
            load_s: self.load_s,
            build_s: pipeline.source().renderer().build_seconds(),
            timings: pipeline.last_frame().timings,
            lookup_failures: pipeline.last_frame().lookup_failures,
            adaptive_plan_ms: plan_ms,
            mean_rgb: [m[0], m[1], m[2]],
            output: out.to_path_buf(),
            cancelled,
        }))
    }
}

/// The filtered branch of `filtrace render`: one still frame.
pub fn run(common: &CommonArgs, filter: &FilterArgs, adaptive: &AdaptiveArgs) -> anyhow::Result<()> {
    let (settings, choice) = pipeline_settings(common, filter, adaptive)?;
    // First: until the frame starts, Ctrl-C exits at once and writes nothing.
    let ctrlc = CtrlC::install();
    let t0 = Instant::now();
    let scene = common.load_scene().with_context(|| format!("cannot load scene '{}'", common.scene))?;
    let load_s = t0.elapsed().as_secs_f64();
    if !common.json {
        scene.stats.warnings.iter().for_each(|w| eprintln!("warning: {w}"));
    }
    test_hook("loaded", ctrlc.flag());
    let pool = common.thread_pool()?;
    let trace = common.trace.map(|t| t.mode());
    let mut pipeline =
        pool.install(|| build_pipeline_traced(scene, settings, common.max_depth, &choice, trace))?;
    test_hook("built", ctrlc.flag());
    pipeline.set_cancel(Some(ctrlc.flag().clone()));
    ctrlc.arm();
    test_hook("rendering", ctrlc.flag());
    let out = common.output_path();
    let run = FilteredRun { common, adaptive, pool: &pool, cancel: ctrlc.flag(), load_s };
    let Some(summary) = run.render_frame(&mut pipeline, &out, &[])? else {
        eprintln!(
            "cancelled before the guide rays were done: nothing written ({} left as it was)",
            out.display()
        );
        return Err(Interrupted.into());
    };
    let mut stdout = super::output::stdout();
    if common.json {
        writeln!(stdout, "{}", serde_json::to_string(&summary)?)?;
    } else {
        print_summary(&mut stdout, &summary, adaptive)?;
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
        "cancelled: wrote the frame of {} of {} spp per pixel to {}",
        s.spp_done,
        s.spp,
        s.output.display()
    )
}

fn print_summary(stdout: &mut impl Write, s: &Summary, adaptive: &AdaptiveArgs) -> std::io::Result<()> {
    let t = &s.timings;
    let paths = match adaptive.params() {
        Some(p) => {
            format!("adaptive indirect paths, {} per pixel on average, at least {}", p.budget_spp, p.min_spp)
        }
        None => format!("{} indirect path(s) per guide ray", s.indirect_paths),
    };
    writeln!(
        stdout,
        "{}: {}x{} at {} spp ({paths}), max depth {}, filter {}, {} threads",
        s.scene, s.width, s.height, s.spp, s.max_depth, s.filter, s.threads
    )?;
    writeln!(
        stdout,
        "  frame {:.1} ms: guide rays {:.1}, filter {:.1}, further samples {:.1}, lookup {:.1} (trace {:.1})",
        t.total_ms,
        t.guide_ms,
        t.filter_ms,
        t.samples_ms,
        t.lookup_ms,
        t.trace_ms()
    )?;
    let m = s.mean_rgb;
    writeln!(
        stdout,
        "  load {:.3} s, build {:.3} s; mean linear RGB {:.6} {:.6} {:.6}",
        s.load_s, s.build_s, m[0], m[1], m[2]
    )?;
    if let Some(p) = s.adaptive_plan_ms {
        writeln!(stdout, "  adaptive sampling: plan (G-buffer pass, importance, apportionment) {p:.1} ms")?;
    }
    if s.lookup_failures > 0 {
        writeln!(
            stdout,
            "  {} further samples found no guide ray that hit (no indirect light)",
            s.lookup_failures
        )?;
    }
    writeln!(stdout, "  wrote {} and {}", s.output.display(), s.output.with_extension("png").display())
}

/// One EXR with every layer of the frame (`R,G,B` final, `noisy`, `direct`, `indirect`,
/// `filtered` = filtered indirect, `indirect_map`/`filtered_map` = the guide rays' map
/// before/after the filter, guide `albedo`, `normal`, `position`, `depth`, then `extra`)
/// and the PNG of the final image beside it; header text `attributes`.
pub fn write_frame(
    exr_path: &Path,
    frame: &Frame,
    extra: &[(&str, &[&str], &filtrace_core::Image)],
    attributes: &[(&str, String)],
    tonemap: &filtrace_io::TonemapParams,
) -> anyhow::Result<()> {
    if let Some(dir) = exr_path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create folder {}", dir.display()))?;
    }
    const RGB: &[&str] = &["R", "G", "B"];
    const XYZ: &[&str] = &["X", "Y", "Z"];
    let im = &frame.images;
    let mut exr = filtrace_io::ExrImage::new(im.color.width(), im.color.height());
    let mut layers: Vec<(&str, &[&str], &filtrace_core::Image)> = vec![
        ("", RGB, &im.color),
        ("noisy", RGB, &im.noisy),
        ("direct", RGB, &im.direct),
        ("indirect", RGB, &im.indirect),
        ("filtered", RGB, &im.filtered_indirect),
        ("indirect_map", RGB, &im.indirect_map),
        ("filtered_map", RGB, &im.filtered_map),
        ("albedo", RGB, &im.guide.albedo),
        ("normal", XYZ, &im.guide.normal),
        ("position", XYZ, &im.guide.position),
        ("depth", &["Z"], &im.guide.depth),
    ];
    if im.filtered_direct.pixel_count() > 0 {
        layers.push(("filtered_direct", RGB, &im.filtered_direct));
    }
    layers.extend_from_slice(extra);
    for (name, channels, image) in layers {
        exr.insert(name, channels, image)?;
    }
    for (name, value) in attributes {
        exr.set_attribute(name, value)?;
    }
    filtrace_io::write_exr(exr_path, &exr)?;
    filtrace_io::write_png(exr_path.with_extension("png"), &im.color, tonemap)?;
    Ok(())
}

/// Adaptive sampling options of `filtrace render` (Bauszat et al. 2011, "Adaptive
/// sampling for geometry-aware reconstruction filters"; see docs/adaptive.md).
#[derive(clap::Args, Debug, Clone)]
pub struct AdaptiveArgs {
    /// Distribute the indirect-light samples by an importance map instead of uniformly.
    #[arg(long)]
    pub adaptive: bool,
    /// Indirect-light paths per pixel on average (the frame traces budget-spp x pixels of
    /// them from the guide rays' hits, apportioned by importance). Without --spp, the eye
    /// samples per pixel (guide ray + direct-light-only samples) are this number too.
    #[arg(long, default_value_t = 4, requires = "adaptive")]
    pub budget_spp: u32,
    /// Minimum samples of every pixel (the paper: 1 or 2).
    #[arg(long, default_value_t = 1, requires = "adaptive")]
    pub min_spp: u32,
    /// Importance window radius, 1..=10 (the paper's "4x4" window is 2).
    #[arg(long, default_value_t = 2, requires = "adaptive", value_parser = clap::value_parser!(u32).range(1..=10))]
    pub importance_radius: u32,
    /// Drop the rounding remainder as the paper does (total may fall short of the budget)
    /// instead of distributing it exactly.
    #[arg(long, requires = "adaptive")]
    pub paper_rounding: bool,
}

impl AdaptiveArgs {
    /// Eye samples per pixel: `--spp` when given; else, with `--adaptive`, the budget (so
    /// that `--budget-spp 4` is a 4-sample frame, not 4 paths under 64 eye samples), and
    /// [`DEFAULT_SPP`] without it.
    pub fn eye_spp(&self, spp: Option<u32>) -> u32 {
        match spp {
            Some(s) => s,
            None if self.adaptive => self.budget_spp.max(1),
            None => DEFAULT_SPP,
        }
    }

    /// The adaptive parameters these options select, or `None` without `--adaptive`.
    pub fn params(&self) -> Option<filtrace_adaptive::AdaptiveParams> {
        use filtrace_adaptive::{AdaptiveParams, ImportanceParams, Mode};
        self.adaptive.then(|| AdaptiveParams {
            importance: ImportanceParams::paper().with_radius(self.importance_radius as usize),
            budget_spp: self.budget_spp,
            min_spp: self.min_spp,
            mode: if self.paper_rounding { Mode::Paper } else { Mode::Exact },
        })
    }
}
