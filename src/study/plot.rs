//! A study's figure as a PNG a person reads at a glance: one or more panels (lines over a
//! numeric axis, or grouped bars over categories), each series a backend or variant with its
//! median and a whisker from the fastest to the slowest repetition, and a caption under them.
//! Drawn by `plotters` into memory and encoded by `image`, written atomically.

use std::collections::BTreeMap;
use std::path::Path;

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use super::StudyError;
use super::record::Row;

/// A whole figure.
pub struct Figure {
    /// The title above the panels.
    pub title: String,
    /// The charts, two to a row, in reading order.
    pub panels: Vec<Panel>,
    /// Lines of text under the panels (the paper's trend, the settings).
    pub caption: Vec<String>,
}

/// One chart.
pub enum Panel {
    /// Lines over a numeric x axis.
    Lines {
        /// The chart's title.
        title: String,
        /// The x axis's label.
        x_label: String,
        /// The y axis's label.
        y_label: String,
        /// How the x axis maps values.
        x_scale: Scale,
        /// How the y axis maps values.
        y_scale: Scale,
        /// The lines.
        series: Vec<Series>,
    },
    /// Groups of bars, one group per category.
    Bars {
        /// The chart's title.
        title: String,
        /// The y axis's label.
        y_label: String,
        /// The categories along x, in order.
        categories: Vec<String>,
        /// One bar of each category per series.
        series: Vec<BarSeries>,
    },
}

/// How an axis maps values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scale {
    /// Values as they are.
    Linear,
    /// Ticks at 1, 2 and 5 times powers of 10.
    Log10,
    /// Ticks at powers of 2 (cluster sizes).
    Log2,
}

impl Scale {
    fn to(self, v: f64) -> f64 {
        match self {
            Scale::Linear => v,
            Scale::Log10 => v.max(1e-300).log10(),
            Scale::Log2 => v.max(1e-300).log2(),
        }
    }

    /// How many tick candidates to ask plotters for over `range` (of transformed values):
    /// log axes ask for many and label only the round ones.
    fn ticks(self, range: (f64, f64)) -> usize {
        match self {
            Scale::Linear => 8,
            Scale::Log10 => 40,
            Scale::Log2 => ((range.1 - range.0).ceil() as usize + 1).max(2),
        }
    }

    /// The label of the tick at transformed value `v` (empty where a log axis has no round value).
    fn label(self, v: f64) -> String {
        match self {
            Scale::Linear => tick(v),
            Scale::Log2 => {
                if (v - v.round()).abs() < 1e-6 {
                    tick(2f64.powf(v.round()))
                } else {
                    String::new()
                }
            }
            Scale::Log10 => {
                let decade = v.floor();
                let mantissa = 10f64.powf(v - decade);
                [1.0, 2.0, 5.0, 10.0]
                    .iter()
                    .find(|&&m| (mantissa / m - 1.0).abs() < 0.012)
                    .map_or(String::new(), |&m| tick(m * 10f64.powf(decade)))
            }
        }
    }
}

/// A line: (x, median, lowest, highest) per point, in x order.
pub struct Series {
    /// The legend's label.
    pub label: String,
    /// (x, median, lowest, highest) per point, in x order.
    pub points: Vec<(f64, f64, f64, f64)>,
    /// Drawn dashed (a reference, such as the particles' bytes beside the structure's).
    pub dashed: bool,
}

impl Series {
    /// A dashed level at `(median, lowest, highest)` from `lo` to `hi` along x (a reference
    /// beside the lines, such as a goal).
    pub fn level(label: String, (lo, hi): (f64, f64), (m, l, h): (f64, f64, f64)) -> Series {
        Series {
            label,
            points: vec![(lo, m, l, h), (hi, m, l, h)],
            dashed: true,
        }
    }
}

/// The least and the greatest of `xs`, where they are finite (none where there are no
/// values).
pub fn span(xs: impl IntoIterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = xs
        .into_iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| {
            (l.min(x), h.max(x))
        });
    lo.is_finite().then_some((lo, hi))
}

/// Bars over the categories: (median, lowest, highest) per category, if measured.
pub struct BarSeries {
    /// The legend's label.
    pub label: String,
    /// (median, lowest, highest) per category; `None` where not measured.
    pub values: Vec<Option<(f64, f64, f64)>>,
}

