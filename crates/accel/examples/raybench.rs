//! Ray throughput from the command line, until `filtrace bench rays` is wired:
//!
//! `cargo run --release -p filtrace-accel --example raybench -- SCENE [--rays N] [--res WxH]
//!  [--threads T] [--repeats K] [--split B] [--spatial B] [--qnodes N] [--json] [--write-obj PATH]`
//!
//! `SCENE` is a scene file or built-in name (`filtrace_scene::load_scene`) or
//! `sphere:N` for `testmesh::displaced_sphere(N, 0.1)` (`sphere:150` has 270k triangles)
//! or `blades:N` for `testmesh::thin_blades(N, 1)` or `grass:N` for the dense grass with
//! N blades (`grass:220000` is the suite's grass-1m); `--split B` sets
//! `BuildParams::split_budget` (pre-splitting of long thin triangles), `--spatial B`
//! `BuildParams::spatial_split_budget` (spatial splits, SBVH; 0.3: up to 30 % more
//! references), `--qnodes N`
//! `BuildParams::min_quantized_triangles` (compressed 8-wide nodes from N triangles; `max`:
//! never).
//! `--write-obj` writes the world-space triangles as OBJ (for `scripts/embree_bench.py`).

use filtrace_accel::bench::{ray_bench, RayBenchOptions};

const USAGE: &str = "usage: raybench SCENE [--rays N] [--res WxH] [--threads T] [--repeats K]
  [--bins K] [--spatial-bins K] [--leaf N] [--ctrav C] [--flat N] [--block N] [--split B]
  [--spatial B] [--qnodes N|max] [--json] [--write-obj PATH]
SCENE: a scene file or built-in name, sphere:N, blades:N or grass:N
--split B: pre-splitting of long thin triangles, up to B*n extra references
--spatial B: spatial splits (SBVH), up to B*n extra references (0: off)
--qnodes N: compressed 8-wide nodes from N triangles (max: never)
RAYBENCH_STATS=1 prints the BVH statistics (SAH cost, references) to stderr
";
use filtrace_scene::builtin::{grass_with, GrassParams};
use filtrace_scene::Scene;
use std::io::Write;

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut opts = RayBenchOptions::default();
    let (mut threads, mut json, mut write_obj, mut spec) = (0usize, false, None, None);
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut val = || it.next().cloned().ok_or(format!("{a} needs a value"));
        match a.as_str() {
            "--rays" => opts.rays = val()?.parse().map_err(|e| format!("--rays: {e}"))?,
            "--threads" => threads = val()?.parse().map_err(|e| format!("--threads: {e}"))?,
            "--repeats" => opts.repeats = val()?.parse().map_err(|e| format!("--repeats: {e}"))?,
            "--res" => {
                let v = val()?;
                let (w, h) = v.split_once('x').ok_or("--res WxH")?;
                opts.width = w.parse().map_err(|e| format!("--res: {e}"))?;
                opts.height = h.parse().map_err(|e| format!("--res: {e}"))?;
            }
            "--bins" => opts.build.bins = val()?.parse().map_err(|e| format!("--bins: {e}"))?,
            "--spatial-bins" => {
                opts.build.spatial_bins = val()?.parse().map_err(|e| format!("--spatial-bins: {e}"))?
            }
            "--leaf" => opts.build.max_leaf_size = val()?.parse().map_err(|e| format!("--leaf: {e}"))?,
            "--ctrav" => opts.build.traversal_cost = val()?.parse().map_err(|e| format!("--ctrav: {e}"))?,
            "--flat" => opts.build.max_flat_triangles = val()?.parse().map_err(|e| format!("--flat: {e}"))?,
            "--block" => opts.build.leaf_block = val()?.parse().map_err(|e| format!("--block: {e}"))?,
            "--split" => opts.build.split_budget = val()?.parse().map_err(|e| format!("--split: {e}"))?,
            "--spatial" => {
                opts.build.spatial_split_budget = val()?.parse().map_err(|e| format!("--spatial: {e}"))?
            }
            "--qnodes" => {
                let v = val()?;
                opts.build.min_quantized_triangles =
                    if v == "max" { usize::MAX } else { v.parse().map_err(|e| format!("--qnodes: {e}"))? };
            }
            "--help" | "-h" => {
                print!("{USAGE}");
                return Ok(());
            }
            "--json" => json = true,
            "--write-obj" => write_obj = Some(val()?),
            s => spec = Some(s.to_string()),
        }
    }
    let spec = spec.ok_or(USAGE)?;
    let scene = match spec.strip_prefix("grass:") {
        // `grass:220000` is the suite's grass-1m (`filtrace bench suite`).
        Some(n) => {
            let blades = n.parse().map_err(|e| format!("grass:N: {e}"))?;
            let p = GrassParams { blades, ..GrassParams::dense() };
            grass_with(&p).map_err(|e| e.to_string())?
        }
        None => filtrace_accel::bench::bench_scene(&spec)?,
    };
    if let Some(path) = write_obj {
        write_world_obj(&scene, &path).map_err(|e| format!("{path}: {e}"))?;
    }
    if threads > 0 {
        rayon::ThreadPoolBuilder::new().num_threads(threads).build_global().map_err(|e| e.to_string())?;
    }
    if std::env::var_os("RAYBENCH_STATS").is_some() {
        eprintln!("{:?}", filtrace_accel::SceneAccel::build_with(&scene, &opts.build).stats());
    }
    let report = ray_bench(&scene, &opts);
    if json {
        println!("{}", serde_json::to_string_pretty(&report).map_err(|e| e.to_string())?);
    } else {
        print!("{}", report.to_markdown());
    }
    Ok(())
}

fn write_world_obj(scene: &Scene, path: &str) -> std::io::Result<()> {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut base = 1usize;
    for inst in &scene.instances {
        let mesh = &scene.meshes[inst.mesh as usize];
        for p in &mesh.positions {
            let p = inst.transform.transform_point3(*p);
            writeln!(f, "v {:e} {:e} {:e}", p.x, p.y, p.z)?;
        }
        for [a, b, c] in &mesh.indices {
            writeln!(f, "f {} {} {}", *a as usize + base, *b as usize + base, *c as usize + base)?;
        }
        base += mesh.positions.len();
    }
    f.flush()
}
