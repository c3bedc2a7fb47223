//! Text drawn onto images (the studies' plots, the legends of renders and slices): one font,
//! registered with plotters once.

use std::sync::Once;

use plotters::style::FontStyle;

/// The family plots and legends name: Hack, which egui ships (a monospace font: ab_glyph does
/// not kern, which spoils proportional fonts at small sizes).
pub const FONT: &str = "sans-serif";

/// Registers [`FONT`] with plotters (once per process).
pub fn register_font() {
    static REGISTERED: Once = Once::new();
    REGISTERED.call_once(|| {
        // The font egui ships; it parses (a test draws a figure), so this cannot fail.
        if plotters::style::register_font(
            FONT,
            FontStyle::Normal,
            epaint_default_fonts::HACK_REGULAR,
        )
        .is_err()
        {
            tracing::warn!("the plot font did not load: plots and legends will have no text");
        }
    });
}
