//! `filtrace bench vpl [SCENE]`: milliseconds per stage of one VPL frame (VPL generation,
//! cache placement + evaluation, shading, optimisation) for each sampler, by default the
//! issue's setting: 512x512, 1 spp, 2048 VPLs, 1024 cache points, all cores.

use super::render_args::BenchScene;
use super::render_vpl::{check_frame_memory, MAX_COUNT};
use filtrace_render::Renderer;
use filtrace_vpl::cache::{CacheParams, SamplerKind, DEFAULT_FAINT_SHARE};
use filtrace_vpl::vpls::{render_vpl_frame, StageTimes, VplParams, VplSettings};
use serde::Serialize;
use std::io::Write;
use std::sync::atomic::AtomicBool;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub target: BenchScene,
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    #[arg(long, default_value_t = 2048, value_parser = clap::value_parser!(u32).range(1..=MAX_COUNT))]
    pub vpls: u32,
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u32).range(1..=MAX_COUNT))]
    pub cache_points: u32,
    /// See `render --cache-faint-share`.
    #[arg(long, default_value_t = DEFAULT_FAINT_SHARE, allow_negative_numbers = true, value_parser = super::render_vpl::parse_faint_share)]
    pub cache_faint_share: f32,
    /// Frames per sampler; each stage reports its median over them (the first frame
    /// also pays for cold caches and page faults).
    #[arg(long, default_value_t = 1)]
    pub repeat: usize,
    /// Comma-separated samplers (default: all five).
    #[arg(long, value_delimiter = ',')]
    pub samplers: Vec<String>,
    /// Print one JSON object instead of a markdown table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct Row {
    sampler: String,
    vpl_generation_ms: f64,
    cache_ms: f64,
    shading_ms: f64,
    optimisation_ms: f64,
    total_ms: f64,
    /// The cache's visibility rays, and the faint VPLs taken as visible without one.
    cache_rays: u64,
    cache_faint_vpls: u64,
    mean_rgb: [f64; 3],
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let settings = args.target.res.settings(args.spp, 8, 0)?;
    let samplers: Vec<SamplerKind> = if args.samplers.is_empty() {
        SamplerKind::ALL.to_vec()
    } else {
        args.samplers
            .iter()
            .map(|s| s.parse())
            .collect::<Result<_, _>>()
            .map_err(|e: String| anyhow::anyhow!(e))?
    };
    let frame_settings = |sampler| VplSettings {
        vpls: VplParams::with_count(args.vpls as usize),
        sampler,
        cache: CacheParams {
            cache_points: args.cache_points as usize,
            faint_share: args.cache_faint_share,
            ..CacheParams::default()
        },
        ground_truth: false,
    };
    // Before the scene is loaded: a frame too large for memory is refused, not swapped.
    for &sampler in &samplers {
        let (threads, max_pass) = (rayon::current_num_threads(), args.spp);
        check_frame_memory(settings.width, settings.height, &frame_settings(sampler), threads, max_pass)?;
    }
    let scene = filtrace_scene::load_scene(&args.target.scene).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut renderer = Renderer::new(scene, settings).map_err(|e| anyhow::anyhow!("{e}"))?;
    let cancel = AtomicBool::new(false);
    let mut rows = Vec::new();
    for sampler in samplers {
        let vs = frame_settings(sampler);
        let mut frames = Vec::new();
        for _ in 0..args.repeat.max(1) {
            let frame = render_vpl_frame(&mut renderer, &vs, args.spp, &cancel)
                .map_err(|e| anyhow::anyhow!(e))?
                .ok_or_else(|| anyhow::anyhow!("cancelled"))?;
            frames.push(frame);
        }
        let t = median_times(frames.iter().map(|f| f.times).collect());
        let mean = frames[0].film.aovs().color.mean();
        rows.push(Row {
            sampler: sampler.name().into(),
            vpl_generation_ms: t.vpl_generation_ms,
            cache_ms: t.cache_ms,
            shading_ms: t.shading_ms,
            optimisation_ms: t.optimisation_ms,
            total_ms: t.vpl_generation_ms + t.cache_ms + t.shading_ms + t.optimisation_ms,
            cache_rays: frames[0].cache_rays.traced,
            cache_faint_vpls: frames[0].cache_rays.faint,
            mean_rgb: [mean[0], mean[1], mean[2]],
        });
    }
    let mut o = super::output::stdout();
    if args.json {
        writeln!(
            o,
            "{}",
            serde_json::json!({ "scene": args.target.scene, "res": args.target.res.to_string(), "spp": args.spp, "vpls": args.vpls, "cache_points": args.cache_points, "cache_faint_share": args.cache_faint_share, "repeat": args.repeat.max(1), "threads": rayon::current_num_threads(), "rows": rows })
        )?;
        return Ok(());
    }
    writeln!(
        o,
        "VPL frame, {} at {}, {} spp, {} VPLs, {} cache points (faint share {}), {} threads, median of {} (ms)\n",
        args.target.scene,
        args.target.res,
        args.spp,
        args.vpls,
        args.cache_points,
        args.cache_faint_share,
        rayon::current_num_threads(),
        args.repeat.max(1)
    )?;
    writeln!(
        o,
        "| sampler | VPLs | cache | shading | optimisation | total | cache rays (faint) | mean G |\n\
         |---|---|---|---|---|---|---|---|"
    )?;
    for r in &rows {
        writeln!(
            o,
            "| {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {} ({}) | {:.4} |",
            r.sampler,
            r.vpl_generation_ms,
            r.cache_ms,
            r.shading_ms,
            r.optimisation_ms,
            r.total_ms,
            r.cache_rays,
            r.cache_faint_vpls,
            r.mean_rgb[1]
        )?;
    }
    Ok(())
}

/// Per stage, the median over the frames (the upper one for an even count).
fn median_times(times: Vec<StageTimes>) -> StageTimes {
    let median = |f: fn(&StageTimes) -> f64| {
        let mut v: Vec<f64> = times.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    StageTimes {
        vpl_generation_ms: median(|t| t.vpl_generation_ms),
        cache_ms: median(|t| t.cache_ms),
        shading_ms: median(|t| t.shading_ms),
        optimisation_ms: median(|t| t.optimisation_ms),
    }
}
