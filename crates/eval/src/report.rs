//! The experiment report: `report.html` (self-contained: inline CSS and SVG plots; the PNGs
//! lie beside it), `results.json` (everything, machine-readable) and `results.csv` (one row
//! per scene x method x spp).

use std::fmt::Write as _;
use std::path::Path;

use crate::experiment::{Clock, Entry, Metric, Results, SceneResult};
use crate::plots::{interpolate_log_log, log_log_plot, Series};

/// Writes `report.html`, `results.json` and `results.csv` into `out` (each through
/// `filtrace_io::write_atomic`: a failed write keeps the previous file).
pub fn write_all(out: &Path, results: &Results) -> Result<(), String> {
    let w = |name: &str, text: String| {
        filtrace_io::write_atomic(out.join(name), |f| f.write_all(text.as_bytes())).map_err(|e| e.to_string())
    };
    w("results.json", serde_json::to_string_pretty(results).map_err(|e| e.to_string())?)?;
    w("results.csv", csv(results))?;
    w("report.html", html(results))
}

/// Stage names over all entries, in first-seen order.
fn stage_names(entries: &[Entry]) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for e in entries {
        for (s, _) in &e.stages {
            if !names.contains(s) {
                names.push(s.clone());
            }
        }
    }
    names
}

fn stage_ms(e: &Entry, stage: &str) -> Option<f64> {
    e.stages.iter().find(|s| s.0 == stage).map(|s| s.1)
}

/// One row per scene x method x spp; stage columns `<stage>_ms` (empty when absent).
pub fn csv(results: &Results) -> String {
    let stages = stage_names(&results.entries);
    let mut s = String::from(
        "scene,method,filter,spp,mse,rel_mse,rel_mse_clamped,psnr,ssim,flip,nonfinite,total_ms,rays,ray_ms",
    );
    for st in &stages {
        let _ = write!(s, ",{st}_ms");
    }
    s.push('\n');
    for e in &results.entries {
        let _ = write!(
            s,
            "{},{},{},{},{:e},{:e},{:e},{},{:.5},{:.5},{},{:.3},{},{}",
            csv_field(&e.scene),
            csv_field(&e.method),
            csv_field(&e.filter),
            e.spp,
            e.errors.mse,
            e.errors.rel_mse,
            e.errors.rel_mse_clamped,
            e.errors.psnr.map_or("inf".to_string(), |p| format!("{p:.4}")),
            e.errors.ssim,
            e.errors.flip,
            e.errors.nonfinite,
            e.total_ms,
            e.rays.map_or(String::new(), |r| r.rays.to_string()),
            e.rays.map_or(String::new(), |r| format!("{:.3}", r.ray_ms))
        );
        for st in &stages {
            match stage_ms(e, st) {
                Some(v) => write!(s, ",{v:.3}"),
                None => write!(s, ","),
            }
            .ok();
        }
        s.push('\n');
    }
    s
}

fn csv_field(v: &str) -> String {
    if v.contains([',', '"', '\n']) {
        format!("\"{}\"", v.replace('"', "\"\""))
    } else {
        v.to_string()
    }
}

