//! `filtrace compare IMAGE.exr REFERENCE.exr`: MSE, relMSE, PSNR, SSIM and LDR-FLIP of an
//! image against a reference (definitions in `filtrace_eval::metrics`), and error maps:
//! `<image>.relmse.exr` / `.relmse.png` (per-pixel relative MSE; the PNG in false colour on
//! a log scale from 1e-4 (black) to 1 (yellow))
//! and `<image>.flip.exr` / `.flip.png` (the FLIP map, magma false colour).

use anyhow::Context;
use filtrace_eval::metrics::{self, Metrics};
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// The image to evaluate (EXR; its colour layer unless --layer says otherwise).
    pub image: PathBuf,
    /// The reference (EXR; its colour layer).
    pub reference: PathBuf,
    /// Layer of IMAGE to compare, e.g. `filtered` (names as in `filtrace_io::aliases`).
    #[arg(long, default_value = "color")]
    pub layer: String,
    /// Layer of REFERENCE to compare against.
    #[arg(long, default_value = "color")]
    pub reference_layer: String,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Folder for the error maps (default: beside IMAGE).
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
    /// Do not write error maps.
    #[arg(long)]
    pub no_maps: bool,
}

#[derive(Serialize)]
struct Report<'a> {
    image: &'a Path,
    reference: &'a Path,
    layer: &'a str,
    width: usize,
    height: usize,
    #[serde(flatten)]
    metrics: &'a Metrics,
    error_maps: Vec<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let read = |p: &Path, layer: &str| -> anyhow::Result<filtrace_core::Image> {
        let exr = filtrace_io::read_exr(p)?;
        Ok(exr.require_layer(&[layer])?)
    };
    let image = read(&args.image, &args.layer)?;
    let reference = read(&args.reference, &args.reference_layer)?;
    let maps = if args.no_maps { Vec::new() } else { prepare_maps(&args)? };
    let m = metrics::compare(&image, &reference).with_context(|| {
        format!("cannot compare {} with {}", args.image.display(), args.reference.display())
    })?;
    if !maps.is_empty() {
        write_maps(&maps, &image, &reference)?;
    }

    let mut out = super::output::stdout();
    if args.json {
        let report = Report {
            image: &args.image,
            reference: &args.reference,
            layer: &args.layer,
            width: image.width(),
            height: image.height(),
            metrics: &m,
            error_maps: maps,
        };
        writeln!(out, "{}", serde_json::to_string(&report)?)?;
        return Ok(out.flush()?);
    }
    writeln!(out, "{} ({}) vs {}", args.image.display(), args.layer, args.reference.display())?;
    writeln!(out, "  MSE     {:.6e}", m.mse)?;
    writeln!(out, "  relMSE  {:.6e}", m.rel_mse)?;
    match m.psnr {
        Some(p) => writeln!(out, "  PSNR    {p:.3} dB (peak 1.0, clamped)")?,
        None => writeln!(out, "  PSNR    inf (identical after clamping)")?,
    }
    writeln!(out, "  SSIM    {:.6}", m.ssim)?;
    writeln!(out, "  FLIP    {:.6}", m.flip)?;
    if m.nonfinite_image + m.nonfinite_reference > 0 {
        writeln!(
            out,
            "  warning: non-finite values read as 0: {} in the image, {} in the reference",
            m.nonfinite_image, m.nonfinite_reference
        )?;
    }
    for p in &maps {
        writeln!(out, "  wrote {}", p.display())?;
    }
    Ok(out.flush()?)
}

/// The error map files: `<stem>[.<layer>].{relmse,flip}.{exr,png}` in `--out-dir` or beside
/// IMAGE.
fn map_paths(args: &Args) -> Vec<PathBuf> {
    let dir = match &args.out_dir {
        Some(d) => d.clone(),
        None => args.image.parent().map(Path::to_path_buf).unwrap_or_default(),
    };
    let stem = args.image.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or("image".into());
    let stem = if args.layer == "color" { stem } else { format!("{stem}.{}", args.layer) };
    let mut paths = Vec::new();
    for name in ["relmse", "flip"] {
        for ext in ["exr", "png"] {
            paths.push(dir.join(format!("{stem}.{name}.{ext}")));
        }
    }
    paths
}

/// Refuses to write a map over either input (`compare x.exr x.relmse.exr` would overwrite
/// its reference) and checks every map can be written, before the maps are computed.
fn check_map_paths(args: &Args, maps: &[PathBuf]) -> anyhow::Result<()> {
    let inputs: Vec<PathBuf> =
        [&args.image, &args.reference].iter().filter_map(|p| std::fs::canonicalize(p).ok()).collect();
    for map in maps {
        if let Ok(canonical) = std::fs::canonicalize(map) {
            if inputs.contains(&canonical) {
                anyhow::bail!(
                    "the error map {} would overwrite an input image: rename the input, or use \
                     --out-dir or --no-maps",
                    map.display()
                );
            }
        }
        filtrace_io::check_writable(map).context("cannot write the error maps (see --out-dir, --no-maps)")?;
    }
    Ok(())
}

/// [`map_paths`], their folder created and each checked by [`check_map_paths`].
fn prepare_maps(args: &Args) -> anyhow::Result<Vec<PathBuf>> {
    let paths = map_paths(args);
    if let Some(dir) = paths[0].parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    check_map_paths(args, &paths)?;
    Ok(paths)
}

/// Computes and writes the relMSE and FLIP maps (EXR values, false-colour PNGs) to `paths`
/// (as [`map_paths`] orders them).
fn write_maps(
    paths: &[PathBuf],
    image: &filtrace_core::Image,
    reference: &filtrace_core::Image,
) -> anyhow::Result<()> {
    let relmse = metrics::rel_mse_map(image, reference)?;
    let flip = metrics::flip_map(image, reference)?;
    let relmse_shown = metrics::log_scale(&relmse, 1e-4, 1.0);
    let maps = [(&relmse, &relmse_shown), (&flip, &flip)];
    for ((map, shown), pair) in maps.into_iter().zip(paths.chunks(2)) {
        filtrace_io::write_image(&pair[0], map)?;
        filtrace_io::write_image(&pair[1], &metrics::false_color(shown))?;
    }
    Ok(())
}
