//! Single-ray throughput for A/B comparisons on a loaded machine:
//!
//! `cargo run --release -p filtrace-accel --example abrays -- MESH [--repeats K] [--block N] [--only primary|closest|any]`
//!
//! One thread. The ray sets of `raybench` (primary closest, incoherent closest, incoherent
//! any) are cut into blocks of `N` rays (default 16384); every block is cast `K` times
//! (default 7) and timed by this thread's CPU time (`clock_gettime(CLOCK_THREAD_CPUTIME_ID)`); the
//! reported Mrays per CPU-s is the ray count over the sum of the per-block minima. Each
//! block's minimum is a run that other processes disturbed least (no preemption, warm
//! caches), so two builds compare more steadily than by whole-set timings; the figure is
//! an optimistic bound and is not comparable with `raybench`'s or Embree's numbers.
//!
//! `--packets`: the 8-ray packet queries instead (blocks of `N / 8` packets): primary
//! rays in 4x2 pixel tiles, and full packets of eight consecutive rays: incoherent
//! closest and shadow rays (`raybench`'s sets), and the bounce and shadow rays of `bench::surface_rays` (origins on the
//! surfaces, as a path tracer's compacted bounces after the first hit).

use filtrace_accel::bench::{
    incoherent_rays, packets_of, primary_rays, shadow_rays, surface_rays, tile_packets,
};
use filtrace_accel::{RayPacket, SceneAccel};
use filtrace_core::Ray;

#[repr(C)]
struct Timespec {
    sec: i64,
    nsec: i64,
}

extern "C" {
    fn clock_gettime(clock: i32, ts: *mut Timespec) -> i32;
}

/// This thread's CPU time in ns (`CLOCK_THREAD_CPUTIME_ID`, Linux x86_64).
fn thread_cpu_ns() -> u64 {
    let mut ts = Timespec { sec: 0, nsec: 0 };
    // SAFETY: `ts` is a valid `struct timespec` on x86_64 Linux; 3 = CLOCK_THREAD_CPUTIME_ID.
    if unsafe { clock_gettime(3, &mut ts) } != 0 {
        return 0;
    }
    ts.sec as u64 * 1_000_000_000 + ts.nsec as u64
}

/// Mrays per CPU-s from per-block minima; `query` returns whether a ray hit.
fn measure(rays: &[Ray], block: usize, repeats: usize, query: impl Fn(&Ray) -> bool) -> (f64, usize) {
    let mut best = vec![u64::MAX; rays.len().div_ceil(block)];
    let mut hits = 0;
    for _ in 0..repeats {
        hits = 0;
        for (b, chunk) in rays.chunks(block).enumerate() {
            let t0 = thread_cpu_ns();
            hits += chunk.iter().filter(|r| query(r)).count();
            best[b] = best[b].min(thread_cpu_ns() - t0);
        }
    }
    let ns: u64 = best.iter().sum();
    (rays.len() as f64 / (ns as f64 * 1e-9) / 1e6, hits)
}

/// [`measure`] for packets: `query` returns the mask of lanes that hit.
fn measure_packets(
    packets: &[(RayPacket, u8)],
    block: usize,
    repeats: usize,
    query: impl Fn(&RayPacket, u8) -> u8,
) -> (f64, usize) {
    let block = block.div_ceil(8);
    let mut best = vec![u64::MAX; packets.len().div_ceil(block)];
    let mut hits = 0;
    for _ in 0..repeats {
        hits = 0;
        for (b, chunk) in packets.chunks(block).enumerate() {
            let t0 = thread_cpu_ns();
            hits += chunk.iter().map(|(p, a)| query(p, *a).count_ones() as usize).sum::<usize>();
            best[b] = best[b].min(thread_cpu_ns() - t0);
        }
    }
    let ns: u64 = best.iter().sum();
    let rays: usize = packets.iter().map(|p| p.1.count_ones() as usize).sum();
    (rays as f64 / (ns as f64 * 1e-9) / 1e6, hits)
}

/// The `--packets` figures (see the module docs).
fn packet_figures(
    scene: &filtrace_scene::Scene,
    accel: &SceneAccel,
    block: usize,
    repeats: usize,
    only: Option<&str>,
) {
    let run = |q: &str| only.is_none_or(|o| o == q);
    let n = 1 << 20;
    let (bounce, surface_shadow) = surface_rays(scene, accel, n, 7);
    let sets = [
        ("primary", tile_packets(&primary_rays(scene, 1024, 1024), 1024, 1024), true),
        ("closest", packets_of(&incoherent_rays(scene, n, 7)), true),
        ("shadow", packets_of(&shadow_rays(scene, n, 7)), false),
        ("bounce", packets_of(&bounce), true),
        ("surface-shadow", packets_of(&surface_shadow), false),
    ];
    for (name, packets, closest) in &sets {
        if !run(name) {
            continue;
        }
        let (m, h) = if *closest {
            measure_packets(packets, block, repeats, |p, a| accel.intersect_packet(p, a).mask)
        } else {
            measure_packets(packets, block, repeats, |p, a| accel.occluded_packet(p, a))
        };
        print!("{name} {m:.3} (hits {h})  ");
    }
    println!();
}

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (mut repeats, mut block, mut spec, mut only) = (7usize, 16384usize, None, None);
    let mut packets = false;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut val = || it.next().cloned().ok_or(format!("{a} needs a value"));
        match a.as_str() {
            "--repeats" => repeats = val()?.parse().map_err(|e| format!("--repeats: {e}"))?,
            "--block" => block = val()?.parse().map_err(|e| format!("--block: {e}"))?,
            "--only" => only = Some(val()?),
            "--packets" => packets = true,
            s => spec = Some(s.to_string()),
        }
    }
    if repeats == 0 || block == 0 {
        return Err("--repeats and --block must be positive".into());
    }
    let spec = spec.ok_or("usage: abrays MESH [--repeats K] [--block N]")?;
    let scene = filtrace_accel::bench::bench_scene(&spec)?;
    let accel = SceneAccel::build(&scene);
    if packets {
        packet_figures(&scene, &accel, block, repeats, only.as_deref());
        return Ok(());
    }
    let primary = primary_rays(&scene, 1024, 1024);
    let incoherent = incoherent_rays(&scene, 1 << 20, 7);
    // `--only primary|closest|any` runs one query (for `perf record`).
    let run = |q: &str| only.as_deref().is_none_or(|o| o == q);
    let skip = (0.0, 0);
    let (p, hp) = if run("primary") {
        measure(&primary, block, repeats, |r| accel.intersect(r).is_some())
    } else {
        skip
    };
    let (c, hc) = if run("closest") {
        measure(&incoherent, block, repeats, |r| accel.intersect(r).is_some())
    } else {
        skip
    };
    let (a, ha) = if run("any") { measure(&incoherent, block, repeats, |r| accel.occluded(r)) } else { skip };
    println!("primary {p:.3} closest {c:.3} any {a:.3}  (hits {hp} {hc} {ha})");
    Ok(())
}
