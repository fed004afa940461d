//! The options every rendering command shares ([`CommonArgs`]: scene, resolution, samples,
//! depth, seed, threads, output, tone mapping) and their parsers; flattened into
//! `render::Args` and read by the plain, filtered and sequence renders.

use anyhow::Context;
use filtrace_io::TonemapParams;
use filtrace_render::RenderSettings;
use std::path::{Path, PathBuf};

/// Samples per pixel without `--spp` (with `--adaptive`, the budget is used instead).
pub const DEFAULT_SPP: u32 = 64;

/// Largest accepted image side (same as the renderer's limit).
pub const MAX_SIDE: u32 = filtrace_render::renderer::MAX_SIDE;

/// Options every rendering command shares (also read by `render_filtered::run`).
#[derive(clap::Args, Debug, Clone)]
pub struct CommonArgs {
    /// Built-in scene name (`cornell`) or a scene file (.toml, .obj, .gltf/.glb, .ply).
    #[arg(default_value = "cornell")]
    pub scene: String,
    /// Samples per pixel [default: 64; with --adaptive: the --budget-spp].
    #[arg(long, value_name = "N")]
    pub spp: Option<u32>,
    /// Resolution as WIDTHxHEIGHT, each side 1..=32768.
    #[arg(long, default_value = "512x512", value_parser = parse_resolution)]
    pub res: Resolution,
    /// Maximum path depth, Mitsuba's convention: 1 = emitters only, 2 = direct light,
    /// -1 = unbounded.
    #[arg(long, default_value_t = 8, allow_negative_numbers = true)]
    pub max_depth: i32,
    /// Seed of the sampler (the image is a deterministic function of it).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub threads: Option<u32>,
    /// Output EXR (default: filtrace-out/<scene>.exr); the PNG is written beside it.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print one JSON object instead of the human summary.
    #[arg(long)]
    pub json: bool,
    /// Most samples per pixel added by one progressive pass (default: spp/16, at least 1);
    /// passes start at 1 sample and double up to it.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub passes_spp: Option<u32>,
    /// PNG exposure in stops (a finite number).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true, value_parser = super::args::finite_f32)]
    pub exposure: f32,
    /// PNG with a filmic curve instead of the plain sRGB clamp.
    #[arg(long)]
    pub filmic: bool,
    /// How the path tracer walks its paths: one at a time (`scalar`) or 8 in SIMD lockstep
    /// (`lockstep`). The image is bit-identical; only the speed differs. Default: the
    /// renderer's default.
    #[arg(long, value_enum)]
    pub trace: Option<TraceArg>,
    /// Do not light a bare mesh file (.obj, .ply, .gltf/.glb) that has no light of its own
    /// by the default sky and sun (docs/scenes.md); it then renders black, with a warning.
    #[arg(long)]
    pub no_default_light: bool,
}

/// `--trace` values (filtrace_render::TraceMode).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum TraceArg {
    Scalar,
    Lockstep,
}

impl TraceArg {
    pub fn mode(self) -> filtrace_render::TraceMode {
        match self {
            TraceArg::Scalar => filtrace_render::TraceMode::Scalar,
            TraceArg::Lockstep => filtrace_render::TraceMode::Lockstep,
        }
    }
}

/// The scene and resolution a benchmark renders (`bench render`, `pipeline`, `vpl`).
#[derive(clap::Args)]
pub struct BenchScene {
    /// Scene: a built-in name or a file.
    #[arg(default_value = "cornell")]
    pub scene: String,
    /// Resolution as WIDTHxHEIGHT, each side 1..=32768.
    #[arg(long, default_value = "512x512", value_parser = parse_resolution)]
    pub res: Resolution,
}

/// An image size parsed from `WxH`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Resolution {
    pub width: u32,
    pub height: u32,
}

impl Resolution {
    /// Renderer settings at this resolution (validated).
    pub fn settings(self, spp: u32, max_depth: i32, seed: u64) -> anyhow::Result<RenderSettings> {
        let s = RenderSettings { width: self.width, height: self.height, spp, max_depth, seed };
        s.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
        Ok(s)
    }
}

impl std::fmt::Display for Resolution {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}", self.width, self.height)
    }
}

