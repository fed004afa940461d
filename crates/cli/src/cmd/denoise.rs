//! `filtrace denoise IN.exr --filter atrous|guided|bilateral --out OUT.exr`: filters the
//! colour (or indirect) layer of an EXR with one of `filtrace-denoise`'s filters, guided by
//! the G-buffer layers of the same file (normal, position, depth, albedo) or of separate
//! files (`--normal N.exr`, ...). Layer names of other renderers (Blender, Mitsuba 3) are
//! understood through `filtrace_io::aliases`.
//!
//! With an albedo layer the illumination `colour / albedo` is filtered and re-modulated
//! (Dammertz et al. 2010, deferred shading) unless `--no-demodulate`. With
//! `--layer indirect`, the output colour is `direct + filtered indirect` when the file has a
//! direct layer.
//!
//! Default layer: each filter's own design. À-Trous filters the full colour (Dammertz et
//! al. 2010: its colour edge-stopping term keeps shadow edges). The guided and
//! cross-bilateral filters see only geometry, so they blur what the guides do not show
//! (shadow edges of direct light): Bauszat et al. 2011 filter the indirect light and add the
//! direct light unfiltered. They default to `--layer indirect` when the file has an
//! indirect layer (docs/perf-filters.md has the errors of both choices), else filter the
//! colour with a note.
//!
//! Output: `--out` must name an `.exr`; a tonemapped PNG is written beside it, as `render`
//! does. An input layer without a single valid value (all NaN, or >= 1e30) is an error,
//! never a black image. Non-finite input values are reported and never spread (see
//! `filtrace_denoise::gbuffer`). Guides a filter's preset wants but the file lacks are
//! dropped with a warning (e.g. Mitsuba's AOVs have no position: the position weight is
//! switched off; without depth the guided filter uses normal-only guidance).

use anyhow::{bail, Context};
use filtrace_core::Image;
use filtrace_denoise::gbuffer::is_valid_color;
use filtrace_denoise::{AtrousParams, BilateralParams, Filter, GBuffer, Guidance, GuidedParams};
use filtrace_io::{read_exr, write_exr, write_png, ExrImage, TonemapParams};
use std::path::{Path, PathBuf};

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum FilterKind {
    Atrous,
    Guided,
    Bilateral,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layer {
    /// The full colour (`R,G,B`).
    #[value(alias = "color")]
    Colour,
    /// The indirect illumination (`indirect.R/G/B`).
    Indirect,
}

#[derive(clap::Args)]
pub struct Args {
    /// Input EXR (as written by `filtrace render`, or AOVs of another renderer).
    pub input: PathBuf,
    /// Output EXR (must end in .exr); a tonemapped PNG is written beside it.
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, value_enum, default_value = "atrous")]
    pub filter: FilterKind,
    /// Layer to filter [default: atrous: colour; guided and bilateral: indirect when the
    /// file has one (direct light added unfiltered, as Bauszat et al. 2011), else colour].
    #[arg(long, value_enum)]
    pub layer: Option<Layer>,
    /// À-Trous iterations (1-10; paper: 5).
    #[arg(long)]
    pub iterations: Option<u32>,
    /// Window radius of the guided (paper: 24; 1-1024) or cross-bilateral (16; 1-64) filter.
    #[arg(long)]
    pub radius: Option<u32>,
    /// Guided filter: eps of the normal channels (paper: 0.01; finite, > 0).
    #[arg(long)]
    pub eps_normal: Option<f32>,
    /// Guided filter: eps of the depth channel (paper: 0.01-0.03; finite, > 0).
    #[arg(long)]
    pub eps_depth: Option<f32>,
    /// Guided filter guidance channels: 1 (grey normal), 3 (normal), 4 (normal + depth).
    #[arg(long)]
    pub guidance: Option<u32>,
    /// Edge-stopping sigma of the colour term (`off` switches it off).
    #[arg(long)]
    pub sigma_color: Option<String>,
    /// Edge-stopping sigma of the normal term (`off` switches it off).
    #[arg(long)]
    pub sigma_normal: Option<String>,
    /// Edge-stopping sigma of the position term, in scene-scale units (`off` switches it off).
    #[arg(long)]
    pub sigma_position: Option<String>,
    /// Length positions and depth are divided by (finite, > 0; default: estimated from the
    /// image's surface pixels).
    #[arg(long)]
    pub scene_scale: Option<f32>,
    /// Filter the colour itself, not colour / albedo.
    #[arg(long)]
    pub no_demodulate: bool,
    /// Albedos below this are clamped when demodulating (0 < eps <= 1).
    #[arg(long, default_value_t = filtrace_denoise::DEFAULT_ALBEDO_EPS)]
    pub albedo_eps: f32,
    /// Read the normal from this EXR instead of IN.
    #[arg(long)]
    pub normal: Option<PathBuf>,
    /// Read the albedo from this EXR instead of IN.
    #[arg(long)]
    pub albedo: Option<PathBuf>,
    /// Read the position from this EXR instead of IN.
    #[arg(long)]
    pub position: Option<PathBuf>,
    /// Read the depth from this EXR instead of IN.
    #[arg(long)]
    pub depth: Option<PathBuf>,
}

