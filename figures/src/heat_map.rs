//! A heat map of square cells with a colour bar and an outline, e.g. an accuracy figure over a
//! workspace.

use crate::{colour_map, FONT_FAMILY};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::Path;

/// What a heat map shows.
pub struct HeatMap<'a> {
    /// Title.
    pub title: &'a str,
    /// Cells: centre (x, y) in mm and value.
    pub cells: &'a [([f64; 2], f64)],
    /// Side of a cell, mm.
    pub cell_mm: f64,
    /// Outline segments (e.g. the workspace boundary), mm.
    pub outline: &'a [[[f64; 2]; 2]],
    /// Points to mark (e.g. the maximum), with a label.
    pub marks: &'a [([f64; 2], String)],
    /// Label of the colour bar (quantity and unit).
    pub value_label: &'a str,
}

/// Draws a heat map as SVG. Errors are plotters' messages.
pub fn draw_heat_map(path: &Path, h: &HeatMap) -> Result<(), String> {
    crate::init();
    let err = |e: &dyn std::fmt::Debug| format!("{}: {e:?}", path.display());
    if h.cells.is_empty() {
        return Err(format!("{}: no cells to draw", path.display()));
    }
    let half = h.cell_mm / 2.0;
    let mut b = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for (c, _) in h.cells {
        b = [
            b[0].min(c[0] - half),
            b[1].max(c[0] + half),
            b[2].min(c[1] - half),
            b[3].max(c[1] + half),
        ];
    }
    let (lo, hi) = h
        .cells
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, c| {
            (a.0.min(c.1), a.1.max(c.1))
        });
    let root = SVGBackend::new(path, (900, 820)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let (main, bar) = root.split_horizontally(770);
    let mut chart = ChartBuilder::on(&main)
        .caption(h.title, (FONT_FAMILY, 20))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(b[0] - 5.0..b[1] + 5.0, b[2] - 5.0..b[3] + 5.0)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .label_style((FONT_FAMILY, 13))
        .draw()
        .map_err(|e| err(&e))?;
    chart
        .draw_series(h.cells.iter().map(|(c, v)| {
            let t = if hi > lo { (v - lo) / (hi - lo) } else { 0.5 };
            Rectangle::new(
                [(c[0] - half, c[1] - half), (c[0] + half, c[1] + half)],
                colour_map(t).filled(),
            )
        }))
        .map_err(|e| err(&e))?;
    chart
        .draw_series(h.outline.iter().map(|s| {
            PathElement::new(
                vec![(s[0][0], s[0][1]), (s[1][0], s[1][1])],
                BLACK.stroke_width(1),
            )
        }))
        .map_err(|e| err(&e))?;
    for (p, label) in h.marks {
        chart
            .draw_series(std::iter::once(Cross::new(
                (p[0], p[1]),
                6,
                RED.stroke_width(2),
            )))
            .map_err(|e| err(&e))?;
        chart
            .draw_series(std::iter::once(Text::new(
                label.clone(),
                (p[0] + 2.0, p[1] + 2.0),
                (FONT_FAMILY, 13).into_font().color(&BLACK),
            )))
            .map_err(|e| err(&e))?;
    }
    draw_colour_bar(&bar, lo, hi, h.value_label).map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

/// Top margin of the colour bar (pixels), about the map's plotting area's.
const BAR_TOP: i32 = 60;
/// Bottom margin of the colour bar (pixels).
const BAR_BOTTOM: i32 = 55;
/// Left edge of the colour strip in its area (pixels).
const BAR_X: i32 = 10;
/// Width of the colour strip (pixels).
const BAR_W: i32 = 22;

/// The colour bar of values `lo..hi`: a framed strip, ticks and labels on its right and the
/// quantity rotated beside them, all inside `area`.
fn draw_colour_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    lo: f64,
    hi: f64,
    value_label: &str,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (w, h) = area.dim_in_pixel();
    let (top, bottom) = (BAR_TOP, h as i32 - BAR_BOTTOM);
    let (x0, x1) = (BAR_X, BAR_X + BAR_W);
    let n = 100;
    for k in 0..n {
        let ya = bottom - (bottom - top) * k / n;
        let yb = bottom - (bottom - top) * (k + 1) / n;
        area.draw(&Rectangle::new(
            [(x0, yb), (x1, ya)],
            colour_map((k as f64 + 0.5) / n as f64).filled(),
        ))?;
    }
    area.draw(&Rectangle::new(
        [(x0, top), (x1, bottom)],
        BLACK.stroke_width(1),
    ))?;
    let span = hi - lo;
    let font = (FONT_FAMILY, 12).into_font().color(&BLACK);
    for (v, label) in bar_ticks(lo, hi) {
        let f = if span > 0.0 { (v - lo) / span } else { 0.5 };
        let y = bottom - ((bottom - top) as f64 * f).round() as i32;
        area.draw(&PathElement::new(vec![(x1, y), (x1 + 5, y)], BLACK))?;
        area.draw(&Text::new(
            label,
            (x1 + 8, y),
            font.clone().pos(Pos::new(HPos::Left, VPos::Center)),
        ))?;
    }
    area.draw(&Text::new(
        value_label.to_string(),
        ((x1 + 62).min(w as i32 - 12), (top + bottom) / 2),
        (FONT_FAMILY, 13)
            .into_font()
            .transform(FontTransform::Rotate270)
            .color(&BLACK)
            .pos(Pos::new(HPos::Center, VPos::Center)),
    ))?;
    Ok(())
}

