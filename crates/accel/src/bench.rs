//! Ray-casting throughput benchmark (the library side of `filtrace bench rays`).
//!
//! Three ray sets, generated deterministically from [`RayBenchOptions::seed`] before any
//! timing starts:
//! - **primary**: a `width x height` pinhole camera (45 degree vertical field of view)
//!   outside the scene's bounding box, looking at its centre, one ray per pixel;
//! - **incoherent**: `rays` rays with origins uniform in the bounding box and directions
//!   uniform on the sphere, `t` in `[0, inf)`; cast as closest-hit and as any-hit
//!   queries (the any-hit set uses the same rays, also with `t_max = inf`).
//!
//! - **shadow**: `rays` segments from origins uniform in the bounding box to points on a
//!   small quad (a fifth of the box's x and z extent) just below the top of the box, as
//!   towards a ceiling light, `t` in `[10^-4, 1 - 10^-4]`; any hit.
//!
//! The same sets are also cast as 8-ray packets ([`SceneAccel::intersect_packet`],
//! [`SceneAccel::occluded_packet`]): primary rays in 4x2 pixel tiles, the other sets as
//! eight consecutive rays (the `packet_*` fields).
//!
//! Rays are cast in parallel with rayon (chunks of 1024 rays) on the current pool;
//! throughput is total rays / wall time, best of `repeats` runs.

use crate::testmesh::SplitMix64;
use crate::{BuildParams, RayPacket, SceneAccel, LANES};
use filtrace_core::{Aabb, Ray, Vec3};
use filtrace_scene::Scene;
use rayon::prelude::*;
use serde::Serialize;
use std::time::Instant;

/// Options of [`ray_bench`].
#[derive(Clone, Debug, PartialEq)]
pub struct RayBenchOptions {
    /// Number of incoherent rays.
    pub rays: usize,
    /// Primary-ray image size.
    pub width: usize,
    pub height: usize,
    /// Seed of the ray generator.
    pub seed: u64,
    /// Each measurement is repeated this many times; the fastest run is reported.
    pub repeats: usize,
    pub build: BuildParams,
}

impl Default for RayBenchOptions {
    fn default() -> Self {
        Self { rays: 1 << 20, width: 1024, height: 1024, seed: 7, repeats: 3, build: BuildParams::default() }
    }
}

impl RayBenchOptions {
    /// A small configuration for smoke tests.
    pub fn quick() -> Self {
        Self { rays: 1 << 14, width: 128, height: 128, repeats: 1, ..Self::default() }
    }
}

/// Results of [`ray_bench`]; `*_mrays` are millions of rays per second over all threads.
#[derive(Clone, Debug, Serialize)]
pub struct RayBenchReport {
    pub scene: String,
    pub triangles: usize,
    /// Size of the rayon pool the rays were cast on.
    pub threads: usize,
    /// SIMD kernels of the bottom levels (`"Sse"` or `"Avx2"`, see [`crate::Simd`]).
    pub kernel: String,
    pub build_s: f64,
    pub primary_rays: usize,
    pub incoherent_rays: usize,
    pub primary_closest_mrays: f64,
    pub incoherent_closest_mrays: f64,
    pub incoherent_any_mrays: f64,
    /// Millions of rays per CPU-second summed over all threads (Linux; `None` elsewhere):
    /// the per-thread speed, insensitive to other processes sharing the machine.
    pub primary_closest_mrays_per_cpu_s: Option<f64>,
    pub incoherent_closest_mrays_per_cpu_s: Option<f64>,
    pub incoherent_any_mrays_per_cpu_s: Option<f64>,
    /// Fraction of rays that hit something, per query (a sanity check of the ray sets).
    pub primary_hit_fraction: f64,
    pub incoherent_hit_fraction: f64,
    pub incoherent_any_hit_fraction: f64,
    /// Shadow rays towards a small quad, single-ray any hit.
    pub shadow_rays: usize,
    pub shadow_any_mrays: f64,
    pub shadow_any_mrays_per_cpu_s: Option<f64>,
    pub shadow_hit_fraction: f64,
    /// The same queries as 8-ray packets (hit fractions equal the single-ray ones: the
    /// packet queries give the same answers).
    pub packet_primary_closest_mrays: f64,
    pub packet_incoherent_closest_mrays: f64,
    pub packet_incoherent_any_mrays: f64,
    pub packet_shadow_mrays: f64,
    pub packet_primary_closest_mrays_per_cpu_s: Option<f64>,
    pub packet_incoherent_closest_mrays_per_cpu_s: Option<f64>,
    pub packet_incoherent_any_mrays_per_cpu_s: Option<f64>,
    pub packet_shadow_mrays_per_cpu_s: Option<f64>,
    pub packet_primary_hit_fraction: f64,
    pub packet_incoherent_hit_fraction: f64,
    pub packet_incoherent_any_hit_fraction: f64,
    pub packet_shadow_hit_fraction: f64,
}

