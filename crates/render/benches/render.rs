//! Path tracer throughput on the built-in Cornell box (max depth 8).
//!
//! `cargo bench -p filtrace-render --bench render` (criterion, 128 x 128 at 4 spp per
//! iteration on the global rayon pool). The headline number (samples/s at 512 x 512 on
//! 2 threads) comes from `filtrace_render::render_bench`; see `docs/perf-render.md`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use filtrace_render::{RenderSettings, Renderer};
use std::sync::atomic::AtomicBool;

fn cornell(c: &mut Criterion) {
    let settings = RenderSettings { width: 128, height: 128, spp: 4, max_depth: 8, seed: 0 };
    let renderer = Renderer::new(filtrace_scene::builtin("cornell").expect("cornell"), settings).unwrap();
    let cancel = AtomicBool::new(false);
    let mut group = c.benchmark_group("path");
    group.throughput(Throughput::Elements(128 * 128 * 4));
    group.sample_size(10);
    group.bench_function("cornell_128px_4spp", |b| b.iter(|| renderer.render(&cancel)));
    group.finish();
}

criterion_group!(benches, cornell);
criterion_main!(benches);
