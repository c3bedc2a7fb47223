//! A piecewise-linear map editor drawn with egui's painter: control points dragged over the
//! attribute's histogram (no egui 0.37 crate has a transfer-function widget).
//!
//! Drag a point to move it (between its neighbours); double-click empty space to add one;
//! right-click a point to remove it (one always stays).

use egui::{Color32, Pos2, Rect, Sense, Shape, Stroke, Vec2};

use super::worker::Histogram;
use crate::scene::maps::PiecewiseLinear;

/// Pixels within which the pointer grabs a control point.
const GRAB_RADIUS: f32 = 8.0;

/// The editor's height in points.
pub const EDITOR_HEIGHT: f32 = 90.0;

/// The editor's own memory between frames: which point is being dragged.
#[derive(Clone, Copy, Default)]
struct DragState {
    point: Option<usize>,
}

/// Where control points are drawn: x over the width, y from `y_max` at the top to 0.
pub struct MapFrame {
    /// The editor's area on screen, in points.
    pub rect: Rect,
    /// The map value drawn at the top edge (the bottom is 0).
    pub y_max: f64,
}

impl MapFrame {
    /// The screen position of control point `p` (x in [0, 1], y in [0, `y_max`]).
    pub fn to_screen(&self, p: [f64; 2]) -> Pos2 {
        Pos2::new(
            self.rect.left() + p[0] as f32 * self.rect.width(),
            self.rect.bottom() - (p[1] / self.y_max) as f32 * self.rect.height(),
        )
    }

    /// The control point at screen position `pos`, clamped to x in [0, 1] and y in [0, `y_max`].
    pub fn from_screen(&self, pos: Pos2) -> [f64; 2] {
        let x = f64::from((pos.x - self.rect.left()) / self.rect.width());
        let y = f64::from((self.rect.bottom() - pos.y) / self.rect.height()) * self.y_max;
        [x.clamp(0.0, 1.0), y.clamp(0.0, self.y_max)]
    }
}

/// Moves point `index` of `points` to `to`, kept between its neighbours in x.
pub fn move_point(points: &mut [[f64; 2]], index: usize, to: [f64; 2]) {
    let lo = if index > 0 { points[index - 1][0] } else { 0.0 };
    let hi = points.get(index + 1).map_or(1.0, |p| p[0]);
    points[index] = [to[0].clamp(lo, hi), to[1]];
}

/// Inserts a point at `at`, keeping x ascending.
pub fn insert_point(points: &mut Vec<[f64; 2]>, at: [f64; 2]) {
    let i = points.partition_point(|p| p[0] <= at[0]);
    points.insert(i, at);
}

/// Shows the editor for `map` (values in [0, `y_max`]), with `histogram` behind it (log-scaled
/// counts with `log_y`). `label` names it for screen readers and tests. Returns whether the
/// map changed.
pub fn map_editor(
    ui: &mut egui::Ui,
    label: &str,
    map: &mut PiecewiseLinear,
    y_max: f64,
    histogram: Option<&Histogram>,
    log_y: bool,
) -> bool {
    let width = ui.available_width().max(120.0);
    let (rect, response) =
        ui.allocate_exact_size(Vec2::new(width, EDITOR_HEIGHT), Sense::click_and_drag());
    response.widget_info(|| egui::WidgetInfo::labeled(egui::Role::Canvas, ui.is_enabled(), label));
    let frame = MapFrame {
        rect: rect.shrink(4.0),
        y_max,
    };
    let id = response.id;
    let mut drag: DragState = ui.data(|d| d.get_temp(id)).unwrap_or_default();
    let mut points = map.points().to_vec();
    let nearest = |points: &[[f64; 2]], pos: Pos2| -> Option<usize> {
        points
            .iter()
            .enumerate()
            .map(|(i, p)| (i, frame.to_screen(*p).distance(pos)))
            .filter(|(_, d)| *d <= GRAB_RADIUS)
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
    };
    let mut changed = false;
    // A drag grabs the point under where the button went down (egui starts a drag only
    // once the pointer has moved a little).
    if response.drag_started()
        && let Some(pos) = ui.input(|i| i.pointer.press_origin())
    {
        drag.point = nearest(&points, pos);
    }
    if response.dragged()
        && let (Some(i), Some(pos)) = (drag.point, response.interact_pointer_pos())
    {
        let to = frame.from_screen(pos);
        if points[i] != to {
            move_point(&mut points, i, to);
            changed = true;
        }
    }
    if response.drag_stopped() {
        drag.point = None;
    }
    if response.double_clicked()
        && let Some(pos) = response.interact_pointer_pos()
        && nearest(&points, pos).is_none()
    {
        insert_point(&mut points, frame.from_screen(pos));
        changed = true;
    }
    if response.secondary_clicked()
        && let Some(pos) = response.interact_pointer_pos()
        && let Some(i) = nearest(&points, pos)
        && points.len() > 1
    {
        points.remove(i);
        changed = true;
    }
    ui.data_mut(|d| d.insert_temp(id, drag));
    if changed && let Ok(m) = PiecewiseLinear::new(points.clone()) {
        *map = m;
    } else {
        changed = false;
    }
    paint(ui, &frame, rect, map.points(), histogram, log_y, drag.point);
    changed
}

