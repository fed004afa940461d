//! `filtrace compare IMAGE.exr REFERENCE.exr`: MSE, relMSE, PSNR, SSIM and LDR-FLIP of an
//! image against a reference (definitions in `filtrace_eval::metrics`), and error maps:
//! `<image>.relmse.exr` / `.relmse.png` (per-pixel relative MSE; the PNG in false colour on
//! a log scale from 1e-4 (black) to 1 (yellow))
//! and `<image>.flip.exr` / `.flip.png` (the FLIP map, magma false colour).

use anyhow::Context;
use filtrace_eval::metrics::{self, Metrics};
use serde::Serialize;
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
    let m = metrics::compare(&image, &reference).with_context(|| {
        format!("cannot compare {} with {}", args.image.display(), args.reference.display())
    })?;

    let mut maps = Vec::new();
    if !args.no_maps {
        let dir = match &args.out_dir {
            Some(d) => d.clone(),
            None => args.image.parent().map(Path::to_path_buf).unwrap_or_default(),
        };
        if !dir.as_os_str().is_empty() {
            std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
        }
        let stem = args.image.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or("image".into());
        let stem = if args.layer == "color" { stem } else { format!("{stem}.{}", args.layer) };
        let relmse = metrics::rel_mse_map(&image, &reference)?;
        let flip = metrics::flip_map(&image, &reference)?;
        let relmse_shown = metrics::log_scale(&relmse, 1e-4, 1.0);
        for (name, map, shown) in [("relmse", &relmse, &relmse_shown), ("flip", &flip, &flip)] {
            let exr = dir.join(format!("{stem}.{name}.exr"));
            let png = dir.join(format!("{stem}.{name}.png"));
            filtrace_io::write_image(&exr, map)?;
            filtrace_io::write_image(&png, &metrics::false_color(shown))?;
            maps.extend([exr, png]);
        }
    }

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
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    println!("{} ({}) vs {}", args.image.display(), args.layer, args.reference.display());
    println!("  MSE     {:.6e}", m.mse);
    println!("  relMSE  {:.6e}", m.rel_mse);
    match m.psnr {
        Some(p) => println!("  PSNR    {p:.3} dB (peak 1.0, clamped)"),
        None => println!("  PSNR    inf (identical after clamping)"),
    }
    println!("  SSIM    {:.6}", m.ssim);
    println!("  FLIP    {:.6}", m.flip);
    if m.nonfinite_image + m.nonfinite_reference > 0 {
        println!(
            "  warning: non-finite values read as 0: {} in the image, {} in the reference",
            m.nonfinite_image, m.nonfinite_reference
        );
    }
    for p in &maps {
        println!("  wrote {}", p.display());
    }
    Ok(())
}
