//! Uniform vs adaptive sampling of the indirect light at the same total number of paths,
//! filtered with each reconstruction filter (Bauszat et al. 2011, §5 / Figs. 6-8).
//!
//! ```text
//! cargo run -p filtrace-adaptive --example adaptive_experiment -- \
//!     [--scenes grass,colonnade,cornell] [--width 192] [--height 144] [--budget 4] \
//!     [--min 1,2] [--seeds 3] [--ref-paths 256] [--max-depth 4] [--radius 2] \
//!     [--filters atrous,guided,bilateral] [--out out/adaptive]
//! ```
//!
//! Per scene: a reference indirect map (the guide rays' demodulated indirect light with
//! `ref-paths` paths, another seed); then per seed one uniform frame (`budget` paths per
//! pixel) and one adaptive frame per `min` (the same total, apportioned by importance),
//! traced unfiltered; each noisy map is filtered by every filter with the pipeline's own
//! filter slot and compared with the reference. Reported: MSE of the unfiltered and of
//! each filtered map, the mean of the worst 0.1% squared errors (outliers), and the MSE
//! split by importance (top 20% of pixels vs the rest). Images (PNG) and `results.json`
//! go to `--out`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use filtrace_adaptive::{AdaptiveParams, ImportanceParams, Mode, SampleCounts};
use filtrace_core::Image;
use filtrace_pipeline::{
    adaptive as pa, FilterChoice, FilteredRenderer, IndirectFilter, NoFilter, PipelineSettings, RenderSource,
};
use filtrace_render::{RenderSettings, Renderer};

struct Args {
    scenes: Vec<String>,
    width: u32,
    height: u32,
    budget: u32,
    mins: Vec<u32>,
    seeds: u64,
    ref_paths: u32,
    max_depth: i32,
    radius: usize,
    filters: Vec<String>,
    out: PathBuf,
}

impl Args {
    /// Width and height of the frames in pixels.
    fn size(&self) -> (usize, usize) {
        (self.width as usize, self.height as usize)
    }
}

fn parse() -> Result<Args, String> {
    let mut a = Args {
        scenes: vec!["grass".into(), "colonnade".into(), "cornell".into()],
        width: 192,
        height: 144,
        budget: 4,
        mins: vec![1, 2],
        seeds: 3,
        ref_paths: 256,
        max_depth: 4,
        radius: 2,
        filters: vec!["atrous".into(), "guided".into(), "bilateral".into()],
        out: "out/adaptive".into(),
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let v = it.next().ok_or_else(|| format!("{k} needs a value"))?;
        let num = |v: &str| v.parse::<u64>().map_err(|e| format!("{k} {v}: {e}"));
        let list = |v: &str| v.split(',').map(str::to_string).collect::<Vec<_>>();
        match k.as_str() {
            "--scenes" => a.scenes = list(&v),
            "--width" => a.width = num(&v)? as u32,
            "--height" => a.height = num(&v)? as u32,
            "--budget" => a.budget = num(&v)? as u32,
            "--min" => {
                a.mins = list(&v).iter().map(|s| num(s).map(|n| n as u32)).collect::<Result<_, _>>()?
            }
            "--seeds" => a.seeds = num(&v)?,
            "--ref-paths" => a.ref_paths = num(&v)? as u32,
            "--max-depth" => a.max_depth = num(&v)? as i32,
            "--radius" => a.radius = num(&v)? as usize,
            "--filters" => a.filters = list(&v),
            "--out" => a.out = v.into(),
            _ => return Err(format!("unknown option {k}")),
        }
    }
    Ok(a)
}

/// Squared error per pixel (mean over the 3 channels).
fn sq_error(img: &Image, reference: &Image) -> Vec<f64> {
    img.data()
        .chunks_exact(3)
        .zip(reference.data().chunks_exact(3))
        .map(|(a, b)| a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum::<f64>() / 3.0)
        .collect()
}

