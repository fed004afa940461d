//! The render state of one loaded scene, owned by the worker thread: one BVH, used by both
//! kinds of frame, with the camera moved in place ([`Renderer::set_view`]).
//!
//! - **moving** ([`Engine::moving_frame`]): the filtered pipeline of Bauszat et al. 2011 at
//!   1 spp (one guide ray per pixel, its indirect light filtered), at a resolution the
//!   worker scales to keep the frame rate;
//! - **still** ([`Engine::still_frame`]): progressive path tracing at full resolution, each
//!   frame adding `spp_per_frame` samples to one film. Samples are added in index order per
//!   pixel, so after `n` samples the film is bit for bit `filtrace render --spp n`'s. Or
//!   the many-light (VPL) renderer: one frame of `spp_per_frame` samples, as
//!   `filtrace render --integrator vpl`.
//!
//! Every frame is of one frame of the scene's animation ([`Engine::place`]): the renderer's
//! per-frame update ([`Renderer::set_pose`]) moves what moved since the frame before, so
//! the `motion` layer points to where each surface was in the view rendered before.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use filtrace_adaptive::AdaptiveParams;
use filtrace_core::Image;
use filtrace_pipeline::{FilterChoice, FilteredRenderer, IndirectFilter, PipelineSettings, RenderSource};
use filtrace_render::integrator::PathIntegrator;
use filtrace_render::{Film, RenderSettings, Renderer};
use filtrace_scene::{Camera, Scene};
use filtrace_vpl::vpls::{render_vpl_frame, VplParams, VplSettings};

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
    frame: i64,
    width: u32,
    height: u32,
    max_depth: i32,
    seed: u64,
    still: StillRenderer,
    adaptive: bool,
}

