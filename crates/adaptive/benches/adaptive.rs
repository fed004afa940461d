//! Criterion benchmarks of the three passes at 1024x768 (the paper's resolution):
//! importance map per window radius, apportionment (exact vs paper), batch schedule.
//! `cargo bench -p filtrace-adaptive`.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use filtrace_adaptive::synthetic::grass_gbuffer;
use filtrace_adaptive::{apportion, importance_map, BatchSchedule, ImportanceParams, Mode};

fn passes(c: &mut Criterion) {
    let (w, h) = (1024, 768);
    let (normal, position) = grass_gbuffer(w, h, 1500, 1);
    let mut g = c.benchmark_group("importance_map");
    g.sample_size(10);
    for r in [1, 2, 4] {
        let p = ImportanceParams::paper().with_radius(r);
        g.bench_with_input(BenchmarkId::from_parameter(r), &p, |b, p| {
            b.iter(|| importance_map(&normal, &position, p).unwrap())
        });
    }
    g.finish();

    let imp = importance_map(&normal, &position, &ImportanceParams::paper()).unwrap();
    let budget = 4 * (w * h) as u64;
    let mut g = c.benchmark_group("apportion");
    g.sample_size(10);
    for (name, mode) in [("exact", Mode::Exact), ("paper", Mode::Paper)] {
        g.bench_function(name, |b| b.iter(|| apportion(&imp, budget, 1, mode).unwrap()));
    }
    g.finish();

    let counts = apportion(&imp, budget, 1, Mode::Exact).unwrap();
    c.bench_function("schedule_scan", |b| b.iter(|| BatchSchedule::new(&counts, w * h).unwrap()));
}

criterion_group!(benches, passes);
criterion_main!(benches);
