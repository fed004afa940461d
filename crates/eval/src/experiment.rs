//! Experiments: every method at every sample count on every scene, against a reference.
//!
//! A spec is a TOML file (see `experiments/*.toml`):
//!
//! ```toml
//! name = "bauszat-fig8"
//! width = 256
//! height = 256
//! max_depth = 3          # Mitsuba convention: 3 = direct light + one indirect bounce
//! seed = 1
//! spp = [1, 4]           # eye samples per pixel of each method
//! repeats = 1            # timing runs per cell (median reported)
//!
//! [reference]
//! spp = 1024             # rendered once, cached by a hash of its settings
//!
//! [[scenes]]
//! name = "cornell-box"
//! # reference_file = "../shared/reference/cornell_mitsuba_4096spp.exr"  # instead of rendering
//! # crop = [x, y, w, h]  # zoomed crop shown in the report (default: centre quarter)
//!
//! [[methods]]
//! name = "guided"        # label
//! filter = "guided"      # none | atrous | guided | bilateral
//! preset = "paper"       # optional, the filter's named preset
//! # indirect_paths = 1   # paths per guide ray (default 1; "spp" = as many as eye samples)
//! # filter_direct = false
//! ```
//!
//! The crate sees only images: a [`Backend`] (the CLI, on top of the renderer and the
//! filtered pipeline) renders references and runs methods; this module orders the work,
//! caches references, measures the error and collects [`Results`], which
//! [`crate::report`] turns into `report.html`, `results.json` and `results.csv`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use filtrace_core::Image;
use serde::{Deserialize, Serialize};

/// Version of the cache key; bump when the renderer changes what a reference contains.
pub const CACHE_VERSION: u32 = 1;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentSpec {
    pub name: String,
    pub width: u32,
    pub height: u32,
    #[serde(default = "default_max_depth")]
    pub max_depth: i32,
    #[serde(default)]
    pub seed: u64,
    pub spp: Vec<u32>,
    #[serde(default = "default_repeats")]
    pub repeats: u32,
    pub reference: ReferenceSpec,
    pub scenes: Vec<SceneSpec>,
    pub methods: Vec<MethodSpec>,
    /// Also denoise the frame of every unfiltered method (filter "none") with Intel Open
    /// Image Denoise (see [`crate::oidn`]); reported as method "<name>+oidn".
    #[serde(default)]
    pub oidn: bool,
    /// Path of `oidnDenoise` (relative to the spec file); default: `$FILTRACE_OIDN`, PATH.
    #[serde(default)]
    pub oidn_executable: Option<PathBuf>,
}

