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
//! Options that parse but do not combine (`--filter` with `--integrator vpl`, a VPL option
//! such as `--vpl-sampler` without it, ...) are a usage error, exit code 2 as clap's own,
//! found before anything is loaded.

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
    /// The VPL options given on the command line, as opposed to their defaults
    /// ([`explicit_vpl_options`]; filled by `main`, which holds the parsed matches).
    #[arg(skip)]
    pub explicit_vpl: Vec<&'static str>,
}

/// The options of the many-light renderer (clap id, flag, what it does): given without
/// `--integrator vpl`, the path tracer would render and silently ignore them.
const VPL_OPTIONS: [(&str, &str, &str); 7] = [
    ("vpls", "--vpls", "it sets the number of VPLs"),
    ("vpl_sampler", "--vpl-sampler", "it chooses how the importance cache samples the VPLs"),
    ("cache_points", "--cache-points", "it sets the importance cache's points"),
    ("cache_neighbours", "--cache-neighbours", "it sets the records interpolated per shading point"),
    ("cache_faint_share", "--cache-faint-share", "it sets which VPLs a cache record takes as visible"),
    ("ground_truth", "--ground-truth", "it is the exhaustive sum over the VPLs"),
    ("vpl_clamp", "--vpl-clamp", "it bounds the VPLs' geometry term"),
];

/// The VPL options `matches` (of `filtrace render`) got from the command line rather than
/// from their defaults (clap's value source), as their flags.
pub fn explicit_vpl_options(matches: &clap::ArgMatches) -> Vec<&'static str> {
    VPL_OPTIONS
        .iter()
        .filter(|(id, ..)| matches.value_source(id) == Some(clap::parser::ValueSource::CommandLine))
        .map(|&(_, flag, _)| flag)
        .collect()
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
        if !self.vpl.enabled() {
            return self.check_vpl_options_need_vpl();
        }
        let conflicts = [
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
        ];
        match conflicts.iter().find(|(given, ..)| *given) {
            Some((_, what, why)) => Err(usage_error(format!("{what}: {why}"))),
            None => Ok(()),
        }
    }

    /// Without `--integrator vpl`, the VPL options given on the command line are refused,
    /// all of them named: the path tracer would ignore them.
    fn check_vpl_options_need_vpl(&self) -> Result<(), clap::Error> {
        let given: Vec<_> =
            VPL_OPTIONS.iter().filter(|(_, flag, _)| self.explicit_vpl.contains(flag)).collect();
        let message = match given[..] {
            [] => return Ok(()),
            [(_, flag, why)] => format!(
                "the argument '{flag}' needs '--integrator vpl': {why} of the many-light renderer, \
                 which the path tracer would ignore; add --integrator vpl to render with it"
            ),
            _ => {
                let flags: Vec<String> = given.iter().map(|(_, flag, _)| format!("'{flag}'")).collect();
                format!(
                    "the arguments {} need '--integrator vpl': they are options of the many-light \
                     renderer, which the path tracer would ignore; add --integrator vpl to render with them",
                    flags.join(", ")
                )
            }
        };
        Err(usage_error(message))
    }
}

/// A usage error (exit code 2 in `main`, as clap's own).
fn usage_error(message: String) -> clap::Error {
    clap::Error::raw(clap::error::ErrorKind::ArgumentConflict, format!("{message}\n"))
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

    /// A VPL option counts as given when it is on the command line, even at its default
    /// value; without `--integrator vpl` the error names every one given.
    #[test]
    fn vpl_options_given_without_the_vpl_integrator_are_refused() {
        use clap::CommandFactory;
        let check = |argv: &[&str]| {
            let m = Cli::command().try_get_matches_from(argv).unwrap();
            let mut a = Cli::try_parse_from(argv).unwrap().args;
            a.explicit_vpl = super::explicit_vpl_options(&m);
            a.check_combinations().map_err(|e| e.to_string())
        };
        assert!(check(&["t", "cornell", "--spp", "2"]).is_ok(), "defaults are not given");
        assert!(check(&["t", "--integrator", "vpl", "--vpls", "64", "--ground-truth"]).is_ok());
        let one = check(&["t", "--vpls", "2048"]).unwrap_err();
        assert!(
            one.contains("'--vpls' needs '--integrator vpl'") && one.contains("add --integrator vpl"),
            "{one}"
        );
        let two =
            check(&["t", "--integrator", "path", "--cache-neighbours", "3", "--vpl-sampler", "balance"]);
        let two = two.unwrap_err();
        assert!(two.contains("'--vpl-sampler', '--cache-neighbours' need '--integrator vpl'"), "{two}");
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