/// `off` → `None`, a positive number → `Some`.
fn parse_sigma(name: &str, s: &Option<String>, default: Option<f32>) -> anyhow::Result<Option<f32>> {
    match s.as_deref() {
        None => Ok(default),
        Some("off" | "none") => Ok(None),
        Some(v) => {
            let x: f32 =
                v.parse().with_context(|| format!("--{name}: expected a number or `off`, got {v:?}"))?;
            if !(x.is_finite() && x > 0.0) {
                bail!("--{name} must be > 0 (or `off`), got {v}");
            }
            Ok(Some(x))
        }
    }
}

/// A guide layer from its own file (the named layer, else the file's colour) or from IN.
fn guide_layer(
    input: &ExrImage,
    own_file: &Option<PathBuf>,
    names: &[&str],
    what: &str,
) -> anyhow::Result<Option<Image>> {
    match own_file {
        Some(path) => {
            let exr = read_exr(path).with_context(|| format!("reading the {what} file"))?;
            let mut all: Vec<&str> = names.to_vec();
            all.push("color");
            Ok(Some(exr.require_layer(&all).with_context(|| format!("{}: no {what} layer", path.display()))?))
        }
        None => Ok(input.layer(names)),
    }
}

fn check_size(im: &Image, w: usize, h: usize, what: &str, path: &Path) -> anyhow::Result<()> {
    if im.width() != w || im.height() != h {
        bail!("{what} is {}x{} but {} is {w}x{h}: sizes must match", im.width(), im.height(), path.display());
    }
    Ok(())
}

fn report_non_finite(im: &Image, what: &str) {
    let n = im.count_non_finite();
    if n > 0 {
        eprintln!(
            "warning: {n} non-finite values in the {what} layer: treated as missing (never spread; \
             colour pixels are rebuilt from valid neighbours)"
        );
    }
}

/// Checks every float and count option before any work: finite and in range.
fn check_numbers(args: &Args) -> anyhow::Result<()> {
    let positive = |flag: &str, v: Option<f32>| -> anyhow::Result<()> {
        match v {
            Some(x) if !(x.is_finite() && x > 0.0) => bail!("--{flag} must be a finite number > 0, got {x}"),
            _ => Ok(()),
        }
    };
    positive("eps-normal", args.eps_normal)?;
    positive("eps-depth", args.eps_depth)?;
    positive("scene-scale", args.scene_scale)?;
    positive("albedo-eps", Some(args.albedo_eps))?;
    if args.albedo_eps > 1.0 {
        bail!("--albedo-eps must be <= 1 (albedos are reflectances), got {}", args.albedo_eps);
    }
    if let Some(n) = args.iterations.filter(|n| !(1..=10).contains(n)) {
        bail!("--iterations must be 1-10, got {n}");
    }
    let max_radius = if args.filter == FilterKind::Bilateral { 64 } else { 1024 };
    if let Some(r) = args.radius.filter(|r| !(1..=max_radius).contains(r)) {
        bail!("--radius must be 1-{max_radius} for the {:?} filter, got {r}", args.filter);
    }
    Ok(())
}