#[derive(serde::Serialize, Clone, Default)]
struct Errors {
    mse: f64,
    /// Mean of the worst 0.1% per-pixel squared errors.
    outliers: f64,
    /// MSE over the 20% most important pixels, and over the rest.
    mse_important: f64,
    mse_rest: f64,
}

fn errors(img: &Image, reference: &Image, important: &[bool]) -> Errors {
    let e = sq_error(img, reference);
    let mse = e.iter().sum::<f64>() / e.len() as f64;
    let mut sorted = e.clone();
    sorted.sort_by(|a, b| b.total_cmp(a));
    let k = (e.len() / 1000).max(1);
    let outliers = sorted[..k].iter().sum::<f64>() / k as f64;
    let mean_where = |want: bool| {
        let (s, n) = e
            .iter()
            .zip(important)
            .filter(|(_, &i)| i == want)
            .fold((0.0, 0), |(s, n), (v, _)| (s + v, n + 1));
        s / n.max(1) as f64
    };
    Errors { mse, outliers, mse_important: mean_where(true), mse_rest: mean_where(false) }
}

/// A scalar map as a black-red-yellow-white heat image (linear RGB), `v / scale` clamped.
fn heat(values: &[f64], w: usize, h: usize, scale: f64) -> Image {
    let mut img = Image::new(w, h, 3);
    for (px, v) in img.data_mut().chunks_exact_mut(3).zip(values) {
        let t = (v / scale).clamp(0.0, 1.0) as f32 * 3.0;
        px.copy_from_slice(&[t.min(1.0), (t - 1.0).clamp(0.0, 1.0), (t - 2.0).clamp(0.0, 1.0)]);
    }
    img
}

/// Crop `(x0, y0, size)` of `img`, magnified `zoom` times (nearest), for close-ups.
fn crop(img: &Image, x0: usize, y0: usize, size: usize, zoom: usize) -> Image {
    let c = img.channels();
    let mut out = Image::new(size * zoom, size * zoom, c);
    for y in 0..size * zoom {
        for x in 0..size * zoom {
            let src = img.pixel(x0 + x / zoom, y0 + y / zoom).to_vec();
            out.pixel_mut(x, y).copy_from_slice(&src);
        }
    }
    out
}

fn save(dir: &Path, name: &str, img: &Image) {
    if let Err(e) = filtrace_io::write_image(dir.join(name), img) {
        eprintln!("warning: cannot write {name}: {e}");
    }
}

fn pipeline(scene: &str, a: &Args, seed: u64) -> Result<FilteredRenderer<RenderSource, NoFilter>, String> {
    let scene = filtrace_scene::load_scene(scene).map_err(|e| e.to_string())?;
    let rs = RenderSettings { width: a.width, height: a.height, spp: 1, max_depth: a.max_depth, seed };
    let r = Renderer::new(scene, rs).map_err(|e| e.to_string())?;
    let st = PipelineSettings { seed, ..PipelineSettings::interactive(a.width, a.height) };
    FilteredRenderer::new(RenderSource::new(r), NoFilter, st).map_err(|e| e.to_string())
}

fn main() {
    let a = match parse() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(2);
        }
    };
    if let Err(e) = run(&a) {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}

/// method -> filter -> per-seed errors.
type Results = BTreeMap<String, BTreeMap<String, Vec<Errors>>>;

/// The seed-0 filtered images, by (method, filter).
type Kept = BTreeMap<(String, String), Image>;

fn run(a: &Args) -> Result<(), String> {
    let mut all = BTreeMap::new();
    let mut summary: BTreeMap<String, f64> = BTreeMap::new();
    for scene in &a.scenes {
        let (ref_noise, res) = run_scene(a, scene)?;
        summary.insert(scene.clone(), ref_noise);
        all.insert(scene.clone(), res);
    }
    let json =
        serde_json::to_string_pretty(&serde_json::json!({ "errors": all, "reference_noise_floor": summary }))
            .map_err(|e| e.to_string())?;
    std::fs::write(a.out.join("results.json"), json).map_err(|e| e.to_string())?;
    Ok(())
}

