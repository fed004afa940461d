//! Where 8-ray packets pay off: CPU time per active ray of the packet queries and of one
//! single-ray query per active lane, for packets with 1..8 active lanes (1 thread).
//!
//! `cargo run --release -p filtrace-accel --example packet_lanes -- [SCENE] [--rays N]`
//! (SCENE as in `raybench`: `cornell`, `sphere:N` or an OBJ path; default `cornell`).
//! Prints, per ray set and active-lane count, ns per ray for both and their ratio.

use filtrace_accel::bench::{
    incoherent_rays, packets_of, primary_rays, process_cpu_seconds, shadow_rays, tile_packets,
};
use filtrace_accel::{testmesh, RayPacket, SceneAccel, LANES};
use filtrace_scene::Scene;
use std::hint::black_box;

fn load(arg: &str) -> Result<Scene, String> {
    if let Some(s) = filtrace_scene::builtin(arg) {
        return Ok(s);
    }
    let mut scene = Scene { name: arg.to_string(), ..Scene::default() };
    if let Some(n) = arg.strip_prefix("sphere:") {
        let n = n.parse().map_err(|e| format!("{arg}: {e}"))?;
        scene.add_mesh(testmesh::displaced_sphere(n, 0.1));
    } else {
        scene.add_mesh(testmesh::read_obj(std::path::Path::new(arg))?);
    }
    Ok(scene)
}

/// CPU ns per active ray of `f` over `packets`: passes repeated for at least 0.2 s (the
/// scheduler's CPU time has a resolution of a few ms), best of 3.
fn ns_per_ray(packets: &[(RayPacket, u8)], f: impl Fn(&RayPacket, u8) -> u32) -> f64 {
    let n: u64 = packets.iter().map(|p| p.1.count_ones() as u64).sum();
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let t0 = process_cpu_seconds();
        let start = std::time::Instant::now();
        let (mut acc, mut passes) = (0u32, 0u64);
        while passes == 0 || start.elapsed().as_secs_f64() < 0.2 {
            for (p, a) in packets {
                acc = acc.wrapping_add(f(black_box(p), *a));
            }
            passes += 1;
        }
        black_box(acc);
        let secs = match (t0, process_cpu_seconds()) {
            (Some(a), Some(b)) => b - a,
            _ => start.elapsed().as_secs_f64(),
        };
        best = best.min(secs / passes as f64);
    }
    best * 1e9 / n.max(1) as f64
}

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut scene_arg = "cornell".to_string();
    let mut rays = 1 << 18;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--rays" => rays = it.next().ok_or("--rays N")?.parse().map_err(|e| format!("--rays: {e}"))?,
            s => scene_arg = s.to_string(),
        }
    }
    let scene = load(&scene_arg)?;
    let accel = SceneAccel::build(&scene);
    let side = (rays as f64).sqrt() as usize;
    let sets = [
        ("primary closest", tile_packets(&primary_rays(&scene, side, side), side, side), true),
        ("incoherent closest", packets_of(&incoherent_rays(&scene, rays, 7)), true),
        ("incoherent any", packets_of(&incoherent_rays(&scene, rays, 7)), false),
        ("shadow any", packets_of(&shadow_rays(&scene, rays, 7)), false),
    ];
    println!("scene `{scene_arg}`, {:?} kernels, 1 thread; CPU ns per active ray", accel.simd());
    // Coherence: camera tiles of 4x2 rays whose pixels lie `stride` pixels apart (1024^2
    // image), all 8 lanes active; the packet query takes the packet traversal when the
    // lanes share direction signs and permutation.
    let (w, h) = (1024usize, 1024usize);
    let cam = primary_rays(&scene, w, h);
    println!("| tile pixel stride | packet | single rays | single / packet |");
    println!("|---:|---:|---:|---:|");
    for stride in [1usize, 2, 4, 8, 16, 32, 64] {
        let mut tiles = Vec::new();
        for ty in (0..h - stride).step_by(2 * stride.min(8)) {
            for tx in (0..w - 3 * stride).step_by(4 * stride.min(8)) {
                let lanes: Vec<_> =
                    (0..LANES).map(|i| cam[(ty + stride * (i / 4)) * w + tx + stride * (i % 4)]).collect();
                tiles.push(RayPacket::from_rays(&lanes));
            }
        }
        tiles.truncate(rays / LANES);
        let packet = ns_per_ray(&tiles, |p, a| accel.intersect_packet(p, a).mask as u32);
        let single = ns_per_ray(&tiles, |p, a| accel.intersect_packet_lanes(p, a).mask as u32);
        println!("| {stride} | {packet:.1} | {single:.1} | {:.2} |", single / packet);
    }
    println!("| rays | active lanes | packet | single rays | single / packet |");
    println!("|---|---:|---:|---:|---:|");
    for (name, packets, closest) in &sets {
        for k in (1..=LANES).rev() {
            // The first `k` lanes of every packet.
            let masked: Vec<(RayPacket, u8)> =
                packets.iter().map(|(p, a)| (*p, a & ((1u32 << k) - 1) as u8)).collect();
            let (packet, single) = if *closest {
                (
                    ns_per_ray(&masked, |p, a| accel.intersect_packet(p, a).mask as u32),
                    ns_per_ray(&masked, |p, a| accel.intersect_packet_lanes(p, a).mask as u32),
                )
            } else {
                (
                    ns_per_ray(&masked, |p, a| accel.occluded_packet(p, a) as u32),
                    ns_per_ray(&masked, |p, a| accel.occluded_packet_lanes(p, a) as u32),
                )
            };
            println!("| {name} | {k} | {packet:.1} | {single:.1} | {:.2} |", single / packet);
        }
    }
    Ok(())
}