/// `--out`, checked before any work: an `.exr` name (the PNG goes beside it) that is not a
/// folder, in a folder that exists (created now).
fn prepare_output(out: &Path) -> anyhow::Result<()> {
    let is_exr = out.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    if !is_exr {
        bail!("--out {}: the output must be an .exr file (the PNG is written beside it)", out.display());
    }
    if out.is_dir() {
        bail!("--out {}: is a folder, expected an .exr file name", out.display());
    }
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create output folder {}", dir.display()))?;
    }
    Ok(())
}

/// The layer to filter: `--layer`, else the filter's design (see the module docs).
fn choose_layer(args: &Args, input: &ExrImage) -> Layer {
    if let Some(l) = args.layer {
        return l;
    }
    match args.filter {
        FilterKind::Atrous => Layer::Colour,
        FilterKind::Guided | FilterKind::Bilateral if input.layer(&["indirect"]).is_some() => Layer::Indirect,
        FilterKind::Guided | FilterKind::Bilateral => {
            eprintln!(
                "note: {} has no indirect layer: filtering the full colour. The {:?} filter sees only \
                 geometry and blurs shadow edges; it was designed for the indirect light (render with \
                 filtrace, which writes direct and indirect layers, for the better result)",
                args.input.display(),
                args.filter
            );
            Layer::Colour
        }
    }
}

/// Errors when no pixel of the layer to filter holds a usable value (all NaN, infinite or
/// >= 1e30): filtering it would give a black image that looks like a result.
fn require_valid_values(im: &Image, layer: Layer, path: &Path) -> anyhow::Result<()> {
    let valid = im.data().chunks_exact(3).filter(|px| px.iter().all(|v| is_valid_color(*v))).count();
    if valid == 0 && im.pixel_count() > 0 {
        bail!(
            "{}: the {layer:?} layer has no valid pixel (all {} pixels hold NaN, infinite or absurd \
             (>= 1e30) values): nothing to filter",
            path.display(),
            im.pixel_count()
        );
    }
    Ok(())
}

pub fn run(args: Args) -> anyhow::Result<()> {
    check_numbers(&args)?;
    prepare_output(&args.out)?;
    let input = read_exr(&args.input).with_context(|| format!("reading {}", args.input.display()))?;
    for w in input.warnings() {
        eprintln!("warning: {w}");
    }
    let (layer, noisy) = read_noisy_layer(&args, &input)?;
    let guide = read_guides(&args, &input)?;
    let filter = filter_from_args(&args, &guide)?;

    // Filter (illumination when an albedo is there).
    let start = std::time::Instant::now();
    let demodulate = guide.albedo.is_some() && !args.no_demodulate;
    let filtered = if demodulate {
        filter.apply_demodulated(&noisy, &guide, args.albedo_eps)?
    } else {
        filter.apply(&noisy, &guide)?
    };
    let ms = start.elapsed().as_secs_f64() * 1e3;
    let png = write_result(&args.out, &input, layer, &filtered)?;
    eprintln!(
        "{} {}x{} {layer:?} layer, {:?}{} in {ms:.1} ms -> {} and {}",
        filter.name(),
        input.width(),
        input.height(),
        filter,
        if demodulate { " (albedo demodulated)" } else { "" },
        args.out.display(),
        png.display()
    );
    Ok(())
}

