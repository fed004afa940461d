//! `filtrace render --integrator vpl`: the many-light renderer (filtrace-vpl, the thesis's
//! importance caching). Writes the usual EXR (colour and the G-buffer AOVs, so the filters
//! can run on it) plus a `cache_distance` layer (d-distance of each pixel's surface to the
//! closest cache point, the thesis's Figure 27) and the PNG; prints a summary with the
//! milliseconds per stage.

use super::render_args::CommonArgs;
use super::render_output::{render_attributes, write_outputs};
use super::render_session::{CtrlC, Interrupted};
use anyhow::Context;
use filtrace_render::Renderer;
use filtrace_vpl::cache::{CacheParams, SamplerKind};
use filtrace_vpl::vpls::{render_vpl_frame, GeometryBound, VplParams, VplSettings};
use std::io::Write;

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

    /// The integrator's settings; `radius` is the scene's bounding radius.
    pub fn settings(&self, seed: u64, radius: f32) -> anyhow::Result<VplSettings> {
        let mut vpls = VplParams { seed, ..VplParams::with_count(self.vpls as usize) };
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

/// Renders `c.scene` with the VPL integrator and writes the outputs.
pub fn run(c: &CommonArgs, v: &VplArgs) -> anyhow::Result<()> {
    let settings = c.settings()?;
    let ctrlc = CtrlC::install();
    let scene = c.load_scene().with_context(|| format!("cannot load scene '{}'", c.scene))?;
    let out = c.prepare_output()?;
    let pool = c.thread_pool()?;
    let renderer =
        pool.install(|| Renderer::new(scene, settings.clone())).map_err(|e| anyhow::anyhow!("{e}"))?;
    let vs = v.settings(settings.seed, renderer.lights().scene_radius())?;
    ctrlc.arm();
    let frame = pool
        .install(|| render_vpl_frame(&renderer, &vs, settings.spp, ctrlc.flag()))
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let Some(frame) = frame else {
        eprintln!("cancelled: nothing written ({} left as it was)", out.display());
        return Err(Interrupted.into());
    };
    let aovs = frame.film.try_aovs()?;
    let counts = frame.film.sample_counts();
    let attributes = render_attributes(settings.spp, frame.film.min_samples(), false);
    let extra: [(&str, &[&str], &filtrace_core::Image); 2] =
        [("samples", &["Y"], &counts), ("cache_distance", &["Y"], &frame.cache_distance)];
    let written = write_outputs(&out, &aovs, &extra, &attributes, None, &c.tonemap())?;
    let mean = aovs.color.mean();
    let t = frame.times;
    let sampler = if vs.ground_truth { "exhaustive" } else { vs.sampler.name() };
    let summary = serde_json::json!({
        "scene": c.scene, "res": c.res.to_string(), "spp": settings.spp, "seed": settings.seed,
        "integrator": "vpl", "sampler": sampler, "vpls": frame.vpls.len(),
        "light_paths": frame.vpls.light_paths, "cache_records": frame.cache_records,
        "vpl_generation_ms": t.vpl_generation_ms, "cache_ms": t.cache_ms,
        "shading_ms": t.shading_ms, "optimisation_ms": t.optimisation_ms,
        "mean_rgb": [mean[0], mean[1], mean[2]], "output": written.exr, "png": written.png,
        "nonfinite_samples": frame.film.dropped_samples(),
    });
    let mut o = super::output::stdout();
    if c.json {
        writeln!(o, "{summary}")?;
    } else {
        writeln!(
            o,
            "rendered {} with {} VPLs ({sampler}, {} cache records) at {} spp: VPLs {:.1} ms, cache {:.1} ms, shading {:.1} ms, optimisation {:.1} ms\nwrote {}",
            c.scene, frame.vpls.len(), frame.cache_records, settings.spp,
            t.vpl_generation_ms, t.cache_ms, t.shading_ms, t.optimisation_ms, written.exr.display()
        )?;
    }
    Ok(())
}