impl StillKey {
    fn new(camera: &Camera, frame: i64, c: &RenderChoice) -> Self {
        Self {
            camera: camera.clone(),
            frame,
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
    /// Motion of the view (to the one rendered before), computed once per key.
    motion: Option<Image>,
    /// The VPL renderer's distance to the closest cache point.
    cache_distance: Option<Image>,
}

/// One scene ready to render (see the module docs).
pub struct Engine {
    pipeline: Pipeline,
    filter: FilterChoice,
    scene_scale: f32,
    still: Option<Accumulation>,
    /// The animation frame the renderer was last posed at (`None`: the rest pose).
    placed: Option<i64>,
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
        Ok(Self { pipeline, filter: choice.filter.clone(), scene_scale, still: None, placed: None })
    }

    /// The camera the scene file gives (or the framing of its bounds).
    pub fn scene_camera(scene: &Scene) -> Camera {
        scene.camera.clone().unwrap_or_else(|| filtrace_scene::default_camera_for(scene.bounds()))
    }

    /// Samples per pixel the still film holds for this view and choice (0 if another).
    pub fn still_spp(&self, camera: &Camera, frame: i64, choice: &RenderChoice) -> u32 {
        match &self.still {
            Some(a) if a.key == StillKey::new(camera, frame, choice) => a.spp,
            _ => 0,
        }
    }

    /// True when the still image of this view is finished (nothing left to render).
    pub fn still_done(&self, camera: &Camera, frame: i64, choice: &RenderChoice) -> bool {
        self.still_spp(camera, frame, choice) >= still_limit(choice)
    }

    /// Brings the renderer to `camera` at frame `frame` of the scene's animation (any frame
    /// of a still scene) with settings `rs`. When the camera or the frame changed this is
    /// one update of the renderer ([`Renderer::set_pose`] with the pose's camera replaced
    /// by `camera`): the state before becomes its previous frame, which the motion layer
    /// points into. A change of resolution alone keeps the frame (moving and still frames
    /// differ in size); a change of depth or seed starts the view again.
    pub fn place(&mut self, camera: &Camera, frame: i64, rs: RenderSettings) -> Result<(), String> {
        let r = self.pipeline.source_mut().renderer_mut();
        let (w, h) = (r.settings().width, r.settings().height);
        if (RenderSettings { width: w, height: h, ..rs.clone() }) != *r.settings() {
            let current = r.frame().camera.clone();
            r.set_view(&current, rs).map_err(|e| e.to_string())?;
        } else if (rs.width, rs.height) != (w, h) {
            r.set_resolution(rs.width, rs.height).map_err(|e| e.to_string())?;
        }
        if self.placed != Some(frame) || r.frame().camera != *camera {
            let mut pose = r.scene().pose_at_frame(frame).map_err(|e| e.to_string())?;
            pose.camera = Some(camera.clone());
            r.set_pose(&pose).map_err(|e| e.to_string())?;
            self.placed = Some(frame);
        }
        Ok(())
    }

    /// A moving frame at `width x height` (see the module docs) holding the layers named
    /// in `shown` (the motion layer costs a primary ray per pixel, so it is made only then).
    pub fn moving_frame(
        &mut self,
        view: (&Camera, i64),
        choice: &RenderChoice,
        (width, height): (u32, u32),
        shown: &[&str],
    ) -> Result<FrameOut, String> {
        let start = Instant::now();
        if self.filter != choice.filter {
            self.pipeline.set_filter(choice.filter.build(Some(self.scene_scale))?);
            self.filter = choice.filter.clone();
        }
        self.place(view.0, view.1, render_settings(choice, width, height))?;
        let place_ms = ms(start);
        self.pipeline.set_settings(pipeline_settings(choice, width, height)).map_err(|e| e.to_string())?;
        let (frame, plan) = if choice.adaptive {
            let (frame, plan) =
                self.pipeline.render_frame_adaptive(&AdaptiveParams::paper()).map_err(|e| e.to_string())?;
            (frame, Some(plan))
        } else {
            (self.pipeline.render_frame().map_err(|e| e.to_string())?, None)
        };
        // Only the layers shown are copied out of the pipeline's buffers (a 512x512 layer
        // is 3 MB; a moving frame has eight); the others are named for the selector.
        let t_layers = Instant::now();
        let im = &frame.images;
        let keep = |name: &str| shown.contains(&name);
        let mut layers = LayerSet::new(width as usize, height as usize);
        layers.offer("colour", &keep, || im.color.clone());
        layers.offer("noisy", &keep, || im.noisy.clone());
        layers.offer("direct", &keep, || im.direct.clone());
        // The indirect light the colour holds: filtered.
        layers.offer("indirect", &keep, || im.filtered_indirect.clone());
        layers.offer("albedo", &keep, || im.guide.albedo.clone());
        layers.offer("normal", &keep, || im.guide.normal.clone());
        layers.offer("depth", &keep, || im.guide.depth.clone());
        layers.offer("position", &keep, || im.guide.position.clone());
        let mut stages = vec![("place", place_ms)];
        stages.extend(frame.timings.stages());
        if let Some(plan) = plan {
            stages.push(("prepass", plan.prepass_ms));
            stages.push(("plan", plan.plan_ms));
            layers.offer("importance", &keep, || plan.importance);
        }
        stages.push(("layers", ms(t_layers)));
        let t = Instant::now();
        layers.offer("motion", &keep, || self.pipeline.source().renderer().motion_aov().motion);
        if keep("motion") {
            stages.push(("motion", ms(t)));
        }
        let scale = width as f32 / choice.width as f32;
        Ok(FrameOut {
            layers: Arc::new(layers),
            kind: FrameKind::Moving { scale },
            stages,
            total_ms: ms(start),
        })
    }

    /// Adds `choice.spp_per_frame` samples to the still film (started again when the camera,
    /// the frame or a setting changed). `None` when the film is at `choice.max_spp` or
    /// `cancel` cut the pass short (the film then starts again next time: its pixels would
    /// differ in sample count). The VPL renderer renders its one frame, then is done.
    pub fn still_frame(
        &mut self,
        (camera, frame): (&Camera, i64),
        choice: &RenderChoice,
        cancel: &AtomicBool,
    ) -> Result<Option<FrameOut>, String> {
        let start = Instant::now();
        let key = StillKey::new(camera, frame, choice);
        self.place(camera, frame, render_settings(choice, choice.width, choice.height))?;
        let renderer = self.pipeline.source().renderer();
        let mut acc = match self.still.take() {
            Some(a) if a.key == key => a,
            // A new film: its motion is that of this view against the one rendered before.
            _ => Accumulation {
                key,
                film: renderer.new_film(),
                spp: 0,
                importance: None,
                motion: Some(renderer.motion_aov().motion),
                cache_distance: None,
            },
        };
        let limit = still_limit(choice);
        if acc.spp >= limit {
            self.still = Some(acc);
            return Ok(None);
        }
        let count = choice.spp_per_frame.max(1).min(limit - acc.spp);
        let t0 = Instant::now();
        let done = match choice.still {
            StillRenderer::PathTracer => {
                self.pipeline.source().renderer().render_pass(&mut acc.film, acc.spp, count, cancel)
            }
            StillRenderer::Vpl => {
                vpl_pass(self.pipeline.source_mut().renderer_mut(), &mut acc, count, cancel)?
            }
        };
        if !done {
            return Ok(None);
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

/// Samples per pixel at which the still image is finished: the path tracer accumulates to
/// `max_spp`; the VPL renderer renders one frame.
pub(crate) fn still_limit(choice: &RenderChoice) -> u32 {
    match choice.still {
        StillRenderer::PathTracer => choice.max_spp,
        StillRenderer::Vpl => choice.spp_per_frame.max(1).min(choice.max_spp),
    }
}

/// The VPL renderer's frame of `count` samples into `acc` (`filtrace render --integrator
/// vpl`'s defaults: 2048 VPLs, 2048 cache points, the optimised sampler); false when
/// cancelled.
fn vpl_pass(
    renderer: &mut Renderer,
    acc: &mut Accumulation,
    count: u32,
    cancel: &AtomicBool,
) -> Result<bool, String> {
    let settings = VplSettings { vpls: VplParams::with_count(2048), ..VplSettings::default() };
    let frame = render_vpl_frame(renderer, &settings, count, cancel);
    // The moving frames and the path-traced stills go on with the path tracer.
    renderer.set_integrator(Box::new(PathIntegrator));
    let Some(frame) = frame? else { return Ok(false) };
    acc.film = frame.film;
    acc.cache_distance = Some(frame.cache_distance);
    Ok(true)
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
    if let Some(m) = &acc.motion {
        layers.insert("motion", m.clone());
    }
    if let Some(d) = &acc.cache_distance {
        layers.insert("cache_distance", d.clone());
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
        engine.still_frame((&cam, 0), &c, &never).unwrap().unwrap();
        engine.moving_frame((&cam, 0), &c, (8, 6), &["motion"]).unwrap();
        let out = engine.still_frame((&cam, 0), &c, &never).unwrap().unwrap();
        assert_eq!(out.kind, FrameKind::Still { spp: 4 });
        assert!(engine.still_frame((&cam, 0), &c, &never).unwrap().is_none(), "max_spp reached");

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
            let all = ["colour", "noisy", "direct", "indirect", "albedo", "normal", "depth", "position"];
            let out = engine.moving_frame((&cam, 0), &c, (10, 8), &all).unwrap();
            assert_eq!((out.layers.width, out.layers.height), (10, 8));
            assert_eq!(out.kind, FrameKind::Moving { scale: 10.0 / 16.0 });
            for l in all {
                assert!(out.layers.has(l), "{name}: {l}");
            }
            assert_eq!(out.layers.available().any(|l| l == "importance"), c.adaptive, "{name}");
            // Only the layers shown are copied; the others are offered by name.
            let out = engine.moving_frame((&cam, 0), &c, (10, 8), &["normal"]).unwrap();
            assert!(out.layers.has("normal") && !out.layers.has("colour"));
            let mut names: Vec<_> = out.layers.available().collect();
            names.sort_unstable();
            let mut want = all.to_vec();
            want.extend(c.adaptive.then_some("importance"));
            want.push("motion");
            want.sort_unstable();
            assert_eq!(names, want, "{name}");
            assert!(out.stages.iter().any(|(s, _)| *s == "filter"));
        }
    }

    #[test]
    fn a_cancelled_still_pass_gives_no_frame_and_starts_again() {
        let scene = filtrace_scene::builtin("cornell").unwrap();
        let cam = Engine::scene_camera(&scene);
        let c = choice();
        let mut engine = Engine::new(scene, &c).unwrap();
        assert!(engine.still_frame((&cam, 0), &c, &AtomicBool::new(true)).unwrap().is_none());
        assert_eq!(engine.still_spp(&cam, 0, &c), 0);
        let out = engine.still_frame((&cam, 0), &c, &AtomicBool::new(false)).unwrap().unwrap();
        assert_eq!(out.kind, FrameKind::Still { spp: 2 });
    }

    /// Frame n of an animation, reached from the rest pose, is `filtrace render --frame n`'s
    /// film (the scene posed at n, moved n-1 then n), and after a step to n+1 the motion
    /// layer is that render's motion AOV of frame n+1.
    #[test]
    fn animation_frames_are_the_sequence_renders_and_motion_follows_the_step() {
        let scene = filtrace_scene::builtin("cornell-anim").unwrap();
        let c = choice();
        let never = AtomicBool::new(false);
        let cam_at = |n: i64| scene.pose_at_frame(n).unwrap().camera.unwrap();
        let reference = |n: i64| {
            let settings = RenderSettings { width: 16, height: 12, spp: 4, max_depth: 4, seed: 0 };
            let mut posed = scene.clone();
            posed.apply_pose(&scene.pose_at_frame(n).unwrap());
            let mut r = Renderer::new(posed, settings).unwrap();
            r.prepare_frame(n - 1).unwrap();
            r.prepare_frame(n).unwrap();
            (r.render(&never).aovs().color, r.motion_aov().motion)
        };
        let mut engine = Engine::new(scene.clone(), &c).unwrap();
        engine.still_frame((&cam_at(5), 5), &c, &never).unwrap().unwrap();
        let out = engine.still_frame((&cam_at(5), 5), &c, &never).unwrap().unwrap();
        assert_eq!(out.layers.get("colour").unwrap(), &reference(5).0);
        engine.moving_frame((&cam_at(6), 6), &c, (8, 6), &["colour"]).unwrap();
        let out = engine.still_frame((&cam_at(6), 6), &c, &never).unwrap().unwrap();
        let (colour, motion) = reference(6);
        assert_eq!(out.layers.get("motion").unwrap(), &motion);
        assert!(motion.data().iter().any(|v| *v != 0.0), "the camera moves between frames 5 and 6");
        let out = engine.still_frame((&cam_at(6), 6), &c, &never).unwrap().unwrap();
        assert_eq!(out.kind, FrameKind::Still { spp: 4 });
        assert_eq!(out.layers.get("colour").unwrap(), &colour);
    }

    #[test]
    fn the_vpl_renderer_gives_one_frame_with_the_cache_distance() {
        let scene = filtrace_scene::builtin("cornell").unwrap();
        let cam = Engine::scene_camera(&scene);
        let c = RenderChoice { still: StillRenderer::Vpl, ..choice() };
        let mut engine = Engine::new(scene, &c).unwrap();
        let never = AtomicBool::new(false);
        let out = engine.still_frame((&cam, 0), &c, &never).unwrap().unwrap();
        assert_eq!(out.kind, FrameKind::Still { spp: 2 });
        assert!(out.layers.has("cache_distance") && out.layers.has("colour"));
        assert!(engine.still_done(&cam, 0, &c));
        assert!(engine.still_frame((&cam, 0), &c, &never).unwrap().is_none());
    }
}