/// The layer to filter and its values, checked: 3 channels, some valid pixel.
fn read_noisy_layer(args: &Args, input: &ExrImage) -> anyhow::Result<(Layer, Image)> {
    let layer = choose_layer(args, input);
    let layer_names: &[&str] = match layer {
        Layer::Colour => &["color"],
        Layer::Indirect => &["indirect"],
    };
    let noisy = input.require_layer(layer_names)?;
    if noisy.channels() != 3 {
        bail!("the {layer:?} layer has {} channels, expected 3", noisy.channels());
    }
    require_valid_values(&noisy, layer, &args.input)?;
    report_non_finite(&noisy, "input colour");
    Ok((layer, noisy))
}

/// The G-buffer: the normal (required), position, depth and albedo, each of the input's
/// size, from IN or their own files.
fn read_guides(args: &Args, input: &ExrImage) -> anyhow::Result<GBuffer> {
    let (w, h) = (input.width(), input.height());
    let normal = guide_layer(input, &args.normal, &["normal"], "normal")?.with_context(|| {
        format!(
            "{} has no normal layer (looked for normal, Normal, Denoising Normal, nn, ...; channels: {}); \
             give one with --normal FILE",
            args.input.display(),
            input.channel_names().join(", ")
        )
    })?;
    let position = guide_layer(input, &args.position, &["position"], "position")?;
    let depth = guide_layer(input, &args.depth, &["depth"], "depth")?;
    let albedo = guide_layer(input, &args.albedo, &["albedo"], "albedo")?;
    let checked = |im: Image, what: &str| -> anyhow::Result<Image> {
        check_size(&im, w, h, &format!("the {what} layer"), &args.input)?;
        report_non_finite(&im, what);
        Ok(im)
    };
    let mut guide = GBuffer::new(checked(normal, "normal")?);
    if let Some(p) = position {
        guide = guide.with_position(checked(p, "position")?);
    }
    if let Some(d) = depth {
        let d = if d.channels() == 1 { d } else { d.channels_range(0..1) };
        guide = guide.with_depth(checked(d, "depth")?);
    }
    if let Some(a) = albedo {
        guide = guide.with_albedo(checked(a, "albedo")?);
    }
    guide.scene_scale = args.scene_scale;
    Ok(guide)
}

/// Errors when `flag` was given (`set`) but applies to other filters only.
fn only_for(set: bool, flag: &str, filters: &str) -> anyhow::Result<()> {
    if set {
        bail!("{flag} applies to the {filters} filter only");
    }
    Ok(())
}

/// The filter's parameters: the paper preset, then the overrides.
fn filter_from_args(args: &Args, guide: &GBuffer) -> anyhow::Result<Filter> {
    let has_pos = guide.position.is_some() || guide.depth.is_some();
    let guided_flags = args.eps_normal.is_some() || args.eps_depth.is_some() || args.guidance.is_some();
    let sigma_flags =
        args.sigma_color.is_some() || args.sigma_normal.is_some() || args.sigma_position.is_some();
    Ok(match args.filter {
        FilterKind::Atrous => {
            only_for(args.radius.is_some(), "--radius", "guided and bilateral")?;
            only_for(guided_flags, "--eps-*/--guidance", "guided")?;
            let d = AtrousParams::paper();
            let (sigma_color, sigma_normal, sigma_position) =
                parse_sigmas(args, d.sigma_color, d.sigma_normal, d.sigma_position)?;
            Filter::Atrous(AtrousParams {
                iterations: args.iterations.unwrap_or(d.iterations),
                sigma_color,
                sigma_normal,
                sigma_position: position_weight(sigma_position, has_pos),
            })
        }
        FilterKind::Guided => {
            only_for(args.iterations.is_some(), "--iterations", "atrous")?;
            only_for(sigma_flags, "--sigma-*", "atrous and bilateral")?;
            Filter::Guided(guided_params(args, guide)?)
        }
        FilterKind::Bilateral => {
            only_for(args.iterations.is_some(), "--iterations", "atrous")?;
            only_for(guided_flags, "--eps-*/--guidance", "guided")?;
            let d = BilateralParams::reference();
            let radius = args.radius.unwrap_or(d.radius);
            let (sigma_color, sigma_normal, sigma_position) =
                parse_sigmas(args, d.sigma_color, d.sigma_normal, d.sigma_position)?;
            Filter::Bilateral(BilateralParams {
                radius,
                sigma_spatial: radius as f32 / 2.0,
                sigma_color,
                sigma_normal,
                sigma_position: position_weight(sigma_position, has_pos),
            })
        }
    })
}

