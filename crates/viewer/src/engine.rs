//! The render state of one loaded scene, owned by the worker thread: one BVH, used by both
//! kinds of frame, with the camera moved in place ([`Renderer::set_view`]).
//!
//! - **moving** ([`Engine::moving_frame`]): the filtered pipeline of Bauszat et al. 2011 at
//!   1 spp (one guide ray per pixel, its indirect light filtered), at a resolution the
//!   worker scales to keep the frame rate;
//! - **still** ([`Engine::still_frame`]): progressive path tracing at full resolution, each
//!   frame adding `spp_per_frame` samples to one film. Samples are added in index order per
//!   pixel, so after `n` samples the film is bit for bit `filtrace render --spp n`'s.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use filtrace_adaptive::AdaptiveParams;
use filtrace_core::Image;
use filtrace_pipeline::{FilterChoice, FilteredRenderer, IndirectFilter, PipelineSettings, RenderSource};
use filtrace_render::{Film, RenderSettings, Renderer};
use filtrace_scene::{Camera, Scene};

use crate::layers::LayerSet;
use crate::settings::{RenderChoice, StillRenderer};

type Pipeline = FilteredRenderer<RenderSource, Box<dyn IndirectFilter>>;

/// What a frame was.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FrameKind {
    /// Progressive accumulation, `spp` samples per pixel so far.
    Still { spp: u32 },
    /// The 1-spp filtered pipeline at a fraction `scale` of the full resolution.
    Moving { scale: f32 },
}

/// One rendered frame with its layers and costs.
#[derive(Clone, Debug)]
pub struct FrameOut {
    /// Shared with the published frame and saves (no copy of the images).
    pub layers: Arc<LayerSet>,
    pub kind: FrameKind,
    /// Milliseconds of each stage, in frame order.
    pub stages: Vec<(&'static str, f64)>,
    pub total_ms: f64,
}

/// What the still film holds: a change of any of these starts it again.
#[derive(Clone, Debug, PartialEq)]
struct StillKey {
    camera: Camera,
    width: u32,
    height: u32,
    max_depth: i32,
    seed: u64,
    still: StillRenderer,
    adaptive: bool,
}

impl StillKey {
    fn new(camera: &Camera, c: &RenderChoice) -> Self {
        Self {
            camera: camera.clone(),
            width: c.width,
            height: c.height,
            max_depth: c.max_depth,
            seed: c.seed,
            still: c.still,
            adaptive: c.adaptive,
        }
    }
}

/// The progressive film and what it holds.
struct Accumulation {
    key: StillKey,
    film: Film,
    spp: u32,
    /// Importance map of the film's G-buffer (adaptive on), computed once per key.
    importance: Option<Image>,
}

/// One scene ready to render (see the module docs).
pub struct Engine {
    pipeline: Pipeline,
    filter: FilterChoice,
    scene_scale: f32,
    still: Option<Accumulation>,
}

impl Engine {
    /// Builds the BVH and lights of `scene` and the pipeline with `choice`'s filter.
    pub fn new(scene: Scene, choice: &RenderChoice) -> Result<Self, String> {
        let settings = render_settings(choice, choice.width, choice.height);
        let renderer = Renderer::new(scene, settings).map_err(|e| e.to_string())?;
        let source = RenderSource::new(renderer);
        let scene_scale = source.scene_scale();
        let filter = choice.filter.build(Some(scene_scale))?;
        let ps = pipeline_settings(choice, choice.width, choice.height);
        let pipeline = FilteredRenderer::new(source, filter, ps).map_err(|e| e.to_string())?;
        Ok(Self { pipeline, filter: choice.filter.clone(), scene_scale, still: None })
    }

    /// The camera the scene file gives (or the framing of its bounds).
    pub fn scene_camera(scene: &Scene) -> Camera {
        scene.camera.clone().unwrap_or_else(|| filtrace_scene::default_camera_for(scene.bounds()))
    }

    /// Samples per pixel the still film holds for this camera and choice (0 if another).
    pub fn still_spp(&self, camera: &Camera, choice: &RenderChoice) -> u32 {
        match &self.still {
            Some(a) if a.key == StillKey::new(camera, choice) => a.spp,
            _ => 0,
        }
    }

