//! The colour legend over the viewer's image: the same content as `--legend` draws on a
//! rendered image ([`Legend`]), painted by egui so it stays sharp at any window size.

use egui::{Color32, FontId, Pos2, Rect, Stroke, StrokeKind, pos2, vec2};

use crate::render::legend::{Legend, label};

/// Paints `legend` over the bottom-left corner of `rect`, if it fits.
pub fn paint(painter: &egui::Painter, rect: Rect, legend: &Legend) {
    let size = vec2((rect.width() - 16.0).min(300.0), 52.0);
    if size.x < 100.0 || rect.height() < 80.0 {
        return;
    }
    let frame = Rect::from_min_size(pos2(rect.min.x + 8.0, rect.max.y - 8.0 - size.y), size);
    painter.rect_filled(frame, 3.0, Color32::from_black_alpha(150));
    let text = Color32::from_gray(235);
    painter.text(
        frame.min + vec2(6.0, 4.0),
        egui::Align2::LEFT_TOP,
        &legend.title,
        FontId::proportional(13.0),
        text,
    );
    let bar = Rect::from_min_max(
        frame.min + vec2(6.0, 21.0),
        pos2(frame.max.x - 6.0, frame.min.y + 32.0),
    );
    const SEGMENTS: usize = 64;
    let width = bar.width() / SEGMENTS as f32;
    for i in 0..SEGMENTS {
        let t = (i as f64 + 0.5) / SEGMENTS as f64;
        let [r, g, b] = legend
            .color_map
            .srgb(t)
            .map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8);
        let x = bar.min.x + i as f32 * width;
        painter.rect_filled(
            Rect::from_min_max(pos2(x, bar.min.y), pos2(x + width + 0.5, bar.max.y)),
            0.0,
            Color32::from_rgb(r, g, b),
        );
    }
    painter.rect_stroke(bar, 0.0, Stroke::new(1.0, text), StrokeKind::Outside);
    let font = FontId::proportional(12.0);
    let y = bar.max.y + 2.0;
    let middle = 0.5 * (legend.low + legend.high);
    for (value, x, align) in [
        (legend.low, bar.min.x, egui::Align2::LEFT_TOP),
        (middle, bar.center().x, egui::Align2::CENTER_TOP),
        (legend.high, bar.max.x, egui::Align2::RIGHT_TOP),
    ] {
        painter.text(Pos2::new(x, y), align, label(value), font.clone(), text);
    }
}
