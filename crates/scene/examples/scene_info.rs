//! Loads scenes (built-in names or files) and prints what they hold and how long loading took:
//! `cargo run --release -p filtrace-scene --example scene_info -- cornell ../shared/scenes/bunny/bunny.obj`

use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let names = if args.is_empty() { vec!["cornell".to_string()] } else { args };
    let mut failed = false;
    for arg in names {
        let t0 = Instant::now();
        match filtrace_scene::load_scene(&arg) {
            Ok(s) => {
                let unique: usize = s.meshes.iter().map(|m| m.triangle_count()).sum();
                let b = s.bounds();
                println!(
                    "{arg}: {:.1} ms, {} triangles ({unique} unique), {} meshes, {} instances, {} materials, \
                     {} textures, {} lights, camera {}, {} degenerate skipped, {} warnings, bounds {:?}..{:?}",
                    t0.elapsed().as_secs_f64() * 1e3,
                    s.triangle_count(),
                    s.meshes.len(),
                    s.instances.len(),
                    s.materials.len(),
                    s.textures.len(),
                    s.lights.len(),
                    if s.camera.is_some() { "yes" } else { "no" },
                    s.stats.degenerate_triangles_skipped,
                    s.stats.warnings.len(),
                    b.min.to_array(),
                    b.max.to_array(),
                );
                for w in &s.stats.warnings {
                    println!("  warning: {w}");
                }
            }
            Err(e) => {
                eprintln!("{arg}: error: {e}");
                failed = true;
            }
        }
    }
    if failed {
        std::process::exit(1);
    }
}
