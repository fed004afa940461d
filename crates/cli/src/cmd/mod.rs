//! One module per subcommand.

pub mod args;
pub mod bench;
pub mod bench_adaptive;
pub mod bench_animation;
pub mod bench_filters;
pub mod bench_pipeline;
pub mod bench_rays;
pub mod bench_render;
pub mod bench_suite;
pub mod bench_vpl;
pub mod compare;
pub mod denoise;
pub mod experiment;
pub mod frame_source;
pub mod output;
pub mod preview;
pub mod render;
pub mod render_args;
pub mod render_filtered;
pub mod render_output;
pub mod render_plain;
pub mod render_session;
pub mod render_vpl;
pub mod sequence;
pub mod sequence_files;
pub mod view;
