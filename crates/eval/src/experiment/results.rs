//! What an experiment produces and needs: the [`Backend`] a renderer implements, one
//! run of a method, the errors, the cells ([`Entry`]) and [`Results`].

use std::path::Path;

use filtrace_core::Image;
use serde::{Deserialize, Serialize};

use super::spec::{ExperimentSpec, MethodSpec, Metric, SceneSpec};

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
    /// The ray queries of the run, when the backend counts them (the thesis's second and
    /// third clocks: time without ray queries, number of rays).
    pub rays: Option<RayClock>,
}

/// Ray queries of one run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RayClock {
    /// Rays traced (shadow rays counted, camera rays by number of samples).
    pub rays: u64,
    /// Wall-clock milliseconds of those ray queries alone (an estimate by the backend).
    pub ray_ms: f64,
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
    /// Identifies what the VPL ground truth of `scene` depends on beyond the spec (the
    /// scene's content and the VPLs the renderer makes), for its cache key.
    fn ground_truth_fingerprint(
        &mut self,
        spec: &ExperimentSpec,
        scene: &SceneSpec,
    ) -> Result<String, String> {
        let _ = spec;
        self.scene_fingerprint(scene)
    }
    /// The exhaustive VPL sum over camera samples `0..spp` with the VPLs every method of
    /// `spec` uses (`[reference] ground_truth = "vpl"`); called with increasing `spp`.
    /// `previous` is the same sum over `0..k` for some `k < spp` when the experiment has
    /// it (e.g. from its cache): the backend may extend it instead of starting again.
    fn render_ground_truth(
        &mut self,
        spec: &ExperimentSpec,
        scene: &SceneSpec,
        spp: u32,
        previous: Option<(u32, &Image)>,
    ) -> Result<Image, String> {
        let _ = (spec, spp, previous);
        Err(format!("scene {}: this backend has no VPL ground truth", scene.name))
    }
}

/// Error of an image against the reference ([`crate::metrics`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Errors {
    pub mse: f64,
    /// Mean over pixels and channels of `(x - ref)^2 / (ref^2 + 0.01)`.
    pub rel_mse: f64,
    /// The thesis's relMSE: values clamped to [0, 1], `Σ (x − ref)² / Σ ref²`.
    #[serde(default)]
    pub rel_mse_clamped: f64,
    /// dB, clamped to [0, 1], peak 1; `None` for identical images.
    pub psnr: Option<f64>,
    pub ssim: f64,
    pub flip: f64,
    /// Non-finite values in the image (read as 0 by the metrics, reported here).
    pub nonfinite: usize,
}

impl Errors {
    /// The value of `metric`.
    pub fn get(&self, metric: Metric) -> f64 {
        match metric {
            Metric::RelMse => self.rel_mse,
            Metric::RelMseClamped => self.rel_mse_clamped,
        }
    }
}

/// All metrics of `img` against `reference`.
pub fn errors(img: &Image, reference: &Image) -> Result<Errors, String> {
    let m = crate::metrics::compare(img, reference).map_err(|e| e.to_string())?;
    Ok(Errors {
        mse: m.mse,
        rel_mse: m.rel_mse,
        rel_mse_clamped: crate::metrics::rel_mse_clamped(img, reference).map_err(|e| e.to_string())?,
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
    /// The filter, or `vpl-<sampler>` for a many-light method.
    pub filter: String,
    pub spp: u32,
    pub errors: Errors,
    /// Median milliseconds per stage over the repeats, in frame order.
    pub stages: Vec<(String, f64)>,
    pub total_ms: f64,
    /// Ray queries (median `ray_ms` over the repeats), when the backend counts them.
    #[serde(default)]
    pub rays: Option<RayClock>,
    /// Image file names in the output directory.
    pub image: String,
    pub error_map: String,
    pub crop: String,
}

impl Entry {
    /// The thesis's three clocks (6.5): all time, time without ray queries (ms), rays.
    pub fn clock(&self, c: Clock) -> Option<f64> {
        match c {
            Clock::Spp => Some(self.spp as f64),
            Clock::Total => Some(self.total_ms),
            Clock::WithoutRays => self.rays.map(|r| (self.total_ms - r.ray_ms).max(0.0)),
            Clock::Rays => self.rays.map(|r| r.rays as f64),
        }
    }
}

/// An x axis of the convergence plots.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Clock {
    Spp,
    Total,
    WithoutRays,
    Rays,
}

impl Clock {
    pub const ALL: [Clock; 4] = [Clock::Spp, Clock::Total, Clock::WithoutRays, Clock::Rays];

    pub fn label(self) -> &'static str {
        match self {
            Clock::Spp => "samples per pixel",
            Clock::Total => "ms per frame (all time)",
            Clock::WithoutRays => "ms without ray queries",
            Clock::Rays => "rays traced",
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneResult {
    pub name: String,
    /// File names of the reference image and its crop, and where it came from (with the
    /// VPL ground truth: the one of the lowest sample count, the pixel centres).
    pub reference: String,
    pub reference_crop: String,
    pub reference_source: String,
    pub crop: [u32; 4],
    /// With the VPL ground truth: the reference of each sample count (spp, image, crop).
    #[serde(default)]
    pub references_by_spp: Vec<(u32, String, String)>,
}

impl SceneResult {
    /// The reference image and crop the cells at `spp` were judged against.
    pub fn reference_at(&self, spp: u32) -> (&str, &str) {
        match self.references_by_spp.iter().find(|r| r.0 == spp) {
            Some((_, image, crop)) => (image, crop),
            None => (&self.reference, &self.reference_crop),
        }
    }
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

/// The centre quarter (half the width and height) of the image.
pub fn default_crop(w: u32, h: u32) -> [u32; 4] {
    let (cw, ch) = ((w / 4).max(1), (h / 4).max(1));
    [(w - cw) / 2, (h - ch) / 2, cw, ch]
}

/// A file-name-safe form of a scene name or path.
pub fn file_stem(name: &str) -> String {
    let stem = Path::new(name).file_stem().and_then(|s| s.to_str()).unwrap_or(name);
    stem.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect()
}
