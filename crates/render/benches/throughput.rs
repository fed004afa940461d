//! Headline throughput: samples per second on the built-in Cornell box at 512 x 512,
//! max depth 8, on local rayon pools of 1 and 2 threads (build time excluded).
//!
//! `cargo bench -p filtrace-render --bench throughput [-- SPP [THREADS...] [scalar|lockstep|portable] [packets|perlane] [lanes]]`
//! (default 16 spp, threads 1 2, the renderer's default trace mode). Prints one line per
//! thread count and a JSON line; `lanes` also prints the lockstep lane utilisation.

use filtrace_render::{render_bench, RayQueries, RenderSettings, Renderer, TraceMode};

fn main() {
    // cargo bench passes `--bench`; ignore flags.
    let args: Vec<u32> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let spp = args.first().copied().unwrap_or(16);
    let threads: Vec<usize> =
        if args.len() > 1 { args[1..].iter().map(|&t| t as usize).collect() } else { vec![1, 2] };
    let settings = RenderSettings { width: 512, height: 512, spp, max_depth: 8, seed: 0 };
    let words: Vec<String> = std::env::args().skip(1).collect();
    let has = |w: &str| words.iter().any(|a| a == w);
    let mut renderer = Renderer::new(filtrace_scene::builtin("cornell").expect("cornell"), settings).unwrap();
    for (word, mode) in [
        ("scalar", TraceMode::Scalar),
        ("lockstep", TraceMode::Lockstep),
        ("portable", TraceMode::LockstepPortable),
    ] {
        if has(word) {
            renderer = renderer.with_trace_mode(mode);
        }
    }
    if has("packets") {
        renderer = renderer.with_ray_queries(RayQueries::Packet);
    }
    if has("perlane") {
        renderer = renderer.with_ray_queries(RayQueries::PerLane);
    }
    println!(
        "cornell 512x512 spp {spp} max_depth 8, trace mode {:?}, ray queries {:?}, build {:.3} ms",
        renderer.trace_mode(),
        renderer.ray_queries(),
        renderer.build_seconds() * 1e3
    );
    if has("lanes") {
        let s = renderer.lane_stats(0, spp);
        let per_vertex: Vec<String> = (0..8).map(|v| format!("{:.3}", s.utilisation(v))).collect();
        println!(
            "lanes: {} groups, alive per vertex (fraction of 8 lanes) [{}], mean utilisation over bounces run {:.3}",
            s.groups,
            per_vertex.join(" "),
            s.mean_utilisation()
        );
    }
    for t in threads {
        let cpu0 = cpu_seconds();
        let r = render_bench(&renderer, t);
        let cpu = cpu_seconds().zip(cpu0).map(|(a, b)| a - b);
        if let Some(cpu) = cpu {
            // On a shared machine wall time lies; CPU time does not (tiles scale linearly).
            println!(
                "threads {t}: {:.3} CPU s, {:.2} M samples per CPU second",
                cpu,
                r.samples as f64 / cpu / 1e6
            );
        }
        println!(
            "threads {t}: {:.3} s, {:.2} M samples/s, mean [{:.5} {:.5} {:.5}]",
            r.seconds,
            r.samples_per_second / 1e6,
            r.mean_color[0],
            r.mean_color[1],
            r.mean_color[2]
        );
        println!(
            "{{\"bench\":\"render_cornell_512\",\"mode\":\"{:?}\",\"threads\":{t},\"spp\":{spp},\"seconds\":{:.4},\"samples_per_second\":{:.0}}}",
            renderer.trace_mode(),
            r.seconds,
            r.samples_per_second
        );
    }
}

/// User + system CPU time of this process from `/proc/self/stat` (Linux; `None` elsewhere).
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which is in parentheses and may hold spaces).
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}
