//! Criterion benchmark of single-ray queries: closest and any hit, primary and incoherent
//! rays, on a tiny scene (Cornell box or a 48-triangle cube), the bunny (when
//! `../shared/scenes` is present) and the 270k-triangle displaced sphere.
//!
//! `cargo bench -p filtrace-accel --bench rays`

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use filtrace_accel::bench::{incoherent_rays, primary_rays};
use filtrace_accel::{testmesh, SceneAccel};
use filtrace_scene::Scene;
use std::hint::black_box;
use std::path::PathBuf;

fn shared(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared").join(rel)
}

fn scenes() -> Vec<Scene> {
    let mut out = Vec::new();
    let mut add = |name: &str, mesh| {
        let mut s = Scene { name: name.to_string(), ..Scene::default() };
        s.add_mesh(mesh);
        out.push(s);
    };
    match testmesh::read_obj(&shared("scenes/cornell_box/cornell_box_lit.obj")) {
        Ok(m) => add("cornell", m),
        Err(_) => add("cube48", testmesh::subdivided_cube(2)),
    }
    match testmesh::read_obj(&shared("scenes/bunny/bunny.obj")) {
        Ok(m) => add("bunny", m),
        Err(e) => eprintln!("skipping bunny: {e}"),
    }
    add("displaced_sphere_270k", testmesh::displaced_sphere(150, 0.1));
    out
}

fn rays(c: &mut Criterion) {
    const N: usize = 1 << 14;
    for scene in scenes() {
        let accel = SceneAccel::build(&scene);
        let mut g = c.benchmark_group(scene.name.clone());
        g.throughput(Throughput::Elements(N as u64));
        let primary = primary_rays(&scene, 128, 128);
        let incoherent = incoherent_rays(&scene, N, 7);
        g.bench_function("primary_closest", |b| {
            b.iter(|| primary.iter().filter(|r| accel.intersect(black_box(r)).is_some()).count())
        });
        g.bench_function("incoherent_closest", |b| {
            b.iter(|| incoherent.iter().filter(|r| accel.intersect(black_box(r)).is_some()).count())
        });
        g.bench_function("incoherent_any", |b| {
            b.iter(|| incoherent.iter().filter(|r| accel.occluded(black_box(r))).count())
        });
        g.finish();
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = rays
}
criterion_main!(benches);
