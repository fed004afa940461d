//! Times one filter call at 1920x1080 on the input of `filtrace bench filters` (a copy of its
//! `synthetic_input`), for A/B runs while optimising: prints the median wall-clock ms and the
//! median CPU ms (all threads) of `REPEATS` calls after one warm-up.
//!
//! `cargo run --release -p filtrace-denoise --example filter_time -- atrous|guided [REPEATS]`
//! (threads: `RAYON_NUM_THREADS`). The reported numbers are `filtrace bench filters`'.

use filtrace_denoise::{AtrousParams, Filter, GBuffer, Guidance, GuidedParams, Image};
use std::time::Instant;

fn synthetic_input(w: usize, h: usize) -> (Image, GBuffer) {
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut rnd = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let (mut c, mut n, mut p, mut d) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for y in 0..h {
        for x in 0..w {
            let (u, v) = (x as f32 / w as f32, y as f32 / h as f32);
            let in_box = (0.2..0.45).contains(&u) && (0.4..0.9).contains(&v);
            let (normal, depth) = if in_box {
                ([0.0, 0.0, -1.0], 0.6)
            } else if u < 0.1 {
                ([1.0, 0.0, 0.0], 0.8 + u)
            } else if v > 0.9 {
                ([0.0, 1.0, 0.0], 0.8 + (1.0 - v))
            } else {
                ([0.0, 0.0, -1.0], 1.0)
            };
            n.extend_from_slice(&normal);
            p.extend_from_slice(&[u, 1.0 - v, depth]);
            d.push(depth);
            let base = 0.3 + 0.5 * u;
            for _ in 0..3 {
                let r = rnd();
                c.push(base * (-(1.0 - r).max(1e-6).ln()) * if rnd() < 0.001 { 50.0 } else { 1.0 });
            }
        }
    }
    let im = |ch, v| Image::from_vec(w, h, ch, v).expect("sizes match");
    let g = GBuffer::new(im(3, n)).with_position(im(3, p)).with_depth(im(1, d)).with_scene_scale(1.5);
    (im(3, c), g)
}

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