impl RayBenchReport {
    /// A Markdown table, totals and per-thread throughput.
    pub fn to_markdown(&self) -> String {
        let t = self.threads.max(1) as f64;
        let mut s = String::new();
        s.push_str(&format!(
            "scene `{}`: {} triangles, build {:.3} s, {} thread(s), {} kernels\n\n",
            self.scene, self.triangles, self.build_s, self.threads, self.kernel
        ));
        s.push_str("| query | rays | hit fraction | Mrays/s | Mrays/s per thread | Mrays per CPU-s |\n");
        s.push_str("|---|---:|---:|---:|---:|---:|\n");
        let rows = [
            (
                "primary closest",
                self.primary_rays,
                self.primary_hit_fraction,
                self.primary_closest_mrays,
                self.primary_closest_mrays_per_cpu_s,
            ),
            (
                "incoherent closest",
                self.incoherent_rays,
                self.incoherent_hit_fraction,
                self.incoherent_closest_mrays,
                self.incoherent_closest_mrays_per_cpu_s,
            ),
            (
                "incoherent any",
                self.incoherent_rays,
                self.incoherent_any_hit_fraction,
                self.incoherent_any_mrays,
                self.incoherent_any_mrays_per_cpu_s,
            ),
            (
                "shadow any",
                self.shadow_rays,
                self.shadow_hit_fraction,
                self.shadow_any_mrays,
                self.shadow_any_mrays_per_cpu_s,
            ),
            (
                "packet primary closest",
                self.primary_rays,
                self.packet_primary_hit_fraction,
                self.packet_primary_closest_mrays,
                self.packet_primary_closest_mrays_per_cpu_s,
            ),
            (
                "packet incoherent closest",
                self.incoherent_rays,
                self.packet_incoherent_hit_fraction,
                self.packet_incoherent_closest_mrays,
                self.packet_incoherent_closest_mrays_per_cpu_s,
            ),
            (
                "packet incoherent any",
                self.incoherent_rays,
                self.packet_incoherent_any_hit_fraction,
                self.packet_incoherent_any_mrays,
                self.packet_incoherent_any_mrays_per_cpu_s,
            ),
            (
                "packet shadow any",
                self.shadow_rays,
                self.packet_shadow_hit_fraction,
                self.packet_shadow_mrays,
                self.packet_shadow_mrays_per_cpu_s,
            ),
        ];
        for (name, n, hit, m, c) in rows {
            let c = c.map_or("n/a".to_string(), |c| format!("{c:.2}"));
            s.push_str(&format!("| {name} | {n} | {hit:.3} | {m:.2} | {:.2} | {c} |\n", m / t));
        }
        s
    }
}

