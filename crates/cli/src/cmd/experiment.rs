//! `filtrace experiment SPEC.toml... --out DIR`: every method of the spec at every sample
//! count on every scene, against a reference rendered once (cached under `DIR/cache` by a
//! hash of its settings) or read from a file; writes `DIR/report.html`, `DIR/results.json`,
//! `DIR/results.csv` and the PNGs the report shows (several specs: `DIR/<name>/...`, one
//! cache). See `filtrace_eval::experiment` for the spec format and `experiments/` for
//! checked-in specs; the many-light methods are in [`super::experiment_vpl`].

use anyhow::Context;
use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use filtrace_core::Image;
use filtrace_eval::experiment::{
    run_experiment_with_cache, Backend, Clock, ExperimentSpec, MethodRun, MethodSpec, SceneSpec,
};
use filtrace_pipeline::{FilterChoice, PipelineSettings};
use filtrace_render::{RenderSettings, Renderer};
use filtrace_scene::Scene;

#[derive(clap::Args)]
pub struct Args {
    /// The experiment spec(s) (TOML). With several, each writes into OUT/<its name> and
    /// all share the reference cache OUT/cache.
    #[arg(required = true, num_args = 1..)]
    pub spec: Vec<PathBuf>,
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
    fingerprints: HashMap<String, String>,
    /// The many-light methods and their ground truth.
    vpl: super::experiment_vpl::VplBackend,
}

impl PipelineBackend {
    pub fn new(spec_dir: &Path) -> Self {
        Self {
            spec_dir: spec_dir.to_path_buf(),
            scenes: HashMap::new(),
            fingerprints: HashMap::new(),
            vpl: Default::default(),
        }
    }

    fn scene(&mut self, name: &str) -> Result<Scene, String> {
        cached_scene(&mut self.scenes, &self.spec_dir, name)
    }
}

/// The scene `name` (a file beside the spec, else a built-in or a path), loaded once.
fn cached_scene(scenes: &mut HashMap<String, Scene>, spec_dir: &Path, name: &str) -> Result<Scene, String> {
    if let Some(s) = scenes.get(name) {
        return Ok(s.clone());
    }
    let beside_spec = spec_dir.join(name);
    let arg =
        if beside_spec.is_file() { beside_spec.to_string_lossy().into_owned() } else { name.to_string() };
    let s = filtrace_scene::load_scene(&arg).map_err(|e| format!("cannot load scene '{name}': {e}"))?;
    scenes.insert(name.to_string(), s.clone());
    Ok(s)
}

impl Backend for PipelineBackend {
    fn tag(&self) -> String {
        format!("filtrace-path-{}", env!("CARGO_PKG_VERSION"))
    }

    fn scene_fingerprint(&mut self, scene: &SceneSpec) -> Result<String, String> {
        if let Some(f) = self.fingerprints.get(&scene.name) {
            return Ok(f.clone());
        }
        // Everything the renderer reads is plain data with a Debug form: hash that.
        let s = self.scene(&scene.name)?;
        let text = format!(
            "{:?}|{:?}|{:?}|{:?}|{:?}|{:?}",
            s.meshes, s.instances, s.materials, s.textures, s.lights, s.camera
        );
        let f = format!("{:016x}", filtrace_eval::experiment::fnv1a64(text.as_bytes()));
        self.fingerprints.insert(scene.name.clone(), f.clone());
        Ok(f)
    }

    fn ground_truth_fingerprint(
        &mut self,
        spec: &ExperimentSpec,
        scene: &SceneSpec,
    ) -> Result<String, String> {
        // The VPLs too: a renderer that makes other VPLs never meets a stale ground truth.
        let f = self.scene_fingerprint(scene)?;
        let (scenes, dir) = (&mut self.scenes, &self.spec_dir);
        let vpls = self.vpl.vpl_fingerprint(spec, &scene.name, || cached_scene(scenes, dir, &scene.name))?;
        Ok(format!("{f}-{vpls:016x}"))
    }

    fn render_ground_truth(
        &mut self,
        spec: &ExperimentSpec,
        scene: &SceneSpec,
        spp: u32,
        previous: Option<(u32, &Image)>,
    ) -> Result<Image, String> {
        let (scenes, dir) = (&mut self.scenes, &self.spec_dir);
        self.vpl.ground_truth(spec, &scene.name, || cached_scene(scenes, dir, &scene.name), spp, previous)
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
        if let Some(vm) = spec.vpl_method(m) {
            let (scenes, dir) = (&mut self.scenes, &self.spec_dir);
            return self.vpl.run(spec, &scene.name, || cached_scene(scenes, dir, &scene.name), &vm, spp);
        }
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
            rays: None,
        })
    }
}

