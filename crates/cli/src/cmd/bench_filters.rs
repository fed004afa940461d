//! `filtrace bench filters`: reconstruction filter timings on this machine, in the shape of
//! Dammertz et al. 2010 Table 2 (À-Trous: resolution x iterations x number of edge-stopping
//! weights) and Bauszat et al. 2011 Table 2 (cross-bilateral radius 16/24/32, À-Trous 4/5/6
//! iterations, guided filter with 1/3/4 guidance channels). Prints markdown tables, or JSON.
//!
//! Inputs are synthetic but shaped like a render (noisy colour, a box-like G-buffer with
//! normal, position and depth edges): the filters' cost does not depend on the content.
//! Each configuration is run `--repeats` times after one warm-up; the median is reported.

use std::io::Write;
use std::time::Instant;

use filtrace_core::Image;
use filtrace_denoise::bench_input::synthetic_input;
use filtrace_denoise::{AtrousParams, BilateralParams, Filter, GBuffer, Guidance, GuidedParams};
use serde_json::{json, Value};

#[derive(clap::Args)]
pub struct Args {
    /// One resolution WxH for both tables (default: Dammertz's 512x512, 1024x1024,
    /// 1920x1080, and Bauszat's 1024x768).
    #[arg(long)]
    pub res: Option<String>,
    /// Runs per configuration (median reported).
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
    /// Skip the (slow, O(r^2)) cross-bilateral rows.
    #[arg(long)]
    pub no_bilateral: bool,
    /// Run only the Bauszat table rows whose filter name (a-trous, cross-bilateral, guided)
    /// contains this (e.g. `guided`), and skip the Dammertz table unless it is `a-trous`
    /// (for profiling one filter).
    #[arg(long)]
    pub only: Option<String>,
    /// Print one JSON object instead of tables.
    #[arg(long)]
    pub json: bool,
}

fn parse_res(s: &str) -> anyhow::Result<(usize, usize)> {
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(|| anyhow::anyhow!("--res must be WxH, got {s:?}"))?;
    let (w, h): (usize, usize) = (w.trim().parse()?, h.trim().parse()?);
    anyhow::ensure!(w > 0 && h > 0 && w * h <= 64 << 20, "--res {s}: size out of range");
    Ok((w, h))
}

/// CPU time of all threads of this process in nanoseconds (Linux `/proc/self/task/*/schedstat`),
/// `None` elsewhere.
fn process_cpu_ns() -> Option<u64> {
    let mut total = 0u64;
    for task in std::fs::read_dir("/proc/self/task").ok()? {
        let path = task.ok()?.path().join("schedstat");
        let s = std::fs::read_to_string(path).ok()?;
        total += s.split_whitespace().next()?.parse::<u64>().ok()?;
    }
    Some(total)
}

/// Median wall-clock ms and median CPU ms (all threads) of `repeats` runs of `filter`, after
/// one warm-up run. On a shared machine the wall time includes waiting for a core; CPU time
/// divided by the thread count is what the wall time would be with the cores to ourselves.
fn time_ms(filter: &Filter, color: &Image, g: &GBuffer, repeats: usize) -> anyhow::Result<(f64, f64)> {
    let mut out = Image::new(color.width(), color.height(), 3);
    filter.apply_into(color, g, &mut out)?;
    let mut wall = Vec::with_capacity(repeats);
    let mut cpu = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        let c0 = process_cpu_ns();
        let s = Instant::now();
        filter.apply_into(color, g, &mut out)?;
        wall.push(s.elapsed().as_secs_f64() * 1e3);
        cpu.push(match (c0, process_cpu_ns()) {
            (Some(a), Some(b)) => (b.saturating_sub(a)) as f64 * 1e-6,
            _ => f64::NAN,
        });
    }
    wall.sort_by(f64::total_cmp);
    cpu.sort_by(f64::total_cmp);
    Ok((wall[repeats / 2], cpu[repeats / 2]))
}