/// The scene a benchmark driver names: `sphere:N` for `testmesh::displaced_sphere(N, 0.1)`
/// (`sphere:150` has 270k triangles), `blades:N` for `testmesh::thin_blades(N, 1)`, else a
/// scene file or built-in scene name.
pub fn bench_scene(spec: &str) -> Result<Scene, String> {
    if let Some(n) = spec.strip_prefix("blades:") {
        let n: usize = n.parse().map_err(|e| format!("blades:N: {e}"))?;
        let mut s = Scene { name: format!("thin_blades_{n}"), ..Scene::default() };
        s.add_mesh(crate::testmesh::thin_blades(n, 1));
        return Ok(s);
    }
    let Some(n) = spec.strip_prefix("sphere:") else {
        return filtrace_scene::load_scene(spec).map_err(|e| e.to_string());
    };
    let n: usize = n.parse().map_err(|e| format!("sphere:N: {e}"))?;
    let mut s = Scene { name: format!("displaced_sphere_{n}"), ..Scene::default() };
    s.add_mesh(crate::testmesh::displaced_sphere(n, 0.1));
    Ok(s)
}

/// Tight world-space bounds of every instanced triangle corner. (`Scene::bounds` boxes the
/// transformed object boxes, which is looser for rotated instances; the Embree script
/// uses the tight box, so the benchmark does too.)
pub fn triangle_bounds(scene: &Scene) -> Aabb {
    let mut b = Aabb::EMPTY;
    for inst in &scene.instances {
        let Some(mesh) = scene.meshes.get(inst.mesh as usize) else { continue };
        for tri in &mesh.indices {
            for &i in tri {
                if let Some(p) = mesh.positions.get(i as usize) {
                    b = b.grow_point(inst.transform.transform_point3(*p));
                }
            }
        }
    }
    b
}

/// Pinhole-camera rays through every pixel of a `width x height` image, looking at the
/// centre of `scene`'s [`triangle_bounds`] from outside (45 degree vertical field of view).
pub fn primary_rays(scene: &Scene, width: usize, height: usize) -> Vec<Ray> {
    let b = triangle_bounds(scene);
    if b.is_empty() || width == 0 || height == 0 {
        return Vec::new();
    }
    let c = b.center();
    let r = b.bounding_radius().max(1e-6);
    let eye = c + Vec3::new(0.5, 0.4, 1.0).normalize() * (2.4 * r);
    let w = (c - eye).normalize();
    let u = w.cross(Vec3::Y).normalize();
    let v = u.cross(w);
    let tan_half = (22.5f32).to_radians().tan();
    let aspect = width as f32 / height as f32;
    let mut rays = Vec::with_capacity(width * height);
    for y in 0..height {
        for x in 0..width {
            let sx = (2.0 * (x as f32 + 0.5) / width as f32 - 1.0) * tan_half * aspect;
            let sy = (1.0 - 2.0 * (y as f32 + 0.5) / height as f32) * tan_half;
            rays.push(Ray::new(eye, w + sx * u + sy * v));
        }
    }
    rays
}

/// `n` rays with origins uniform in [`triangle_bounds`] and directions uniform on the sphere.
pub fn incoherent_rays(scene: &Scene, n: usize, seed: u64) -> Vec<Ray> {
    let b = triangle_bounds(scene);
    if b.is_empty() {
        return Vec::new();
    }
    let mut rng = SplitMix64(seed);
    (0..n)
        .map(|_| {
            let o = b.min + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * b.extent();
            Ray::new(o, rng.unit_vector())
        })
        .collect()
}

/// `n` shadow segments from origins uniform in [`triangle_bounds`] to points on a small
/// quad just below the top of the box (see the module docs).
pub fn shadow_rays(scene: &Scene, n: usize, seed: u64) -> Vec<Ray> {
    let b = triangle_bounds(scene);
    if b.is_empty() {
        return Vec::new();
    }
    let e = b.extent();
    let c = Vec3::new(b.center().x, b.max.y - 0.01 * e.y, b.center().z);
    let mut rng = SplitMix64(seed ^ 0x5AD0);
    (0..n)
        .map(|_| {
            let o = b.min + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * e;
            let q = c + Vec3::new(rng.next_f32() - 0.5, 0.0, rng.next_f32() - 0.5) * 0.2 * e;
            Ray::segment(o, q - o, 1e-4, 1.0 - 1e-4)
        })
        .collect()
}

