//! Options of `filtrace render` for the filtered pipeline (Bauszat et al. 2011) and for
//! adaptive sampling; flattened into `render::Args`.

/// Reconstruction filter options of `filtrace render`.
#[derive(clap::Args, Debug, Clone)]
pub struct FilterArgs {}

/// Adaptive sampling options of `filtrace render`.
#[derive(clap::Args, Debug, Clone)]
pub struct AdaptiveArgs {}
