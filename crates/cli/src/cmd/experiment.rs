//! `filtrace experiment SPEC.toml --out DIR`: every method of the spec at every sample count
//! on every scene, against a reference rendered once (cached under `DIR/cache` by a hash of
//! its settings) or read from a file; writes `DIR/report.html`, `DIR/results.json`,
//! `DIR/results.csv` and the PNGs the report shows. See `filtrace_eval::experiment` for the
//! spec format and `experiments/` for checked-in specs.

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use filtrace_core::Image;
use filtrace_eval::experiment::{run_experiment, Backend, ExperimentSpec, MethodRun, MethodSpec, SceneSpec};
use filtrace_pipeline::{FilterChoice, PipelineSettings};
use filtrace_render::{RenderSettings, Renderer};
use filtrace_scene::Scene;

#[derive(clap::Args)]
pub struct Args {
    /// The experiment spec (TOML).
    pub spec: PathBuf,
    /// Output folder (created).
    #[arg(long)]
    pub out: PathBuf,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub threads: Option<u32>,
}

/// Seed offset of references, so that a reference never shares sample streams with the
/// methods it judges.
const REFERENCE_SEED_OFFSET: u64 = 0x5eed_0000_0000;

/// The renderer and the filtered pipeline as an experiment backend.
pub struct PipelineBackend {
    /// Folder of the spec: scene files are looked up relative to it first.
    spec_dir: PathBuf,
    scenes: HashMap<String, Scene>,
}

impl PipelineBackend {
    pub fn new(spec_dir: &Path) -> Self {
        Self { spec_dir: spec_dir.to_path_buf(), scenes: HashMap::new() }
    }

    fn scene(&mut self, name: &str) -> Result<Scene, String> {
        if let Some(s) = self.scenes.get(name) {
            return Ok(s.clone());
        }
        let beside_spec = self.spec_dir.join(name);
        let arg =
            if beside_spec.is_file() { beside_spec.to_string_lossy().into_owned() } else { name.to_string() };
        let s = filtrace_scene::load_scene(&arg).map_err(|e| format!("cannot load scene '{name}': {e}"))?;
        self.scenes.insert(name.to_string(), s.clone());
        Ok(s)
    }
}

impl Backend for PipelineBackend {
    fn tag(&self) -> String {
        format!("filtrace-path-{}", env!("CARGO_PKG_VERSION"))
    }

    fn scene_fingerprint(&mut self, scene: &SceneSpec) -> Result<String, String> {
        // Everything the renderer reads is plain data with a Debug form: hash that.
        let s = self.scene(&scene.name)?;
        let text = format!(
            "{:?}|{:?}|{:?}|{:?}|{:?}|{:?}",
            s.meshes, s.instances, s.materials, s.textures, s.lights, s.camera
        );
        Ok(format!("{:016x}", filtrace_eval::experiment::fnv1a64(text.as_bytes())))
    }

    fn render_reference(&mut self, spec: &ExperimentSpec, scene: &SceneSpec) -> Result<Image, String> {
        let settings = RenderSettings {
            width: spec.width,
            height: spec.height,
            spp: spec.reference.spp,
            max_depth: spec.reference.max_depth.unwrap_or(spec.max_depth),
            seed: spec.seed.wrapping_add(REFERENCE_SEED_OFFSET),
        };
        let r = Renderer::new(self.scene(&scene.name)?, settings).map_err(|e| e.to_string())?;
        let film = r.render(&AtomicBool::new(false));
        Ok(film.aovs().color)
    }

    fn load_reference(&mut self, path: &Path) -> Result<Image, String> {
        let exr = filtrace_io::read_exr(path).map_err(|e| format!("{}: {e}", path.display()))?;
        exr.layer(&["color"]).ok_or_else(|| format!("{}: no colour (R, G, B) layer", path.display()))
    }