/// Rays as a path tracer's bounces cast them: from the hits of [`incoherent_rays`] on
/// the surfaces of `scene` (`accel` built from it), each origin moved off its surface by
/// `1.6e-6` of the scene's extent along the geometric normal (the renderer's offset), as
/// `(bounce, shadow)`: a bounce ray into the hemisphere of that side (`t` in `[0, inf)`),
/// and a shadow segment to a random point of a random emissive triangle (the quad of
/// [`shadow_rays`] in scenes without one), ending `10^-4` of its length short of it as the
/// renderer's (`t` in `[0, 1 - 10^-4]`). Consecutive rays come from unrelated points
/// (incoherent packets).
pub fn surface_rays(scene: &Scene, accel: &SceneAccel, n: usize, seed: u64) -> (Vec<Ray>, Vec<Ray>) {
    let b = triangle_bounds(scene);
    let e = b.extent();
    let offset = 1.6e-6 * e.max_element();
    let light = Vec3::new(b.center().x, b.max.y - 0.01 * e.y, b.center().z);
    let lights = emissive_triangles(scene);
    let mut rng = SplitMix64(seed ^ 0xB0B0);
    let (mut bounce, mut shadow) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for ray in incoherent_rays(scene, 2 * n, seed) {
        if bounce.len() == n {
            break;
        }
        let Some(hit) = accel.intersect(&ray) else { continue };
        let inst = &scene.instances[hit.instance as usize];
        let [p0, p1, p2] = scene.meshes[inst.mesh as usize].triangle(hit.prim as usize);
        let [p0, p1, p2] = [p0, p1, p2].map(|p| inst.transform.transform_point3(p));
        let mut normal = (p1 - p0).cross(p2 - p0).normalize_or_zero();
        if normal.dot(ray.dir) > 0.0 {
            normal = -normal;
        }
        let o = ray.origin + ray.dir * hit.t + normal * offset;
        let mut d = rng.unit_vector();
        if d.dot(normal) < 0.0 {
            d = -d;
        }
        bounce.push(Ray::new(o, d));
        let q = if lights.is_empty() {
            light + Vec3::new(rng.next_f32() - 0.5, 0.0, rng.next_f32() - 0.5) * 0.2 * e
        } else {
            let [a, b, c] = lights[(rng.next_f32() * lights.len() as f32) as usize % lights.len()];
            let (s, t) = (rng.next_f32(), rng.next_f32());
            let (s, t) = if s + t > 1.0 { (1.0 - s, 1.0 - t) } else { (s, t) };
            a + s * (b - a) + t * (c - a)
        };
        shadow.push(Ray::segment(o, q - o, 0.0, 1.0 - 1e-4));
    }
    (bounce, shadow)
}

/// The world-space corners of the triangles with emissive materials.
fn emissive_triangles(scene: &Scene) -> Vec<[Vec3; 3]> {
    let mut out = Vec::new();
    for (i, inst) in scene.instances.iter().enumerate() {
        let mesh = &scene.meshes[inst.mesh as usize];
        for p in 0..mesh.triangle_count() {
            let m = scene.material_of(i as u32, p as u32) as usize;
            if scene.materials.get(m).is_some_and(|m| m.is_emissive()) {
                out.push(mesh.triangle(p).map(|v| inst.transform.transform_point3(v)));
            }
        }
    }
    out
}

/// Groups `rays` into packets of eight consecutive rays (the last one partial).
pub fn packets_of(rays: &[Ray]) -> Vec<(RayPacket, u8)> {
    rays.chunks(LANES).map(RayPacket::from_rays).collect()
}