fn default_max_depth() -> i32 {
    3
}
fn default_repeats() -> u32 {
    1
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceSpec {
    pub spp: u32,
    /// `max_depth` of the reference (default: the experiment's).
    #[serde(default)]
    pub max_depth: Option<i32>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    /// A built-in scene name or a scene file path (relative to the spec file).
    pub name: String,
    /// Use this EXR as the reference instead of rendering one (relative to the spec file).
    #[serde(default)]
    pub reference_file: Option<PathBuf>,
    /// `[x, y, w, h]` of the zoomed crop in the report.
    #[serde(default)]
    pub crop: Option<[u32; 4]>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MethodSpec {
    pub name: String,
    pub filter: String,
    #[serde(default)]
    pub preset: Option<String>,
    /// Paths per guide ray: a number, or "spp" for as many as eye samples per pixel.
    #[serde(default)]
    pub indirect_paths: Option<toml::Value>,
    #[serde(default)]
    pub filter_direct: bool,
    /// Extra filter parameters (name → number), passed to the backend.
    #[serde(default)]
    pub params: BTreeMap<String, f64>,
}

impl MethodSpec {
    /// Paths per guide ray at `spp` eye samples per pixel.
    pub fn indirect_paths_at(&self, spp: u32) -> Result<u32, String> {
        match &self.indirect_paths {
            None => Ok(1),
            Some(toml::Value::Integer(n)) if *n >= 0 && *n <= 1 << 20 => Ok(*n as u32),
            Some(toml::Value::String(s)) if s == "spp" => Ok(spp),
            Some(v) => {
                Err(format!("method {}: indirect_paths must be a count or \"spp\", got {v}", self.name))
            }
        }
    }
}

impl ExperimentSpec {
    /// Parses and checks a spec.
    pub fn from_toml(text: &str) -> Result<Self, String> {
        let spec: ExperimentSpec = toml::from_str(text).map_err(|e| format!("experiment spec: {e}"))?;
        spec.validate()?;
        Ok(spec)
    }

    pub fn load(path: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        Self::from_toml(&text).map_err(|e| format!("{}: {e}", path.display()))
    }

    pub fn validate(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 || self.width > 16384 || self.height > 16384 {
            return Err(format!("resolution {}x{} out of range (1..=16384)", self.width, self.height));
        }
        if self.spp.is_empty() || self.spp.iter().any(|&s| s == 0 || s > 1 << 16) {
            return Err(format!("spp must be a non-empty list of counts in 1..=65536, got {:?}", self.spp));
        }
        if self.reference.spp == 0 {
            return Err("reference.spp must be at least 1".into());
        }
        if self.max_depth == 0 || self.max_depth < -1 {
            return Err(format!("max_depth must be -1 or >= 1, got {}", self.max_depth));
        }
        if self.scenes.is_empty() || self.methods.is_empty() {
            return Err("an experiment needs at least one scene and one method".into());
        }
        if self.repeats == 0 || self.repeats > 100 {
            return Err("repeats must be in 1..=100".into());
        }
        let mut names: Vec<_> = self.methods.iter().map(|m| m.name.as_str()).collect();
        names.sort();
        names.dedup();
        if names.len() != self.methods.len() {
            return Err("method names must be unique".into());
        }
        for m in &self.methods {
            if !m.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_') {
                return Err(format!("method name {:?}: use letters, digits, '-' and '_'", m.name));
            }
            for &s in &self.spp {
                m.indirect_paths_at(s)?;
            }
        }
        for s in &self.scenes {
            if let Some([x, y, w, h]) = s.crop {
                if w == 0 || h == 0 || x + w > self.width || y + h > self.height {
                    return Err(format!("scene {}: crop {:?} outside the image", s.name, [x, y, w, h]));
                }
            }
        }
        Ok(())
    }

    /// The stable hash of everything that determines a scene's reference: the renderer
    /// (`backend_tag`), the scene's content (`scene_fingerprint`, e.g. a hash of the loaded
    /// scene, so that an edited scene file or built-in is never judged against a stale
    /// reference) and the reference settings.
    pub fn reference_key(&self, scene: &SceneSpec, backend_tag: &str, scene_fingerprint: &str) -> String {
        let text = format!(
            "v{CACHE_VERSION}|{backend_tag}|{}|{scene_fingerprint}|{}x{}|spp{}|depth{}|seed{}",
            scene.name,
            self.width,
            self.height,
            self.reference.spp,
            self.reference.max_depth.unwrap_or(self.max_depth),
            self.seed
        );
        format!("{:016x}", fnv1a64(text.as_bytes()))
    }
}

/// FNV-1a, 64 bit: stable across runs and platforms (unlike `DefaultHasher`).
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// One run of one method.
#[derive(Clone, Debug)]
pub struct MethodRun {
    /// The final image (3 channels).
    pub image: Image,
    /// The unfiltered frame (for the report and for OIDN), when the method has one.
    pub noisy: Option<Image>,
    /// Albedo and normal of the guide rays (for OIDN).
    pub albedo: Option<Image>,
    pub normal: Option<Image>,
    /// Milliseconds per stage, in frame order.
    pub stages: Vec<(String, f64)>,
}

/// What an experiment needs from a renderer.
pub trait Backend {
    /// Identifies the renderer version in reference cache keys.
    fn tag(&self) -> String;
    /// Identifies the content of `scene` in reference cache keys (a hash of the loaded scene).
    fn scene_fingerprint(&mut self, scene: &SceneSpec) -> Result<String, String>;
    /// Renders the reference of `scene`.
    fn render_reference(&mut self, spec: &ExperimentSpec, scene: &SceneSpec) -> Result<Image, String>;
    /// Reads a reference image file (EXR).
    fn load_reference(&mut self, path: &Path) -> Result<Image, String>;
    /// Runs `method` on `scene` at `spp` eye samples per pixel.
    fn run(
        &mut self,
        spec: &ExperimentSpec,
        scene: &SceneSpec,
        method: &MethodSpec,
        spp: u32,
    ) -> Result<MethodRun, String>;
}

/// Error of an image against the reference ([`crate::metrics`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Errors {
    pub mse: f64,
    /// Mean over pixels and channels of `(x - ref)^2 / (ref^2 + 0.01)`.
    pub rel_mse: f64,
    /// dB, clamped to [0, 1], peak 1; `None` for identical images.
    pub psnr: Option<f64>,
    pub ssim: f64,
    pub flip: f64,
    /// Non-finite values in the image (read as 0 by the metrics, reported here).
    pub nonfinite: usize,
}

