//! Window input to camera moves and actions.
//!
//! Mouse drags are measured from where the button went down, and the camera is the camera
//! at that moment moved by the whole drag ([`crate::camera::orbit`] of the total offset):
//! however the events are split into frames, a drag of (dx, dy) pixels ends at the same
//! camera, so a test can inject a drag and know where the camera must be.

use eframe::egui::{self, Key, Pos2};
use filtrace_scene::Camera;

use crate::camera;

/// Degrees of field of view per `+`/`-` press.
pub const FOV_STEP_DEG: f32 = 5.0;
/// Scroll points per zoom step (one wheel notch is about 50 points in egui).
const SCROLL_PER_STEP: f32 = 50.0;

/// Actions other than camera moves, from keys.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action {
    Close,
    /// Save the frame: EXR with every layer, and the displayed PNG.
    Save,
    /// Save a screenshot of the image area.
    Screenshot,
    ResetCamera,
    ToggleSplit,
    ToggleOverlay,
    /// Show layer `n` of [`crate::layers::LAYERS`].
    Layer(usize),
    /// Animation: play or pause.
    TogglePlay,
    /// Animation: one frame on (1) or back (-1), pausing.
    StepFrame(i64),
}

/// Key bindings of [`Action`]s (also listed in the README).
const ACTION_KEYS: &[(Key, Action)] = &[
    (Key::Escape, Action::Close),
    (Key::F2, Action::Save),
    (Key::F12, Action::Screenshot),
    (Key::R, Action::ResetCamera),
    (Key::V, Action::ToggleSplit),
    (Key::O, Action::ToggleOverlay),
    (Key::Space, Action::TogglePlay),
    (Key::ArrowRight, Action::StepFrame(1)),
    (Key::ArrowLeft, Action::StepFrame(-1)),
];

/// Keys 1-9 and 0 pick the first ten layers of [`crate::layers::LAYERS`].
const LAYER_KEYS: [Key; 10] = [
    Key::Num1,
    Key::Num2,
    Key::Num3,
    Key::Num4,
    Key::Num5,
    Key::Num6,
    Key::Num7,
    Key::Num8,
    Key::Num9,
    Key::Num0,
];

/// Which camera move a drag makes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum DragKind {
    Orbit,
    Pan,
}

/// Mouse and keyboard state of the camera between frames.
#[derive(Default)]
pub struct Navigator {
    drag: Option<(Camera, Pos2, DragKind)>,
}

/// What one frame's input did.
pub struct Navigation {
    pub camera: Camera,
    /// A drag or a fly key is held: the camera is being moved even if it did not move in
    /// this very frame.
    pub active: bool,
    pub actions: Vec<Action>,
}

impl Navigator {
    /// Applies this frame's input to `cam`. `image` is the image's rect (drags must start
    /// on it; scrolling zooms when the pointer is over it); `height_px` its height in pixels.
    pub fn update(
        &mut self,
        ctx: &egui::Context,
        image: egui::Rect,
        cam: &Camera,
        height_px: f32,
    ) -> Navigation {
        let typing = ctx.egui_wants_keyboard_input();
        ctx.input(|i| {
            let mut cam = self.mouse(i, image, cam, height_px);
            let mut actions = Vec::new();
            let mut flying = false;
            if !typing {
                (cam, flying) = fly(i, &cam);
                if i.key_pressed(Key::Equals) || i.key_pressed(Key::Plus) {
                    cam = camera::with_fov(&cam, -FOV_STEP_DEG);
                }
                if i.key_pressed(Key::Minus) {
                    cam = camera::with_fov(&cam, FOV_STEP_DEG);
                }
                actions.extend(ACTION_KEYS.iter().filter(|(k, _)| i.key_pressed(*k)).map(|(_, a)| *a));
                let layer = LAYER_KEYS.iter().position(|k| i.key_pressed(*k));
                actions.extend(layer.map(Action::Layer));
            }
            Navigation { camera: cam, active: self.drag.is_some() || flying, actions }
        })
    }

    /// Drags from the frame's pointer events in order, so that a press, moves and a release
    /// arriving in one frame still make the whole drag.
    fn mouse(&mut self, i: &egui::InputState, image: egui::Rect, cam: &Camera, height_px: f32) -> Camera {
        let mut out = cam.clone();
        for event in &i.events {
            match event {
                egui::Event::PointerButton { pos, button, pressed: true, modifiers }
                    if self.drag.is_none() && image.contains(*pos) =>
                {
                    let pan = *button != egui::PointerButton::Primary || modifiers.shift;
                    self.drag = Some((out.clone(), *pos, if pan { DragKind::Pan } else { DragKind::Orbit }));
                }
                egui::Event::PointerMoved(pos) => out = self.dragged(&out, *pos, height_px),
                egui::Event::PointerButton { pos, pressed: false, .. } => {
                    out = self.dragged(&out, *pos, height_px);
                    self.drag = None;
                }
                _ => {}
            }
        }
        let hovered = i.pointer.hover_pos().is_some_and(|h| image.contains(h));
        if hovered && i.smooth_scroll_delta.y != 0.0 {
            out = camera::zoom(&out, i.smooth_scroll_delta.y / SCROLL_PER_STEP);
        }
        out
    }

    /// The camera of the drag in progress with the pointer at `pos` (`cam` if none).
    fn dragged(&self, cam: &Camera, pos: Pos2, height_px: f32) -> Camera {
        let Some((start, origin, kind)) = &self.drag else { return cam.clone() };
        let d = pos - *origin;
        match kind {
            DragKind::Orbit => camera::orbit(start, d.x, d.y),
            DragKind::Pan => camera::pan(start, d.x, d.y, height_px),
        }
    }
}

/// W/S forward and back, A/D left and right, Q/E down and up, at [`camera::FLY_SPEED`]
/// (Shift: 4x) for the frame's time. Returns the camera and whether a fly key is held.
fn fly(i: &egui::InputState, cam: &Camera) -> (Camera, bool) {
    let axis = |plus: Key, minus: Key| (i.key_down(plus) as i32 - i.key_down(minus) as i32) as f32;
    let (f, r, u) = (axis(Key::W, Key::S), axis(Key::D, Key::A), axis(Key::E, Key::Q));
    if f == 0.0 && r == 0.0 && u == 0.0 {
        return (cam.clone(), false);
    }
    let speed = camera::FLY_SPEED * if i.modifiers.shift { 4.0 } else { 1.0 } * i.stable_dt.min(0.1);
    (camera::fly(cam, f * speed, r * speed, u * speed), true)
}
