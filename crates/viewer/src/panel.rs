//! The settings panel: renderer and filter with presets and main parameters, depth and
//! samples, adaptive sampling, display (exposure, tone curve, layer, split view), camera.
//! Widgets write straight into the app's [`RenderChoice`](crate::settings::RenderChoice)
//! and [`DisplayChoice`](crate::settings::DisplayChoice); the next job carries them.

use eframe::egui::{self, ComboBox, DragValue, Slider};

use crate::app::ViewerApp;
use crate::camera::VFOV_RANGE;
use crate::input::Action;
use crate::layers::LAYERS;
use crate::settings::{filter_presets, StillRenderer, FILTERS};

impl ViewerApp {
    /// The settings panel; its widgets write into this app's choices.
    pub(crate) fn show_panel(&mut self, ui: &mut egui::Ui) {
        show(ui, self)
    }
}

fn show(ui: &mut egui::Ui, app: &mut ViewerApp) {
    egui::ScrollArea::vertical().show(ui, |ui| {
        ui.heading("filtrace view");
        ui.label(&app.opts.scene);
        ui.separator();
        if app.timeline.is_some() {
            timeline_section(ui, app);
            ui.separator();
        }
        render_section(ui, app);
        ui.separator();
        filter_section(ui, app);
        ui.separator();
        display_section(ui, app);
        ui.separator();
        camera_section(ui, app);
    });
}

/// Play/pause, step, scrub; frame number and time; the camera track.
fn timeline_section(ui: &mut egui::Ui, app: &mut ViewerApp) {
    let Some(t) = &app.timeline else { return };
    let (clock, mut frame, playing) = (t.clock, t.frame(), t.playing());
    ui.label(format!(
        "Animation: frame {frame} ({:.3} s) of {}..{} at {} fps",
        t.time(),
        clock.first,
        clock.last,
        clock.fps
    ));
    ui.horizontal(|ui| {
        if ui.button("<").on_hover_text("previous frame (Left)").clicked() {
            app.timeline_action(Action::StepFrame(-1));
        }
        let label = if playing { "pause (Space)" } else { "play (Space)" };
        if ui.button(label).clicked() {
            app.timeline_action(Action::TogglePlay);
        }
        if ui.button(">").on_hover_text("next frame (Right)").clicked() {
            app.timeline_action(Action::StepFrame(1));
        }
    });
    if ui.add(Slider::new(&mut frame, clock.first..=clock.last).text("frame")).changed() {
        if let Some(t) = &mut app.timeline {
            t.set_frame(frame);
        }
        app.last_change = Some(std::time::Instant::now());
    }
    if let Some(t) = app.timeline.as_mut().filter(|t| t.has_camera_track()) {
        ui.checkbox(&mut t.follow_camera, "camera follows the animation (R)");
    }
}

fn render_section(ui: &mut egui::Ui, app: &mut ViewerApp) {
    let r = &mut app.render;
    ui.label("Still image");
    ComboBox::from_id_salt("still").selected_text(r.still.label()).show_ui(ui, |ui| {
        for s in StillRenderer::ALL {
            ui.selectable_value(&mut r.still, *s, s.label());
        }
    });
    ui.horizontal(|ui| {
        ui.label("max depth");
        ui.add(DragValue::new(&mut r.max_depth).range(-1..=64));
        if r.max_depth == 0 {
            r.max_depth = 1;
        }
    });
    ui.add(Slider::new(&mut r.spp_per_frame, 1..=64).text("spp per frame"));
    ui.horizontal(|ui| {
        ui.label("stop at spp");
        ui.add(DragValue::new(&mut r.max_spp).range(1..=1 << 20));
    });
    ui.horizontal(|ui| {
        ui.label("resolution");
        ui.add(DragValue::new(&mut r.width).range(8..=4096));
        ui.label("x");
        ui.add(DragValue::new(&mut r.height).range(8..=4096));
    });
    ui.add(DragValue::new(&mut r.seed).prefix("seed "));
}