/// The À-Trous weight subsets of Dammertz's Figure 4 / Table 2: 0 = pure, 1 = rt,
/// 2 = rt + n, 3 = rt + n + x.
fn atrous_with_weights(iterations: u32, weights: usize) -> AtrousParams {
    let p = AtrousParams { iterations, ..AtrousParams::paper() };
    match weights {
        0 => AtrousParams { iterations, ..AtrousParams::pure() },
        1 => AtrousParams { sigma_normal: None, sigma_position: None, ..p },
        2 => AtrousParams { sigma_position: None, ..p },
        _ => p,
    }
}

/// The filter names `--only` selects from.
const FILTER_NAMES: [&str; 3] = ["a-trous", "cross-bilateral", "guided"];

/// `--only` must select at least one row: an unknown name is an error, not empty tables.
fn check_only(only: &str, no_bilateral: bool) -> anyhow::Result<()> {
    let selected: Vec<&str> = FILTER_NAMES
        .into_iter()
        .filter(|n| n.contains(only) && !(no_bilateral && *n == "cross-bilateral"))
        .collect();
    anyhow::ensure!(
        !selected.is_empty(),
        "--only {only:?} selects no filter{}: the filters are {}",
        if no_bilateral { " (with --no-bilateral)" } else { "" },
        FILTER_NAMES.join(", ")
    );
    Ok(())
}

/// The measured rows of both tables, and what they were measured at.
struct Tables {
    threads: usize,
    /// Dammertz's resolutions (empty when `--only` skips the table).
    dammertz_res: Vec<(usize, usize)>,
    dammertz: Vec<Value>,
    bauszat_res: (usize, usize),
    bauszat: Vec<Value>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(args.repeats > 0, "--repeats must be at least 1");
    check_only(args.only.as_deref().unwrap_or(""), args.no_bilateral)?;
    let fixed = args.res.as_deref().map(parse_res).transpose()?;
    let only = args.only.clone().unwrap_or_default();
    let dammertz_res = match fixed {
        _ if !"a-trous".contains(only.as_str()) => Vec::new(),
        Some(r) => vec![r],
        None => vec![(512, 512), (1024, 1024), (1920, 1080)],
    };
    let bauszat_res = fixed.unwrap_or((1024, 768));
    let tables = Tables {
        threads: rayon::current_num_threads(),
        dammertz: dammertz_rows(&dammertz_res, args.repeats)?,
        dammertz_res,
        bauszat: bauszat_rows(bauszat_res, &args, &only)?,
        bauszat_res,
    };
    let mut out = super::output::stdout();
    if args.json {
        write_json(&mut out, &tables, args.repeats)?;
    } else {
        write_dammertz_table(&mut out, &tables)?;
        write_bauszat_table(&mut out, &tables)?;
    }
    Ok(out.flush()?)
}

/// Dammertz Table 2: resolution x iterations x weights.
fn dammertz_rows(resolutions: &[(usize, usize)], repeats: usize) -> anyhow::Result<Vec<Value>> {
    let mut rows = Vec::new();
    for &(w, h) in resolutions {
        let (color, g) = synthetic_input(w, h);
        for weights in 0..=3 {
            for iterations in [1, 5, 10] {
                let f = Filter::Atrous(atrous_with_weights(iterations, weights));
                let (ms, cpu_ms) = time_ms(&f, &color, &g, repeats)?;
                rows.push(json!({"width": w, "height": h, "iterations": iterations, "weights": weights,
                    "ms": ms, "cpu_ms": cpu_ms}));
            }
        }
    }
    Ok(rows)
}

