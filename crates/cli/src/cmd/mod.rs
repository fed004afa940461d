//! One module per subcommand.

pub mod args;
pub mod bench;
pub mod bench_adaptive;
pub mod bench_filters;
pub mod bench_pipeline;
pub mod bench_rays;
pub mod bench_render;
pub mod bench_vpl;
pub mod compare;
pub mod denoise;
pub mod experiment;
pub mod output;
pub mod render;
pub mod render_filtered;
pub mod render_vpl;