/// The lines of `metric` in `rows`, one per series name `name(row)`, over `x(row)`, values
/// multiplied by `scale` (units).
pub fn lines(
    rows: &[Row],
    metric: &str,
    name: impl Fn(&Row) -> String,
    x: impl Fn(&Row) -> f64,
    scale: f64,
) -> Vec<Series> {
    let mut by: BTreeMap<String, Vec<(f64, f64, f64, f64)>> = BTreeMap::new();
    for r in rows.iter().filter(|r| r.metric == metric) {
        by.entry(name(r)).or_default().push((
            x(r),
            r.median() * scale,
            r.min() * scale,
            r.max() * scale,
        ));
    }
    by.into_iter()
        .map(|(label, mut points)| {
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            Series {
                label,
                points,
                dashed: false,
            }
        })
        .collect()
}

/// Bars of `metric`: a category per `category(row)` (in first-seen order), a series per
/// `name(row)`.
pub fn bars(
    rows: &[Row],
    metric: &str,
    category: impl Fn(&Row) -> String,
    name: impl Fn(&Row) -> String,
) -> (Vec<String>, Vec<BarSeries>) {
    let rows: Vec<&Row> = rows.iter().filter(|r| r.metric == metric).collect();
    let mut categories: Vec<String> = Vec::new();
    let mut names: Vec<String> = Vec::new();
    for r in &rows {
        let (c, n) = (category(r), name(r));
        if !categories.contains(&c) {
            categories.push(c);
        }
        if !names.contains(&n) {
            names.push(n);
        }
    }
    let series = names
        .into_iter()
        .map(|n| BarSeries {
            values: categories
                .iter()
                .map(|c| {
                    rows.iter()
                        .find(|r| name(r) == n && category(r) == *c)
                        .map(|r| (r.median(), r.min(), r.max()))
                })
                .collect(),
            label: n,
        })
        .collect();
    (categories, series)
}

const PANEL: (u32, u32) = (760, 480);
const TITLE_HEIGHT: u32 = 44;
const CAPTION_LINE: u32 = 24;

const COLOURS: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

fn colour(i: usize) -> RGBColor {
    COLOURS[i % COLOURS.len()]
}

use crate::io::text::{FONT, register_font};

fn plot_error(e: impl std::fmt::Display) -> StudyError {
    StudyError::Plot(e.to_string())
}

/// Pixels per character of the caption's font (Hack, monospace, at 15 px).
const CAPTION_CHAR: u32 = 9;

/// The caption's lines wrapped at word boundaries to `width` pixels.
fn caption_lines(figure: &Figure, width: u32) -> Vec<String> {
    let max = ((width.saturating_sub(32)) / CAPTION_CHAR).max(20) as usize;
    let mut out = Vec::new();
    for text in &figure.caption {
        let mut line = String::new();
        for word in text.split_whitespace() {
            if !line.is_empty() && line.chars().count() + 1 + word.chars().count() > max {
                out.push(std::mem::take(&mut line));
            }
            if !line.is_empty() {
                line.push(' ');
            }
            line.push_str(word);
        }
        if !line.is_empty() {
            out.push(line);
        }
    }
    out
}

/// The figure's size in pixels.
pub fn size(figure: &Figure) -> (u32, u32) {
    let cols = if figure.panels.len() > 1 { 2 } else { 1 };
    let rows = figure.panels.len().div_ceil(cols).max(1) as u32;
    let width = PANEL.0 * cols as u32;
    let lines = caption_lines(figure, width).len() as u32;
    (
        width,
        TITLE_HEIGHT + PANEL.1 * rows + CAPTION_LINE * lines + 16,
    )
}

