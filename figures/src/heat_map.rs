//! A heat map of square cells with a colour bar and an outline, e.g. an accuracy figure over a
//! workspace.

use crate::{colour_map, FONT_FAMILY};
use plotters::prelude::*;
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
    let mut cb = ChartBuilder::on(&bar)
        .margin_top(60)
        .margin_bottom(55)
        .margin_right(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..1.0, lo..hi.max(lo + 1e-9))
        .map_err(|e| err(&e))?;
    cb.configure_mesh()
        .disable_x_mesh()
        .disable_x_axis()
        .y_desc(h.value_label)
        .label_style((FONT_FAMILY, 12))
        .draw()
        .map_err(|e| err(&e))?;
    let n = 100;
    cb.draw_series((0..n).map(|k| {
        let a = lo + (hi - lo) * k as f64 / n as f64;
        let bb = lo + (hi - lo) * (k + 1) as f64 / n as f64;
        Rectangle::new(
            [(0.0, a), (1.0, bb)],
            colour_map(k as f64 / n as f64).filled(),
        )
    }))
    .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
