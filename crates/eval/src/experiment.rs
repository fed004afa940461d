//! Experiments: every method at every sample count on every scene, against a reference.
//!
//! A spec is a TOML file (see `experiments/*.toml`):
//!
//! ```toml
//! name = "bauszat-fig8"
//! width = 256
//! height = 256
//! max_depth = 3          # Mitsuba convention: 3 = direct light + one indirect bounce
//! seed = 1
//! spp = [1, 4]           # eye samples per pixel of each method
//! repeats = 1            # timing runs per cell (median reported)
//! # metric = "relmse"    # or "relmse-clamped" (the thesis's); what the plots show
//! # equal_time = "guided"  # equal-time tables at this method's measured times
//!
//! [reference]
//! spp = 1024             # rendered once, cached by a hash of its settings
//! # ground_truth = "vpl" # instead: the exhaustive VPL sum on each method's own samples
//!
//! [[scenes]]
//! name = "cornell-box"
//! # reference_file = "../shared/reference/cornell_mitsuba_4096spp.exr"  # instead of rendering
//! # crop = [x, y, w, h]  # zoomed crop shown in the report (default: centre quarter)
//!
//! [[methods]]
//! name = "guided"        # label
//! filter = "guided"      # none | atrous | guided | bilateral
//! preset = "paper"       # optional, the filter's named preset
//! # indirect_paths = 1   # paths per guide ray (default 1; "spp" = as many as eye samples)
//! # filter_direct = false
//! ```
//!
//! Many-light methods (the VPL renderer, issue 14) name a `sampler` instead of a filter:
//!
//! ```toml
//! [reference]
//! ground_truth = "vpl"   # each method at n spp against the exhaustive VPL sum, same VPLs, samples 0..n
//!
//! [vpl]                  # the VPL set and the methods' defaults
//! vpls = 2048            # one eighth on the lights
//! # clamp = 0.01         # geometry-term bound, fraction of the scene radius (default off)
//! cache_points = 256
//! neighbours = 2         # M
//! distributions = 4      # uniform included: 1 uniform, 2 +full, 3 +unoccluded, 4 +bounded
//!
//! [[methods]]
//! name = "alpha-max-M3"
//! sampler = "alpha-max"  # uniform | alpha-max | balance | balance-cv | optimized
//! neighbours = 3
//! ```
//!
//! The crate sees only images: a [`Backend`] (the CLI, on top of the renderers and the
//! filtered pipeline) renders references and runs methods; this module orders the work,
//! caches references, measures the error and collects [`Results`], which
//! [`crate::report`] turns into `report.html`, `results.json` and `results.csv`.

mod results;
mod runner;
mod spec;
mod vpl_spec;

pub use results::*;
pub use runner::{run_experiment, run_experiment_with_cache};
pub use spec::*;