/// All metrics of `img` against `reference`.
pub fn errors(img: &Image, reference: &Image) -> Result<Errors, String> {
    let m = crate::metrics::compare(img, reference).map_err(|e| e.to_string())?;
    Ok(Errors {
        mse: m.mse,
        rel_mse: m.rel_mse,
        psnr: m.psnr,
        ssim: m.ssim,
        flip: m.flip,
        nonfinite: m.nonfinite_image,
    })
}

/// One cell of the experiment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Entry {
    pub scene: String,
    pub method: String,
    pub filter: String,
    pub spp: u32,
    pub errors: Errors,
    /// Median milliseconds per stage over the repeats, in frame order.
    pub stages: Vec<(String, f64)>,
    pub total_ms: f64,
    /// Image file names in the output directory.
    pub image: String,
    pub error_map: String,
    pub crop: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneResult {
    pub name: String,
    /// File names of the reference image and its crop, and where it came from.
    pub reference: String,
    pub reference_crop: String,
    pub reference_source: String,
    pub crop: [u32; 4],
}

/// Everything an experiment measured.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Results {
    pub spec: ExperimentSpec,
    pub scenes: Vec<SceneResult>,
    pub entries: Vec<Entry>,
    /// Lines for the report (e.g. how to enable OIDN, skipped cells).
    pub notes: Vec<String>,
}

/// Progress of a running experiment: `done` of `total` steps, and what runs now.
pub struct Progress<'a> {
    pub done: usize,
    pub total: usize,
    pub message: &'a str,
}