/// `--sigma-color`, `--sigma-normal`, `--sigma-position` over the preset's sigmas, in
/// that order.
fn parse_sigmas(
    args: &Args,
    color: Option<f32>,
    normal: Option<f32>,
    position: Option<f32>,
) -> anyhow::Result<(Option<f32>, Option<f32>, Option<f32>)> {
    Ok((
        parse_sigma("sigma-color", &args.sigma_color, color)?,
        parse_sigma("sigma-normal", &args.sigma_normal, normal)?,
        parse_sigma("sigma-position", &args.sigma_position, position)?,
    ))
}

/// The position weight's sigma, switched off (with a warning) when no position or depth
/// layer is there to weigh by.
fn position_weight(sigma: Option<f32>, has_pos: bool) -> Option<f32> {
    if sigma.is_some() && !has_pos {
        eprintln!("warning: no position or depth layer: the position weight is switched off");
        return None;
    }
    sigma
}

/// The guided filter's parameters: `--guidance` (default normal + depth, normal-only
/// without a depth layer), radius and eps over the paper's preset.
fn guided_params(args: &Args, guide: &GBuffer) -> anyhow::Result<GuidedParams> {
    let d = GuidedParams::paper();
    let guidance = match args.guidance {
        None if guide.depth.is_none() => {
            eprintln!("warning: no depth layer: the guided filter uses normal-only guidance (3 channels)");
            Guidance::Normal
        }
        None | Some(4) => Guidance::NormalDepth,
        Some(3) => Guidance::Normal,
        Some(1) => Guidance::GreyNormal,
        Some(n) => bail!("--guidance must be 1, 3 or 4, got {n}"),
    };
    Ok(GuidedParams {
        radius: args.radius.unwrap_or(d.radius),
        guidance,
        eps_normal: args.eps_normal.unwrap_or(d.eps_normal),
        eps_depth: args.eps_depth.unwrap_or(d.eps_depth),
    })
}

/// Writes `--out` (colour: `direct + filtered indirect` when the indirect layer was
/// filtered and the file has a direct layer, plus the filtered layer itself) and the
/// tonemapped PNG beside it; returns the PNG's path.
fn write_result(
    out_path: &Path,
    input: &ExrImage,
    layer: Layer,
    filtered: &Image,
) -> anyhow::Result<PathBuf> {
    let result = match (layer, input.layer(&["direct"])) {
        (Layer::Indirect, Some(direct)) if direct.same_size(filtered) && direct.channels() == 3 => {
            let mut sum = filtered.clone();
            for (s, d) in sum.data_mut().iter_mut().zip(direct.data()) {
                *s += if d.is_finite() { *d } else { 0.0 };
            }
            sum
        }
        _ => filtered.clone(),
    };
    let mut out = ExrImage::new(input.width(), input.height());
    out.insert("", &["R", "G", "B"], &result)?;
    if layer == Layer::Indirect {
        out.insert("indirect_filtered", &["R", "G", "B"], filtered)?;
    }
    write_exr(out_path, &out).with_context(|| format!("writing {}", out_path.display()))?;
    let png = out_path.with_extension("png");
    write_png(&png, &result, &TonemapParams::srgb_clamp())
        .with_context(|| format!("writing {}", png.display()))?;
    Ok(png)
}
