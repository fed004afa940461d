//! The window: each UI frame polls the scene file, turns input into a camera, posts the job
//! to the worker, shows the newest frame the worker published, and draws the panel and the
//! overlay. Nothing here renders or waits for a render.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use eframe::egui::{self, Color32, TextureOptions};
use filtrace_scene::Camera;

use crate::engine::{Engine, FrameKind};
use crate::input::{Action, Navigator};
use crate::layers::LAYERS;
use crate::scene_watch::{SceneEvent, SceneWatch};
use crate::settings::{DisplayChoice, RenderChoice};
use crate::stats::UiStats;
use crate::timeline::Timeline;
use crate::worker::{Job, Published, Worker};
use crate::{save, ViewerOptions, ViewerOutcome};

/// The camera counts as moving for this long after its last change (then the still
/// accumulation starts).
const SETTLE: Duration = Duration::from_millis(150);
/// Width of the settings panel in points.
pub const PANEL_WIDTH: f32 = 270.0;

/// A screenshot asked of the window: where to write it and which part to keep.
struct PendingShot {
    path: std::path::PathBuf,
    rect: egui::Rect,
    image: Arc<Mutex<Option<Arc<egui::ColorImage>>>>,
    /// Close the window once written (headless `--screenshot`).
    then_close: bool,
}

pub struct ViewerApp {
    pub(crate) opts: ViewerOptions,
    worker: Worker,
    scene: SceneWatch,
    pub(crate) camera: Camera,
    /// The camera of the scene file (R resets to it; a reload that changes it moves there).
    pub(crate) home: Option<Camera>,
    pub(crate) render: RenderChoice,
    pub(crate) display: DisplayChoice,
    /// The animated scene's timeline (`None` for a still scene).
    pub(crate) timeline: Option<Timeline>,
    navigator: Navigator,
    pub(crate) last_change: Option<Instant>,
    texture: Option<egui::TextureHandle>,
    pub(crate) shown: Option<Published>,
    pub(crate) scene_error: Option<String>,
    pub(crate) message: Option<String>,
    pub(crate) overlay: bool,
    pub(crate) stats: UiStats,
    shot: Option<PendingShot>,
    shots_taken: u32,
    /// Where the image was drawn in the last frame.
    pub(crate) last_image: egui::Rect,
    /// `--log-frames`: the shown frame is to be logged once drawn (with its position).
    log_pending: bool,
    outcome: Arc<Mutex<ViewerOutcome>>,
}

impl ViewerApp {
    pub fn new(
        cc: &eframe::CreationContext<'_>,
        opts: ViewerOptions,
        outcome: Arc<Mutex<ViewerOutcome>>,
    ) -> Result<Self, String> {
        let ctx = cc.egui_ctx.clone();
        let worker = Worker::start(opts.threads, move || ctx.request_repaint())?;
        let scene =
            SceneWatch::start(&opts.scene, filtrace_scene::LoadOptions { default_light: opts.default_light });
        let mut render = RenderChoice::new(opts.width, opts.height);
        render.max_depth = opts.max_depth;
        render.seed = opts.seed;
        render.spp_per_frame = opts.spp_per_frame;
        render.max_spp = opts.max_spp();
        render.filter = opts.filter.clone();
        render.adaptive = opts.adaptive;
        render.target_fps = opts.target_fps;
        render.still = opts.still;
        let display = DisplayChoice { layer: opts.layer, ..DisplayChoice::default() };
        Ok(Self {
            camera: opts.camera.clone().unwrap_or_else(filtrace_scene::Camera::cornell),
            home: None,
            overlay: !opts.no_overlay,
            opts,
            worker,
            scene,
            render,
            display,
            timeline: None,
            navigator: Navigator::default(),
            last_change: None,
            texture: None,
            shown: None,
            scene_error: None,
            message: None,
            stats: UiStats::default(),
            shot: None,
            shots_taken: 0,
            last_image: egui::Rect::NOTHING,
            log_pending: false,
            outcome,
        })
    }

