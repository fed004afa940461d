//! `filtrace render`: load a scene and render it, as one still image or as a sequence of
//! numbered frames of its animation (`--frames A..B`, `--frame N`; see `sequence`).
//!
//! The command reads top down through its modules, each importing only those below it:
//! `render_args` (the options), `render_session` (Ctrl-C, test hook, progress),
//! `render_output` (the EXR + PNG writer), then the renders: `render_plain` (path tracing in
//! progressive passes), `render_filtered` (the filtered pipeline and adaptive sampling),
//! `render_vpl` (the many-light renderer) and `sequence` (frames of an animation, with any
//! of them).
//!
//! Options that parse but do not combine (`--filter` with `--integrator vpl`, ...) are a
//! usage error, exit code 2 as clap's own, found before anything is loaded.

pub use super::render_args::{parse_resolution, CommonArgs, Resolution};
use super::render_filtered::{AdaptiveArgs, FilterArgs};
pub use super::render_session::Interrupted;
use super::sequence::SequenceArgs;

/// `filtrace render` options.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    #[command(flatten)]
    pub common: CommonArgs,
    #[command(flatten)]
    pub filter: FilterArgs,
    #[command(flatten)]
    pub adaptive: AdaptiveArgs,
    #[command(flatten)]
    pub sequence: SequenceArgs,
    #[command(flatten)]
    pub vpl: super::render_vpl::VplArgs,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    args.check_combinations()?;
    if args.sequence.is_sequence() {
        return super::sequence::run(&args.common, &args.filter, &args.adaptive, &args.vpl, &args.sequence);
    }
    args.sequence.check_still()?;
    if args.vpl.enabled() {
        return super::render_vpl::run(&args.common, &args.vpl);
    }
    // The filtered pipeline (and adaptive sampling, which drives it).
    if args.filter.enabled() || args.adaptive.adaptive {
        return super::render_filtered::run(&args.common, &args.filter, &args.adaptive);
    }
    super::render_plain::run(&args.common)
}

impl Args {
    /// Refuses options that parse but do not combine, naming them (a `clap::Error`, which
    /// `main` turns into exit code 2).
    fn check_combinations(&self) -> Result<(), clap::Error> {
        let conflicts: Vec<(bool, &str, &str)> = if self.vpl.enabled() {
            vec![
                (
                    self.filter.enabled(),
                    "the argument '--filter' cannot be used with '--integrator vpl'",
                    "the many-light renderer has no filtered pipeline; denoise its EXR with `filtrace denoise`",
                ),
                (
                    self.adaptive.adaptive,
                    "the argument '--adaptive' cannot be used with '--integrator vpl'",
                    "adaptive sampling drives the filtered pipeline",
                ),
                (
                    self.common.trace.is_some(),
                    "the argument '--trace' cannot be used with '--integrator vpl'",
                    "it chooses how the path tracer walks its paths; the VPL integrator has one way",
                ),
            ]
        } else {
            vec![
                (
                    self.vpl.ground_truth,
                    "the argument '--ground-truth' needs '--integrator vpl'",
                    "it is the exhaustive sum over the VPLs",
                ),
                (
                    self.vpl.vpl_clamp.is_some(),
                    "the argument '--vpl-clamp' needs '--integrator vpl'",
                    "it bounds the VPLs' geometry term",
                ),
            ]
        };
        match conflicts.iter().find(|(given, ..)| *given) {
            Some((_, what, why)) => {
                Err(clap::Error::raw(clap::error::ErrorKind::ArgumentConflict, format!("{what}: {why}\n")))
            }
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: super::Args,
    }

    fn render(extra: &[&str]) -> filtrace_io::ExrImage {
        let dir = std::env::temp_dir().join(format!("filtrace-rf-{}-{}", std::process::id(), extra.len()));
        let out = dir.join("f.exr");
        let mut argv = vec!["t", "cornell", "--res", "16x12", "--max-depth", "3", "--json"];
        let out_s = out.to_string_lossy().into_owned();
        argv.extend_from_slice(&["--out", &out_s]);
        argv.extend_from_slice(extra);
        let a = Cli::try_parse_from(argv).unwrap().args;
        super::super::render_filtered::run(&a.common, &a.filter, &a.adaptive).unwrap();
        let exr = filtrace_io::read_exr(&out).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        exr
    }

    #[test]
    fn filtered_render_writes_every_layer_and_colour_is_direct_plus_filtered_indirect() {
        let exr = render(&["--filter", "guided", "--filter-radius", "3", "--spp", "2"]);
        let layer = |n: &str| exr.layer(&[n]).unwrap_or_else(|| panic!("layer {n} missing"));
        let (color, direct, filtered) = (layer("color"), layer("direct"), layer("filtered"));
        for n in ["noisy", "indirect", "indirect_map", "filtered_map", "albedo", "normal", "depth"] {
            assert_eq!(layer(n).width(), 16, "{n}");
        }
        for i in 0..color.data().len() {
            let want = direct.data()[i] + filtered.data()[i];
            assert!((color.data()[i] - want).abs() <= 1e-5 * (1.0 + want.abs()));
        }
    }

    #[test]
    fn adaptive_render_adds_importance_and_path_count_layers() {
        let exr = render(&["--adaptive", "--budget-spp", "2"]);
        let counts = exr.layer(&["indirect_paths"]).expect("indirect_paths layer");
        let total: f32 = counts.data().iter().sum();
        assert_eq!(total, 2.0 * 16.0 * 12.0, "the budget is spent exactly");
        assert!(exr.layer(&["importance"]).is_some());
    }
}