fn esc(v: &str) -> String {
    v.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// The self-contained HTML report.
pub fn html(r: &Results) -> String {
    let spec = &r.spec;
    let metric = spec.metric();
    let mut h = String::new();
    let _ = write!(
        h,
        "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>{name}</title><style>\
body{{font-family:sans-serif;margin:1.5em;max-width:1400px}}table{{border-collapse:collapse;margin:.5em 0}}\
td,th{{border:1px solid #bbb;padding:2px 6px;text-align:right}}th{{background:#eee}}td.l{{text-align:left}}\
.best{{font-weight:bold;background:#e6f4ea}}.grid{{display:flex;flex-wrap:wrap;gap:8px}}\
figure{{margin:0}}figcaption{{font-size:12px;text-align:center}}img.crop{{image-rendering:pixelated;width:192px}}\
img.full{{width:256px}}</style></head><body>\n<h1>Experiment: {name}</h1>\n<p>{w}x{hh}, max_depth {d}, seed {seed}, \
{reference}, sample counts {spp:?}, timing: median of {rep} run(s). Errors: relMSE = mean of \
(x&minus;ref)&sup2;/(ref&sup2;+0.01); relMSE (clamped) = &Sigma;(x&minus;ref)&sup2;/&Sigma;ref&sup2; on values clamped \
to [0, 1] (the importance-caching thesis, 6.1.2); lower is better. Plots and tables marked best use {metric}. \
Times are wall-clock milliseconds per frame stage.</p>\n",
        name = esc(&spec.name),
        w = spec.width,
        hh = spec.height,
        d = spec.max_depth,
        seed = spec.seed,
        reference = if spec.is_vpl_ground_truth() {
            format!("reference: the exhaustive sum of the {} VPLs on each method's own camera samples", spec.vpl.vpls)
        } else {
            format!("reference {} spp", spec.reference.spp)
        },
        spp = spec.spp,
        rep = spec.repeats,
        metric = metric.label()
    );
    if r.entries.iter().any(|e| e.rays.is_some()) {
        h.push_str("<p>Clocks (the thesis, 6.5): all time; time without ray queries (all time minus the backend's estimate of the ray queries' wall-clock time); rays traced.</p>\n");
    }
    if !r.notes.is_empty() {
        h.push_str("<ul>");
        for n in &r.notes {
            let _ = write!(h, "<li>{}</li>", esc(n));
        }
        h.push_str("</ul>\n");
    }
    if r.scenes.len() > 1 {
        h.push_str(&summary_table(r, metric));
    }
    for scene in &r.scenes {
        scene_section(&mut h, r, scene, metric);
    }
    h.push_str("</body></html>\n");
    h
}

/// Method × scene at each sample count, best per column marked.
fn summary_table(r: &Results, metric: Metric) -> String {
    let mut h = format!("<h2>All scenes: {}</h2>\n<table><tr><th>method</th>", metric.label());
    let mut spps = r.spec.spp.clone();
    spps.sort_unstable();
    spps.dedup();
    for &spp in &spps {
        for s in &r.scenes {
            let _ = write!(h, "<th>{} {spp} spp</th>", esc(&s.name));
        }
    }
    h.push_str("</tr>\n");
    let methods = method_names(&r.entries);
    for m in &methods {
        let _ = write!(h, "<tr><td class=\"l\">{}</td>", esc(m));
        for &spp in &spps {
            for s in &r.scenes {
                let cell = |e: &&Entry| e.scene == s.name && e.spp == spp;
                let best =
                    r.entries.iter().filter(cell).map(|e| e.errors.get(metric)).fold(f64::INFINITY, f64::min);
                match r.entries.iter().filter(cell).find(|e| &e.method == m) {
                    Some(e) => {
                        let v = e.errors.get(metric);
                        let cls = if v == best { " class=\"best\"" } else { "" };
                        let _ = write!(h, "<td{cls}>{v:.3e}</td>");
                    }
                    None => h.push_str("<td></td>"),
                }
            }
        }
        h.push_str("</tr>\n");
    }
    h.push_str("</table>\n");
    h
}

/// Method names in first-seen order.
fn method_names(entries: &[Entry]) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for e in entries {
        if !names.contains(&e.method) {
            names.push(e.method.clone());
        }
    }
    names
}

fn scene_section(h: &mut String, r: &Results, scene: &SceneResult, metric: Metric) {
    let spec = &r.spec;
    let entries: Vec<&Entry> = r.entries.iter().filter(|e| e.scene == scene.name).collect();
    let _ = write!(h, "<h2>{}</h2>\n<p>Reference: {}</p>\n", esc(&scene.name), esc(&scene.reference_source));
    h.push_str(&scene_table(&entries, &spec.spp, metric));
    let methods = method_names(&r.entries);
    let with_rays = entries.iter().any(|e| e.rays.is_some());
    let clocks: &[Clock] = if with_rays { &Clock::ALL } else { &[Clock::Spp, Clock::Total] };
    h.push_str("<div class=\"grid\">");
    for &c in clocks {
        h.push_str(&log_log_plot(&series(&entries, &methods, c, metric), c.label(), metric.label()));
    }
    h.push_str("</div>\n");
    if let Some(base) = &spec.equal_time {
        for &c in clocks.iter().filter(|c| **c != Clock::Spp) {
            h.push_str(&equal_time_table(&entries, &methods, base, c, metric));
        }
    }
    // Images side by side, one row per sample count: full frame, zoomed crop, error map.
    let [cx, cy, cw, ch] = scene.crop;
    let _ = writeln!(h, "<p>Crops: {cw}x{ch} pixels at ({cx}, {cy}), enlarged. Error maps: per-pixel relative squared error, log scale 1e-4 (black) to 1e1 (white).</p>");
    for &spp in &spec.spp {
        let _ = writeln!(h, "<h3>{spp} spp</h3><div class=\"grid\">");
        let (reference, reference_crop) = scene.reference_at(spp);
        let _ = write!(
            h,
            "<figure><img class=\"full\" src=\"{}\"><br><img class=\"crop\" src=\"{}\"><figcaption>reference</figcaption></figure>",
            esc(reference),
            esc(reference_crop)
        );
        for e in entries.iter().filter(|e| e.spp == spp) {
            let _ = write!(
                h,
                "<figure><img class=\"full\" src=\"{}\"><br><img class=\"crop\" src=\"{}\"><br>\
<img class=\"full\" src=\"{}\"><figcaption>{} &middot; {:.3e} &middot; {:.1} ms</figcaption></figure>",
                esc(&e.image),
                esc(&e.crop),
                esc(&e.error_map),
                esc(&e.method),
                e.errors.get(metric),
                e.total_ms
            );
        }
        h.push_str("</div>\n");
    }
}

