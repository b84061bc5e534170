//! Figures of the kinematic tools: workspace contours, the base-radius sweep, accuracy maps.

use anyhow::{anyhow, Result};
use pcr_figures::{colour_map, FONT_FAMILY, LEG_COLOURS};
use pcr_kinematics::workspace::{AlphaWorkspace, Workspace};
use pcr_kinematics::{Pose, Robot};
use plotters::prelude::*;
use std::collections::HashMap;

fn err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("drawing failed: {e:?}")
}

/// Boundary edges of a set of triangles (edges used by exactly one triangle).
fn boundary(triangles: &[[[f64; 2]; 3]]) -> Vec<[[f64; 2]; 2]> {
    let key = |p: [f64; 2]| ((p[0] * 1e6).round() as i64, (p[1] * 1e6).round() as i64);
    type Edge = ((i64, i64), (i64, i64));
    let mut count: HashMap<Edge, ([f64; 2], [f64; 2], u32)> = HashMap::new();
    for t in triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            let (ka, kb) = (key(a), key(b));
            let k = if ka < kb { (ka, kb) } else { (kb, ka) };
            count.entry(k).or_insert((a, b, 0)).2 += 1;
        }
    }
    count
        .into_values()
        .filter(|v| v.2 == 1)
        .map(|v| [v.0, v.1])
        .collect()
}

fn draw_robot_outline<DB: DrawingBackend>(
    chart: &mut ChartContext<
        '_,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
    robot: &Robot,
) -> Result<()> {
    let home = Pose::default();
    for i in 0..3 {
        let c = LEG_COLOURS[i];
        let shape: Vec<(f64, f64)> = robot.legs[i]
            .shape(robot.home_kappa[i], 30)
            .iter()
            .map(|p| (p[0], p[1]))
            .collect();
        chart
            .draw_series(LineSeries::new(shape.clone(), c.mix(0.5).stroke_width(2)))
            .map_err(err)?;
        let m = robot.joint_m(i, robot.home_kappa[i]);
        let p = robot.joint_p(i, &home);
        chart
            .draw_series(LineSeries::new(
                vec![(m[0], m[1]), (p[0], p[1])],
                BLACK.mix(0.3).stroke_width(1),
            ))
            .map_err(err)?;
        chart
            .draw_series(std::iter::once(Circle::new(shape[0], 4, c.filled())))
            .map_err(err)?;
    }
    let tri: Vec<(f64, f64)> = (0..=3)
        .map(|i| robot.joint_p(i % 3, &home))
        .map(|p| (p[0], p[1]))
        .collect();
    chart
        .draw_series(LineSeries::new(tri, BLACK.mix(0.4).stroke_width(1)))
        .map_err(err)?;
    Ok(())
}

fn segments<DB: DrawingBackend>(
    chart: &mut ChartContext<
        '_,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
    segs: &[[[f64; 2]; 2]],
    style: ShapeStyle,
) -> Result<()> {
    chart
        .draw_series(
            segs.iter()
                .map(|s| PathElement::new(vec![(s[0][0], s[0][1]), (s[1][0], s[1][1])], style)),
        )
        .map_err(err)?;
    Ok(())
}

/// The workspace (grid contour, alpha-shape contour and each leg's alpha shape) over the robot.
pub fn workspace_svg(
    path: &str,
    robot: &Robot,
    grid: Option<&Workspace>,
    alpha: Option<&AlphaWorkspace>,
) -> Result<()> {
    pcr_figures::init();
    let root = SVGBackend::new(path, (900, 900)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let r = robot
        .legs
        .iter()
        .map(|l| l.b[0].hypot(l.b[1]))
        .fold(0.0, f64::max)
        + 40.0;
    let phi = grid
        .map(|g| g.phi)
        .or(alpha.map(|a| a.workspace.phi))
        .unwrap_or(0.0);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "Translational workspace, phi = {:.1} deg, working mode {}",
                phi.to_degrees(),
                pcr_robot::WorkingMode::triple_to_string(&robot.mode)
            ),
            (FONT_FAMILY, 20),
        )
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(-r..r, -r..r)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .label_style((FONT_FAMILY, 13))
        .draw()
        .map_err(err)?;
    draw_robot_outline(&mut chart, robot)?;
    if let Some(a) = alpha {
        for (i, leg) in a.legs.iter().enumerate() {
            let b = boundary(&leg.triangles);
            segments(&mut chart, &b, LEG_COLOURS[i].mix(0.35).stroke_width(1))?;
        }
        segments(&mut chart, &a.workspace.contour(), BLUE.stroke_width(2))?;
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(0.0, 0.0)],
                BLUE.stroke_width(2),
            )))
            .map_err(err)?
            .label(format!("alpha shapes: {:.0} mm^2", a.workspace.area()))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE.stroke_width(2)));
    }
    if let Some(g) = grid {
        segments(&mut chart, &g.contour(), BLACK.stroke_width(1))?;
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(0.0, 0.0)],
                BLACK.stroke_width(1),
            )))
            .map_err(err)?
            .label(format!("IK feasibility grid: {:.0} mm^2", g.area()))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(1)));
    }
    chart
        .configure_series_labels()
        .label_font((FONT_FAMILY, 14))
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}

