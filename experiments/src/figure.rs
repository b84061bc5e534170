//! The calibration set as a figure in the style of the paper's Fig. 5: one panel per
//! orientation with the workspace boundary, its scaled copies and the poses, training and test
//! marked differently.

use crate::calibration::CalibrationSet;
use pcr_figures::{FONT_FAMILY, LEG_COLOURS};
use pcr_recording::Split;
use plotters::prelude::*;
use std::path::Path;

/// Why the figure could not be drawn.
#[derive(Debug, thiserror::Error)]
#[error("{path}: drawing failed: {message}")]
pub struct FigureError {
    /// The file.
    pub path: String,
    /// The drawing backend's message.
    pub message: String,
}

/// Draws the calibration set to an SVG file.
pub fn calibration_set_svg(set: &CalibrationSet, path: &Path) -> Result<(), FigureError> {
    pcr_figures::init();
    let err = |e: &dyn std::fmt::Debug| FigureError {
        path: path.display().to_string(),
        message: format!("{e:?}"),
    };
    let n = set.boundaries.len().max(1);
    let root = SVGBackend::new(path, (520 * n as u32, 580)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    // One axis range for every panel: the largest extent of any boundary, with a margin.
    let r = set
        .boundaries
        .iter()
        .flat_map(|b| b.vertices.iter())
        .map(|v| v[0].abs().max(v[1].abs()))
        .fold(10.0, f64::max)
        * 1.12;
    let panels = root.split_evenly((1, n));
    let (train, test) = (LEG_COLOURS[0], LEG_COLOURS[1]);
    for (k, (panel, b)) in panels.iter().zip(&set.boundaries).enumerate() {
        let phi_deg = set.options.phis_deg[k];
        let mut chart = ChartBuilder::on(panel)
            .caption(format!("phi = {phi_deg:+} deg"), (FONT_FAMILY, 20))
            .margin(12)
            .x_label_area_size(38)
            .y_label_area_size(46)
            .build_cartesian_2d(-r..r, -r..r)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("x (mm)")
            .y_desc("y (mm)")
            .label_style((FONT_FAMILY, 13))
            .draw()
            .map_err(|e| err(&e))?;
        let closed = |s: f64| -> Vec<(f64, f64)> {
            b.vertices
                .iter()
                .chain(b.vertices.first())
                .map(|v| (s * v[0], s * v[1]))
                .collect()
        };
        chart
            .draw_series(LineSeries::new(closed(1.0), BLACK.stroke_width(2)))
            .map_err(|e| err(&e))?
            .label("workspace boundary")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
        for &s in &set.options.scales {
            chart
                .draw_series(LineSeries::new(closed(s), BLACK.mix(0.35).stroke_width(1)))
                .map_err(|e| err(&e))?;
        }
        let poses: Vec<_> = set.at_phi(phi_deg).collect();
        chart
            .draw_series(
                poses
                    .iter()
                    .filter(|p| p.set == Split::Train)
                    .map(|p| Circle::new((p.pose.x, p.pose.y), 4, train.filled())),
            )
            .map_err(|e| err(&e))?
            .label(format!(
                "training ({})",
                poses.iter().filter(|p| p.set == Split::Train).count()
            ))
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, train.filled()));
        chart
            .draw_series(
                poses
                    .iter()
                    .filter(|p| p.set == Split::Test)
                    .map(|p| Cross::new((p.pose.x, p.pose.y), 5, test.stroke_width(2))),
            )
            .map_err(|e| err(&e))?
            .label(format!(
                "test ({})",
                poses.iter().filter(|p| p.set == Split::Test).count()
            ))
            .legend(move |(x, y)| Cross::new((x + 10, y), 5, test.stroke_width(2)));
        // the origin every pose is approached from
        chart
            .draw_series(std::iter::once(TriangleMarker::new(
                (0.0, 0.0),
                6,
                BLACK.filled(),
            )))
            .map_err(|e| err(&e))?;
        chart
            .configure_series_labels()
            .label_font((FONT_FAMILY, 13))
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