    /// A moving frame at `width x height` (see the module docs).
    pub fn moving_frame(
        &mut self,
        camera: &Camera,
        choice: &RenderChoice,
        (width, height): (u32, u32),
    ) -> Result<FrameOut, String> {
        let start = Instant::now();
        if self.filter != choice.filter {
            self.pipeline.set_filter(choice.filter.build(Some(self.scene_scale))?);
            self.filter = choice.filter.clone();
        }
        let rs = render_settings(choice, width, height);
        self.pipeline.source_mut().renderer_mut().set_view(camera, rs).map_err(|e| e.to_string())?;
        self.pipeline.set_settings(pipeline_settings(choice, width, height)).map_err(|e| e.to_string())?;
        let (frame, plan) = if choice.adaptive {
            let (frame, plan) =
                self.pipeline.render_frame_adaptive(&AdaptiveParams::paper()).map_err(|e| e.to_string())?;
            (frame, Some(plan))
        } else {
            (self.pipeline.render_frame().map_err(|e| e.to_string())?, None)
        };
        let im = &frame.images;
        let mut layers = LayerSet::new(width as usize, height as usize);
        layers.insert("colour", im.color.clone());
        layers.insert("noisy", im.noisy.clone());
        layers.insert("direct", im.direct.clone());
        // The indirect light the colour holds: filtered.
        layers.insert("indirect", im.filtered_indirect.clone());
        layers.insert("albedo", im.guide.albedo.clone());
        layers.insert("normal", im.guide.normal.clone());
        layers.insert("depth", im.guide.depth.clone());
        layers.insert("position", im.guide.position.clone());
        let mut stages = Vec::new();
        if let Some(plan) = plan {
            stages.push(("prepass", plan.prepass_ms));
            stages.push(("plan", plan.plan_ms));
            layers.insert("importance", plan.importance);
        }
        stages.extend(frame.timings.stages());
        let scale = width as f32 / choice.width as f32;
        Ok(FrameOut {
            layers: Arc::new(layers),
            kind: FrameKind::Moving { scale },
            stages,
            total_ms: ms(start),
        })
    }