/// Draws `figure` and writes it to `path` as a PNG (atomically; over an existing file only
/// with `force`).
pub fn write_png(path: &Path, figure: &Figure, force: bool) -> Result<(), StudyError> {
    register_font();
    let (w, h) = size(figure);
    let mut buffer = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_error)?;
        let (title, rest) = root.split_vertically(TITLE_HEIGHT);
        title
            .draw_text(
                &figure.title,
                &(FONT, 24).into_font().color(&BLACK),
                (16, 10),
            )
            .map_err(plot_error)?;
        let cols = if figure.panels.len() > 1 { 2 } else { 1 };
        let rows = figure.panels.len().div_ceil(cols).max(1);
        let (grid, caption) = rest.split_vertically(PANEL.1 * rows as u32);
        for (area, panel) in grid.split_evenly((rows, cols)).iter().zip(&figure.panels) {
            match panel {
                Panel::Lines { .. } => draw_lines(area, panel)?,
                Panel::Bars { .. } => draw_bars(area, panel)?,
            }
        }
        let style = (FONT, 15).into_font().color(&BLACK);
        for (i, line) in caption_lines(figure, w).iter().enumerate() {
            caption
                .draw_text(line, &style, (16, 4 + CAPTION_LINE as i32 * i as i32))
                .map_err(plot_error)?;
        }
        root.present().map_err(plot_error)?;
    }
    let image = image::RgbImage::from_raw(w, h, buffer)
        .ok_or_else(|| StudyError::Plot("the plot buffer has the wrong size".into()))?;
    crate::io::output::write_atomically(path, force, |p| {
        image
            .save_with_format(p, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })?;
    Ok(())
}

/// A tick label: few digits, scientific for very large or small values.
fn tick(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if (1.0..1e6).contains(&a) && (v - v.round()).abs() < 1e-9 * a {
        format!("{v:.0}")
    } else if !(1e-3..1e6).contains(&a) {
        format!("{v:.1e}")
    } else if a >= 100.0 {
        format!("{v:.0}")
    } else if a >= 10.0 {
        format!("{v:.1}")
    } else if a >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

/// A padded range over `values`; for linear values that are all positive it starts at 0.
fn range(values: impl Iterator<Item = f64>, log: bool, from_zero: bool) -> (f64, f64) {
    let (mut lo, mut hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(v), h.max(v))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if from_zero && !log && lo >= 0.0 {
        lo = 0.0;
    }
    let pad = if hi > lo {
        0.06 * (hi - lo)
    } else {
        0.5 * hi.abs().max(1.0)
    };
    if !(from_zero && !log && lo == 0.0) {
        lo -= pad;
    }
    hi += pad;
    (lo, hi)
}

fn draw_lines(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    panel: &Panel,
) -> Result<(), StudyError> {
    let Panel::Lines {
        title,
        x_label,
        y_label,
        x_scale,
        y_scale,
        series,
    } = panel
    else {
        unreachable!("called for a line panel")
    };
    let (sx, sy) = (*x_scale, *y_scale);
    // Log axes are drawn as linear axes over the log of the values, labelled with the values.
    let tx = move |v: f64| sx.to(v);
    let ty = move |v: f64| sy.to(v);
    let xs = range(
        series.iter().flat_map(|s| s.points.iter().map(|p| tx(p.0))),
        sx != Scale::Linear,
        false,
    );
    let ys = range(
        series
            .iter()
            .flat_map(|s| s.points.iter().flat_map(|p| [ty(p.2), ty(p.3)])),
        sy != Scale::Linear,
        true,
    );
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FONT, 19))
        .margin(14)
        .x_label_area_size(52)
        .y_label_area_size(84)
        .build_cartesian_2d(xs.0..xs.1, ys.0..ys.1)
        .map_err(plot_error)?;
    let fx = move |v: &f64| sx.label(*v);
    let fy = move |v: &f64| sy.label(*v);
    let mut mesh = chart.configure_mesh();
    mesh.x_desc(x_label.as_str())
        .y_desc(y_label.as_str())
        .x_labels(sx.ticks(xs))
        .y_labels(sy.ticks(ys))
        .x_label_formatter(&fx)
        .y_label_formatter(&fy)
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 15))
        .light_line_style(RGBColor(240, 240, 240));
    if sx == Scale::Log10 {
        mesh.disable_x_mesh();
    }
    if sy == Scale::Log10 {
        mesh.disable_y_mesh();
    }
    mesh.draw().map_err(plot_error)?;
    for (i, s) in series.iter().enumerate() {
        let style = ShapeStyle {
            color: colour(i).to_rgba(),
            filled: true,
            stroke_width: 2,
        };
        let points: Vec<(f64, f64)> = s.points.iter().map(|p| (tx(p.0), ty(p.1))).collect();
        let drawn = if s.dashed {
            chart.draw_series(DashedLineSeries::new(points.clone(), 10, 6, style))
        } else {
            chart.draw_series(LineSeries::new(points.clone(), style))
        }
        .map_err(plot_error)?;
        drawn
            .label(s.label.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 22, y)], style));
        chart
            .draw_series(points.iter().map(|&p| Circle::new(p, 3, style.filled())))
            .map_err(plot_error)?;
        chart
            .draw_series(
                s.points
                    .iter()
                    .filter(|p| p.3 > p.2)
                    .map(|p| PathElement::new(vec![(tx(p.0), ty(p.2)), (tx(p.0), ty(p.3))], style)),
            )
            .map_err(plot_error)?;
    }
    if !series.is_empty() {
        // The legend goes in the corner with the fewest points.
        let (mx, my) = (0.5 * (xs.0 + xs.1), 0.5 * (ys.0 + ys.1));
        let mut count = [0usize; 4];
        for p in series.iter().flat_map(|s| &s.points) {
            let (x, y) = (tx(p.0), ty(p.1));
            count[usize::from(x > mx) + 2 * usize::from(y < my)] += 1;
        }
        let corner = match (0..4).min_by_key(|&i| count[i]).unwrap_or(0) {
            0 => SeriesLabelPosition::UpperLeft,
            1 => SeriesLabelPosition::UpperRight,
            2 => SeriesLabelPosition::LowerLeft,
            _ => SeriesLabelPosition::LowerRight,
        };
        draw_legend(&mut chart, corner)?;
    }
    Ok(())
}