/// One scene: reference, plans, the traced and filtered frames, their images and tables;
/// returns the reference's noise floor and the errors.
fn run_scene(a: &Args, scene: &str) -> Result<(f64, Results), String> {
    let (w, h) = a.size();
    let dir = a.out.join(scene);
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let mut p = pipeline(scene, a, 0)?;
    let scale = p.source().scene_scale();
    let (reference, ref_noise) = reference_map(a, scene, &mut p, &dir)?;
    let plans = adaptive_plans(a, scene, &p, &dir)?;
    let important = most_important(&plans[0].1.importance);
    let mut filters = Vec::new();
    for f in &a.filters {
        filters.push((f.clone(), FilterChoice::named(f).build(Some(scale))?));
    }
    let mut methods: Vec<(String, SampleCounts)> =
        vec![(format!("uniform{}", a.budget), SampleCounts::uniform(w, h, a.budget))];
    for (min, plan) in &plans {
        methods.push((format!("adaptive_min{min}"), plan.counts.clone()));
    }
    let truth = Truth { reference: &reference, important: &important };
    let (res, kept) = trace_and_filter(a, scene, &mut p, &dir, &methods, &mut filters, &truth)?;
    let method_names: Vec<String> = methods.iter().map(|(m, _)| m.clone()).collect();
    let filter_names: Vec<String> = filters.iter().map(|(f, _)| f.clone()).collect();
    save_error_maps(a, &dir, &kept, &method_names, &filter_names, &reference);
    if let Some(f0) = filter_names.first() {
        save_closeups(a, scene, &dir, &kept, &kept[&(method_names[0].clone(), f0.clone())], &reference);
    }
    print_tables(a, scene, &res, &method_names, ref_noise);
    Ok((ref_noise, res))
}

/// Reference: many paths per guide ray, unrelated seeds. Two independent halves: their
/// mean is the reference, and E|R1 - R2|² / 4 is the variance of that mean, the noise floor
/// every MSE contains. Returns the reference and that floor.
fn reference_map(
    a: &Args,
    scene: &str,
    p: &mut FilteredRenderer<RenderSource, NoFilter>,
    dir: &Path,
) -> Result<(Image, f64), String> {
    let (w, h) = a.size();
    let n = w * h;
    let t = Instant::now();
    let mut halves = Vec::new();
    for seed in [0x0005_eed0_f2ef_u64, 0x0005_eed0_f2f0] {
        let mut st = p.settings().clone();
        st.seed = seed;
        p.set_settings(st).map_err(|e| e.to_string())?;
        let counts = vec![a.ref_paths.div_ceil(2); n];
        let f = p.render_frame_with_counts(Some(&counts)).map_err(|e| e.to_string())?;
        halves.push(f.images.indirect_map.clone());
    }
    let mut reference = halves[0].clone();
    for (r, b) in reference.data_mut().iter_mut().zip(halves[1].data()) {
        *r = 0.5 * (*r + b);
    }
    let ref_noise = sq_error(&halves[0], &halves[1]).iter().sum::<f64>() / n as f64 / 4.0;
    eprintln!(
        "{scene}: reference {} paths/px in {:.1} s, noise floor (MSE) {ref_noise:.3e}",
        a.ref_paths,
        t.elapsed().as_secs_f64()
    );
    save(dir, "reference.png", &reference);
    Ok((reference, ref_noise))
}

