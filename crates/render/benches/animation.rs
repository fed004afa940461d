//! The per-frame renderer (`filtrace_render::frame_bench`): a frame update when one ball
//! of 960 triangles rolls over a meadow of a million triangles, against building the
//! renderer anew, and a small render of the animated frame against the still one.
//!
//! `cargo bench -p filtrace-render --bench animation` (criterion). `filtrace bench
//! animation` prints the same comparison as a table.

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use filtrace_render::frame_bench::{moving_object_scene, still_at, FRAMES};
use filtrace_render::{RenderSettings, Renderer};
use std::hint::black_box;
use std::sync::atomic::AtomicBool;

fn settings() -> RenderSettings {
    RenderSettings { width: 64, height: 36, spp: 1, max_depth: 8, seed: 0 }
}

fn updates(c: &mut Criterion) {
    let scene = moving_object_scene(200_000).expect("scene");
    let mut renderer = Renderer::new(scene.clone(), settings()).expect("renderer");
    let mut frame = 0;
    let mut group = c.benchmark_group("animation");
    group.bench_function("frame update (1 of 1M triangles moving)", |b| {
        b.iter(|| {
            frame = (frame + 1) % FRAMES;
            black_box(renderer.prepare_frame(frame).expect("frame"))
        })
    });
    group.sample_size(10);
    let still = still_at(&scene, FRAMES / 2).expect("still");
    group.bench_function("full build (1M triangles)", |b| {
        b.iter_batched(
            || still.clone(),
            |s| black_box(Renderer::new(s, settings()).expect("renderer")),
            BatchSize::LargeInput,
        )
    });
    let cancel = AtomicBool::new(false);
    renderer.prepare_frame(FRAMES / 2).expect("frame");
    let built = Renderer::new(still, settings()).expect("renderer");
    group.bench_function("render animated frame", |b| b.iter(|| black_box(renderer.render(&cancel))));
    group.bench_function("render still frame", |b| b.iter(|| black_box(built.render(&cancel))));
    group.finish();
}

criterion_group!(benches, updates);
criterion_main!(benches);