    /// Takes a finished load or reload.
    fn poll_scene(&mut self) {
        match self.scene.poll() {
            Some(SceneEvent::Loaded(scene)) => {
                // A reload keeps the shown frame where the animation still has it.
                let start = self.timeline.as_ref().map(|t| t.frame()).or(self.opts.frame);
                let timeline = match Timeline::new(&scene, start).or_else(|e| {
                    if self.home.is_some() {
                        Timeline::new(&scene, None)
                    } else {
                        Err(e)
                    }
                }) {
                    Ok(t) => t,
                    Err(e) => {
                        eprintln!("filtrace view: {e}");
                        self.scene_error = Some(e);
                        return;
                    }
                };
                let first_load = self.home.is_none();
                let follow = self.timeline.as_ref().is_none_or(|t| t.follow_camera);
                self.timeline = timeline.map(|mut t| {
                    t.follow_camera &= follow && !(first_load && self.opts.camera.is_some());
                    if first_load && self.opts.play {
                        t.toggle_play(Instant::now());
                    }
                    t
                });
                let file_cam = Engine::scene_camera(&scene);
                // The first scene, or a reload that moved the file's camera, sets the camera
                // (unless --camera chose one); otherwise the user's camera stays.
                if self.home.as_ref() != Some(&file_cam)
                    && (self.home.is_some() || self.opts.camera.is_none())
                {
                    self.camera = file_cam.clone();
                }
                if self.scene.loads > 1 {
                    eprintln!("filtrace view: reloaded {}", self.opts.scene);
                }
                self.home = Some(file_cam);
                self.scene_error = None;
                self.worker.set_scene(*scene);
            }
            Some(SceneEvent::Failed(e)) => {
                let kept = if self.home.is_some() { " (keeping the last good scene)" } else { "" };
                eprintln!("filtrace view: {e}{kept}");
                self.scene_error = Some(format!("{e}{kept}"));
            }
            None => {}
        }
    }

    /// Input: camera moves and key actions.
    fn handle_input(&mut self, ctx: &egui::Context, image: egui::Rect) {
        let nav = self.navigator.update(ctx, image, &self.camera, self.render.height as f32);
        if nav.camera != self.camera || nav.active {
            self.last_change = Some(Instant::now());
            // The user's hand takes the camera from the animation's track (R gives it back).
            if let Some(t) = &mut self.timeline {
                t.follow_camera = false;
            }
        }
        self.camera = nav.camera;
        for action in nav.actions {
            self.act(ctx, action, image);
        }
    }

    /// Playback, and the animated camera when the camera follows the track. A change of
    /// frame counts as movement: the filtered path until the frame stays.
    fn animate(&mut self, ctx: &egui::Context) {
        let Some(t) = &mut self.timeline else { return };
        if t.tick(Instant::now()) {
            self.last_change = Some(Instant::now());
        }
        if t.playing() {
            ctx.request_repaint_after(Duration::from_secs_f64(t.frame_seconds()));
        }
        if t.follow_camera {
            if let Some(cam) = t.animated_camera() {
                self.camera = cam;
            }
        }
    }

    /// Animation actions (keys and panel buttons).
    pub(crate) fn timeline_action(&mut self, action: Action) {
        let Some(t) = &mut self.timeline else { return };
        match action {
            Action::TogglePlay => t.toggle_play(Instant::now()),
            Action::StepFrame(d) => t.step(d),
            _ => return,
        }
        self.last_change = Some(Instant::now());
    }

    pub(crate) fn act(&mut self, ctx: &egui::Context, action: Action, image: egui::Rect) {
        match action {
            Action::Close => ctx.send_viewport_cmd(egui::ViewportCommand::Close),
            Action::Save => self.save_frame(),
            Action::Screenshot => {
                let path =
                    save::next_free(&self.opts.out_dir, &format!("{}-screenshot", self.opts.scene_name()))
                        .with_extension("png");
                self.request_shot(ctx, path, image, false);
            }
            Action::ResetCamera => match &mut self.timeline {
                // Back to the animation's camera, which the view follows again.
                Some(t) if t.has_camera_track() => t.follow_camera = true,
                _ => {
                    if let Some(home) = &self.home {
                        self.camera = home.clone();
                    }
                }
            },
            Action::TogglePlay | Action::StepFrame(_) => self.timeline_action(action),
            Action::ToggleSplit => self.display.split = !self.display.split,
            Action::ToggleOverlay => self.overlay = !self.overlay,
            Action::Layer(n) => {
                if let Some(l) = LAYERS.get(n) {
                    self.display.layer = l.name;
                }
            }
        }
    }

