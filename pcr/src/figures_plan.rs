//! Figure of a plan: the planned path and the speed along it over time.

use anyhow::{anyhow, Result};
use pcr_figures::{FONT_FAMILY, PLANNED};
use pcr_kinematics::Robot;
use plotters::prelude::*;

fn err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("drawing failed: {e:?}")
}

/// `rows` are (t s, x mm, y mm, speed mm/s) every 20 ms, with the speed limit along the path
/// (mm/s, one per row; NaN where there is none, e.g. dwells, rest-to-rest lines and joint
/// moves) drawn in grey behind the speed.
pub fn plan_svg_with_limit(
    path: &str,
    robot: &Robot,
    rows: &[(f64, f64, f64, f64)],
    limit: &[f64],
) -> Result<()> {
    pcr_figures::init();
    let root = SVGBackend::new(path, (1200, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (left, right) = root.split_horizontally(560);
    let ws = pcr_kinematics::workspace::grid_workspace(robot, 0.0, 2.0, &|_| {});
    let ext = 100.0;
    let mut c = ChartBuilder::on(&left)
        .caption(
            "Planned path (workspace at phi = 0 in grey)",
            (FONT_FAMILY, 18),
        )
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
    c.draw_series(ws.contour().iter().map(|s| {
        PathElement::new(
            vec![(s[0][0], s[0][1]), (s[1][0], s[1][1])],
            RGBColor(170, 170, 170).stroke_width(1),
        )
    }))
    .map_err(err)?;
    c.draw_series(LineSeries::new(
        rows.iter().map(|r| (r.1, r.2)),
        PLANNED.stroke_width(2),
    ))
    .map_err(err)?;
    c.draw_series(
        rows.iter()
            .step_by(25)
            .map(|r| Circle::new((r.1, r.2), 2, PLANNED.filled())),
    )
    .map_err(err)?;
    let tmax = rows.last().map_or(1.0, |r| r.0).max(1e-3);
    let vmax = rows
        .iter()
        .map(|r| r.3)
        .chain(limit.iter().copied().filter(|v| v.is_finite()))
        .fold(1.0, f64::max)
        * 1.15;
    let caption = if limit.is_empty() {
        "Speed along the path (20 ms setpoints)"
    } else {
        "Speed along the path and its limit (grey), 20 ms"
    };
    let mut c2 = ChartBuilder::on(&right)
        .caption(caption, (FONT_FAMILY, 18))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..tmax, 0.0..vmax)
        .map_err(err)?;
    c2.configure_mesh()
        .x_desc("t (s)")
        .y_desc("speed (mm/s)")
        .label_style((FONT_FAMILY, 13))
        .draw()
        .map_err(err)?;
    // The limit in runs of finite values (it is undefined during dwells and joint moves).
    let mut run: Vec<(f64, f64)> = Vec::new();
    for (r, l) in rows
        .iter()
        .zip(limit)
        .chain(std::iter::once((&(0.0, 0.0, 0.0, 0.0), &f64::NAN)))
    {
        if l.is_finite() {
            run.push((r.0, *l));
        } else if !run.is_empty() {
            c2.draw_series(LineSeries::new(
                run.drain(..),
                RGBColor(160, 160, 160).stroke_width(3),
            ))
            .map_err(err)?;
        }
    }
    c2.draw_series(LineSeries::new(
        rows.iter().map(|r| (r.0, r.3)),
        PLANNED.stroke_width(2),
    ))
    .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}
