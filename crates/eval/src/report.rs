//! The experiment report: `report.html` (self-contained: inline CSS and SVG plots; the PNGs
//! lie beside it), `results.json` (everything, machine-readable) and `results.csv` (one row
//! per scene x method x spp).

use std::fmt::Write as _;
use std::path::Path;

use crate::experiment::{Entry, Results};

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
    let mut s = String::from("scene,method,filter,spp,mse,rel_mse,psnr,ssim,flip,nonfinite,total_ms");
    for st in &stages {
        let _ = write!(s, ",{st}_ms");
    }
    s.push('\n');
    for e in &results.entries {
        let _ = write!(
            s,
            "{},{},{},{},{:e},{:e},{},{:.5},{:.5},{},{:.3}",
            csv_field(&e.scene),
            csv_field(&e.method),
            csv_field(&e.filter),
            e.spp,
            e.errors.mse,
            e.errors.rel_mse,
            e.errors.psnr.map_or("inf".to_string(), |p| format!("{p:.4}")),
            e.errors.ssim,
            e.errors.flip,
            e.errors.nonfinite,
            e.total_ms
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

/// Series colours of the plots (colour-blind-safe Okabe-Ito palette).
const COLOURS: [&str; 8] =
    ["#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#F0E442", "#000000"];

/// The self-contained HTML report.
pub fn html(r: &Results) -> String {
    let spec = &r.spec;
    let mut h = String::new();
    let _ = write!(
        h,
        "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>{name}</title><style>\
body{{font-family:sans-serif;margin:1.5em;max-width:1400px}}table{{border-collapse:collapse;margin:.5em 0}}\
td,th{{border:1px solid #bbb;padding:2px 6px;text-align:right}}th{{background:#eee}}td.l{{text-align:left}}\
.best{{font-weight:bold;background:#e6f4ea}}.grid{{display:flex;flex-wrap:wrap;gap:8px}}\
figure{{margin:0}}figcaption{{font-size:12px;text-align:center}}img.crop{{image-rendering:pixelated;width:192px}}\
img.full{{width:256px}}</style></head><body>\n<h1>Experiment: {name}</h1>\n<p>{w}x{hh}, max_depth {d}, seed {seed}, \
reference {rs} spp, sample counts {spp:?}, timing: median of {rep} run(s). Error: relMSE = mean of \
(x&minus;ref)&sup2;/(ref&sup2;+0.01); lower is better. Times are wall-clock milliseconds per frame stage.</p>\n",
        name = esc(&spec.name),
        w = spec.width,
        hh = spec.height,
        d = spec.max_depth,
        seed = spec.seed,
        rs = spec.reference.spp,
        spp = spec.spp,
        rep = spec.repeats
    );
    if !r.notes.is_empty() {
        h.push_str("<ul>");
        for n in &r.notes {
            let _ = write!(h, "<li>{}</li>", esc(n));
        }
        h.push_str("</ul>\n");
    }
    let stages = stage_names(&r.entries);
    for scene in &r.scenes {
        let entries: Vec<&Entry> = r.entries.iter().filter(|e| e.scene == scene.name).collect();
        let _ =
            write!(h, "<h2>{}</h2>\n<p>Reference: {}</p>\n", esc(&scene.name), esc(&scene.reference_source));
        // Table of error and milliseconds per stage.
        h.push_str("<table><tr><th>method</th><th>spp</th><th>relMSE</th><th>PSNR (dB)</th><th>SSIM</th><th>FLIP</th><th>MSE</th>");
        for st in &stages {
            let _ = write!(h, "<th>{} ms</th>", esc(st));
        }
        h.push_str("<th>total ms</th></tr>\n");
        for &spp in &spec.spp {
            let best = entries
                .iter()
                .filter(|e| e.spp == spp)
                .map(|e| e.errors.rel_mse)
                .filter(|v| v.is_finite())
                .fold(f64::INFINITY, f64::min);
            for e in entries.iter().filter(|e| e.spp == spp) {
                let cls = if e.errors.rel_mse == best { " class=\"best\"" } else { "" };
                let _ = write!(
                    h,
                    "<tr><td class=\"l\">{}</td><td>{}</td><td{cls}>{:.4e}</td><td>{}</td><td>{:.4}</td><td>{:.4}</td><td>{:.4e}</td>",
                    esc(&e.method),
                    e.spp,
                    e.errors.rel_mse,
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
                let _ = writeln!(h, "<td>{:.1}</td></tr>", e.total_ms);
            }
        }
        h.push_str("</table>\n");
        h.push_str(&error_time_plot(
            &entries,
            &spec.methods.iter().map(|m| m.name.clone()).collect::<Vec<_>>(),
        ));
        // Images side by side, one row per sample count: full frame, zoomed crop, error map.
        let [cx, cy, cw, ch] = scene.crop;
        let _ = writeln!(h, "<p>Crops: {cw}x{ch} pixels at ({cx}, {cy}), enlarged. Error maps: per-pixel relative squared error, log scale 1e-4 (black) to 1e1 (white).</p>");
        for &spp in &spec.spp {
            let _ = writeln!(h, "<h3>{spp} spp</h3><div class=\"grid\">");
            let _ = write!(
                h,
                "<figure><img class=\"full\" src=\"{}\"><br><img class=\"crop\" src=\"{}\"><figcaption>reference</figcaption></figure>",
                esc(&scene.reference),
                esc(&scene.reference_crop)
            );
            for e in entries.iter().filter(|e| e.spp == spp) {
                let _ = write!(
                    h,
                    "<figure><img class=\"full\" src=\"{}\"><br><img class=\"crop\" src=\"{}\"><br>\
<img class=\"full\" src=\"{}\"><figcaption>{} &middot; relMSE {:.3e} &middot; {:.1} ms</figcaption></figure>",
                    esc(&e.image),
                    esc(&e.crop),
                    esc(&e.error_map),
                    esc(&e.method),
                    e.errors.rel_mse,
                    e.total_ms
                );
            }
            h.push_str("</div>\n");
        }
    }
    h.push_str("</body></html>\n");
    h
}

/// Log-log plot of relMSE against total milliseconds, one polyline per method (points in
/// increasing spp), as inline SVG.
pub fn error_time_plot(entries: &[&Entry], methods: &[String]) -> String {
    let pts: Vec<(f64, f64)> = entries
        .iter()
        .map(|e| (e.total_ms, e.errors.rel_mse))
        .filter(|(t, e)| *t > 0.0 && *e > 0.0 && t.is_finite() && e.is_finite())
        .collect();
    if pts.is_empty() {
        return "<p>(no finite positive points to plot)</p>\n".into();
    }
    let (w, h, m) = (520.0, 320.0, 60.0);
    let lx = |v: f64| v.log10();
    let (mut x0, mut x1) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY);
    for &(t, e) in &pts {
        x0 = x0.min(lx(t).floor());
        x1 = x1.max(lx(t).ceil());
        y0 = y0.min(lx(e).floor());
        y1 = y1.max(lx(e).ceil());
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    if y1 <= y0 {
        y1 = y0 + 1.0;
    }
    let px = |t: f64| m + (lx(t) - x0) / (x1 - x0) * (w - 1.5 * m);
    let py = |e: f64| h - m + -(lx(e) - y0) / (y1 - y0) * (h - 1.5 * m);
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" font-size=\"11\" font-family=\"sans-serif\">\
<rect x=\"0\" y=\"0\" width=\"{w}\" height=\"{h}\" fill=\"white\"/>"
    );
    // Axes with decade ticks.
    for d in (x0 as i32)..=(x1 as i32) {
        let x = px(10f64.powi(d));
        let _ = write!(
            s,
            "<line x1=\"{x:.1}\" y1=\"{:.1}\" x2=\"{x:.1}\" y2=\"{:.1}\" stroke=\"#ddd\"/><text x=\"{x:.1}\" y=\"{:.1}\" text-anchor=\"middle\">1e{d}</text>",
            m / 2.0,
            h - m,
            h - m + 14.0
        );
    }
    for d in (y0 as i32)..=(y1 as i32) {
        let y = py(10f64.powi(d));
        let _ = write!(
            s,
            "<line x1=\"{m}\" y1=\"{y:.1}\" x2=\"{:.1}\" y2=\"{y:.1}\" stroke=\"#ddd\"/><text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">1e{d}</text>",
            w - m / 2.0,
            m - 4.0,
            y + 4.0
        );
    }
    let _ = write!(
        s,
        "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">total ms per frame (log)</text>\
<text x=\"12\" y=\"{:.1}\" transform=\"rotate(-90 12 {:.1})\" text-anchor=\"middle\">relMSE (log)</text>",
        w / 2.0,
        h - 20.0,
        h / 2.0,
        h / 2.0
    );
    for (k, name) in methods.iter().enumerate() {
        let col = COLOURS[k % COLOURS.len()];
        let mut ms: Vec<&&Entry> = entries.iter().filter(|e| &e.method == name).collect();
        ms.sort_by_key(|e| e.spp);
        let p: Vec<(f64, f64, u32)> = ms
            .iter()
            .filter(|e| e.total_ms > 0.0 && e.errors.rel_mse > 0.0 && e.errors.rel_mse.is_finite())
            .map(|e| (px(e.total_ms), py(e.errors.rel_mse), e.spp))
            .collect();
        if p.is_empty() {
            continue;
        }
        let poly: Vec<String> = p.iter().map(|(x, y, _)| format!("{x:.1},{y:.1}")).collect();
        let _ = write!(
            s,
            "<polyline fill=\"none\" stroke=\"{col}\" stroke-width=\"1.5\" points=\"{}\"/>",
            poly.join(" ")
        );
        for (x, y, spp) in &p {
            let _ = write!(
                s,
                "<circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"3.5\" fill=\"{col}\"><title>{} {spp} spp</title></circle>",
                esc(name)
            );
        }
        let ly = m / 2.0 + 14.0 * k as f64;
        let _ = write!(
            s,
            "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"10\" height=\"10\" fill=\"{col}\"/><text x=\"{:.1}\" y=\"{:.1}\">{}</text>",
            w - 150.0,
            ly - 9.0,
            w - 136.0,
            ly,
            esc(name)
        );
    }
    s.push_str("</svg>\n");
    s
}
