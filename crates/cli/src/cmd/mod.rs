//! One module per subcommand.

pub mod bench;
pub mod compare;
pub mod denoise;
pub mod experiment;
pub mod render;