/// Runs `spec` with `backend`, writing images into `out` and the reference cache into
/// `out/cache`. `spec_dir` resolves relative paths of the spec. Does not write the report
/// (see [`crate::report::write_all`]).
pub fn run_experiment(
    spec: &ExperimentSpec,
    spec_dir: &Path,
    out: &Path,
    backend: &mut dyn Backend,
    progress: &mut dyn FnMut(Progress),
) -> Result<Results, String> {
    spec.validate()?;
    let cache = out.join("cache");
    std::fs::create_dir_all(&cache).map_err(|e| format!("{}: {e}", cache.display()))?;
    let total = spec.scenes.len() * (1 + spec.methods.len() * spec.spp.len());
    let mut done = 0;
    let mut results = Results { spec: spec.clone(), scenes: vec![], entries: vec![], notes: vec![] };
    let oidn_exe = if spec.oidn {
        let from_spec = spec.oidn_executable.as_ref().map(|p| spec_dir.join(p));
        let exe = crate::oidn::find_executable(from_spec.as_deref());
        match &exe {
            Some(p) => results.notes.push(format!(
                "Intel Open Image Denoise: {} on the unfiltered frames (whole colour, with the guide rays' albedo and normal); its ms include process start and PFM I/O.",
                p.display()
            )),
            None => results.notes.push(format!("OIDN was asked for but oidnDenoise was not found. {}", crate::oidn::HOW_TO_ENABLE)),
        }
        exe
    } else {
        results.notes.push(crate::oidn::HOW_TO_ENABLE.to_string());
        None
    };
    for scene in &spec.scenes {
        let sname = file_stem(&scene.name);
        // The reference: a given file, the cache, or a fresh render.
        progress(Progress { done, total, message: &format!("{}: reference", scene.name) });
        let (reference, source) = match &scene.reference_file {
            Some(f) => {
                let p = spec_dir.join(f);
                (backend.load_reference(&p)?, format!("file {}", f.display()))
            }
            None => {
                let fingerprint = backend.scene_fingerprint(scene)?;
                let key = spec.reference_key(scene, &backend.tag(), &fingerprint);
                let path = cache.join(format!("{sname}-{key}.pfm"));
                match crate::pfm::read_pfm(&path) {
                    Ok(img) if img.width() == spec.width as usize && img.height() == spec.height as usize => {
                        (img, format!("cached {} spp render ({})", spec.reference.spp, key))
                    }
                    _ => {
                        let img = backend.render_reference(spec, scene)?;
                        crate::pfm::write_pfm(&path, &img).map_err(|e| e.to_string())?;
                        (img, format!("{} spp render ({})", spec.reference.spp, key))
                    }
                }
            }
        };
        if reference.width() != spec.width as usize || reference.height() != spec.height as usize {
            return Err(format!(
                "scene {}: reference is {}x{}, the experiment renders {}x{}",
                scene.name,
                reference.width(),
                reference.height(),
                spec.width,
                spec.height
            ));
        }
        done += 1;
        let crop = scene.crop.unwrap_or_else(|| default_crop(spec.width, spec.height));
        let ref_name = format!("{sname}-reference.png");
        let ref_crop = format!("{sname}-reference-crop.png");
        crate::figures::write_png(&out.join(&ref_name), &reference)?;
        crate::figures::write_png(&out.join(&ref_crop), &crate::figures::zoomed_crop(&reference, crop))?;
        results.scenes.push(SceneResult {
            name: scene.name.clone(),
            reference: ref_name,
            reference_crop: ref_crop,
            reference_source: source,
            crop,
        });

        for method in &spec.methods {
            for &spp in &spec.spp {
                let msg = format!("{}: {} at {spp} spp", scene.name, method.name);
                progress(Progress { done, total, message: &msg });
                let mut runs = Vec::with_capacity(spec.repeats as usize);
                for _ in 0..spec.repeats {
                    runs.push(backend.run(spec, scene, method, spp)?);
                }
                let stages = median_stages(&runs);
                let run = runs.pop().expect("repeats >= 1");
                let err = errors(&run.image, &reference)?;
                let base = format!("{sname}-{}-{spp}spp", method.name);
                let (image, error_map, crop_name) =
                    (format!("{base}.png"), format!("{base}-error.png"), format!("{base}-crop.png"));
                crate::figures::write_png(&out.join(&image), &run.image)?;
                crate::figures::write_png(
                    &out.join(&crop_name),
                    &crate::figures::zoomed_crop(&run.image, crop),
                )?;
                let map = crate::metrics::rel_mse_map(&run.image, &reference).map_err(|e| e.to_string())?;
                crate::figures::write_error_map(&out.join(&error_map), &map)?;
                results.entries.push(Entry {
                    scene: scene.name.clone(),
                    method: method.name.clone(),
                    filter: method.filter.clone(),
                    spp,
                    errors: err,
                    total_ms: stages.iter().map(|s| s.1).sum(),
                    stages,
                    image,
                    error_map,
                    crop: crop_name,
                });
                // Intel Open Image Denoise on the unfiltered frame, same samples.
                if let (Some(exe), "none", Some(albedo), Some(normal)) =
                    (&oidn_exe, method.filter.as_str(), &run.albedo, &run.normal)
                {
                    let noisy = run.noisy.as_ref().unwrap_or(&run.image);
                    let (img, ms) = crate::oidn::denoise(exe, &cache.join("oidn"), noisy, albedo, normal)?;
                    let mut stages = results.entries.last().map(|e| e.stages.clone()).unwrap_or_default();
                    stages.push(("oidn".to_string(), ms));
                    let name = format!("{}+oidn", method.name);
                    let base = format!("{sname}-{name}-{spp}spp");
                    let (image, error_map, crop_name) =
                        (format!("{base}.png"), format!("{base}-error.png"), format!("{base}-crop.png"));
                    crate::figures::write_png(&out.join(&image), &img)?;
                    crate::figures::write_png(
                        &out.join(&crop_name),
                        &crate::figures::zoomed_crop(&img, crop),
                    )?;
                    let map = crate::metrics::rel_mse_map(&img, &reference).map_err(|e| e.to_string())?;
                    crate::figures::write_error_map(&out.join(&error_map), &map)?;
                    results.entries.push(Entry {
                        scene: scene.name.clone(),
                        method: name,
                        filter: "oidn".into(),
                        spp,
                        errors: errors(&img, &reference)?,
                        total_ms: stages.iter().map(|s| s.1).sum(),
                        stages,
                        image,
                        error_map,
                        crop: crop_name,
                    });
                }
                done += 1;
            }
        }
    }
    progress(Progress { done, total, message: "done" });
    Ok(results)
}

/// The centre quarter (half the width and height) of the image.
pub fn default_crop(w: u32, h: u32) -> [u32; 4] {
    let (cw, ch) = ((w / 4).max(1), (h / 4).max(1));
    [(w - cw) / 2, (h - ch) / 2, cw, ch]
}

fn median_stages(runs: &[MethodRun]) -> Vec<(String, f64)> {
    let first = &runs[0].stages;
    first
        .iter()
        .enumerate()
        .map(|(k, (name, _))| {
            let mut v: Vec<f64> = runs.iter().filter_map(|r| r.stages.get(k).map(|s| s.1)).collect();
            v.sort_by(|a, b| a.total_cmp(b));
            (name.clone(), v[v.len() / 2])
        })
        .collect()
}

/// A file-name-safe form of a scene name or path.
pub fn file_stem(name: &str) -> String {
    let stem = Path::new(name).file_stem().and_then(|s| s.to_str()).unwrap_or(name);
    stem.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect()
}