/// Parses `WxH` (also `W*H`), each side in 1..=32768.
pub fn parse_resolution(s: &str) -> Result<Resolution, String> {
    let malformed = || format!("'{s}' is not a resolution: expected WIDTHxHEIGHT, e.g. 512x512");
    let (w, h) = s.trim().split_once(['x', 'X', '*']).ok_or_else(malformed)?;
    let side = |v: &str| v.trim().parse::<u64>().map_err(|_| malformed());
    let (w, h) = (side(w)?, side(h)?);
    if w == 0 || h == 0 {
        return Err(format!("resolution {w}x{h} has no pixels: both sides must be at least 1"));
    }
    if w > MAX_SIDE as u64 || h > MAX_SIDE as u64 {
        return Err(format!("resolution {w}x{h} is too large: at most {MAX_SIDE} per side"));
    }
    Ok(Resolution { width: w as u32, height: h as u32 })
}

impl CommonArgs {
    /// Loads the scene argument with the load options these flags select.
    pub fn load_scene(&self) -> Result<filtrace_scene::Scene, filtrace_scene::SceneError> {
        let options = filtrace_scene::LoadOptions { default_light: !self.no_default_light };
        filtrace_scene::load_scene_with(&self.scene, &options)
    }

    /// The renderer settings these options select (validated).
    pub fn settings(&self) -> anyhow::Result<RenderSettings> {
        self.res.settings(self.spp(), self.max_depth, self.seed)
    }

    /// `--spp`, or [`DEFAULT_SPP`].
    pub fn spp(&self) -> u32 {
        self.spp.unwrap_or(DEFAULT_SPP)
    }

    /// A short name for the scene: the built-in name or the file stem.
    pub fn scene_name(&self) -> String {
        let p = Path::new(&self.scene);
        match p.extension() {
            Some(_) => p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or("scene".into()),
            None => p.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or("scene".into()),
        }
    }

    /// The EXR path: `--out`, or `filtrace-out/<scene>.exr`.
    pub fn output_path(&self) -> PathBuf {
        self.out
            .clone()
            .unwrap_or_else(|| PathBuf::from("filtrace-out").join(format!("{}.exr", self.scene_name())))
    }

    /// [`CommonArgs::output_path`], checked before any work: it must end in `.exr`, its
    /// folder is created now, and the EXR and the PNG beside it must be writable
    /// ([`filtrace_io::check_writable`]), so that a long render never fails at the end for
    /// want of a place to write.
    pub fn prepare_output(&self) -> anyhow::Result<PathBuf> {
        let out = self.output_path();
        let is_exr = out.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("exr"));
        if !is_exr {
            anyhow::bail!(
                "--out {}: the output must be an .exr file (the PNG is written beside it)",
                out.display()
            );
        }
        if out.is_dir() {
            anyhow::bail!("--out {}: is a folder, expected an .exr file name", out.display());
        }
        if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create output folder {}", dir.display()))?;
        }
        for path in [out.clone(), out.with_extension("png")] {
            filtrace_io::check_writable(&path).context("the output cannot be written (see --out)")?;
        }
        Ok(out)
    }

    pub fn thread_count(&self) -> usize {
        self.threads
            .map(|t| t as usize)
            .unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1))
    }

    /// A rayon pool of [`CommonArgs::thread_count`] threads.
    pub fn thread_pool(&self) -> anyhow::Result<rayon::ThreadPool> {
        rayon::ThreadPoolBuilder::new()
            .num_threads(self.thread_count())
            .build()
            .context("cannot start the worker threads")
    }

    pub fn tonemap(&self) -> TonemapParams {
        let base = if self.filmic { TonemapParams::filmic() } else { TonemapParams::srgb_clamp() };
        TonemapParams { exposure: self.exposure, ..base }
    }

    /// Most samples per pixel per pass.
    pub fn pass_spp(&self) -> u32 {
        self.passes_spp.unwrap_or((self.spp() / 16).max(1)).min(self.spp().max(1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resolution_parsing() {
        assert_eq!(parse_resolution("640x480"), Ok(Resolution { width: 640, height: 480 }));
        assert_eq!(parse_resolution(" 32X16 "), Ok(Resolution { width: 32, height: 16 }));
        assert_eq!(parse_resolution("1x32768").unwrap().height, 32768);
        for bad in ["abc", "0x0", "10x0", "x10", "10x", "-5x10", "32769x1", "1.5x2", "99999999999999999999x1"]
        {
            let e = parse_resolution(bad).unwrap_err();
            assert!(!e.is_empty(), "{bad}");
        }
        assert!(parse_resolution("0x4").unwrap_err().contains("at least 1"));
        assert!(parse_resolution("40000x4").unwrap_err().contains("too large"));
        assert!(parse_resolution("abc").unwrap_err().contains("WIDTHxHEIGHT"));
    }
}