fn draw_bars(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    panel: &Panel,
) -> Result<(), StudyError> {
    let Panel::Bars {
        title,
        y_label,
        categories,
        series,
    } = panel
    else {
        unreachable!("called for a bar panel")
    };
    let n = categories.len().max(1);
    let axis = BarAxis::of(series);
    let (log, base) = (axis.log, axis.range.start);
    // Labels longer than a category's width go on two staggered rows.
    let longest = categories
        .iter()
        .map(|c| c.chars().count())
        .max()
        .unwrap_or(0);
    let (area_w, _) = area.dim_in_pixel();
    let staggered = (longest as f64 * 7.5) > 0.9 * f64::from(area_w.saturating_sub(110)) / n as f64;
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FONT, 19))
        .margin(14)
        .x_label_area_size(if staggered { 60 } else { 52 })
        .y_label_area_size(78)
        .build_cartesian_2d(-0.5..(n as f64 - 0.5), axis.range.clone())
        .map_err(plot_error)?;
    let names = categories.clone();
    let fx = move |v: &f64| {
        let i = v.round();
        if (v - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < names.len() {
            // The odd categories' labels are drawn a row lower, below.
            if staggered && i as usize % 2 == 1 {
                String::new()
            } else {
                names[i as usize].clone()
            }
        } else {
            String::new()
        }
    };
    let y_desc = if log {
        format!("{y_label}, log scale")
    } else {
        y_label.clone()
    };
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(n)
        .y_desc(y_desc.as_str())
        .x_label_formatter(&fx)
        .y_label_formatter(&|v| if log { tick(10f64.powf(*v)) } else { tick(*v) })
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 15))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(plot_error)?;
    if staggered {
        let style = TextStyle::from((FONT, 13).into_font()).color(&BLACK);
        let (ax, ay) = area.get_base_pixel();
        for (i, name) in categories.iter().enumerate().filter(|(i, _)| i % 2 == 1) {
            let (px, py) = chart.backend_coord(&(i as f64, base));
            let (tw, _) = area.estimate_text_size(name, &style).map_err(plot_error)?;
            area.draw_text(name, &style, (px - ax - tw as i32 / 2, py - ay + 24))
                .map_err(plot_error)?;
        }
    }
    draw_bar_series(&mut chart, series, &axis)?;
    if !series.is_empty() {
        draw_legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
    }
    Ok(())
}