/// Adaptive plans, one per `--min` (the guide rays go through pixel centres, so the plans
/// do not depend on the seed); saves the importance and the count maps.
fn adaptive_plans(
    a: &Args,
    scene: &str,
    p: &FilteredRenderer<RenderSource, NoFilter>,
    dir: &Path,
) -> Result<Vec<(u32, pa::AdaptivePlan)>, String> {
    let (w, h) = a.size();
    let mut plans = Vec::new();
    for &min in &a.mins {
        let params = AdaptiveParams {
            importance: ImportanceParams::paper().with_radius(a.radius),
            budget_spp: a.budget,
            min_spp: min,
            mode: Mode::Exact,
        };
        let plan = pa::plan(p.source(), p.settings(), &params).map_err(|e| e.to_string())?;
        assert_eq!(plan.counts.total(), a.budget as u64 * (w * h) as u64);
        eprintln!(
            "{scene}: min {min}: counts {}..{}, plan {:.1} ms (G-buffer pre-pass {:.1} ms)",
            plan.counts.min(),
            plan.counts.max(),
            plan.plan_ms,
            plan.prepass_ms
        );
        save(dir, &format!("importance_r{}.png", a.radius), &plan.importance);
        let cmax = plan.counts.max().max(1) as f64;
        let cvals: Vec<f64> = plan.counts.counts().iter().map(|&c| c as f64).collect();
        save(dir, &format!("counts_min{min}.png"), &heat(&cvals, w, h, cmax));
        plans.push((min, plan));
    }
    Ok(plans)
}

/// "Important" pixels: the top 20% by importance (ties included).
fn most_important(importance: &Image) -> Vec<bool> {
    let imp = importance.data();
    let mut sorted: Vec<f32> = imp.to_vec();
    sorted.sort_by(|x, y| y.total_cmp(x));
    let cut = sorted[imp.len() / 5];
    imp.iter().map(|&v| v > cut).collect()
}

/// What every frame is compared with: the reference and the important pixels.
struct Truth<'a> {
    reference: &'a Image,
    important: &'a [bool],
}

/// Per seed and method: traces a frame with the method's counts and filters it with every
/// filter; returns the errors and the seed-0 filtered images (all images of seed 0 saved).
fn trace_and_filter(
    a: &Args,
    scene: &str,
    p: &mut FilteredRenderer<RenderSource, NoFilter>,
    dir: &Path,
    methods: &[(String, SampleCounts)],
    filters: &mut [(String, Box<dyn IndirectFilter>)],
    truth: &Truth,
) -> Result<(Results, Kept), String> {
    let (w, h) = a.size();
    let mut res = Results::new();
    let mut kept = Kept::new();
    for seed in 0..a.seeds {
        let mut st = p.settings().clone();
        st.seed = seed + 1;
        p.set_settings(st).map_err(|e| e.to_string())?;
        for (name, counts) in methods {
            let t = Instant::now();
            let frame = p.render_frame_with_counts(Some(counts.counts())).map_err(|e| e.to_string())?.clone();
            let noisy = &frame.images.indirect_map;
            let trace_s = t.elapsed().as_secs_f64();
            let errors_of = |img: &Image| errors(img, truth.reference, truth.important);
            res.entry(name.clone()).or_default().entry("none".into()).or_default().push(errors_of(noisy));
            if seed == 0 {
                save(dir, &format!("{name}_none.png"), noisy);
            }
            for (fname, filter) in filters.iter_mut() {
                let mut out = Image::new(w, h, 3);
                filter.apply(noisy, &frame.images.guide, &mut out)?;
                let e = errors_of(&out);
                if seed == 0 {
                    save(dir, &format!("{name}_{fname}.png"), &out);
                    kept.insert((name.clone(), fname.clone()), out);
                }
                res.entry(name.clone()).or_default().entry(fname.clone()).or_default().push(e);
            }
            eprintln!("{scene}: seed {seed} {name}: traced in {trace_s:.1} s");
        }
    }
    Ok((res, kept))
}

/// Error maps, one scale per filter: white = 20x the uniform frame's MSE (`methods[0]`).
fn save_error_maps(
    a: &Args,
    dir: &Path,
    kept: &Kept,
    methods: &[String],
    filters: &[String],
    reference: &Image,
) {
    let (w, h) = a.size();
    let sq_error_of = |m: &String, f: &String| sq_error(&kept[&(m.clone(), f.clone())], reference);
    for f in filters {
        let uni_mse = sq_error_of(&methods[0], f).iter().sum::<f64>() / (w * h) as f64;
        for m in methods {
            let se = sq_error_of(m, f);
            save(dir, &format!("{m}_{f}_error.png"), &heat(&se, w, h, 20.0 * uni_mse.max(1e-12)));
        }
    }
}

