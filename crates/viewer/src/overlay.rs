//! Text drawn over the image: frame kind, resolution, samples, frame rates and the
//! milliseconds of each stage of the last frame; and error boxes.

use eframe::egui::{self, Color32, FontId};

use crate::engine::FrameKind;
use crate::stats::UiStats;
use crate::worker::Published;

/// A semi-transparent box with `text` at the top left of `rect`.
fn text_box(painter: &egui::Painter, rect: egui::Rect, text: &str, color: Color32) {
    let font = FontId::monospace(12.0);
    let galley = painter.layout(text.to_string(), font, color, rect.width() - 12.0);
    let bg = egui::Rect::from_min_size(rect.min + egui::vec2(4.0, 4.0), galley.size() + egui::vec2(8.0, 6.0));
    painter.rect_filled(bg, 3.0, Color32::from_black_alpha(170));
    painter.galley(bg.min + egui::vec2(4.0, 3.0), galley, color);
}

/// The overlay of the shown frame `shown`, with the UI's `stats` and a status `message`.
pub fn draw(
    painter: &egui::Painter,
    rect: egui::Rect,
    shown: Option<&Published>,
    animated: bool,
    stats: &UiStats,
    message: Option<&str>,
) {
    let Some(f) = shown else { return };
    let [w, h] = f.image.size;
    let mut lines = vec![match f.kind {
        FrameKind::Still { spp } => {
            format!("still {w}x{h}  {spp} spp  ({} per frame)", f.job.render.spp_per_frame)
        }
        FrameKind::Moving { scale } => {
            format!("moving {w}x{h} ({:.0}%)  1 spp  {}", scale * 100.0, f.job.render.filter.name)
        }
    }];
    if animated {
        lines.push(format!("animation frame {}", f.job.frame));
    }
    lines.push(format!("render {:.1} fps, frame {:.1} ms", stats.render_fps(), f.total_ms));
    lines.push(format!(
        "UI {:.0} fps, {:.1} ms (max {:.1} rendering)",
        stats.ui_fps(),
        stats.last_ui_ms,
        stats.max_busy_frame_ms
    ));
    let stages: Vec<String> = f.stages.iter().map(|(s, ms)| format!("{s} {ms:.1}")).collect();
    lines.push(format!("{} ms", stages.join("  ")));
    if !f.missing.is_empty() {
        lines.push(format!("not in this frame: {}", f.missing.join(", ")));
    }
    if let Some(m) = message {
        lines.push(m.to_string());
    }
    text_box(painter, rect, &lines.join("\n"), Color32::WHITE);
}

/// An error (or status) message over the image.
pub fn error_box(painter: &egui::Painter, rect: egui::Rect, message: &str) {
    let inner = rect.shrink(8.0);
    let r = egui::Rect::from_min_size(inner.min + egui::vec2(0.0, inner.height() * 0.4), inner.size());
    let font = FontId::proportional(14.0);
    let galley = painter.layout(message.to_string(), font, Color32::from_rgb(255, 120, 100), inner.width());
    let bg = egui::Rect::from_min_size(r.min, galley.size() + egui::vec2(8.0, 6.0));
    painter.rect_filled(bg, 3.0, Color32::from_black_alpha(200));
    painter.galley(bg.min + egui::vec2(4.0, 3.0), galley, Color32::WHITE);
}
