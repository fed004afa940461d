//! Times one filter call at 1920x1080 on the input of `filtrace bench filters`
//! (`bench_input::synthetic_input`), for A/B runs while optimising: prints the median
//! wall-clock ms and the median CPU ms (all threads) of `REPEATS` calls after one warm-up.
//!
//! `cargo run --release -p filtrace-denoise --example filter_time -- atrous|guided|guided1 [REPEATS]`
//! (`guided`: 4 channels, r = 32; `guided1`: 1 channel, r = 24)
//! (threads: `RAYON_NUM_THREADS`). The reported numbers are `filtrace bench filters`'.

use filtrace_denoise::bench_input::synthetic_input;
use filtrace_denoise::{AtrousParams, Filter, Guidance, GuidedParams, Image};
use std::time::Instant;

fn cpu_ns() -> u64 {
    let mut total = 0;
    for t in std::fs::read_dir("/proc/self/task").into_iter().flatten().flatten() {
        if let Ok(s) = std::fs::read_to_string(t.path().join("schedstat")) {
            total += s.split_whitespace().next().and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
        }
    }
    total
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let which = args.get(1).map(String::as_str).unwrap_or("atrous");
    let repeats: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(5);
    let f = match which {
        "guided" => Filter::Guided(GuidedParams {
            radius: 32,
            guidance: Guidance::NormalDepth,
            ..GuidedParams::paper()
        }),
        // The `bench filters` row "guided, 1 dimension, radius 24".
        "guided1" => Filter::Guided(GuidedParams { radius: 24, ..GuidedParams::grey() }),
        _ => Filter::Atrous(AtrousParams::paper()),
    };
    let (color, g) = synthetic_input(1920, 1080);
    let mut out = Image::new(1920, 1080, 3);
    f.apply_into(&color, &g, &mut out).expect("filter");
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    for _ in 0..repeats {
        let c0 = cpu_ns();
        let t = Instant::now();
        f.apply_into(&color, &g, &mut out).expect("filter");
        wall.push(t.elapsed().as_secs_f64() * 1e3);
        cpu.push((cpu_ns() - c0) as f64 * 1e-6);
    }
    let checksum: f64 = out.data().iter().map(|v| *v as f64).sum();
    wall.sort_by(f64::total_cmp);
    cpu.sort_by(f64::total_cmp);
    println!(
        "{which} threads {} wall med {:.1} min {:.1}  cpu med {:.1} min {:.1}  checksum {checksum:.6e}",
        rayon::current_num_threads(),
        wall[repeats / 2],
        wall[0],
        cpu[repeats / 2],
        cpu[0]
    );
}
