//! Frame rates and the UI thread's frame times, for the overlay and the exit summary.
//!
//! The UI frame time is eframe's `cpu_usage`: the seconds the UI thread spent on a frame
//! (input, layout, tessellation and painting, without waiting for vsync). Frames while the
//! worker renders are counted apart: the issue's "no UI frame longer than 16 ms while a
//! render runs" is [`UiStats::max_busy_frame_ms`].

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use crate::camera::format_camera;
use crate::engine::FrameKind;
use crate::worker::Published;

/// Frames over which the rates are averaged.
const WINDOW: Duration = Duration::from_secs(1);

#[derive(Default)]
pub struct UiStats {
    /// Times of the last second's published frames.
    published: VecDeque<Instant>,
    /// Times of the last second's UI frames.
    ui: VecDeque<Instant>,
    /// Longest UI frame (ms) while the worker rendered, from one second after the first
    /// published frame (before it: font atlas, first texture, llvmpipe's shader compiles).
    pub max_busy_frame_ms: f64,
    pub busy_frames: u64,
    /// Summed milliseconds of those frames (for their mean).
    busy_ms: f64,
    /// Last UI frame (ms).
    pub last_ui_ms: f64,
    started: Option<Instant>,
    /// Moving frames shown: count, summed render milliseconds and pixels.
    pub moving_frames: u64,
    moving_ms: f64,
    moving_pixels: f64,
    /// Summed milliseconds of each stage over the moving frames, in first-seen order.
    moving_stages: Vec<(&'static str, f64)>,
    /// When the first and the last moving frame were taken (the shown rate, wall clock).
    moving_span: Option<(Instant, Instant)>,
}

fn push(q: &mut VecDeque<Instant>, now: Instant) {
    q.push_back(now);
    while q.front().is_some_and(|t| now.duration_since(*t) > WINDOW) {
        q.pop_front();
    }
}

fn rate(q: &VecDeque<Instant>) -> f64 {
    match (q.front(), q.back()) {
        (Some(a), Some(b)) if q.len() > 1 => {
            (q.len() - 1) as f64 / b.duration_since(*a).as_secs_f64().max(1e-6)
        }
        _ => 0.0,
    }
}

impl UiStats {
    /// Called at the start of every UI frame with the previous frame's CPU seconds.
    pub fn ui_frame(&mut self, cpu_seconds: Option<f32>, worker_busy: bool) {
        push(&mut self.ui, Instant::now());
        let Some(s) = cpu_seconds else { return };
        self.last_ui_ms = s as f64 * 1e3;
        // Start-up frames (font atlas, first texture) are not counted.
        let settled = self.started.is_some_and(|t| t.elapsed() > WINDOW);
        if worker_busy && settled {
            self.busy_frames += 1;
            self.max_busy_frame_ms = self.max_busy_frame_ms.max(self.last_ui_ms);
            self.busy_ms += self.last_ui_ms;
        }
    }

    pub fn frame_published(&mut self, frame: &Published) {
        self.started.get_or_insert_with(Instant::now);
        push(&mut self.published, Instant::now());
        if let FrameKind::Moving { .. } = frame.kind {
            let now = Instant::now();
            self.moving_span = Some(self.moving_span.map_or((now, now), |(first, _)| (first, now)));
            self.moving_frames += 1;
            self.moving_ms += frame.total_ms;
            self.moving_pixels += (frame.image.size[0] * frame.image.size[1]) as f64;
            for &(name, ms) in &frame.stages {
                match self.moving_stages.iter_mut().find(|(n, _)| *n == name) {
                    Some((_, sum)) => *sum += ms,
                    None => self.moving_stages.push((name, ms)),
                }
            }
        }
    }

    /// Mean milliseconds of each stage over the moving frames.
    pub fn moving_stage_means(&self) -> Vec<(&'static str, f64)> {
        let n = self.moving_frames.max(1) as f64;
        self.moving_stages.iter().map(|&(name, sum)| (name, sum / n)).collect()
    }

    /// Moving frames shown per second of wall clock, first to last (0 with fewer than two).
    /// The scene moves without pause in a speed measurement, so this is the shown rate.
    pub fn moving_shown_fps(&self) -> f64 {
        match self.moving_span {
            Some((a, b)) if self.moving_frames > 1 => {
                (self.moving_frames - 1) as f64 / b.duration_since(a).as_secs_f64().max(1e-9)
            }
            _ => 0.0,
        }
    }

    /// Mean UI frame (ms) while a render ran.
    pub fn mean_busy_frame_ms(&self) -> f64 {
        self.busy_ms / self.busy_frames.max(1) as f64
    }

    /// Moving frames: (count, mean render ms, mean pixel count).
    pub fn moving_summary(&self) -> (u64, f64, f64) {
        let n = self.moving_frames.max(1) as f64;
        (self.moving_frames, self.moving_ms / n, self.moving_pixels / n)
    }

    /// Rendered frames per second over the last second.
    pub fn render_fps(&self) -> f64 {
        rate(&self.published)
    }

    /// UI frames per second over the last second.
    pub fn ui_fps(&self) -> f64 {
        rate(&self.ui)
    }
}

/// One line about a frame, for `--log-frames` (tests read it); `image_at` is the image's
/// top-left corner in window pixels.
pub fn describe(f: &Published, image_at: (f32, f32)) -> String {
    let kind = match f.kind {
        FrameKind::Still { spp } => format!("kind=still spp={spp}"),
        FrameKind::Moving { scale } => format!("kind=moving scale={scale:.3}"),
    };
    let [w, h] = f.image.size;
    let stages: Vec<String> = f.stages.iter().map(|(s, ms)| format!("{s}={ms:.1}")).collect();
    format!(
        "{kind} size={w}x{h} layer={} anim_frame={} ms={:.1} {} image={},{} camera={}",
        f.job.display.layer,
        f.job.frame,
        f.total_ms,
        stages.join(" "),
        image_at.0.round(),
        image_at.1.round(),
        format_camera(&f.job.camera)
    )
}
