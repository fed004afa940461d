//! `filtrace`: the command line of the filtrace renderer.
//!
//! Each subcommand lives in its own module under `cmd/` with its clap `Args` and a `run`.

use clap::{Parser, Subcommand};

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
    /// Benchmarks (print a markdown table, or JSON with --json).
    Bench {
        #[command(subcommand)]
        which: cmd::bench::Which,
    },
}

fn main() {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(a) => cmd::render::run(a),
        Command::Denoise(a) => cmd::denoise::run(a),
        Command::Compare(a) => cmd::compare::run(a),
        Command::Experiment(a) => cmd::experiment::run(a),
        Command::Bench { which } => cmd::bench::run(which),
    };
    if let Err(e) = result {
        // A cancelled render has written its partial output already.
        if e.downcast_ref::<cmd::render::Interrupted>().is_some() {
            std::process::exit(130);
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
