//! The figure of a run: planned and measured platform paths, and the position error over time.

use pcr_figures::{FONT_FAMILY, MEASURED, PLANNED};
use plotters::prelude::*;
use std::path::Path;

fn err<E: std::fmt::Debug>(e: E) -> String {
    format!("drawing failed: {e:?}")
}

/// Reads a recording and draws `<recording>.svg` next to it; returns the figure's path.
pub fn run_figure(recording: &Path) -> Result<std::path::PathBuf, String> {
    let rec = pcr_recording::Recording::read_path(recording).map_err(|e| e.to_string())?;
    let planned: Vec<(f64, f64, f64)> = rec
        .rows
        .iter()
        .filter_map(|r| Some((r.t_s, r.planned[0]?, r.planned[1]?)))
        .collect();
    let measured: Vec<(f64, f64, f64)> = rec
        .rows
        .iter()
        .filter_map(|r| Some((r.t_s, r.pose[0]?, r.pose[1]?)))
        .collect();
    let errors: Vec<(f64, f64)> = rec
        .rows
        .iter()
        .filter_map(|r| {
            Some((
                r.t_s,
                (r.pose[0]? - r.planned[0]?).hypot(r.pose[1]? - r.planned[1]?),
            ))
        })
        .collect();
    let out = recording.with_extension("svg");
    pcr_figures::init();
    let root = SVGBackend::new(&out, (1200, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (left, right) = root.split_horizontally(560);
    let ext = planned
        .iter()
        .chain(measured.iter())
        .fold(10.0f64, |m, p| m.max(p.1.abs()).max(p.2.abs()))
        * 1.15;
    let mut c = ChartBuilder::on(&left)
        .caption("Platform path: planned and measured", (FONT_FAMILY, 18))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(-ext..ext, -ext..ext)
        .map_err(err)?;
    c.configure_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .label_style((FONT_FAMILY, 13))
        .draw()
        .map_err(err)?;
    c.draw_series(LineSeries::new(
        planned.iter().map(|p| (p.1, p.2)),
        PLANNED.stroke_width(2),
    ))
    .map_err(err)?
    .label("planned")
    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], PLANNED.stroke_width(2)));
    c.draw_series(LineSeries::new(
        measured.iter().map(|p| (p.1, p.2)),
        MEASURED.stroke_width(1),
    ))
    .map_err(err)?
    .label("measured")
    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], MEASURED.stroke_width(2)));
    c.configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT_FAMILY, 13))
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    let tmax = errors.last().map_or(1.0, |e| e.0).max(1e-3);
    let emax = errors.iter().map(|e| e.1).fold(0.1, f64::max) * 1.15;
    let mut c2 = ChartBuilder::on(&right)
        .caption("Position error (measured - planned)", (FONT_FAMILY, 18))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..tmax, 0.0..emax)
        .map_err(err)?;
    c2.configure_mesh()
        .x_desc("t (s)")
        .y_desc("error (mm)")
        .label_style((FONT_FAMILY, 13))
        .draw()
        .map_err(err)?;
    c2.draw_series(LineSeries::new(
        errors.iter().copied(),
        MEASURED.stroke_width(1),
    ))
    .map_err(err)?;
    root.present().map_err(err)?;
    Ok(recording.with_extension("svg"))
}