    fn run(
        &mut self,
        spec: &ExperimentSpec,
        scene: &SceneSpec,
        m: &MethodSpec,
        spp: u32,
    ) -> Result<MethodRun, String> {
        let choice = FilterChoice {
            name: m.filter.clone(),
            preset: m.preset.clone(),
            radius: m.params.get("radius").map(|v| *v as u32),
            iterations: m.params.get("iterations").map(|v| *v as u32),
        };
        let settings = PipelineSettings {
            width: spec.width,
            height: spec.height,
            spp,
            indirect_paths: m.indirect_paths_at(spp)?,
            seed: spec.seed,
            demodulate_albedo: true,
            filter_direct: m.filter_direct,
        };
        let mut p = super::render_filtered::build_pipeline(
            self.scene(&scene.name)?,
            settings,
            spec.max_depth,
            &choice,
        )
        .map_err(|e| format!("{e:#}"))?;
        let f = p.render_frame().map_err(|e| e.to_string())?;
        let stages = f.timings.stages().iter().map(|(n, ms)| (n.to_string(), *ms)).collect();
        Ok(MethodRun {
            image: f.images.color.clone(),
            noisy: Some(f.images.noisy.clone()),
            albedo: Some(f.images.guide.albedo.clone()),
            normal: Some(f.images.guide.normal.clone()),
            stages,
        })
    }
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let spec = ExperimentSpec::load(&a.spec).map_err(|e| anyhow::anyhow!("{e}"))?;
    std::fs::create_dir_all(&a.out).map_err(|e| anyhow::anyhow!("cannot create {}: {e}", a.out.display()))?;
    // Before the (long) runs, not after them.
    for name in ["report.html", "results.json", "results.csv"] {
        filtrace_io::check_writable(a.out.join(name))?;
    }
    let threads = a
        .threads
        .map(|t| t as usize)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let spec_dir = a.spec.parent().unwrap_or(Path::new(".")).to_path_buf();
    let bar = super::render_session::progress_bar(1, &spec.name);
    let mut backend = PipelineBackend::new(&spec_dir);
    let mut results = pool
        .install(|| {
            run_experiment(&spec, &spec_dir, &a.out, &mut backend, &mut |p| {
                bar.set_length(p.total as u64);
                bar.set_position(p.done as u64);
                bar.set_message(p.message.to_string());
            })
        })
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    bar.finish_and_clear();
    results.notes.push(format!("{threads} worker threads."));
    filtrace_eval::report::write_all(&a.out, &results).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut out = super::output::stdout();
    writeln!(out, "| scene | method | spp | relMSE | PSNR | frame ms |")?;
    writeln!(out, "|---|---|---:|---:|---:|---:|")?;
    for e in &results.entries {
        writeln!(
            out,
            "| {} | {} | {} | {:.4e} | {} | {:.1} |",
            e.scene,
            e.method,
            e.spp,
            e.errors.rel_mse,
            e.errors.psnr.map_or("inf".into(), |p| format!("{p:.2}")),
            e.total_ms
        )?;
    }
    writeln!(out, "wrote {}", a.out.join("report.html").display())?;
    Ok(out.flush()?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The whole experiment on the real renderer and pipeline at 16x16 (fast tier).
    #[test]
    fn tiny_spec_end_to_end_on_the_cornell_box() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments");
        let spec = ExperimentSpec::load(&dir.join("tiny.toml")).unwrap();
        let out = std::env::temp_dir().join(format!("filtrace-cli-exp-{}", std::process::id()));
        std::fs::remove_dir_all(&out).ok();
        let mut b = PipelineBackend::new(&dir);
        let r = run_experiment(&spec, &dir, &out, &mut b, &mut |_| {}).unwrap();
        filtrace_eval::report::write_all(&out, &r).unwrap();
        assert_eq!(r.entries.len(), 6);
        for e in &r.entries {
            assert!(e.errors.rel_mse.is_finite() && e.errors.rel_mse > 0.0, "{e:?}");
            assert_eq!(e.errors.nonfinite, 0);
            assert_eq!(e.stages.len(), 4);
        }
        for f in ["report.html", "results.json", "results.csv", "cornell-guided-2spp.png"] {
            assert!(out.join(f).is_file(), "{f}");
        }
        std::fs::remove_dir_all(&out).ok();
    }

    /// Every checked-in spec parses, and every method's filter choice is valid.
    #[test]
    fn checked_in_specs_are_valid() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments");
        let mut n = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let p = entry.unwrap().path();
            if p.extension().is_some_and(|e| e == "toml") {
                let spec = ExperimentSpec::load(&p).unwrap_or_else(|e| panic!("{e}"));
                for m in &spec.methods {
                    let c = FilterChoice {
                        name: m.filter.clone(),
                        preset: m.preset.clone(),
                        ..Default::default()
                    };
                    c.denoise_filter().unwrap_or_else(|e| panic!("{}: {e}", p.display()));
                }
                n += 1;
            }
        }
        assert!(n >= 3);
    }
}