pub fn run(a: Args) -> anyhow::Result<()> {
    // Every spec is checked before anything runs.
    let specs = a
        .spec
        .iter()
        .map(|p| ExperimentSpec::load(p).map(|s| (p.clone(), s)))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let threads = a
        .threads
        .map(|t| t as usize)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    for (path, spec) in &specs {
        super::experiment_vpl::check_memory(spec, threads).with_context(|| path.display().to_string())?;
    }
    let outs = output_dirs(&a.out, &specs)?;
    for out in &outs {
        std::fs::create_dir_all(out).map_err(|e| anyhow::anyhow!("cannot create {}: {e}", out.display()))?;
        // Before the (long) runs, not after them.
        for name in ["report.html", "results.json", "results.csv"] {
            filtrace_io::check_writable(out.join(name))?;
        }
    }
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    // One reference cache for all the specs of the call: they share ground truths.
    let cache = a.out.join("cache");
    for ((path, spec), out) in specs.iter().zip(&outs) {
        let spec_dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
        let bar = super::render_session::progress_bar(1, &spec.name);
        let mut backend = PipelineBackend::new(&spec_dir);
        let mut results = pool
            .install(|| {
                run_experiment_with_cache(spec, &spec_dir, out, &cache, &mut backend, &mut |p| {
                    bar.set_length(p.total as u64);
                    bar.set_position(p.done as u64);
                    bar.set_message(p.message.to_string());
                })
            })
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        bar.finish_and_clear();
        results.notes.push(format!("{threads} worker threads."));
        filtrace_eval::report::write_all(out, &results).map_err(|e| anyhow::anyhow!("{e}"))?;
        print_summary(&results, out)?;
    }
    Ok(())
}

/// `OUT` for one spec; `OUT/<spec name>` for each of several (names must differ).
fn output_dirs(out: &Path, specs: &[(PathBuf, ExperimentSpec)]) -> anyhow::Result<Vec<PathBuf>> {
    if specs.len() == 1 {
        return Ok(vec![out.to_path_buf()]);
    }
    let mut dirs: Vec<PathBuf> = Vec::new();
    for (path, spec) in specs {
        let d = out.join(filtrace_eval::experiment::file_stem(&spec.name));
        if dirs.contains(&d) || d == out.join("cache") {
            anyhow::bail!(
                "{}: experiment name {:?} used twice (or named \"cache\"): outputs would collide",
                path.display(),
                spec.name
            );
        }
        dirs.push(d);
    }
    Ok(dirs)
}

/// The markdown table of every cell on stdout.
fn print_summary(results: &filtrace_eval::experiment::Results, dir: &Path) -> anyhow::Result<()> {
    let metric = results.spec.metric();
    let mut out = super::output::stdout();
    writeln!(out, "{}:\n", results.spec.name)?;
    writeln!(
        out,
        "| scene | method | spp | {} | PSNR | frame ms | ms without rays | rays |",
        metric.label()
    )?;
    writeln!(out, "|---|---|---:|---:|---:|---:|---:|---:|")?;
    for e in &results.entries {
        let clock = |c: Clock| e.clock(c).map_or(String::new(), |v| format!("{v:.1}"));
        writeln!(
            out,
            "| {} | {} | {} | {:.4e} | {} | {:.1} | {} | {} |",
            e.scene,
            e.method,
            e.spp,
            e.errors.get(metric),
            e.errors.psnr.map_or("inf".into(), |p| format!("{p:.2}")),
            e.total_ms,
            clock(Clock::WithoutRays),
            e.rays.map_or(String::new(), |r| r.rays.to_string())
        )?;
    }
    writeln!(out, "wrote {}", dir.join("report.html").display())?;
    Ok(out.flush()?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use filtrace_eval::experiment::run_experiment;

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

    /// Every checked-in spec parses, every path method's filter choice is valid and every
    /// many-light method's settings are accepted by the renderer.
    #[test]
    fn checked_in_specs_are_valid() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments");
        let mut n = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let p = entry.unwrap().path();
            if p.extension().is_some_and(|e| e == "toml") {
                let spec = ExperimentSpec::load(&p).unwrap_or_else(|e| panic!("{e}"));
                for m in &spec.methods {
                    if let Some(vm) = spec.vpl_method(m) {
                        super::super::experiment_vpl::vpl_settings(&vm, 1.0)
                            .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
                        continue;
                    }
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
        assert!(n >= 7);
    }
}