/// Heat map of the accuracy figure (mm of platform motion per motor step).
pub fn accuracy_svg(path: &str, ws: &Workspace, acc: &[Option<f64>]) -> Result<()> {
    let g = &ws.grid;
    if ws.bounds().is_none() {
        return Err(anyhow!("the workspace is empty: no accuracy map to draw"));
    }
    // At most ~70 x 70 rectangles: sample every `stride` cells.
    let stride = (g.nx.max(g.ny) / 70).max(1);
    let mut cells = Vec::new();
    for j in (0..g.ny).step_by(stride) {
        for i in (0..g.nx).step_by(stride) {
            if let Some(v) = acc[j * g.nx + i] {
                cells.push((g.center(i, j), v));
            }
        }
    }
    let title = format!(
        "Platform motion per motor step (mm), phi = {:.1} deg",
        ws.phi.to_degrees()
    );
    pcr_figures::draw_heat_map(
        std::path::Path::new(path),
        &pcr_figures::HeatMap {
            title: &title,
            cells: &cells,
            cell_mm: g.res * stride as f64,
            outline: &ws.contour(),
            marks: &[],
            value_label: "mm per step",
        },
    )
    .map_err(|e| anyhow!(e))
}

/// The base-radius sweep: area over radius, and the contours of every radius.
pub fn sweep_svg(path: &str, shapes: &[(f64, Workspace)]) -> Result<()> {
    pcr_figures::init();
    let root = SVGBackend::new(path, (1200, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (left, right) = root.split_horizontally(560);
    let (r0, r1) = (
        shapes.iter().map(|s| s.0).fold(f64::INFINITY, f64::min),
        shapes.iter().map(|s| s.0).fold(f64::NEG_INFINITY, f64::max),
    );
    if shapes.is_empty() {
        return Err(anyhow!("no radius of the sweep has a workspace"));
    }
    let amax = shapes.iter().map(|s| s.1.area()).fold(0.0, f64::max) * 1.1 + 1.0;
    let mut c = ChartBuilder::on(&left)
        .caption("Workspace area over base radius", (FONT_FAMILY, 20))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(r0 - 5.0..r1 + 5.0, 0.0..amax)
        .map_err(err)?;
    c.configure_mesh()
        .x_desc("r_base (mm)")
        .y_desc("area (mm^2)")
        .label_style((FONT_FAMILY, 13))
        .draw()
        .map_err(err)?;
    c.draw_series(LineSeries::new(
        shapes.iter().map(|s| (s.0, s.1.area())),
        BLUE.stroke_width(2),
    ))
    .map_err(err)?;
    c.draw_series(
        shapes
            .iter()
            .map(|s| Circle::new((s.0, s.1.area()), 4, BLUE.filled())),
    )
    .map_err(err)?;
    let ext = shapes
        .iter()
        .filter_map(|s| s.1.bounds())
        .fold(10.0f64, |m, b| {
            m.max(b[0].abs())
                .max(b[1].abs())
                .max(b[2].abs())
                .max(b[3].abs())
        })
        + 10.0;
    let mut c2 = ChartBuilder::on(&right)
        .caption("Workspace contours (colour: r_base)", (FONT_FAMILY, 20))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(-ext..ext, -ext..ext)
        .map_err(err)?;
    c2.configure_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .label_style((FONT_FAMILY, 13))
        .draw()
        .map_err(err)?;
    for (r, ws) in shapes {
        let t = if r1 > r0 { (r - r0) / (r1 - r0) } else { 0.5 };
        let col = colour_map(t);
        segments(&mut c2, &ws.contour(), col.stroke_width(1))?;
        c2.draw_series(std::iter::once(PathElement::new(
            vec![(0.0, 0.0)],
            col.stroke_width(2),
        )))
        .map_err(err)?
        .label(format!("{r:.0} mm"))
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], col.stroke_width(2)));
    }
    c2.configure_series_labels()
        .label_font((FONT_FAMILY, 12))
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}
