//! Options of `filtrace render` for the filtered pipeline (Bauszat et al. 2011) and for
//! adaptive sampling; flattened into `render::Args`.

/// Reconstruction filter options of `filtrace render`.
#[derive(clap::Args, Debug, Clone)]
pub struct FilterArgs {}

/// Adaptive sampling options of `filtrace render` (Bauszat et al. 2011, "Adaptive
/// sampling for geometry-aware reconstruction filters"; see docs/adaptive.md).
#[derive(clap::Args, Debug, Clone)]
pub struct AdaptiveArgs {
    /// Distribute the indirect-light samples by an importance map instead of uniformly.
    #[arg(long)]
    pub adaptive: bool,
    /// Frame budget in samples per pixel on average (total = budget-spp x pixels).
    #[arg(long, default_value_t = 4, requires = "adaptive")]
    pub budget_spp: u32,
    /// Minimum samples of every pixel (the paper: 1 or 2).
    #[arg(long, default_value_t = 1, requires = "adaptive")]
    pub min_spp: u32,
    /// Importance window radius, 1..=10 (the paper's "4x4" window is 2).
    #[arg(long, default_value_t = 2, requires = "adaptive", value_parser = clap::value_parser!(u32).range(1..=10))]
    pub importance_radius: u32,
    /// Drop the rounding remainder as the paper does (total may fall short of the budget)
    /// instead of distributing it exactly.
    #[arg(long, requires = "adaptive")]
    pub paper_rounding: bool,
}

impl AdaptiveArgs {
    /// The adaptive parameters these options select, or `None` without `--adaptive`.
    // Read by `filtrace render` once it flattens these options (pipeline engineer).
    #[allow(dead_code)]
    pub fn params(&self) -> Option<filtrace_adaptive::AdaptiveParams> {
        use filtrace_adaptive::{AdaptiveParams, ImportanceParams, Mode};
        self.adaptive.then(|| AdaptiveParams {
            importance: ImportanceParams::paper().with_radius(self.importance_radius as usize),
            budget_spp: self.budget_spp,
            min_spp: self.min_spp,
            mode: if self.paper_rounding { Mode::Paper } else { Mode::Exact },
        })
    }
}