/// Groups row-major `width x height` camera rays into packets of 4x2 pixel tiles.
pub fn tile_packets(rays: &[Ray], width: usize, height: usize) -> Vec<(RayPacket, u8)> {
    let mut out = Vec::with_capacity(rays.len().div_ceil(LANES));
    for y in (0..height).step_by(2) {
        for x in (0..width).step_by(4) {
            let tile: Vec<Ray> = (0..LANES)
                .map(|i| (x + i % 4, y + i / 4))
                .filter(|&(px, py)| px < width && py < height)
                .filter_map(|(px, py)| rays.get(py * width + px).copied())
                .collect();
            if !tile.is_empty() {
                out.push(RayPacket::from_rays(&tile));
            }
        }
    }
    out
}

/// CPU time consumed so far by all threads of this process, in seconds, from
/// `/proc/self/task/*/schedstat` (nanosecond run time; Linux only, `None` elsewhere).
/// On a shared machine, rays per CPU-second is far steadier than rays per wall second.
pub fn process_cpu_seconds() -> Option<f64> {
    let mut ns = 0u64;
    for task in std::fs::read_dir("/proc/self/task").ok()? {
        let stat = std::fs::read_to_string(task.ok()?.path().join("schedstat")).ok()?;
        ns += stat.split_whitespace().next()?.parse::<u64>().ok()?;
    }
    Some(ns as f64 * 1e-9)
}

/// One measured query: best wall-clock and CPU throughput over the repeats.
struct Measured {
    mrays: f64,
    mrays_per_cpu_s: Option<f64>,
    hit_fraction: f64,
}

/// Casts `rays` in parallel with `query` (true = hit).
fn measure(rays: &[Ray], repeats: usize, query: impl Fn(&Ray) -> bool + Sync) -> Measured {
    if rays.is_empty() {
        return Measured { mrays: 0.0, mrays_per_cpu_s: None, hit_fraction: 0.0 };
    }
    let (mut wall, mut cpu) = (f64::INFINITY, None::<f64>);
    let mut hits = 0;
    for _ in 0..repeats.max(1) {
        let cpu0 = process_cpu_seconds();
        let start = Instant::now();
        hits = rays.par_chunks(1024).map(|c| c.iter().filter(|r| query(r)).count()).sum::<usize>();
        wall = wall.min(start.elapsed().as_secs_f64());
        if let (Some(a), Some(b)) = (cpu0, process_cpu_seconds()) {
            cpu = Some(cpu.map_or(b - a, |c| c.min(b - a)));
        }
    }
    let n = rays.len() as f64;
    Measured {
        mrays: n / wall / 1e6,
        mrays_per_cpu_s: cpu.map(|c| n / c / 1e6),
        hit_fraction: hits as f64 / n,
    }
}

/// Casts `packets` in parallel with `query` (the mask of lanes that hit).
fn measure_packets(
    packets: &[(RayPacket, u8)],
    repeats: usize,
    query: impl Fn(&RayPacket, u8) -> u8 + Sync,
) -> Measured {
    let n: usize = packets.iter().map(|p| p.1.count_ones() as usize).sum();
    if n == 0 {
        return Measured { mrays: 0.0, mrays_per_cpu_s: None, hit_fraction: 0.0 };
    }
    let (mut wall, mut cpu) = (f64::INFINITY, None::<f64>);
    let mut hits = 0;
    for _ in 0..repeats.max(1) {
        let cpu0 = process_cpu_seconds();
        let start = Instant::now();
        hits = packets
            .par_chunks(128)
            .map(|c| c.iter().map(|(p, a)| query(p, *a).count_ones() as usize).sum::<usize>())
            .sum::<usize>();
        wall = wall.min(start.elapsed().as_secs_f64());
        if let (Some(a), Some(b)) = (cpu0, process_cpu_seconds()) {
            cpu = Some(cpu.map_or(b - a, |c| c.min(b - a)));
        }
    }
    let n = n as f64;
    Measured {
        mrays: n / wall / 1e6,
        mrays_per_cpu_s: cpu.map(|c| n / c / 1e6),
        hit_fraction: hits as f64 / n,
    }
}