    /// Writes the shown frame's layers (EXR) and its display image (PNG) on a thread.
    pub(crate) fn save_frame(&mut self) {
        let Some(shown) = &self.shown else {
            self.message = Some("nothing to save yet".into());
            return;
        };
        if let Err(e) = std::fs::create_dir_all(&self.opts.out_dir) {
            self.message = Some(format!("cannot create {}: {e}", self.opts.out_dir.display()));
            return;
        }
        let base = save::next_free(&self.opts.out_dir, &self.opts.scene_name());
        let (layers, image) = (shown.layers.clone(), shown.image.clone());
        let mut attrs = vec![("filtrace:camera", crate::camera::format_camera(&shown.job.camera))];
        if let FrameKind::Still { spp } = shown.kind {
            attrs.push(("filtrace:spp_done", spp.to_string()));
        }
        self.message = Some(format!("saving {}.exr/.png", base.display()));
        std::thread::spawn(move || {
            let exr = base.with_extension("exr");
            let attrs: Vec<(&str, String)> = attrs.iter().map(|(k, v)| (*k, v.clone())).collect();
            let r = save::write_layers_exr(&exr, &layers, &attrs)
                .and_then(|_| save::write_png(&base.with_extension("png"), &image));
            match r {
                Ok(()) => eprintln!(
                    "filtrace view: saved {} and {}",
                    exr.display(),
                    base.with_extension("png").display()
                ),
                Err(e) => eprintln!("filtrace view: cannot save {}: {e}", base.display()),
            }
        });
    }

    fn request_shot(
        &mut self,
        ctx: &egui::Context,
        path: std::path::PathBuf,
        rect: egui::Rect,
        then_close: bool,
    ) {
        if self.shot.is_some() {
            return;
        }
        let slot = Arc::new(Mutex::new(None));
        let (s, c) = (slot.clone(), ctx.clone());
        ctx.send_viewport_cmd(egui::ViewportCommand::Screenshot(egui::ScreenshotCallback::new(move |img| {
            *s.lock().unwrap_or_else(|p| p.into_inner()) = Some(img);
            c.request_repaint();
        })));
        self.shot = Some(PendingShot { path, rect, image: slot, then_close });
    }

    /// Writes a screenshot that has arrived.
    fn finish_shot(&mut self, ctx: &egui::Context) {
        let Some(shot) = &self.shot else { return };
        let Some(img) = shot.image.lock().unwrap_or_else(|p| p.into_inner()).take() else { return };
        let ppp = ctx.pixels_per_point();
        let cropped = save::crop(&img, shot.rect, ppp);
        let result = shot.path.parent().filter(|d| !d.as_os_str().is_empty()).map_or(Ok(()), |d| {
            std::fs::create_dir_all(d).map_err(|e| format!("cannot create {}: {e}", d.display()))
        });
        match result.and_then(|_| save::write_png(&shot.path, &cropped)) {
            Ok(()) => eprintln!("filtrace view: saved screenshot {}", shot.path.display()),
            Err(e) => {
                eprintln!("filtrace view: cannot write screenshot {}: {e}", shot.path.display());
                self.outcome.lock().unwrap_or_else(|p| p.into_inner()).error = Some(e);
            }
        }
        self.shots_taken += 1;
        if shot.then_close {
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
        }
        self.shot = None;
    }

    /// Headless `--frames N --screenshot`: once the N-th still frame is on screen (or the
    /// scene failed to load and the error is), take the screenshot and close.
    fn headless(&mut self, ctx: &egui::Context, image: egui::Rect) {
        let Some(frames) = self.opts.frames else { return };
        ctx.request_repaint();
        if self.shots_taken > 0 || self.shot.is_some() {
            return;
        }
        let want = frames.saturating_mul(self.render.spp_per_frame);
        let want = want.min(crate::engine::still_limit(&self.render));
        let done = self.shown.as_ref().is_some_and(|s| {
            s.kind == FrameKind::Still { spp: want }
                && s.job.camera == self.camera
                && s.job.frame == self.frame()
                && !self.moving()
        });
        let render_error = self.worker.error();
        if let Some(e) = &render_error {
            self.outcome.lock().unwrap_or_else(|p| p.into_inner()).error = Some(e.clone());
        }
        let failed = (self.scene_error.is_some() && self.home.is_none()) || render_error.is_some();
        if done || failed {
            let rect = if self.opts.screenshot_window { egui::Rect::EVERYTHING } else { image };
            match self.opts.screenshot.clone() {
                Some(path) => self.request_shot(ctx, path, rect, true),
                None => ctx.send_viewport_cmd(egui::ViewportCommand::Close),
            }
        }
    }

    /// The camera or the scene is moving: a drag, a fly key, a recent change, or playback.
    pub(crate) fn moving(&self) -> bool {
        self.last_change.is_some_and(|t| t.elapsed() < SETTLE)
            || self.timeline.as_ref().is_some_and(|t| t.playing())
    }

