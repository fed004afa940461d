//! Log-log line plots as inline SVG (the report's convergence plots): one polyline per
//! series with a legend, decade grid lines, no dependencies.

use std::fmt::Write as _;

/// Series colours (colour-blind-safe Okabe-Ito palette).
pub const COLOURS: [&str; 8] =
    ["#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#F0E442", "#000000"];

/// One line of a plot: `(x, y, tooltip)` points, drawn in the given order.
#[derive(Clone, Debug, Default)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64, String)>,
}

fn esc(v: &str) -> String {
    v.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// Axis range in decades covering the values (at least one decade).
fn decades(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values {
        lo = lo.min(v.log10().floor());
        hi = hi.max(v.log10().ceil());
    }
    if hi <= lo {
        hi = lo + 1.0;
    }
    (lo, hi)
}

fn plottable(p: &(f64, f64, String)) -> bool {
    p.0 > 0.0 && p.1 > 0.0 && p.0.is_finite() && p.1.is_finite()
}

/// The plot of `series` on log-log axes; points that are not finite and positive are
/// left out (a note says so when nothing is left).
pub fn log_log_plot(series: &[Series], x_label: &str, y_label: &str) -> String {
    let all = || series.iter().flat_map(|s| s.points.iter().filter(|p| plottable(p)));
    if all().next().is_none() {
        return format!("<p>({y_label} against {x_label}: no finite positive points to plot)</p>\n");
    }
    let (w, h, m) = (440.0, 300.0, 56.0);
    let (x0, x1) = decades(all().map(|p| p.0));
    let (y0, y1) = decades(all().map(|p| p.1));
    let legend_w = 130.0;
    let px = |x: f64| m + (x.log10() - x0) / (x1 - x0) * (w - m - legend_w);
    let py = |y: f64| h - m + -(y.log10() - y0) / (y1 - y0) * (h - 1.5 * m);
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" font-size=\"11\" font-family=\"sans-serif\">\
<rect x=\"0\" y=\"0\" width=\"{w}\" height=\"{h}\" fill=\"white\"/>"
    );
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
            w - legend_w,
            m - 4.0,
            y + 4.0
        );
    }
    let _ = write!(
        s,
        "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{} (log)</text>\
<text x=\"12\" y=\"{:.1}\" transform=\"rotate(-90 12 {:.1})\" text-anchor=\"middle\">{} (log)</text>",
        (w - legend_w + m) / 2.0,
        h - 20.0,
        esc(x_label),
        h / 2.0,
        h / 2.0,
        esc(y_label)
    );
    for (k, line) in series.iter().enumerate() {
        draw_series(&mut s, k, line, &px, &py, (w - legend_w + 8.0, m / 2.0 + 14.0 * k as f64));
    }
    s.push_str("</svg>\n");
    s
}

fn draw_series(
    s: &mut String,
    k: usize,
    line: &Series,
    px: &dyn Fn(f64) -> f64,
    py: &dyn Fn(f64) -> f64,
    (lx, ly): (f64, f64),
) {
    let col = COLOURS[k % COLOURS.len()];
    let p: Vec<(f64, f64, &str)> =
        line.points.iter().filter(|p| plottable(p)).map(|(x, y, t)| (px(*x), py(*y), t.as_str())).collect();
    if p.is_empty() {
        return;
    }
    let poly: Vec<String> = p.iter().map(|(x, y, _)| format!("{x:.1},{y:.1}")).collect();
    let dash = if k >= COLOURS.len() { " stroke-dasharray=\"4 2\"" } else { "" };
    let _ = write!(
        s,
        "<polyline fill=\"none\" stroke=\"{col}\" stroke-width=\"1.5\"{dash} points=\"{}\"/>",
        poly.join(" ")
    );
    for (x, y, tip) in &p {
        let _ = write!(
            s,
            "<circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"3\" fill=\"{col}\"><title>{} {}</title></circle>",
            esc(&line.name),
            esc(tip)
        );
    }
    let _ = write!(
        s,
        "<rect x=\"{lx:.1}\" y=\"{:.1}\" width=\"10\" height=\"10\" fill=\"{col}\"/><text x=\"{:.1}\" y=\"{ly:.1}\">{}</text>",
        ly - 9.0,
        lx + 14.0,
        esc(&line.name)
    );
}

/// `y` at `x` on the polyline through `points` (sorted by x here), interpolated linearly
/// in log-log; `None` outside the measured range or where values are not positive.
pub fn interpolate_log_log(points: &[(f64, f64)], x: f64) -> Option<f64> {
    let mut p: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|(a, b)| *a > 0.0 && *b > 0.0 && a.is_finite() && b.is_finite())
        .collect();
    p.sort_by(|a, b| a.0.total_cmp(&b.0));
    if x.is_nan() || x <= 0.0 || p.is_empty() || x < p[0].0 || x > p[p.len() - 1].0 {
        return None;
    }
    let i = p.iter().position(|q| q.0 >= x)?;
    if p[i].0 == x || i == 0 {
        return Some(p[i].1);
    }
    let (a, b) = (p[i - 1], p[i]);
    let t = (x.ln() - a.0.ln()) / (b.0.ln() - a.0.ln());
    Some((a.1.ln() + t * (b.1.ln() - a.1.ln())).exp())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_log_interpolation_is_exact_on_power_laws_and_refuses_to_extrapolate() {
        // y = 3 x^-1: a straight line in log-log.
        let p = [(1.0, 3.0), (4.0, 0.75), (2.0, 1.5)];
        assert!((interpolate_log_log(&p, 3.0).unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(interpolate_log_log(&p, 1.0), Some(3.0));
        assert_eq!(interpolate_log_log(&p, 4.0), Some(0.75));
        assert_eq!(interpolate_log_log(&p, 0.5), None);
        assert_eq!(interpolate_log_log(&p, 5.0), None);
        assert_eq!(interpolate_log_log(&[], 1.0), None);
    }

    #[test]
    fn plot_draws_one_polyline_per_series_and_skips_bad_points() {
        let a =
            Series { name: "a<b".into(), points: vec![(1.0, 0.1, "1 spp".into()), (10.0, 0.01, "".into())] };
        let b = Series { name: "b".into(), points: vec![(f64::NAN, 1.0, "".into()), (0.0, 1.0, "".into())] };
        let svg = log_log_plot(&[a, b], "ms", "relMSE");
        assert_eq!(svg.matches("<polyline").count(), 1);
        assert!(svg.contains("a&lt;b") && svg.starts_with("<svg"));
        assert!(log_log_plot(&[], "ms", "relMSE").contains("no finite positive points"));
    }
}