/// Builds the acceleration structure of `scene` and measures ray throughput (see the
/// module docs for the ray sets).
pub fn ray_bench(scene: &Scene, opts: &RayBenchOptions) -> RayBenchReport {
    let start = Instant::now();
    let accel = SceneAccel::build_with(scene, &opts.build);
    let build_s = start.elapsed().as_secs_f64();
    let primary = primary_rays(scene, opts.width, opts.height);
    let incoherent = incoherent_rays(scene, opts.rays, opts.seed);
    // Warm caches and the thread pool.
    measure(&incoherent[..incoherent.len().min(1 << 14)], 1, |r| accel.intersect(r).is_some());
    let p = measure(&primary, opts.repeats, |r| accel.intersect(r).is_some());
    let ic = measure(&incoherent, opts.repeats, |r| accel.intersect(r).is_some());
    let ia = measure(&incoherent, opts.repeats, |r| accel.occluded(r));
    let shadow = shadow_rays(scene, opts.rays, opts.seed);
    let sa = measure(&shadow, opts.repeats, |r| accel.occluded(r));
    let (primary8, incoherent8, shadow8) =
        (tile_packets(&primary, opts.width, opts.height), packets_of(&incoherent), packets_of(&shadow));
    let pp = measure_packets(&primary8, opts.repeats, |p, a| accel.intersect_packet(p, a).mask);
    let pic = measure_packets(&incoherent8, opts.repeats, |p, a| accel.intersect_packet(p, a).mask);
    let pia = measure_packets(&incoherent8, opts.repeats, |p, a| accel.occluded_packet(p, a));
    let ps = measure_packets(&shadow8, opts.repeats, |p, a| accel.occluded_packet(p, a));
    RayBenchReport {
        scene: scene.name.clone(),
        triangles: accel.triangle_count(),
        threads: rayon::current_num_threads(),
        kernel: format!("{:?}", accel.simd()),
        build_s,
        primary_rays: primary.len(),
        incoherent_rays: incoherent.len(),
        primary_closest_mrays: p.mrays,
        incoherent_closest_mrays: ic.mrays,
        incoherent_any_mrays: ia.mrays,
        primary_closest_mrays_per_cpu_s: p.mrays_per_cpu_s,
        incoherent_closest_mrays_per_cpu_s: ic.mrays_per_cpu_s,
        incoherent_any_mrays_per_cpu_s: ia.mrays_per_cpu_s,
        primary_hit_fraction: p.hit_fraction,
        incoherent_hit_fraction: ic.hit_fraction,
        incoherent_any_hit_fraction: ia.hit_fraction,
        shadow_rays: shadow.len(),
        shadow_any_mrays: sa.mrays,
        shadow_any_mrays_per_cpu_s: sa.mrays_per_cpu_s,
        shadow_hit_fraction: sa.hit_fraction,
        packet_primary_closest_mrays: pp.mrays,
        packet_incoherent_closest_mrays: pic.mrays,
        packet_incoherent_any_mrays: pia.mrays,
        packet_shadow_mrays: ps.mrays,
        packet_primary_closest_mrays_per_cpu_s: pp.mrays_per_cpu_s,
        packet_incoherent_closest_mrays_per_cpu_s: pic.mrays_per_cpu_s,
        packet_incoherent_any_mrays_per_cpu_s: pia.mrays_per_cpu_s,
        packet_shadow_mrays_per_cpu_s: ps.mrays_per_cpu_s,
        packet_primary_hit_fraction: pp.hit_fraction,
        packet_incoherent_hit_fraction: pic.hit_fraction,
        packet_incoherent_any_hit_fraction: pia.hit_fraction,
        packet_shadow_hit_fraction: ps.hit_fraction,
    }
}