/// Bauszat Table 2 at one resolution: the rows of the filters `only` selects.
fn bauszat_rows((w, h): (usize, usize), args: &Args, only: &str) -> anyhow::Result<Vec<Value>> {
    let (color, g) = synthetic_input(w, h);
    let mut rows = Vec::new();
    let mut row = |filter: &str, setting: String, f: Filter, repeats: usize| -> anyhow::Result<()> {
        let (ms, cpu_ms) = time_ms(&f, &color, &g, repeats)?;
        rows.push(json!({"filter": filter, "setting": setting, "ms": ms, "cpu_ms": cpu_ms}));
        Ok(())
    };
    if !args.no_bilateral && "cross-bilateral".contains(only) {
        for radius in [16, 24, 32] {
            let f = Filter::Bilateral(BilateralParams {
                radius,
                sigma_spatial: radius as f32 / 2.0,
                ..BilateralParams::reference()
            });
            row("cross-bilateral", format!("radius {radius}"), f, args.repeats.min(2))?;
        }
    }
    for iterations in [4, 5, 6].into_iter().filter(|_| "a-trous".contains(only)) {
        let f = Filter::Atrous(AtrousParams { iterations, ..AtrousParams::paper() });
        row("a-trous", format!("{iterations} iterations"), f, args.repeats)?;
    }
    let guided_rows = [(Guidance::GreyNormal, 1), (Guidance::Normal, 3), (Guidance::NormalDepth, 4)];
    for (guidance, dims) in guided_rows.into_iter().filter(|_| "guided".contains(only)) {
        for radius in [24, 32] {
            let f = Filter::Guided(GuidedParams { radius, guidance, ..GuidedParams::paper() });
            row("guided", format!("{dims} dimension, radius {radius}"), f, args.repeats)?;
        }
    }
    Ok(rows)
}

fn write_json(out: &mut impl Write, t: &Tables, repeats: usize) -> anyhow::Result<()> {
    let (w, h) = t.bauszat_res;
    let report = json!({
        "threads": t.threads,
        "repeats": repeats,
        "statistic": "median over repeats; ms = wall clock, cpu_ms = CPU time of all threads",
        "dammertz2010_table2": t.dammertz,
        "bauszat2011_table2": {"width": w, "height": h, "rows": t.bauszat},
    });
    writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?;
    Ok(())
}

/// Dammertz's table: a row per weight subset, a column per resolution and iteration count.
fn write_dammertz_table(out: &mut impl Write, t: &Tables) -> anyhow::Result<()> {
    let threads = t.threads;
    writeln!(out, "## À-Trous filter time in ms (Dammertz et al. 2010, Table 2 shape), {threads} threads\n")?;
    writeln!(out, "Each cell: median wall-clock ms / median CPU ms divided by {threads} threads.\n")?;
    let mut header = String::from("| # W |");
    let mut rule = String::from("|---:|");
    for &(w, h) in &t.dammertz_res {
        for it in [1, 5, 10] {
            header += &format!(" {w}x{h} {it} it |");
            rule += "---:|";
        }
    }
    writeln!(out, "{header}\n{rule}")?;
    for weights in 0..=3 {
        let mut line = format!("| {weights} |");
        for &(w, h) in &t.dammertz_res {
            for it in [1, 5, 10] {
                let row = t.dammertz.iter().find(|r| {
                    r["width"] == w && r["height"] == h && r["iterations"] == it && r["weights"] == weights
                });
                let get = |k: &str| row.and_then(|r| r[k].as_f64()).unwrap_or(f64::NAN);
                line += &format!(" {:.1} / {:.1} |", get("ms"), get("cpu_ms") / threads as f64);
            }
        }
        writeln!(out, "{line}")?;
    }
    Ok(())
}

fn write_bauszat_table(out: &mut impl Write, t: &Tables) -> anyhow::Result<()> {
    let ((w, h), threads) = (t.bauszat_res, t.threads);
    writeln!(out, "\n## Filter execution time in ms at {w}x{h} (Bauszat et al. 2011, Table 2 shape)\n")?;
    writeln!(out, "| filter | setting | wall ms | CPU ms / {threads} |\n|---|---|---:|---:|")?;
    for r in &t.bauszat {
        writeln!(
            out,
            "| {} | {} | {:.1} | {:.1} |",
            r["filter"].as_str().unwrap_or(""),
            r["setting"].as_str().unwrap_or(""),
            r["ms"].as_f64().unwrap_or(f64::NAN),
            r["cpu_ms"].as_f64().unwrap_or(f64::NAN) / threads as f64
        )?;
    }
    Ok(())
}