fn filter_section(ui: &mut egui::Ui, app: &mut ViewerApp) {
    let r = &mut app.render;
    ui.label("While moving: 1 spp, filtered");
    let before = r.filter.name.clone();
    ComboBox::from_id_salt("filter").selected_text(&r.filter.name).show_ui(ui, |ui| {
        for f in FILTERS {
            ui.selectable_value(&mut r.filter.name, f.to_string(), *f);
        }
    });
    if r.filter.name != before {
        r.filter = filtrace_pipeline::FilterChoice::named(&r.filter.name);
    }
    let presets = filter_presets(&r.filter.name);
    if !presets.is_empty() {
        let current = r.filter.preset.clone().unwrap_or_else(|| presets[0].to_string());
        ComboBox::from_id_salt("preset").selected_text(format!("preset {current}")).show_ui(ui, |ui| {
            for p in &presets {
                if ui.selectable_label(current == *p, *p).clicked() {
                    r.filter.preset = Some(p.to_string());
                }
            }
        });
    }
    match r.filter.name.as_str() {
        "guided" | "bilateral" => optional_slider(ui, &mut r.filter.radius, 1..=32, "radius", 8),
        "atrous" => optional_slider(ui, &mut r.filter.iterations, 1..=8, "iterations", 5),
        _ => {}
    }
    ui.checkbox(&mut r.filter_direct, "filter the direct light too");
    ui.checkbox(&mut r.adaptive, "adaptive sampling (importance map)");
    ui.add(Slider::new(&mut r.target_fps, 2.0..=60.0).text("target fps"));
}

/// A slider for an optional override: unchecked, the preset's value is used.
fn optional_slider(
    ui: &mut egui::Ui,
    value: &mut Option<u32>,
    range: std::ops::RangeInclusive<u32>,
    label: &str,
    default: u32,
) {
    ui.horizontal(|ui| {
        let mut on = value.is_some();
        ui.checkbox(&mut on, label);
        match (on, value.as_mut()) {
            (true, Some(v)) => {
                ui.add(Slider::new(v, range));
            }
            (true, None) => *value = Some(default),
            (false, _) => *value = None,
        }
    });
}

fn display_section(ui: &mut egui::Ui, app: &mut ViewerApp) {
    let available: Vec<&str> = app.shown.as_ref().map(|s| s.layers.available().collect()).unwrap_or_default();
    let d = &mut app.display;
    ui.label("View");
    layer_combo(ui, "layer", &mut d.layer, &available);
    ui.checkbox(&mut d.split, "split view (V)");
    if d.split {
        layer_combo(ui, "split layer", &mut d.split_layer, &available);
        ui.add(Slider::new(&mut d.split_at, 0.0..=1.0).text("split at"));
    }
    ui.add(Slider::new(&mut d.exposure, -8.0..=8.0).text("exposure (stops)"));
    ui.checkbox(&mut d.filmic, "filmic tone curve");
    ui.checkbox(&mut app.overlay, "overlay (O)");
    ui.horizontal(|ui| {
        if ui.button("Save EXR + PNG (F2)").clicked() {
            app.save_frame();
        }
        if ui.button("Screenshot (F12)").clicked() {
            let ctx = ui.ctx().clone();
            app.act(&ctx, Action::Screenshot, app.last_image);
        }
    });
}

/// Layers of the table; those the current frame lacks are greyed.
fn layer_combo(ui: &mut egui::Ui, id: &str, layer: &mut &'static str, available: &[&str]) {
    ComboBox::from_id_salt(id).selected_text(format!("{id}: {layer}")).show_ui(ui, |ui| {
        for (i, l) in LAYERS.iter().enumerate() {
            let text = if i < 10 { format!("{} ({})", l.name, (i + 1) % 10) } else { l.name.to_string() };
            let text = if available.contains(&l.name) {
                egui::RichText::new(text)
            } else {
                egui::RichText::new(text).weak()
            };
            ui.selectable_value(layer, l.name, text);
        }
    });
}

fn camera_section(ui: &mut egui::Ui, app: &mut ViewerApp) {
    ui.label("Camera");
    let mut fov = app.camera.vfov_deg;
    if ui.add(Slider::new(&mut fov, VFOV_RANGE.0..=VFOV_RANGE.1).text("field of view")).changed() {
        app.camera.vfov_deg = fov;
    }
    if ui.button("Reset camera (R)").clicked() {
        let ctx = ui.ctx().clone();
        app.act(&ctx, Action::ResetCamera, egui::Rect::NOTHING);
    }
    ui.small("drag: orbit, right/middle drag or Shift: pan, wheel: zoom, WASD/QE: fly, +/-: fov");
}