    /// Adds `choice.spp_per_frame` samples to the still film (started again when the camera
    /// or a setting changed). `None` when the film is at `choice.max_spp` or `cancel` cut
    /// the pass short (the film then starts again next time: its pixels would differ in
    /// sample count).
    pub fn still_frame(
        &mut self,
        camera: &Camera,
        choice: &RenderChoice,
        cancel: &AtomicBool,
    ) -> Result<Option<FrameOut>, String> {
        let start = Instant::now();
        let key = StillKey::new(camera, choice);
        let renderer = self.pipeline.source_mut().renderer_mut();
        renderer
            .set_view(camera, render_settings(choice, choice.width, choice.height))
            .map_err(|e| e.to_string())?;
        let mut acc = match self.still.take() {
            Some(a) if a.key == key => a,
            _ => Accumulation { key, film: renderer.new_film(), spp: 0, importance: None },
        };
        if acc.spp >= choice.max_spp {
            self.still = Some(acc);
            return Ok(None);
        }
        let count = choice.spp_per_frame.max(1).min(choice.max_spp - acc.spp);
        let t0 = Instant::now();
        let renderer = self.pipeline.source().renderer();
        match choice.still {
            StillRenderer::PathTracer => {
                if !renderer.render_pass(&mut acc.film, acc.spp, count, cancel) {
                    return Ok(None);
                }
            }
        }
        let trace_ms = ms(t0);
        acc.spp += count;
        let t1 = Instant::now();
        let layers = still_layers(&mut acc, choice.adaptive)?;
        let stages = vec![("trace", trace_ms), ("layers", ms(t1))];
        let spp = acc.spp;
        self.still = Some(acc);
        Ok(Some(FrameOut {
            layers: Arc::new(layers),
            kind: FrameKind::Still { spp },
            stages,
            total_ms: ms(start),
        }))
    }
}

/// The film's AOVs as layers, with the importance map when adaptive sampling is on.
fn still_layers(acc: &mut Accumulation, adaptive: bool) -> Result<LayerSet, String> {
    let aovs = acc.film.try_aovs().map_err(|e| e.to_string())?;
    if adaptive && acc.importance.is_none() {
        let params = AdaptiveParams::paper();
        let map = filtrace_adaptive::importance_map(&aovs.normal, &aovs.position, &params.importance)
            .map_err(|e| e.to_string())?;
        acc.importance = Some(map);
    }
    let mut layers = LayerSet::new(aovs.width, aovs.height);
    if let Some(map) = &acc.importance {
        layers.insert("importance", map.clone());
    }
    layers.insert("colour", aovs.color);
    layers.insert("direct", aovs.direct);
    layers.insert("indirect", aovs.indirect);
    layers.insert("albedo", aovs.albedo);
    layers.insert("normal", aovs.normal);
    layers.insert("depth", aovs.depth);
    layers.insert("position", aovs.position);
    layers.insert("variance", aovs.variance);
    Ok(layers)
}

fn render_settings(c: &RenderChoice, width: u32, height: u32) -> RenderSettings {
    RenderSettings { width, height, spp: c.spp_per_frame.max(1), max_depth: c.max_depth, seed: c.seed }
}

fn pipeline_settings(c: &RenderChoice, width: u32, height: u32) -> PipelineSettings {
    PipelineSettings {
        seed: c.seed,
        filter_direct: c.filter_direct,
        ..PipelineSettings::interactive(width, height)
    }
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

#[cfg(test)]
mod tests {
    use super::*;

    fn choice() -> RenderChoice {
        RenderChoice { max_depth: 4, spp_per_frame: 2, max_spp: 4, ..RenderChoice::new(16, 12) }
    }

    /// Two still frames of 2 spp are the film of one 4-spp render, bit for bit, and the
    /// accumulation stops at max_spp.
    #[test]
    fn still_frames_accumulate_to_the_plain_render() {
        let scene = filtrace_scene::builtin("cornell").unwrap();
        let cam = Engine::scene_camera(&scene);
        let c = choice();
        let mut engine = Engine::new(scene.clone(), &c).unwrap();
        let never = AtomicBool::new(false);
        // A moving frame in between changes the renderer's view; the film must not care.
        engine.still_frame(&cam, &c, &never).unwrap().unwrap();
        engine.moving_frame(&cam, &c, (8, 6)).unwrap();
        let out = engine.still_frame(&cam, &c, &never).unwrap().unwrap();
        assert_eq!(out.kind, FrameKind::Still { spp: 4 });
        assert!(engine.still_frame(&cam, &c, &never).unwrap().is_none(), "max_spp reached");

        let settings = RenderSettings { width: 16, height: 12, spp: 4, max_depth: 4, seed: 0 };
        let want = Renderer::new(scene, settings).unwrap().render(&never).aovs();
        assert_eq!(out.layers.get("colour").unwrap(), &want.color);
        assert_eq!(out.layers.get("normal").unwrap(), &want.normal);
        assert!(!out.layers.has("importance"));
    }

    #[test]
    fn moving_frames_have_every_pipeline_layer_and_the_importance_when_adaptive() {
        let scene = filtrace_scene::builtin("cornell").unwrap();
        let cam = crate::camera::orbit(&Engine::scene_camera(&scene), 20.0, 5.0);
        for name in crate::settings::FILTERS {
            let c =
                RenderChoice { filter: FilterChoice::named(name), adaptive: *name == "guided", ..choice() };
            let mut engine = Engine::new(scene.clone(), &c).unwrap();
            let out = engine.moving_frame(&cam, &c, (10, 8)).unwrap();
            assert_eq!((out.layers.width, out.layers.height), (10, 8));
            assert_eq!(out.kind, FrameKind::Moving { scale: 10.0 / 16.0 });
            for l in ["colour", "noisy", "direct", "indirect", "albedo", "normal", "depth", "position"] {
                assert!(out.layers.has(l), "{name}: {l}");
            }
            assert_eq!(out.layers.has("importance"), c.adaptive, "{name}");
            assert!(out.stages.iter().any(|(s, _)| *s == "filter"));
        }
    }

    #[test]
    fn a_cancelled_still_pass_gives_no_frame_and_starts_again() {
        let scene = filtrace_scene::builtin("cornell").unwrap();
        let cam = Engine::scene_camera(&scene);
        let c = choice();
        let mut engine = Engine::new(scene, &c).unwrap();
        assert!(engine.still_frame(&cam, &c, &AtomicBool::new(true)).unwrap().is_none());
        assert_eq!(engine.still_spp(&cam, &c), 0);
        let out = engine.still_frame(&cam, &c, &AtomicBool::new(false)).unwrap().unwrap();
        assert_eq!(out.kind, FrameKind::Still { spp: 2 });
    }
}
