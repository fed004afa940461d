//! `filtrace bench pipeline`: frames per second of the filtered pipeline (Bauszat et al.
//! 2011) and milliseconds per stage, as a markdown table or one JSON object.
//!
//! Default: the Cornell box at 512x512, 1 spp (the guide ray), max depth 3 (direct light
//! and one indirect bounce), guided filter (paper preset), all cores; 3 warm-up frames,
//! then 20 timed frames of the same renderer (buffers kept between frames, as a viewer
//! would drive it). Per stage: median and mean.

use filtrace_pipeline::{FilterChoice, FrameTimings, PipelineSettings};
use serde::Serialize;

use super::render::{parse_resolution, Resolution};

#[derive(clap::Args)]
pub struct Args {
    /// Built-in scene name or scene file.
    #[arg(default_value = "cornell")]
    pub scene: String,
    #[arg(long, default_value = "512x512", value_parser = parse_resolution)]
    pub res: Resolution,
    /// Eye samples per pixel (the guide ray included).
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    /// Mitsuba convention: 3 = direct light + one indirect bounce.
    #[arg(long, default_value_t = 3, allow_negative_numbers = true)]
    pub max_depth: i32,
    /// Filters to time, comma-separated (none, atrous, guided, bilateral).
    #[arg(long, default_value = "guided", value_delimiter = ',')]
    pub filter: Vec<String>,
    /// Preset of the filter (applies to every filter listed; default: the paper's).
    #[arg(long)]
    pub filter_preset: Option<String>,
    #[arg(long, default_value_t = 1)]
    pub indirect_paths: u32,
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=10000))]
    pub frames: u32,
    #[arg(long, default_value_t = 3)]
    pub warmup: u32,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub threads: Option<u32>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct StageStats {
    stage: String,
    median_ms: f64,
    mean_ms: f64,
}

#[derive(Serialize)]
struct Row {
    filter: String,
    frames: u32,
    fps_median: f64,
    stages: Vec<StageStats>,
}

#[derive(Serialize)]
struct Report {
    scene: String,
    width: u32,
    height: u32,
    spp: u32,
    indirect_paths: u32,
    max_depth: i32,
    threads: usize,
    triangles: usize,
    rows: Vec<Row>,
}

fn stats(name: &str, mut v: Vec<f64>) -> StageStats {
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len().max(1) as f64;
    StageStats { stage: name.into(), median_ms: v[v.len() / 2], mean_ms: v.iter().sum::<f64>() / n }
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let threads = a
        .threads
        .map(|t| t as usize)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let scene = filtrace_scene::load_scene(&a.scene)
        .map_err(|e| anyhow::anyhow!("cannot load scene '{}': {e}", a.scene))?;
    let triangles = scene.triangle_count();
    let settings = PipelineSettings {
        spp: a.spp,
        indirect_paths: a.indirect_paths,
        ..PipelineSettings::interactive(a.res.width, a.res.height)
    };
    let mut rows = Vec::new();
    for f in &a.filter {
        let choice = FilterChoice { preset: a.filter_preset.clone(), ..FilterChoice::named(f) };
        let mut p = pool.install(|| {
            super::render_filtered::build_pipeline(scene.clone(), settings.clone(), a.max_depth, &choice)
        })?;
        let mut times: Vec<FrameTimings> = Vec::new();
        for i in 0..a.warmup + a.frames {
            let t =
                pool.install(|| p.render_frame().map(|fr| fr.timings)).map_err(|e| anyhow::anyhow!("{e}"))?;
            if i >= a.warmup {
                times.push(t);
            }
        }
        let col = |g: fn(&FrameTimings) -> f64| times.iter().map(g).collect::<Vec<_>>();
        let stages = vec![
            stats("guide", col(|t| t.guide_ms)),
            stats("filter", col(|t| t.filter_ms)),
            stats("samples", col(|t| t.samples_ms)),
            stats("lookup", col(|t| t.lookup_ms)),
            stats("total", col(|t| t.total_ms)),
        ];
        let fps_median = 1000.0 / stages[4].median_ms.max(1e-9);
        rows.push(Row { filter: p.filter_mut().label(), frames: a.frames, fps_median, stages });
    }
    let report = Report {
        scene: a.scene.clone(),
        width: a.res.width,
        height: a.res.height,
        spp: a.spp,
        indirect_paths: a.indirect_paths,
        max_depth: a.max_depth,
        threads,
        triangles,
        rows,
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    println!(
        "filtered pipeline: {} {}x{}, {} spp, {} indirect path(s), max depth {}, {} threads, {} triangles, median of {} frames",
        report.scene, report.width, report.height, report.spp, report.indirect_paths, report.max_depth, threads, triangles, a.frames
    );
    println!();
    println!("| filter | guide ms | filter ms | samples ms | lookup ms | frame ms | fps |");
    println!("|---|---:|---:|---:|---:|---:|---:|");
    for r in &report.rows {
        let m: Vec<f64> = r.stages.iter().map(|s| s.median_ms).collect();
        println!(
            "| {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} |",
            r.filter, m[0], m[1], m[2], m[3], m[4], r.fps_median
        );
    }
    Ok(())
}
