//! Adaptive sampling of the guide rays' indirect light (Bauszat, Eisemann and Magnor,
//! *Adaptive Sampling for Geometry-aware Reconstruction Filters*, 2011) on this pipeline.
//!
//! Owned by the adaptive-sampling work (`filtrace-adaptive`); kept apart from the frame in
//! [`crate::pipeline`], which it drives only through
//! [`FilteredRenderer::render_frame_with_counts`]. A frame:
//!
//! 1. **G-buffer pre-pass** — the guide rays' first hits (normal, world position) are
//!    traced with no indirect path: the same eye rays as the guide pass, so the importance
//!    map sees exactly the geometry the filter will see. Costs one primary ray per pixel
//!    ([`PathSource::first_hits`], a row per batch).
//! 2. **importance + apportionment** — [`filtrace_adaptive::plan_frame`] (§4.1, §4.2): a
//!    budget of `budget_spp · pixels` indirect paths, at least `min_spp` each.
//! 3. **frame** — the pipeline's frame with those per-pixel counts; any filter.
//!
//! The batch system of §4.3 ([`filtrace_adaptive::BatchSchedule`]) runs inside the frame:
//! with a source that traces single paths ([`PathSource::traces_single_paths`], e.g.
//! [`crate::RenderSource`]) and an explicit batch size
//! ([`FilteredRenderer::set_batch_size`]) the counts are scanned into sample offsets and
//! the paths traced batch by batch, slot-parallel, then reduced per pixel; by default the
//! whole frame is one batch, each row's guide rays one [`PathSource::trace_batch`] call (see
//! [`crate::guide`]).

use filtrace_adaptive::{AdaptiveError, AdaptiveParams, SampleCounts};
use filtrace_core::{Image, Vec2};
use rayon::prelude::*;

use crate::filter::IndirectFilter;
use crate::pipeline::{FilteredRenderer, Frame, PipelineError, PipelineSettings};
use crate::source::{EyeRay, EyeSample, PathSource, SampleKey};

/// What the adaptive scheme decided for a frame.
#[derive(Clone, Debug)]
pub struct AdaptivePlan {
    /// Importance `1 - W_p / |window|`, 1 channel (write it as a layer to see it).
    pub importance: Image,
    /// Indirect paths of each guide ray.
    pub counts: SampleCounts,
    /// Milliseconds of the G-buffer pre-pass and of importance + apportionment.
    pub prepass_ms: f64,
    pub plan_ms: f64,
}

/// Why an adaptive frame failed.
#[derive(Clone, Debug, PartialEq)]
pub enum AdaptiveFrameError {
    Adaptive(AdaptiveError),
    Pipeline(PipelineError),
}

