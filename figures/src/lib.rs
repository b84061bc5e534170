//! Shared figure support: every figure of the stack is an SVG drawn with `plotters`.
//!
//! Text needs a font; the DejaVu Sans font (its licence is in `assets/`) is embedded so that
//! figures render the same on every machine without system fonts. Call [`init`] once before
//! drawing (it is idempotent).

use plotters::style::{FontStyle, RGBColor};

mod heat_map;
pub use heat_map::{draw_heat_map, HeatMap};
use std::sync::Once;

/// The embedded font.
static FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

/// The family name under which the font is registered; use it (or "sans-serif") in text styles.
pub const FONT_FAMILY: &str = "sans-serif";

static INIT: Once = Once::new();

/// Registers the embedded font with plotters.
pub fn init() {
    INIT.call_once(|| {
        for style in [
            FontStyle::Normal,
            FontStyle::Bold,
            FontStyle::Italic,
            FontStyle::Oblique,
        ] {
            // The embedded font is a valid TrueType file (checked by the test below).
            let _ = plotters::style::register_font(FONT_FAMILY, style, FONT);
        }
    });
}

/// Colours of the three legs, used consistently in every figure.
pub const LEG_COLOURS: [RGBColor; 3] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xd6, 0x27, 0x28),
    RGBColor(0x2c, 0xa0, 0x2c),
];

/// Colour for planned quantities.
pub const PLANNED: RGBColor = RGBColor(0x33, 0x33, 0x33);
/// Colour for measured quantities.
pub const MEASURED: RGBColor = RGBColor(0xff, 0x7f, 0x0e);

/// A perceptually ordered colour map (viridis-like), `t` in [0, 1].
pub fn colour_map(t: f64) -> RGBColor {
    const STOPS: [(f64, [f64; 3]); 5] = [
        (0.0, [68.0, 1.0, 84.0]),
        (0.25, [59.0, 82.0, 139.0]),
        (0.5, [33.0, 145.0, 140.0]),
        (0.75, [94.0, 201.0, 98.0]),
        (1.0, [253.0, 231.0, 37.0]),
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    for w in STOPS.windows(2) {
        let (t0, c0) = w[0];
        let (t1, c1) = w[1];
        if t <= t1 {
            let f = (t - t0) / (t1 - t0);
            let c = |k: usize| (c0[k] + f * (c1[k] - c0[k])).round() as u8;
            return RGBColor(c(0), c(1), c(2));
        }
    }
    RGBColor(253, 231, 37)
}

#[cfg(test)]
mod tests {
    use super::*;
    use plotters::prelude::*;

    #[test]
    fn draws_text_with_the_embedded_font() {
        init();
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, (200, 100)).into_drawing_area();
            root.fill(&WHITE).unwrap();
            root.draw_text(
                "kappa 1/mm",
                &(FONT_FAMILY, 14).into_font().color(&BLACK),
                (10, 10),
            )
            .unwrap();
            root.present().unwrap();
        }
        assert!(svg.contains("kappa 1/mm"));
        assert_eq!(colour_map(0.0), RGBColor(68, 1, 84));
    }
}
