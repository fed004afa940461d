//! `filtrace bench ...`: each benchmark prints a markdown table, or one JSON object with `--json`.
//! One module per benchmark, each owned by the capability it measures.

use clap::Subcommand;

#[derive(Subcommand)]
pub enum Which {
    /// Ray casting throughput of the BVH on a mesh (OBJ, glTF or PLY).
    Rays(super::bench_rays::Args),
    /// Reconstruction filter timings (Dammertz Table 2, Bauszat Table 2 shapes).
    Filters(super::bench_filters::Args),
    /// Path tracer samples per second.
    Render(super::bench_render::Args),
    /// Filtered pipeline frame time per stage.
    Pipeline(super::bench_pipeline::Args),
    /// Adaptive sampling overheads (importance map, apportionment, batches).
    Adaptive(super::bench_adaptive::Args),
    /// The scene suite of issue 13: samples/s and ray throughput per scene.
    Suite(super::bench_suite::Args),
    /// Per-frame update cost and animated-vs-still sampling speed (one object moving).
    Animation(super::bench_animation::Args),
    /// VPL renderer milliseconds per stage (generation, cache, shading, optimisation).
    Vpl(super::bench_vpl::Args),
}

pub fn run(which: Which) -> anyhow::Result<()> {
    match which {
        Which::Rays(a) => super::bench_rays::run(a),
        Which::Filters(a) => super::bench_filters::run(a),
        Which::Render(a) => super::bench_render::run(a),
        Which::Pipeline(a) => super::bench_pipeline::run(a),
        Which::Adaptive(a) => super::bench_adaptive::run(a),
        Which::Suite(a) => super::bench_suite::run(a),
        Which::Animation(a) => super::bench_animation::run(a),
        Which::Vpl(a) => super::bench_vpl::run(a),
    }
}
