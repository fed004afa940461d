//! [`run_experiment`]: references (a file, the cache or a render; per
//! sample count for the VPL ground truth) and the cells (a method at a sample count, its
//! images and errors, plus its OIDN-denoised twin).

use std::path::{Path, PathBuf};

use filtrace_core::Image;

use super::results::{
    default_crop, errors, file_stem, Backend, Entry, MethodRun, Progress, RayClock, Results, SceneResult,
};
use super::spec::{ExperimentSpec, MethodSpec, SceneSpec};
use crate::figures::{write_error_map, write_png, zoomed_crop};

/// The state of a running experiment.
struct Run<'a> {
    pub spec: &'a ExperimentSpec,
    pub spec_dir: &'a Path,
    pub out: &'a Path,
    pub cache: &'a Path,
    pub backend: &'a mut dyn Backend,
    pub oidn: Option<PathBuf>,
    pub done: usize,
}

/// A scene's reference: one image, or one per sample count (VPL ground truth).
enum References {
    One(Image),
    BySpp(Vec<(u32, Image)>),
}

impl References {
    pub fn at(&self, spp: u32) -> &Image {
        match self {
            References::One(img) => img,
            References::BySpp(v) => &v.iter().find(|r| r.0 == spp).expect("a reference per spp").1,
        }
    }
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
    run_experiment_with_cache(spec, spec_dir, out, &out.join("cache"), backend, progress)
}

/// [`run_experiment`] with the reference cache in `cache` (shared by several specs).
pub fn run_experiment_with_cache(
    spec: &ExperimentSpec,
    spec_dir: &Path,
    out: &Path,
    cache: &Path,
    backend: &mut dyn Backend,
    progress: &mut dyn FnMut(Progress),
) -> Result<Results, String> {
    spec.validate()?;
    std::fs::create_dir_all(cache).map_err(|e| format!("{}: {e}", cache.display()))?;
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let total = spec.scenes.len() * (1 + spec.methods.len() * spec.spp.len());
    let mut results = Results { spec: spec.clone(), scenes: vec![], entries: vec![], notes: vec![] };
    let oidn_exe = find_oidn(spec, spec_dir, &mut results.notes);
    let mut run = Run { spec, spec_dir, out, cache, backend, oidn: oidn_exe, done: 0 };
    for scene in &spec.scenes {
        progress(Progress { done: run.done, total, message: &format!("{}: reference", scene.name) });
        let (scene_result, references) = run.references(scene)?;
        run.done += 1;
        for method in &spec.methods {
            for &spp in &spec.spp {
                let msg = format!("{}: {} at {spp} spp", scene.name, method.name);
                progress(Progress { done: run.done, total, message: &msg });
                let reference = references.at(spp);
                results.entries.extend(run.cell(scene, &scene_result, method, spp, reference)?);
                run.done += 1;
            }
        }
        results.scenes.push(scene_result);
    }
    progress(Progress { done: run.done, total, message: "done" });
    Ok(results)
}

/// The OIDN executable when the spec asks for it; notes say what happened.
fn find_oidn(spec: &ExperimentSpec, spec_dir: &Path, notes: &mut Vec<String>) -> Option<PathBuf> {
    if !spec.oidn {
        if !spec.is_vpl_ground_truth() {
            notes.push(crate::oidn::HOW_TO_ENABLE.to_string());
        }
        return None;
    }
    let from_spec = spec.oidn_executable.as_ref().map(|p| spec_dir.join(p));
    let exe = crate::oidn::find_executable(from_spec.as_deref());
    match &exe {
        Some(p) => notes.push(format!(
            "Intel Open Image Denoise: {} on the unfiltered frames (whole colour, with the guide rays' albedo and normal); its ms include process start and PFM I/O.",
            p.display()
        )),
        None => notes.push(format!("OIDN was asked for but oidnDenoise was not found. {}", crate::oidn::HOW_TO_ENABLE)),
    }
    exe
}