/// Error and milliseconds per stage (and the ray clocks) of every cell of a scene.
fn scene_table(entries: &[&Entry], spps: &[u32], metric: Metric) -> String {
    let owned: Vec<Entry> = entries.iter().map(|e| (*e).clone()).collect();
    let stages = stage_names(&owned);
    let with_rays = entries.iter().any(|e| e.rays.is_some());
    let mut h = String::from("<table><tr><th>method</th><th>spp</th><th>relMSE</th><th>relMSE (clamped)</th><th>PSNR (dB)</th><th>SSIM</th><th>FLIP</th><th>MSE</th>");
    for st in &stages {
        let _ = write!(h, "<th>{} ms</th>", esc(st));
    }
    h.push_str("<th>total ms</th>");
    if with_rays {
        h.push_str("<th>ray ms (est.)</th><th>ms without rays</th><th>rays</th>");
    }
    h.push_str("</tr>\n");
    for &spp in spps {
        let best = entries
            .iter()
            .filter(|e| e.spp == spp)
            .map(|e| e.errors.get(metric))
            .fold(f64::INFINITY, f64::min);
        for e in entries.iter().filter(|e| e.spp == spp) {
            let mark =
                |m: Metric| if m == metric && e.errors.get(m) == best { " class=\"best\"" } else { "" };
            let _ = write!(
                h,
                "<tr><td class=\"l\">{}</td><td>{}</td><td{}>{:.4e}</td><td{}>{:.4e}</td><td>{}</td><td>{:.4}</td><td>{:.4}</td><td>{:.4e}</td>",
                esc(&e.method),
                e.spp,
                mark(Metric::RelMse),
                e.errors.rel_mse,
                mark(Metric::RelMseClamped),
                e.errors.rel_mse_clamped,
                e.errors.psnr.map_or("inf".to_string(), |p| format!("{p:.2}")),
                e.errors.ssim,
                e.errors.flip,
                e.errors.mse
            );
            for st in &stages {
                match stage_ms(e, st) {
                    Some(v) => write!(h, "<td>{v:.1}</td>"),
                    None => write!(h, "<td></td>"),
                }
                .ok();
            }
            let _ = write!(h, "<td>{:.1}</td>", e.total_ms);
            if with_rays {
                match e.rays {
                    Some(r) => write!(
                        h,
                        "<td>{:.1}</td><td>{:.1}</td><td>{}</td>",
                        r.ray_ms,
                        e.total_ms - r.ray_ms,
                        r.rays
                    ),
                    None => write!(h, "<td></td><td></td><td></td>"),
                }
                .ok();
            }
            h.push_str("</tr>\n");
        }
    }
    h.push_str("</table>\n");
    h
}

/// One series per method: its error against clock `c`, in increasing spp.
fn series(entries: &[&Entry], methods: &[String], c: Clock, metric: Metric) -> Vec<Series> {
    methods
        .iter()
        .filter(|m| entries.iter().any(|e| &&e.method == m))
        .map(|m| {
            let mut es: Vec<&&Entry> = entries.iter().filter(|e| &e.method == m).collect();
            es.sort_by_key(|e| e.spp);
            let points = es
                .iter()
                .filter_map(|e| Some((e.clock(c)?, e.errors.get(metric), format!("{} spp", e.spp))))
                .collect();
            Series { name: m.clone(), points }
        })
        .collect()
}

/// Every method's error interpolated (log-log) at the times the baseline method measured
/// on clock `c`; blank outside a method's measured range.
fn equal_time_table(entries: &[&Entry], methods: &[String], base: &str, c: Clock, metric: Metric) -> String {
    let mut times: Vec<(u32, f64)> =
        entries.iter().filter(|e| e.method == base).filter_map(|e| Some((e.spp, e.clock(c)?))).collect();
    if times.is_empty() {
        return String::new();
    }
    times.sort_by(|a, b| a.1.total_cmp(&b.1));
    let mut h = format!(
        "<p>Equal {}: {} interpolated at the measurements of {}.</p><table><tr><th>method</th>",
        esc(c.label()),
        metric.label(),
        esc(base)
    );
    for (spp, t) in &times {
        let _ = write!(h, "<th>{} ({} at {spp} spp)</th>", fmt_clock(*t), esc(base));
    }
    h.push_str("</tr>\n");
    let rows: Vec<(String, Vec<Option<f64>>)> = methods
        .iter()
        .map(|m| {
            let pts: Vec<(f64, f64)> = entries
                .iter()
                .filter(|e| &e.method == m)
                .filter_map(|e| Some((e.clock(c)?, e.errors.get(metric))))
                .collect();
            (m.clone(), times.iter().map(|(_, t)| interpolate_log_log(&pts, *t)).collect())
        })
        .collect();
    for (m, vals) in &rows {
        let _ = write!(h, "<tr><td class=\"l\">{}</td>", esc(m));
        for (k, v) in vals.iter().enumerate() {
            let best = rows.iter().filter_map(|r| r.1[k]).fold(f64::INFINITY, f64::min);
            match v {
                Some(v) if *v == best => write!(h, "<td class=\"best\">{v:.3e}</td>"),
                Some(v) => write!(h, "<td>{v:.3e}</td>"),
                None => write!(h, "<td>&mdash;</td>"),
            }
            .ok();
        }
        h.push_str("</tr>\n");
    }
    h.push_str("</table>\n");
    h
}

fn fmt_clock(v: f64) -> String {
    if v >= 1e5 {
        format!("{v:.3e}")
    } else {
        format!("{v:.1}")
    }
}