    /// The animation frame shown (0 for a still scene).
    pub(crate) fn frame(&self) -> i64 {
        self.timeline.as_ref().map_or(0, |t| t.frame())
    }

    /// Takes the worker's newest frame into the texture.
    fn take_frame(&mut self, ctx: &egui::Context) {
        let Some(frame) = self.worker.take() else { return };
        let full = [self.render.width as usize, self.render.height as usize];
        // One texel per screen pixel at full size; a smaller moving frame is stretched.
        // No mipmaps (TextureOptions' default): the image is never minified.
        let options = if frame.image.size == full { TextureOptions::NEAREST } else { TextureOptions::LINEAR };
        let image = egui::ImageData::Color(frame.image.clone());
        match &mut self.texture {
            Some(t) => t.set(image, options),
            None => self.texture = Some(ctx.load_texture("frame", image, options)),
        }
        self.stats.frame_published(&frame);
        self.log_pending = self.opts.log_frames;
        self.shown = Some(frame);
    }

    /// The image's rect: full resolution at one image pixel per screen pixel.
    fn image_rect(&self, ctx: &egui::Context, area: egui::Rect) -> egui::Rect {
        let ppp = ctx.pixels_per_point();
        let size = egui::vec2(self.render.width as f32, self.render.height as f32) / ppp;
        egui::Rect::from_min_size(area.min, size)
    }

    fn draw_image(&mut self, ui: &mut egui::Ui) -> egui::Rect {
        let area = ui.available_rect_before_wrap();
        let rect = self.image_rect(ui.ctx(), area);
        ui.allocate_rect(rect, egui::Sense::hover());
        let painter = ui.painter_at(rect);
        painter.rect_filled(rect, 0.0, Color32::BLACK);
        if let Some(t) = &self.texture {
            let uv = egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0));
            painter.image(t.id(), rect, uv, Color32::WHITE);
        }
        if let Some(e) = self.scene_error.clone().or_else(|| self.worker.error()) {
            crate::overlay::error_box(&painter, rect, &e);
        } else if self.home.is_none() {
            crate::overlay::error_box(&painter, rect, &format!("loading {} ...", self.opts.scene));
        }
        if self.overlay {
            let animated = self.timeline.is_some();
            crate::overlay::draw(
                &painter,
                rect,
                self.shown.as_ref(),
                animated,
                &self.stats,
                self.message.as_deref(),
            );
        }
        rect
    }

    fn post_job(&mut self) {
        if self.home.is_none() {
            return;
        }
        let job = Job {
            camera: self.camera.clone(),
            frame: self.frame(),
            render: self.render.clone(),
            display: self.display.clone(),
            moving: self.moving(),
        };
        self.worker.post(job);
    }
}

impl eframe::App for ViewerApp {
    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        self.stats.ui_frame(frame.info().cpu_usage, self.worker.busy());
        self.poll_scene();
        self.take_frame(&ctx);
        self.finish_shot(&ctx);
        egui::Panel::left("settings").exact_size(PANEL_WIDTH).show(ui, |ui| self.show_panel(ui));
        let image = egui::CentralPanel::default().show(ui, |ui| self.draw_image(ui)).inner;
        self.last_image = image;
        if let (true, Some(frame)) = (std::mem::take(&mut self.log_pending), &self.shown) {
            let at = image.min * ctx.pixels_per_point();
            eprintln!("filtrace view: frame {}", crate::stats::describe(frame, (at.x, at.y)));
        }
        self.handle_input(&ctx, image);
        self.animate(&ctx);
        self.post_job();
        self.headless(&ctx, image);
        if self.moving() {
            ctx.request_repaint_after(SETTLE);
        }
        if self.scene.is_loading() || self.opts.scene_is_file() {
            ctx.request_repaint_after(crate::scene_watch::POLL);
        }
        let mut out = self.outcome.lock().unwrap_or_else(|p| p.into_inner());
        out.camera = Some(self.camera.clone());
        out.max_ui_frame_ms = self.stats.max_busy_frame_ms;
        out.mean_ui_frame_ms = self.stats.mean_busy_frame_ms();
        out.moving_stages = self.stats.moving_stage_means();
        out.moving_shown_fps = self.stats.moving_shown_fps();
        out.ui_frames_while_rendering = self.stats.busy_frames;
        (out.moving_frames, out.moving_mean_ms, out.moving_mean_pixels) = self.stats.moving_summary();
        out.load_error = if self.home.is_none() { self.scene_error.clone() } else { None };
    }
}
