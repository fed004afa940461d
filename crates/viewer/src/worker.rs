//! The render worker: one thread that owns the [`Engine`] and renders on its own rayon pool,
//! so that the UI thread never waits for a frame. The UI posts the latest [`Job`] (camera,
//! settings, display); the worker renders the newest job it finds, never a queue of stale
//! ones, and posts a [`Published`] frame already mapped to display colour.
//!
//! While moving, a frame in flight is finished (cancelling it at every mouse move would
//! show nothing); a still pass in flight is cancelled as soon as the job changes.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use eframe::egui;
use filtrace_scene::{Camera, Scene};

use crate::display::compose;
use crate::engine::{Engine, FrameKind, FrameOut};
use crate::settings::{DisplayChoice, RenderChoice};

/// What the UI wants shown now.
#[derive(Clone, Debug, PartialEq)]
pub struct Job {
    pub camera: Camera,
    /// Frame of the scene's animation (0 for a still scene).
    pub frame: i64,
    pub render: RenderChoice,
    pub display: DisplayChoice,
    /// The camera is moving: render the fast filtered frame.
    pub moving: bool,
}

/// A frame ready for the screen.
#[derive(Clone)]
pub struct Published {
    /// Display colour of the frame (the chosen layer, or the split of two layers), shared
    /// with the texture upload (no copy of the pixels on the UI thread).
    pub image: Arc<egui::ColorImage>,
    pub layers: Arc<crate::layers::LayerSet>,
    pub kind: FrameKind,
    pub stages: Vec<(&'static str, f64)>,
    pub total_ms: f64,
    /// The job this frame is for.
    pub job: Job,
    /// Layers the display asked for that this frame does not have.
    pub missing: Vec<&'static str>,
}

#[derive(Default)]
struct Shared {
    job: Option<Job>,
    /// A scene to switch to (first load or reload).
    scene: Option<Scene>,
    quit: bool,
    out: Option<Published>,
    /// Why the last scene could not be prepared (BVH, settings).
    error: Option<String>,
}

/// Handle held by the UI.
pub struct Worker {
    shared: Arc<(Mutex<Shared>, Condvar)>,
    /// Set when the job changes, to stop a still pass early.
    cancel: Arc<AtomicBool>,
    /// True while a frame is being rendered.
    busy: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Worker {
    /// Starts the thread; `repaint` is called after each published frame (wakes the UI).
    pub fn start(threads: usize, repaint: impl Fn() + Send + Sync + 'static) -> Result<Self, String> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("filtrace-view-render-{i}"))
            .build()
            .map_err(|e| format!("cannot start the render threads: {e}"))?;
        let shared = Arc::new((Mutex::new(Shared::default()), Condvar::new()));
        let cancel = Arc::new(AtomicBool::new(false));
        let busy = Arc::new(AtomicBool::new(false));
        let (s, c, b) = (shared.clone(), cancel.clone(), busy.clone());
        let thread = std::thread::Builder::new()
            .name("filtrace-view-worker".into())
            .spawn(move || pool.install(|| run(&s, &c, &b, &repaint)))
            .map_err(|e| format!("cannot start the render worker: {e}"))?;
        Ok(Self { shared, cancel, busy, thread: Some(thread) })
    }

    /// Posts the job to render next (replacing any not yet started).
    pub fn post(&self, job: Job) {
        let (lock, cv) = &*self.shared;
        let mut s = lock.lock().unwrap_or_else(|p| p.into_inner());
        if s.job.as_ref() != Some(&job) {
            let restarts = match &s.job {
                Some(old) => old.camera != job.camera || old.frame != job.frame || old.render != job.render,
                None => true,
            };
            if restarts {
                self.cancel.store(true, Ordering::Relaxed);
            }
            s.job = Some(job);
            cv.notify_all();
        }
    }

    /// Switches to `scene` (the BVH is built on the worker).
    pub fn set_scene(&self, scene: Scene) {
        let (lock, cv) = &*self.shared;
        let mut s = lock.lock().unwrap_or_else(|p| p.into_inner());
        s.scene = Some(scene);
        self.cancel.store(true, Ordering::Relaxed);
        cv.notify_all();
    }

    /// The newest frame, if one came since the last call.
    pub fn take(&self) -> Option<Published> {
        self.shared.0.lock().unwrap_or_else(|p| p.into_inner()).out.take()
    }

    /// True while the worker renders (or builds a scene).
    pub fn busy(&self) -> bool {
        self.busy.load(Ordering::Relaxed)
    }

    /// Why the scene could not be prepared, if it could not.
    pub fn error(&self) -> Option<String> {
        self.shared.0.lock().unwrap_or_else(|p| p.into_inner()).error.clone()
    }

    /// Stops the worker (a pass in flight stops within a sample's time) and waits for it.
    pub fn stop(&mut self) {
        {
            let (lock, cv) = &*self.shared;
            lock.lock().unwrap_or_else(|p| p.into_inner()).quit = true;
            self.cancel.store(true, Ordering::Relaxed);
            cv.notify_all();
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.stop();
    }
}

/// What the worker does next.
enum Task {
    Quit,
    Scene(Box<Scene>),
    Render(Job),
    /// Only the display changed: map the last frame again.
    Redisplay(Job),
}

/// The worker's state between tasks.
struct State {
    engine: Option<Engine>,
    last: Option<(FrameOut, Job)>,
    /// Moving frames' resolution as a fraction of the full one.
    scale: f32,
    /// A job whose frame failed: not tried again until the job changes.
    failed: Option<Job>,
    published_at: Option<Instant>,
}

/// Shortest time between two published still frames (a 60 Hz display shows no more).
const STILL_INTERVAL: Duration = Duration::from_millis(15);

fn run(shared: &(Mutex<Shared>, Condvar), cancel: &AtomicBool, busy: &AtomicBool, repaint: &dyn Fn()) {
    let mut st = State { engine: None, last: None, scale: 0.5, failed: None, published_at: None };
    loop {
        busy.store(false, Ordering::Relaxed);
        let task = next_task(shared, &st, cancel);
        busy.store(true, Ordering::Relaxed);
        match task {
            Task::Quit => return,
            Task::Scene(scene) => {
                let job = shared.0.lock().unwrap_or_else(|p| p.into_inner()).job.clone();
                let choice = job.map(|j| j.render).unwrap_or_else(|| RenderChoice::new(64, 64));
                let (engine, error) = match Engine::new(*scene, &choice) {
                    Ok(e) => (Some(e), None),
                    Err(e) => (None, Some(e)),
                };
                // A scene that cannot be prepared keeps the last good one.
                if engine.is_some() {
                    st.engine = engine;
                    st.last = None;
                    st.failed = None;
                }
                shared.0.lock().unwrap_or_else(|p| p.into_inner()).error = error;
                repaint();
            }
            Task::Render(job) => {
                let frame = match render(&mut st, &job, cancel) {
                    Ok(Some(frame)) => frame,
                    Ok(None) => continue,
                    Err(e) => {
                        eprintln!("filtrace view: render error: {e}");
                        shared.0.lock().unwrap_or_else(|p| p.into_inner()).error = Some(e);
                        st.failed = Some(job);
                        repaint();
                        continue;
                    }
                };
                // Still frames of a tiny image take well under a millisecond: show at most
                // one per STILL_INTERVAL, and always the last.
                let last_of_film =
                    matches!(frame.kind, FrameKind::Still { spp } if spp >= job.render.max_spp);
                let recent = st.published_at.is_some_and(|t| t.elapsed() < STILL_INTERVAL);
                if matches!(frame.kind, FrameKind::Still { .. }) && recent && !last_of_film {
                    continue;
                }
                st.published_at = Some(Instant::now());
                publish(shared, frame, job, &mut st);
                repaint();
            }
            Task::Redisplay(job) => {
                if let Some((frame, _)) = st.last.take() {
                    publish(shared, frame, job, &mut st);
                    repaint();
                }
            }
        }
    }
}

/// Waits until there is something to do.
fn next_task(shared: &(Mutex<Shared>, Condvar), st: &State, cancel: &AtomicBool) -> Task {
    let (lock, cv) = shared;
    let mut s = lock.lock().unwrap_or_else(|p| p.into_inner());
    loop {
        cancel.store(false, Ordering::Relaxed);
        if s.quit {
            return Task::Quit;
        }
        if let Some(scene) = s.scene.take() {
            return Task::Scene(Box::new(scene));
        }
        if let (Some(job), Some(engine)) = (&s.job, &st.engine) {
            if st.failed.as_ref() == Some(job) {
                s = cv.wait(s).unwrap_or_else(|p| p.into_inner());
                continue;
            }
            let last = st.last.as_ref().map(|(_, j)| j);
            let same_frame = last
                .is_some_and(|l| l.camera == job.camera && l.frame == job.frame && l.render == job.render);
            if job.moving && (!same_frame || st.last.as_ref().is_some_and(|(f, _)| lacks_shown(f, job))) {
                return Task::Render(job.clone());
            }
            if !job.moving && !engine.still_done(&job.camera, job.frame, &job.render) {
                return Task::Render(job.clone());
            }
            if last.is_some_and(|l| l.display != job.display || l.moving != job.moving) && same_frame {
                return Task::Redisplay(job.clone());
            }
        }
        s = cv.wait(s).unwrap_or_else(|p| p.into_inner());
    }
}

/// The layers `job` shows.
fn shown_layers(job: &Job) -> Vec<&'static str> {
    let d = &job.display;
    if d.split {
        vec![d.layer, d.split_layer]
    } else {
        vec![d.layer]
    }
}

/// `frame` lacks a layer `job` shows that its renderer could have given (a moving frame
/// keeps only the layers shown): the frame is rendered again rather than shown black.
fn lacks_shown(frame: &FrameOut, job: &Job) -> bool {
    shown_layers(job).iter().any(|n| !frame.layers.has(n) && frame.layers.available().any(|a| a == *n))
}

/// Renders `job`'s next frame; `None` when there is nothing new to show (a cancelled
/// pass, a film at its sample limit).
fn render(st: &mut State, job: &Job, cancel: &AtomicBool) -> Result<Option<FrameOut>, String> {
    let Some(engine) = st.engine.as_mut() else { return Ok(None) };
    let c = &job.render;
    if job.moving {
        let size = scaled(c.width, c.height, st.scale);
        let r = engine.moving_frame((&job.camera, job.frame), c, size, &shown_layers(job));
        if let Ok(f) = &r {
            st.scale = adapt_scale(st.scale, f.total_ms, c.target_fps);
        }
        r.map(Some)
    } else {
        engine.still_frame((&job.camera, job.frame), c, cancel)
    }
}

fn publish(shared: &(Mutex<Shared>, Condvar), frame: FrameOut, job: Job, st: &mut State) {
    let t = Instant::now();
    let (image, missing) = compose(&frame.layers, &job.display);
    let display_ms = t.elapsed().as_secs_f64() * 1e3;
    let mut stages = frame.stages.clone();
    stages.push(("display", display_ms));
    let p = Published {
        image: Arc::new(image),
        layers: frame.layers.clone(),
        kind: frame.kind,
        stages,
        total_ms: frame.total_ms + display_ms,
        job: job.clone(),
        missing,
    };
    let mut s = shared.0.lock().unwrap_or_else(|p| p.into_inner());
    s.out = Some(p);
    s.error = None;
    st.last = Some((frame, job));
}

/// `width x height` scaled by `scale` (at least 8 pixels a side, at most the full size).
pub fn scaled(width: u32, height: u32, scale: f32) -> (u32, u32) {
    let side = |v: u32| ((v as f32 * scale).round() as u32).clamp(8.min(v), v);
    (side(width), side(height))
}

/// The next resolution scale: frame cost grows with the pixel count (the square of the
/// scale), so the scale moves by the square root of the time ratio, damped to at most 30 %
/// per frame; between 1/8 and 1.
pub fn adapt_scale(scale: f32, frame_ms: f64, target_fps: f32) -> f32 {
    let target_ms = 1000.0 / target_fps.max(1.0) as f64;
    let ratio = (target_ms / frame_ms.max(1e-3)).sqrt() as f32;
    (scale * ratio.clamp(0.7, 1.3)).clamp(0.125, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_adapts_towards_the_target_and_stays_in_range() {
        // Too slow: smaller; too fast: larger; on target: the same.
        assert!(adapt_scale(0.5, 200.0, 10.0) < 0.5);
        assert!(adapt_scale(0.5, 20.0, 10.0) > 0.5);
        assert!((adapt_scale(0.5, 100.0, 10.0) - 0.5).abs() < 1e-6);
        assert_eq!(adapt_scale(1.0, 1.0, 10.0), 1.0);
        assert_eq!(adapt_scale(0.125, 1e6, 10.0), 0.125);
        // A cost proportional to the pixel count converges to the target.
        let mut s = 1.0f32;
        for _ in 0..30 {
            let ms = 400.0 * (s as f64).powi(2);
            s = adapt_scale(s, ms, 10.0);
        }
        assert!((s - 0.5).abs() < 0.02, "{s}");
        assert_eq!(scaled(512, 256, 0.5), (256, 128));
        assert_eq!(scaled(512, 4, 0.1), (51, 4));
    }
}
