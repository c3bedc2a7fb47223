//! The colour legend drawn onto an image (`--legend`): the colour map as a bar, what it shows
//! (the attribute's name and which range, or the density) and the values at its ends and
//! middle, as ParaView's scalar bar does.

use crate::field::FieldSettings;
use crate::io::text::{FONT, register_font};
use crate::scene::maps::ColorMap;

/// The smallest image a legend is drawn on (it covers the bottom-left corner).
pub const MIN_SIZE: (u32, u32) = (120, 64);

/// What a legend says.
#[derive(Clone, Debug, PartialEq)]
pub struct Legend {
    /// What the colours show: `p (series range)`, `density Phi`.
    pub title: String,
    /// The values at the bar's two ends.
    pub low: f64,
    /// The value at the bar's high end.
    pub high: f64,
    /// The colour map the bar shows.
    pub color_map: ColorMap,
}

/// Why a legend cannot be drawn.
#[derive(Debug, thiserror::Error)]
pub enum LegendError {
    /// The image (width, height in pixels) is smaller than [`MIN_SIZE`].
    #[error(
        "--legend needs an image of at least {min_w}x{min_h} pixels, not {0}x{1}",
        min_w = MIN_SIZE.0,
        min_h = MIN_SIZE.1
    )]
    TooSmall(u32, u32),
    /// Drawing the text or bar failed.
    #[error("cannot draw the legend: {0}")]
    Draw(String),
}

/// A value as a label: four significant figures, scientific where that is shorter.
pub fn label(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        return format!("{v:.3e}");
    }
    let decimals = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
    let text = format!("{v:.decimals$}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        text
    }
}

impl Legend {
    /// The legend of an image of `field`: the attribute over the range it is normalised over
    /// (the field's, else the series'), which `range_is` names (`robust range`), or the
    /// density up to `phi_ref` where the image is coloured by density.
    pub fn of_field(
        field: &FieldSettings,
        series_range: Option<(f64, f64)>,
        range_is: &str,
        colour_by_density: bool,
        phi_ref: f64,
    ) -> Legend {
        let color_map = field.color_map.clone();
        match (&field.attribute, colour_by_density) {
            (Some(name), false) => {
                let range = field.attribute_range.or(series_range).unwrap_or((0.0, 0.0));
                Legend {
                    title: format!("{name} ({range_is})"),
                    low: range.0,
                    high: range.1,
                    color_map,
                }
            }
            _ => Legend {
                title: format!("density Phi (Phi_ref {})", label(phi_ref)),
                low: 0.0,
                high: phi_ref,
                color_map,
            },
        }
    }

    /// Draws the legend over the bottom-left corner of `image` (8-bit sRGB).
    pub fn draw(&self, image: &mut image::RgbImage) -> Result<(), LegendError> {
        use plotters::prelude::*;
        let (w, h) = image.dimensions();
        if w < MIN_SIZE.0 || h < MIN_SIZE.1 {
            return Err(LegendError::TooSmall(w, h));
        }
        register_font();
        let draw_err = |e: DrawingAreaErrorKind<_>| LegendError::Draw(e.to_string());
        let root = BitMapBackend::with_buffer(image.as_mut(), (w, h)).into_drawing_area();
        let (box_w, box_h) = ((w - 16).min(300) as i32, 52);
        let (x0, y0) = (8, h as i32 - 8 - box_h);
        root.draw(&Rectangle::new(
            [(x0, y0), (x0 + box_w, y0 + box_h)],
            RGBAColor(0, 0, 0, 0.6).filled(),
        ))
        .map_err(draw_err)?;
        let text = (FONT, 13).into_font().color(&WHITE);
        root.draw_text(&self.title, &text, (x0 + 6, y0 + 4))
            .map_err(draw_err)?;
        let (bar_x0, bar_x1, bar_y) = (x0 + 6, x0 + box_w - 6, y0 + 21);
        for x in bar_x0..bar_x1 {
            let t = f64::from(x - bar_x0) / f64::from((bar_x1 - bar_x0 - 1).max(1));
            let [r, g, b] = self
                .color_map
                .srgb(t)
                .map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8);
            root.draw(&Rectangle::new(
                [(x, bar_y), (x + 1, bar_y + 11)],
                RGBColor(r, g, b).filled(),
            ))
            .map_err(draw_err)?;
        }
        let small = (FONT, 12).into_font().color(&WHITE);
        let middle = 0.5 * (self.low + self.high);
        let labels = [
            (label(self.low), bar_x0, 0.0),
            (label(middle), (bar_x0 + bar_x1) / 2, 0.5),
            (label(self.high), bar_x1, 1.0),
        ];
        for (text, x, anchor) in labels {
            let (tw, _) = root.estimate_text_size(&text, &small).map_err(draw_err)?;
            let left =
                (x - (anchor * f64::from(tw)) as i32).clamp(x0 + 2, x0 + box_w - 2 - tw as i32);
            root.draw_text(&text, &small, (left, bar_y + 14))
                .map_err(draw_err)?;
        }
        root.present().map_err(draw_err)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_keep_four_figures() {
        assert_eq!(label(0.0), "0");
        assert_eq!(label(-13800.0), "-13800");
        assert_eq!(label(22800.0), "22800");
        assert_eq!(label(0.052), "0.052");
        assert_eq!(label(4.486185), "4.486");
        assert_eq!(label(1234567.0), "1.235e6");
        assert_eq!(label(2.5e-5), "2.500e-5");
    }

    #[test]
    fn the_bar_shows_the_map_and_leaves_the_rest_of_the_image() {
        let mut image = image::RgbImage::from_pixel(200, 100, image::Rgb([10, 200, 30]));
        let legend = Legend {
            title: "temperature (series range)".into(),
            low: 300.0,
            high: 1200.0,
            color_map: ColorMap::default(),
        };
        legend.draw(&mut image).unwrap();
        // The bar's ends are the map's ends (viridis: dark purple to yellow).
        let bar_y = 100 - 8 - 52 + 21 + 5;
        let first = image.get_pixel(8 + 6, bar_y).0;
        let last = image.get_pixel(8 + 6 + (184 - 12) - 1, bar_y).0;
        let [r0, g0, b0] = ColorMap::default()
            .srgb(0.0)
            .map(|c| (c * 255.0).round() as u8);
        assert_eq!(first, [r0, g0, b0]);
        assert!(last[0] > 200 && last[1] > 200 && last[2] < 80, "{last:?}");
        // Text was drawn: the box holds light pixels where the title goes.
        let light = (14..150)
            .flat_map(|x| (44..58).map(move |y| (x, y)))
            .filter(|&(x, y)| image.get_pixel(x, y).0.iter().all(|&c| c > 150))
            .count();
        assert!(light > 20, "{light} light pixels in the title");
        // Outside the box nothing changed.
        assert_eq!(image.get_pixel(150, 10).0, [10, 200, 30]);
        assert_eq!(image.get_pixel(199, 99).0, [10, 200, 30]);
        let mut tiny = image::RgbImage::new(64, 64);
        assert!(matches!(
            legend.draw(&mut tiny),
            Err(LegendError::TooSmall(64, 64))
        ));
    }
}
