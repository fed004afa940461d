//! `filtrace`: the command line of the filtrace renderer.
//!
//! Each subcommand lives in its own module under `cmd/` with its clap `Args` and a `run`.

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

mod cmd;

#[derive(Parser)]
#[command(name = "filtrace", version, about = "Path tracing with screen-space reconstruction filters")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene (built-in name, .toml, .obj, .gltf/.glb, .ply); default: the Cornell box.
    Render(cmd::render::Args),
    /// Denoise an EXR with a screen-space filter.
    Denoise(cmd::denoise::Args),
    /// Compare an image against a reference (MSE, relMSE, PSNR, SSIM, FLIP).
    Compare(cmd::compare::Args),
    /// Run an experiment spec: every method at every sample count against a reference.
    Experiment(cmd::experiment::Args),
    /// Interactive viewer: progressive when still, filtered at 1 spp while moving.
    View(cmd::view::Args),
    /// Benchmarks (print a markdown table, or JSON with --json).
    Bench {
        #[command(subcommand)]
        which: cmd::bench::Which,
    },
}

fn main() {
    exit_cleanly_on_println_failure();
    // The one CPU-feature check of the process: every SIMD path asks `cpu::isa()` after it.
    filtrace_core::cpu::isa();
    // The matches are kept: some checks need to know which options were given, not only
    // their values (a default is never a conflict).
    let matches = Cli::command().get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    let result = match cli.command {
        Command::Render(mut a) => {
            if let Some(m) = matches.subcommand_matches("render") {
                a.explicit_vpl = cmd::render::explicit_vpl_options(m);
            }
            cmd::render::run(a)
        }
        Command::Denoise(a) => cmd::denoise::run(a),
        Command::Compare(a) => cmd::compare::run(a),
        Command::Experiment(a) => cmd::experiment::run(a),
        Command::View(a) => cmd::view::run(a),
        Command::Bench { which } => cmd::bench::run(which),
    };
    if let Err(e) = result {
        if let Some(io) = cmd::output::stdout_failure(&e) {
            cmd::output::exit_on_stdout_failure(io);
        }
        // A cancelled render has written its partial output already.
        if e.downcast_ref::<cmd::render::Interrupted>().is_some() {
            std::process::exit(130);
        }
        // Options that parse but do not combine: a usage error, as clap's own (exit code 2).
        if let Some(usage) = e.downcast_ref::<clap::Error>() {
            usage.exit();
        }
        eprintln!("error: {}", error_chain(&e));
        std::process::exit(1);
    }
}

/// The error and its causes joined by ": ", skipping a cause whose text the message
/// already holds (many error types print their source in their own message too).
fn error_chain(e: &anyhow::Error) -> String {
    let mut msg = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if msg.contains(&text) {
            continue;
        }
        if !msg.is_empty() {
            msg.push_str(": ");
        }
        msg.push_str(&text);
    }
    msg
}

/// Results are printed through `cmd::output`, but a `println!` left anywhere (or in a
/// library) panics when stdout is a closed pipe or a full disk. This hook turns exactly
/// that panic (std's message "failed printing to stdout: ...") into the same clean exit;
/// every other panic keeps the default report. Tested by tests/outputs.rs through the
/// binary, so a change of std's wording is caught.
fn exit_cleanly_on_println_failure() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let text = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if let Some(cause) = text.strip_prefix("failed printing to stdout: ") {
            if cause.contains("Broken pipe") {
                std::process::exit(141);
            }
            eprintln!("error: cannot write to standard output: {cause}");
            std::process::exit(1);
        }
        default(info)
    }));
}