/// Close-ups: the 32x32 window where `worst` (the uniform frame, filtered by the first
/// filter) errs most; the same window of the reference and every kept image, magnified 4x.
fn save_closeups(a: &Args, scene: &str, dir: &Path, kept: &Kept, worst: &Image, reference: &Image) {
    let (w, h) = a.size();
    let size = 32.min(w).min(h);
    let se = sq_error(worst, reference);
    let (mut best, mut at) = (-1.0, (0, 0));
    for y0 in (0..=h - size).step_by(4) {
        for x0 in (0..=w - size).step_by(4) {
            let s: f64 = (y0..y0 + size).map(|y| se[y * w + x0..y * w + x0 + size].iter().sum::<f64>()).sum();
            if s > best {
                (best, at) = (s, (x0, y0));
            }
        }
    }
    save(dir, "closeup_reference.png", &crop(reference, at.0, at.1, size, 4));
    for ((m, f), img) in kept {
        save(dir, &format!("closeup_{m}_{f}.png"), &crop(img, at.0, at.1, size, 4));
    }
    eprintln!("{scene}: close-up window at {at:?}, {size}x{size}");
}

fn mean_of(v: &[Errors], f: fn(&Errors) -> f64) -> f64 {
    v.iter().map(f).sum::<f64>() / v.len() as f64
}

/// The scene's two tables: errors per method and filter, and adaptive / uniform ratios.
/// `methods[0]` is the uniform method.
fn print_tables(a: &Args, scene: &str, res: &Results, methods: &[String], ref_noise: f64) {
    println!("\n{scene} ({}x{}, budget {} paths/px, {} seeds, reference {} paths/px, noise floor {ref_noise:.2e})\n", a.width, a.height, a.budget, a.seeds, a.ref_paths);
    println!("| method | filter | MSE (mean ± sd over seeds) | MSE − floor | worst 0.1% | MSE top-20% importance | MSE rest |");
    println!("|---|---|---:|---:|---:|---:|---:|");
    for (method, per_filter) in res {
        for (fname, v) in per_filter {
            let k = v.len() as f64;
            let m = mean_of(v, |e| e.mse);
            let sd = (v.iter().map(|e| (e.mse - m).powi(2)).sum::<f64>() / (k - 1.0).max(1.0)).sqrt();
            println!(
                "| {method} | {fname} | {m:.3e} ± {sd:.1e} | {:.3e} | {:.3e} | {:.3e} | {:.3e} |",
                m - ref_noise,
                mean_of(v, |e| e.outliers),
                mean_of(v, |e| e.mse_important),
                mean_of(v, |e| e.mse_rest)
            );
        }
    }
    // Adaptive / uniform ratios, per filter, noise floor removed; per-seed ratios give
    // the spread (the same seed drives both methods' paths only loosely: counts differ).
    println!(
        "\n| filter | method | MSE ratio vs uniform (floor removed) | per-seed ratios | worst-0.1% ratio |"
    );
    println!("|---|---|---:|---|---:|");
    let uni = &res[&methods[0]];
    for method in methods.iter().skip(1) {
        for (fname, v) in &res[method] {
            let u = &uni[fname];
            let r = (mean_of(v, |e| e.mse) - ref_noise) / (mean_of(u, |e| e.mse) - ref_noise);
            let per: Vec<String> = v
                .iter()
                .zip(u)
                .map(|(a, b)| format!("{:.2}", (a.mse - ref_noise) / (b.mse - ref_noise)))
                .collect();
            let o = mean_of(v, |e| e.outliers) / mean_of(u, |e| e.outliers);
            println!("| {fname} | {method} | {r:.3} | {} | {o:.2} |", per.join(", "));
        }
    }
}