fn paint(
    ui: &egui::Ui,
    frame: &MapFrame,
    rect: Rect,
    points: &[[f64; 2]],
    histogram: Option<&Histogram>,
    log_y: bool,
    active: Option<usize>,
) {
    let painter = ui.painter_at(rect);
    let visuals = ui.visuals();
    painter.rect_filled(rect, 2.0, visuals.extreme_bg_color);
    if let Some(h) = histogram {
        let scale = |c: u32| -> f32 {
            if log_y {
                (1.0 + c as f32).ln()
            } else {
                c as f32
            }
        };
        let top = h.counts.iter().map(|&c| scale(c)).fold(0.0, f32::max);
        if top > 0.0 {
            let n = h.counts.len() as f32;
            for (i, &c) in h.counts.iter().enumerate() {
                let x0 = frame.rect.left() + frame.rect.width() * i as f32 / n;
                let x1 = frame.rect.left() + frame.rect.width() * (i + 1) as f32 / n;
                let y = frame.rect.bottom() - frame.rect.height() * scale(c) / top;
                painter.rect_filled(
                    Rect::from_min_max(Pos2::new(x0, y), Pos2::new(x1, frame.rect.bottom())),
                    0.0,
                    visuals.faint_bg_color.gamma_multiply(3.0),
                );
            }
        }
    }
    // The map as used: constant beyond its first and last points.
    let mut line: Vec<Pos2> = Vec::with_capacity(points.len() + 2);
    line.push(frame.to_screen([0.0, points[0][1]]));
    line.extend(points.iter().map(|p| frame.to_screen(*p)));
    line.push(frame.to_screen([1.0, points[points.len() - 1][1]]));
    let stroke = Stroke::new(1.5, visuals.selection.bg_fill);
    painter.add(Shape::line(line, stroke));
    for (i, p) in points.iter().enumerate() {
        let fill = if Some(i) == active {
            Color32::WHITE
        } else {
            visuals.selection.bg_fill
        };
        painter.circle(
            frame.to_screen(*p),
            4.0,
            fill,
            Stroke::new(1.0, Color32::BLACK),
        );
    }
    painter.text(
        rect.right_top() + Vec2::new(-4.0, 2.0),
        egui::Align2::RIGHT_TOP,
        format!("{:.3}", frame.y_max),
        egui::FontId::proportional(10.0),
        visuals.weak_text_color(),
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_move_between_their_neighbours_and_insert_in_order() {
        let mut p = vec![[0.0, 0.0], [0.5, 1.0], [1.0, 0.5]];
        move_point(&mut p, 1, [0.9, 0.2]);
        assert_eq!(p[1], [0.9, 0.2]);
        move_point(&mut p, 1, [1.5, 0.2]);
        assert_eq!(p[1], [1.0, 0.2]);
        move_point(&mut p, 0, [0.7, 0.3]);
        assert_eq!(p[0], [0.7, 0.3]);
        let mut q = vec![[0.0, 0.0], [1.0, 1.0]];
        insert_point(&mut q, [0.25, 0.5]);
        assert_eq!(q, [[0.0, 0.0], [0.25, 0.5], [1.0, 1.0]]);
        assert!(PiecewiseLinear::new(q).is_ok());
    }

    #[test]
    fn screen_and_map_coordinates_round_trip() {
        let f = MapFrame {
            rect: Rect::from_min_size(Pos2::new(10.0, 20.0), Vec2::new(200.0, 80.0)),
            y_max: 2.0,
        };
        for p in [[0.0, 0.0], [0.25, 1.5], [1.0, 2.0]] {
            let q = f.from_screen(f.to_screen(p));
            assert!(
                (q[0] - p[0]).abs() < 1e-6 && (q[1] - p[1]).abs() < 1e-6,
                "{p:?} {q:?}"
            );
        }
    }
}