impl Run<'_> {
    /// The scene's reference(s), written as PNGs, and its result record.
    pub fn references(&mut self, scene: &SceneSpec) -> Result<(SceneResult, References), String> {
        let spec = self.spec;
        let sname = file_stem(&scene.name);
        let crop = scene.crop.unwrap_or_else(|| default_crop(spec.width, spec.height));
        let mut result = SceneResult {
            name: scene.name.clone(),
            reference: String::new(),
            reference_crop: String::new(),
            reference_source: String::new(),
            crop,
            references_by_spp: vec![],
        };
        if !spec.is_vpl_ground_truth() {
            let (img, source) = self.reference(scene)?;
            self.check_size(scene, &img)?;
            (result.reference, result.reference_crop) = self.write_reference(&sname, &img, crop)?;
            result.reference_source = source;
            return Ok((result, References::One(img)));
        }
        let mut spps = spec.spp.clone();
        spps.sort_unstable();
        spps.dedup();
        let mut refs = Vec::new();
        let mut sources = Vec::new();
        for spp in spps {
            let previous = refs.last().map(|(k, img): &(u32, Image)| (*k, img));
            let (img, cached) = self.ground_truth(scene, spp, previous)?;
            self.check_size(scene, &img)?;
            let (image, crop_name) = self.write_reference(&format!("{sname}-{spp}spp"), &img, crop)?;
            sources.push(format!("{spp} spp{}", if cached { " (cached)" } else { "" }));
            result.references_by_spp.push((spp, image, crop_name));
            refs.push((spp, img));
        }
        (result.reference, result.reference_crop) =
            (result.references_by_spp[0].1.clone(), result.references_by_spp[0].2.clone());
        result.reference_source = format!(
            "exhaustive VPL sum ({} VPLs) on each method's camera samples: {}",
            spec.vpl.vpls,
            sources.join(", ")
        );
        Ok((result, References::BySpp(refs)))
    }

    /// A path-traced reference: a given file, the cache, or a fresh render.
    fn reference(&mut self, scene: &SceneSpec) -> Result<(Image, String), String> {
        let spec = self.spec;
        if let Some(f) = &scene.reference_file {
            let p = self.spec_dir.join(f);
            return Ok((self.backend.load_reference(&p)?, format!("file {}", f.display())));
        }
        let fingerprint = self.backend.scene_fingerprint(scene)?;
        let key = spec.reference_key(scene, &self.backend.tag(), &fingerprint);
        let path = self.cache.join(format!("{}-{key}.pfm", file_stem(&scene.name)));
        if let Some(img) = self.cached(&path) {
            return Ok((img, format!("cached {} spp render ({key})", spec.reference.spp)));
        }
        let img = self.backend.render_reference(spec, scene)?;
        crate::pfm::write_pfm(&path, &img).map_err(|e| e.to_string())?;
        Ok((img, format!("{} spp render ({key})", spec.reference.spp)))
    }

    /// The VPL ground truth at `spp`, from the cache or the backend (extending
    /// `previous`, the one at a lower count); true when cached.
    fn ground_truth(
        &mut self,
        scene: &SceneSpec,
        spp: u32,
        previous: Option<(u32, &Image)>,
    ) -> Result<(Image, bool), String> {
        let fingerprint = self.backend.ground_truth_fingerprint(self.spec, scene)?;
        let key = self.spec.ground_truth_key(scene, spp, &self.backend.tag(), &fingerprint);
        let path = self.cache.join(format!("{}-vpl-gt-{key}.pfm", file_stem(&scene.name)));
        if let Some(img) = self.cached(&path) {
            return Ok((img, true));
        }
        let img = self.backend.render_ground_truth(self.spec, scene, spp, previous)?;
        crate::pfm::write_pfm(&path, &img).map_err(|e| e.to_string())?;
        Ok((img, false))
    }

    fn cached(&self, path: &Path) -> Option<Image> {
        let img = crate::pfm::read_pfm(path).ok()?;
        (img.width() == self.spec.width as usize && img.height() == self.spec.height as usize).then_some(img)
    }

    fn check_size(&self, scene: &SceneSpec, img: &Image) -> Result<(), String> {
        let spec = self.spec;
        if img.width() != spec.width as usize || img.height() != spec.height as usize {
            return Err(format!(
                "scene {}: reference is {}x{}, the experiment renders {}x{}",
                scene.name,
                img.width(),
                img.height(),
                spec.width,
                spec.height
            ));
        }
        Ok(())
    }

    /// Writes `<base>-reference.png` and its crop; their file names.
    fn write_reference(&self, base: &str, img: &Image, crop: [u32; 4]) -> Result<(String, String), String> {
        let (name, crop_name) = (format!("{base}-reference.png"), format!("{base}-reference-crop.png"));
        write_png(&self.out.join(&name), img)?;
        write_png(&self.out.join(&crop_name), &zoomed_crop(img, crop))?;
        Ok((name, crop_name))
    }

    /// `method` at `spp` on `scene` (the median of the repeats' stage times), and its OIDN
    /// twin when asked for.
    pub fn cell(
        &mut self,
        scene: &SceneSpec,
        result: &SceneResult,
        method: &MethodSpec,
        spp: u32,
        reference: &Image,
    ) -> Result<Vec<Entry>, String> {
        let mut runs = Vec::with_capacity(self.spec.repeats as usize);
        for _ in 0..self.spec.repeats {
            runs.push(self.backend.run(self.spec, scene, method, spp)?);
        }
        let stages = median_stages(&runs);
        let rays = median_rays(&runs);
        let run = runs.pop().expect("repeats >= 1");
        let mut entries = vec![self.entry(
            scene,
            result,
            &method.name,
            method.kind_label(),
            spp,
            &run.image,
            reference,
            stages,
            rays,
        )?];
        // Intel Open Image Denoise on the unfiltered frame, same samples.
        if let (Some(exe), "none", Some(albedo), Some(normal)) =
            (&self.oidn, method.filter.as_str(), &run.albedo, &run.normal)
        {
            let noisy = run.noisy.as_ref().unwrap_or(&run.image);
            let (img, ms) = crate::oidn::denoise(exe, &self.cache.join("oidn"), noisy, albedo, normal)?;
            let mut stages = entries[0].stages.clone();
            stages.push(("oidn".to_string(), ms));
            let name = format!("{}+oidn", method.name);
            entries.push(self.entry(
                scene,
                result,
                &name,
                "oidn".into(),
                spp,
                &img,
                reference,
                stages,
                None,
            )?);
        }
        Ok(entries)
    }

    /// Writes a cell's image, crop and error map and measures its error.
    #[allow(clippy::too_many_arguments)]
    fn entry(
        &self,
        scene: &SceneSpec,
        result: &SceneResult,
        method: &str,
        filter: String,
        spp: u32,
        img: &Image,
        reference: &Image,
        stages: Vec<(String, f64)>,
        rays: Option<RayClock>,
    ) -> Result<Entry, String> {
        let base = format!("{}-{method}-{spp}spp", file_stem(&scene.name));
        let (image, error_map, crop) =
            (format!("{base}.png"), format!("{base}-error.png"), format!("{base}-crop.png"));
        write_png(&self.out.join(&image), img)?;
        write_png(&self.out.join(&crop), &zoomed_crop(img, result.crop))?;
        let map = crate::metrics::rel_mse_map(img, reference).map_err(|e| e.to_string())?;
        write_error_map(&self.out.join(&error_map), &map)?;
        Ok(Entry {
            scene: scene.name.clone(),
            method: method.to_string(),
            filter,
            spp,
            errors: errors(img, reference)?,
            total_ms: stages.iter().map(|s| s.1).sum(),
            stages,
            rays,
            image,
            error_map,
            crop,
        })
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn median_stages(runs: &[MethodRun]) -> Vec<(String, f64)> {
    let first = &runs[0].stages;
    first
        .iter()
        .enumerate()
        .map(|(k, (name, _))| {
            (name.clone(), median(runs.iter().filter_map(|r| r.stages.get(k).map(|s| s.1)).collect()))
        })
        .collect()
}

/// The last run's ray count (deterministic) with the median ray time.
fn median_rays(runs: &[MethodRun]) -> Option<RayClock> {
    let last = runs.last()?.rays?;
    let ms: Vec<f64> = runs.iter().filter_map(|r| r.rays.map(|c| c.ray_ms)).collect();
    Some(RayClock { rays: last.rays, ray_ms: median(ms) })
}