/// Three to eight round tick values over `lo..=hi` (steps of 1, 2 or 5 times a power of ten), with
/// their labels at the step's decimals; the one value when `lo == hi`.
fn bar_ticks(lo: f64, hi: f64) -> Vec<(f64, String)> {
    if !(lo.is_finite() && hi.is_finite()) || hi < lo {
        return Vec::new();
    }
    let span = hi - lo;
    if span <= f64::EPSILON * hi.abs().max(lo.abs()).max(1e-300) {
        return vec![(lo, format!("{lo:.3}"))];
    }
    let raw = span / 8.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let decimals = (-(step.log10() + 1e-9).floor()).max(0.0) as usize;
    let first = (lo / step - 1e-9).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    (first..=last)
        .map(|k| {
            let v = k as f64 * step;
            (v, format!("{v:.decimals$}"))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bar_ticks_are_round_and_inside_the_range() {
        let t = bar_ticks(1.08, 1.78);
        let labels: Vec<&str> = t.iter().map(|x| x.1.as_str()).collect();
        assert_eq!(labels, ["1.1", "1.2", "1.3", "1.4", "1.5", "1.6", "1.7"]);
        let t = bar_ticks(0.215, 0.355);
        assert!(t.iter().all(|x| x.0 >= 0.215 && x.0 <= 0.355), "{t:?}");
        assert_eq!(t[0].1, "0.22");
        assert_eq!(bar_ticks(0.0, 12.5).last().unwrap().1, "12");
        assert_eq!(bar_ticks(2.0, 2.0).len(), 1);
        assert!(bar_ticks(f64::NAN, 1.0).is_empty());
    }

    /// Every rectangle and text of the SVG lies inside its width (text extents estimated at
    /// 0.65 of the font size per character, wider than the embedded font's digits).
    #[test]
    fn the_colour_bar_lies_inside_the_figure() {
        let file = std::env::temp_dir().join(format!("pcr-heat-map-{}.svg", std::process::id()));
        let cells: Vec<([f64; 2], f64)> = (0..400)
            .map(|k| {
                let (i, j) = ((k % 20) as f64, (k / 20) as f64);
                (
                    [i * 4.0 - 40.0, j * 4.0 - 40.0],
                    0.1 + 12.4 * (i + j) / 38.0,
                )
            })
            .collect();
        draw_heat_map(
            &file,
            &HeatMap {
                title: "test map",
                cells: &cells,
                cell_mm: 4.0,
                outline: &[],
                marks: &[],
                value_label: "worst-case error (mm)",
            },
        )
        .unwrap();
        let svg = std::fs::read_to_string(&file).unwrap();
        let _ = std::fs::remove_file(&file);
        let attr = |tag: &str, name: &str| -> f64 {
            let key = format!(" {name}=\"");
            tag.find(&key)
                .and_then(|i| {
                    let v = &tag[i + key.len()..];
                    v[..v.find('"')?].parse().ok()
                })
                .unwrap_or(0.0)
        };
        let width = attr(&svg[..svg.find('>').unwrap()], "width");
        assert_eq!(width, 900.0);
        for r in svg.split("<rect").skip(1) {
            let tag = &r[..r.find('>').unwrap()];
            let right = attr(tag, "x") + attr(tag, "width");
            assert!(right <= width, "rect beyond the right edge: {tag}");
        }
        let mut bar_labels = Vec::new();
        for t in svg.split("<text").skip(1) {
            let (tag, rest) = t.split_once('>').unwrap();
            let text = rest.split_once("</text>").unwrap().0.trim();
            let size = attr(tag, "font-size");
            let x = attr(tag, "x");
            let right = if tag.contains("rotate(") {
                x + size
            } else if tag.contains("text-anchor=\"start\"") {
                x + 0.65 * size * text.chars().count() as f64
            } else if tag.contains("text-anchor=\"middle\"") {
                x + 0.33 * size * text.chars().count() as f64
            } else {
                x
            };
            assert!(right <= width, "text beyond the right edge: {text:?} {tag}");
            if x > 770.0 && !tag.contains("rotate(") {
                bar_labels.push(text.to_string());
            }
        }
        assert_eq!(bar_labels, ["2", "4", "6", "8", "10", "12"]);
    }
}