impl std::fmt::Display for AdaptiveFrameError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Adaptive(e) => write!(f, "adaptive sampling: {e}"),
            Self::Pipeline(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for AdaptiveFrameError {}

/// Normal and world position of each pixel's guide ray (zero normal where it escaped:
/// background for the importance map).
pub fn guide_gbuffer<S: PathSource>(source: &S, settings: &PipelineSettings) -> (Image, Image) {
    let (w, h) = (settings.width as usize, settings.height as usize);
    let mut normal = Image::new(w, h, 3);
    let mut position = Image::new(w, h, 3);
    normal
        .data_mut()
        .par_chunks_mut(w * 3)
        .zip(position.data_mut().par_chunks_mut(w * 3))
        .enumerate()
        .for_each(|(y, (nrow, prow))| {
            // The row's guide rays as one batch (`PathSource::first_hits`).
            let rays: Vec<EyeRay> = (0..w)
                .map(|x| {
                    let key = SampleKey { x: x as u32, y: y as u32, sample: 0, seed: settings.seed };
                    EyeRay { key, film: Vec2::new(x as f32 + 0.5, y as f32 + 0.5), paths: 0 }
                })
                .collect();
            let mut hits = vec![EyeSample::default(); w];
            source.first_hits(&rays, &mut hits);
            for (x, e) in hits.iter().enumerate() {
                if let Some(hit) = e.hit {
                    nrow[x * 3..x * 3 + 3].copy_from_slice(&hit.normal.to_array());
                    prow[x * 3..x * 3 + 3].copy_from_slice(&e.position.to_array());
                }
            }
        });
    (normal, position)
}

/// Importance map and per-pixel indirect counts for the frame `settings` describes.
pub fn plan<S: PathSource>(
    source: &S,
    settings: &PipelineSettings,
    params: &AdaptiveParams,
) -> Result<AdaptivePlan, AdaptiveError> {
    let t0 = std::time::Instant::now();
    let (normal, position) = guide_gbuffer(source, settings);
    let prepass_ms = t0.elapsed().as_secs_f64() * 1e3;
    let t1 = std::time::Instant::now();
    let (importance, counts) = filtrace_adaptive::plan_frame(&normal, &position, params)?;
    Ok(AdaptivePlan { importance, counts, prepass_ms, plan_ms: t1.elapsed().as_secs_f64() * 1e3 })
}

impl<S: PathSource, F: IndirectFilter> FilteredRenderer<S, F> {
    /// A frame whose guide rays trace their indirect paths as the adaptive scheme
    /// apportions `params.budget_spp · pixels` of them (`settings.indirect_paths` is not
    /// used). Returns the frame and the plan.
    pub fn render_frame_adaptive(
        &mut self,
        params: &AdaptiveParams,
    ) -> Result<(&Frame, AdaptivePlan), AdaptiveFrameError> {
        let plan = plan(self.source(), self.settings(), params).map_err(AdaptiveFrameError::Adaptive)?;
        let frame = self
            .render_frame_with_counts(Some(plan.counts.counts()))
            .map_err(AdaptiveFrameError::Pipeline)?;
        Ok((frame, plan))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lookup::HitGeometry;
    use crate::NoFilter;
    use filtrace_core::{Rgb, Vec3};
    use std::sync::atomic::{AtomicU64, Ordering};
    use std::sync::Mutex;

    /// Analytic frame: sky in the top rows, a floor facing +y below with a wall facing -z on
    /// the right half (a crease). Counts every indirect path asked for, per pixel.
    struct Crease {
        w: u32,
        paths: AtomicU64,
        per_pixel: Mutex<Vec<u32>>,
    }

    impl PathSource for Crease {
        fn trace(&self, key: SampleKey, _film: Vec2, indirect_paths: u32) -> EyeSample {
            self.paths.fetch_add(indirect_paths as u64, Ordering::Relaxed);
            if indirect_paths > 0 {
                self.per_pixel.lock().unwrap()[(key.y * self.w + key.x) as usize] += indirect_paths;
            }
            if key.y < 2 {
                return EyeSample::default(); // sky
            }
            let (normal, position) = if key.x < self.w / 2 {
                (Vec3::Y, Vec3::new(key.x as f32, 0.0, key.y as f32))
            } else {
                (-Vec3::Z, Vec3::new(key.x as f32, key.y as f32, 0.0))
            };
            EyeSample {
                hit: Some(HitGeometry { normal, depth: 1.0 }),
                albedo: Rgb::splat(0.5),
                position,
                direct: Rgb::ZERO,
                indirect: Rgb::splat(0.25),
            }
        }
    }

    #[test]
    fn adaptive_frame_traces_exactly_the_budget_where_planned() {
        let (w, h) = (16u32, 10u32);
        let n = (w * h) as usize;
        let src = Crease { w, paths: AtomicU64::new(0), per_pixel: Mutex::new(vec![0; n]) };
        let mut r = FilteredRenderer::new(&src, NoFilter, PipelineSettings::interactive(w, h)).unwrap();
        let params = AdaptiveParams::paper();
        let plan = {
            let (_, plan) = r.render_frame_adaptive(&params).unwrap();
            plan
        };
        // The frame traced exactly the budget (the pre-pass traces no indirect path).
        assert_eq!(src.paths.load(Ordering::Relaxed), 4 * n as u64);
        assert_eq!(plan.counts.total(), 4 * n as u64);
        // ... and each pixel exactly its planned count.
        assert_eq!(*src.per_pixel.lock().unwrap(), plan.counts.counts());
        // Sky is background: importance 0 and the minimum; the crease is the most important.
        let imp = |x: u32, y: u32| plan.importance.pixel(x as usize, y as usize)[0];
        for x in 0..w {
            assert_eq!(imp(x, 0), 0.0);
            assert_eq!(plan.counts.counts()[x as usize], params.min_spp);
        }
        assert!(imp(w / 2, 6) > imp(2, 6), "{} vs {}", imp(w / 2, 6), imp(2, 6));
        assert!(plan.counts.counts()[(6 * w + w / 2) as usize] > plan.counts.counts()[(6 * w + 2) as usize]);
    }

    #[test]
    fn bad_adaptive_parameters_are_errors_not_panics() {
        let src = Crease { w: 4, paths: AtomicU64::new(0), per_pixel: Mutex::new(vec![0; 16]) };
        let mut r = FilteredRenderer::new(&src, NoFilter, PipelineSettings::interactive(4, 4)).unwrap();
        let params = AdaptiveParams { budget_spp: 1, min_spp: 2, ..AdaptiveParams::paper() };
        let e = r.render_frame_adaptive(&params).map(|_| ()).unwrap_err();
        assert!(matches!(e, AdaptiveFrameError::Adaptive(AdaptiveError::BudgetBelowMinimum { .. })), "{e}");
        assert!(e.to_string().contains("below the minimum"));
    }
}