/// The chart of a panel: f64 on both axes.
type Chart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The series' legend, in the corner `at`.
fn draw_legend<'a, 'b: 'a>(
    chart: &mut Chart<'a, 'b>,
    at: SeriesLabelPosition,
) -> Result<(), StudyError> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(160, 160, 160))
        .label_font((FONT, 13))
        .position(at)
        .draw()
        .map_err(plot_error)
}

/// A bar panel's y axis: linear from 0, or in decades (y is the log10 of the value) where the
/// bars span more than 30x, so the small ones stay readable beside the largest.
struct BarAxis {
    log: bool,
    range: std::ops::Range<f64>,
}

impl BarAxis {
    fn of(series: &[BarSeries]) -> BarAxis {
        let values = || series.iter().flat_map(|s| s.values.iter().flatten());
        let top = values().map(|v| v.2).fold(0.0f64, f64::max);
        let bottom = values()
            .map(|v| v.1)
            .filter(|&v| v > 0.0)
            .fold(f64::INFINITY, f64::min);
        let log = top > 30.0 * bottom;
        let range = if log {
            let lo = (bottom.log10() - 0.3).floor();
            // Headroom above the tallest bar for the legend, as below.
            let hi = top.log10() + 0.5 + 0.15 * (top.log10() - lo);
            lo..hi
        } else {
            // Headroom above the tallest bar for the legend (up to about 5 entries).
            let top = if top > 0.0 { top * 1.4 } else { 1.0 };
            0.0..top
        };
        BarAxis { log, range }
    }

    /// Where value `v` stands on the axis.
    fn y(&self, v: f64) -> f64 {
        if self.log {
            v.max(10f64.powf(self.range.start)).log10()
        } else {
            v
        }
    }
}

/// Each series' bars side by side in each category, with whiskers from the lowest to the
/// highest value.
fn draw_bar_series(
    chart: &mut Chart<'_, '_>,
    series: &[BarSeries],
    axis: &BarAxis,
) -> Result<(), StudyError> {
    let base = axis.range.start;
    let y = |v: f64| axis.y(v);
    let width = 0.8 / series.len().max(1) as f64;
    for (j, s) in series.iter().enumerate() {
        let fill = colour(j).filled();
        let line = ShapeStyle {
            color: BLACK.to_rgba(),
            filled: false,
            stroke_width: 1,
        };
        let x0 = |i: usize| i as f64 - 0.4 + j as f64 * width;
        chart
            .draw_series(s.values.iter().enumerate().filter_map(|(i, v)| {
                v.map(|v| Rectangle::new([(x0(i), base), (x0(i) + 0.92 * width, y(v.0))], fill))
            }))
            .map_err(plot_error)?
            .label(s.label.as_str())
            .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 16, y + 6)], fill));
        chart
            .draw_series(s.values.iter().enumerate().filter_map(|(i, v)| {
                v.filter(|v| v.2 > v.1).map(|v| {
                    let c = x0(i) + 0.46 * width;
                    PathElement::new(vec![(c, y(v.1)), (c, y(v.2))], line)
                })
            }))
            .map_err(plot_error)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_figure_with_both_kinds_of_panel_is_drawn() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.png");
        let figure = Figure {
            title: "test".into(),
            panels: vec![
                Panel::Lines {
                    title: "lines".into(),
                    x_label: "N".into(),
                    y_label: "time (ms)".into(),
                    x_scale: Scale::Log10,
                    y_scale: Scale::Log10,
                    series: vec![Series {
                        label: "cpu".into(),
                        points: vec![(1e4, 1.0, 0.9, 1.1), (1e5, 10.0, 9.0, 11.0)],
                        dashed: false,
                    }],
                },
                Panel::Bars {
                    title: "bars".into(),
                    y_label: "time (ms)".into(),
                    categories: vec!["a".into(), "b".into()],
                    series: vec![BarSeries {
                        label: "x".into(),
                        values: vec![Some((1.0, 0.5, 1.5)), None],
                    }],
                },
            ],
            caption: vec!["a caption".into()],
        };
        write_png(&path, &figure, false).unwrap();
        let image = image::open(&path).unwrap();
        assert_eq!((image.width(), image.height()), size(&figure));
        // Not blank: text and lines were drawn.
        let rgb = image.to_rgb8();
        assert!(rgb.pixels().filter(|p| p.0 != [255, 255, 255]).count() > 1000);
    }
}
