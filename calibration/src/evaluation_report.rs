//! The Markdown report of an evaluation: Table II, repeatability, model accuracy, backlash, and
//! the figures (Fig. 6 paths, Fig. 7 error map, backlash amplitudes).

use crate::backlash::{draw_error_map, Backlash};
use crate::evaluate::{table_two, Evaluation};
use crate::figures::{self, CurvePanel, FigureError};
use crate::report::ReportError;
use crate::stats::Summary;
use pcr_figures::{FONT_FAMILY, MEASURED, PLANNED};
use pcr_recording::Recording;
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

fn io(path: &Path) -> impl Fn(std::io::Error) -> ReportError + '_ {
    move |source| ReportError::Io {
        path: path.display().to_string(),
        source,
    }
}

/// Table II (paper layout) as Markdown.
pub fn table_two_markdown(evals: &[Evaluation]) -> String {
    let cols = table_two(evals);
    let mut s = String::from("| |");
    for c in &cols {
        let _ = write!(s, " {} |", c.head);
    }
    s.push_str("\n|---|");
    for _ in &cols {
        s.push_str("---|");
    }
    s.push('\n');
    type Get = fn(&Summary) -> f64;
    let rows: [(&str, bool, Get, bool); 8] = [
        ("mean dr (mm)", false, |s| s.mean, false),
        ("max dr (mm)", false, |s| s.max, false),
        ("sigma dr (mm)", false, |s| s.sigma, false),
        ("mean dphi (deg)", true, |s| s.mean, false),
        ("max dphi (deg)", true, |s| s.max, false),
        ("sigma dphi (deg)", true, |s| s.sigma, false),
        ("RMS (mm)", false, |s| s.rms, true),
        ("RMS (deg)", true, |s| s.rms, true),
    ];
    for (name, orient, get, path_only) in rows {
        let _ = write!(s, "| {name} |");
        for c in &cols {
            if path_only && !c.path {
                s.push_str(" |");
                continue;
            }
            let v = if orient {
                get(&c.orientation_deg)
            } else {
                get(&c.position_mm)
            };
            let _ = write!(s, " {v:.2} |");
        }
        s.push('\n');
    }
    // Percent of l_C.
    let _ = write!(s, "| mean dr (% of l_C) |");
    for e in evals {
        if let Some(p) = &e.pose_accuracy {
            let _ = write!(s, " {:.2} |", p.position_percent_l_c.mean);
        }
        for p in &e.paths {
            let _ = write!(s, " {:.2} |", p.position_percent_l_c.mean);
        }
    }
    s.push('\n');
    s
}

/// Writes `report.md` and its figures into `dir`. `recordings` are the evaluated recordings in
/// the order of `evals` (for the path figures).
pub fn write_evaluation_report(
    dir: &Path,
    evals: &[Evaluation],
    recordings: &[&Recording],
    backlash: Option<&Backlash>,
) -> Result<PathBuf, ReportError> {
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let mut md = String::from("# Evaluation report\n\n");
    for e in evals {
        let _ = writeln!(
            md,
            "- `{}`: {} (l_C = {:.1} mm for percentages)",
            e.file, e.label, e.l_c_mm
        );
    }
    if evals
        .iter()
        .any(|e| e.pose_accuracy.is_some() || !e.paths.is_empty())
    {
        let _ = writeln!(
            md,
            "\n## Table II: pose and path accuracy\n\n\
             Pose: static poses (settled rows averaged) against the targeted pose. Paths: planned \
             minus measured pose at the same time, every row with both.\n\n{}",
            table_two_markdown(evals)
        );
    }
    for e in evals {
        if let Some(r) = &e.repeatability {
            let _ = writeln!(
                md,
                "\n## Repeatability ({})\n\n{} targets, {} visits. Paper's 2-sigma neighbourhood: \
                 **{:.3} mm ({:.2} % of l_C), {:.3} deg**. ISO 9283 RP = mean(l) + 3 S_l: mean over \
                 targets {:.3} mm, max {:.3} mm; orientation 3 S_phi max {:.3} deg.",
                e.label,
                r.targets,
                r.visits,
                r.two_sigma_mm,
                r.two_sigma_percent_l_c,
                r.two_sigma_deg,
                r.iso_rp_mean_mm,
                r.iso_rp_max_mm,
                r.iso_rp_phi_max_deg
            );
        }
        if let Some(p) = &e.pose_accuracy {
            let _ = writeln!(
                md,
                "\nISO 9283 pose accuracy AP ({}): mean over targets {:.3} mm, max {:.3} mm.",
                e.label, p.iso_ap_mean_mm, p.iso_ap_max_mm
            );
        }
        if let Some(m) = &e.model {
            let _ = writeln!(
                md,
                "\nModel prediction ({}): forward kinematics of the commanded motors against the \
                 measured static poses: position RMS {:.3} mm (max {:.3}), orientation RMS {:.3} deg; \
                 M_i RMS {:.3} mm.",
                e.label,
                m.pose.position_rms_mm,
                m.pose.position_max_mm,
                m.pose.orientation_rms_deg,
                m.m_rms_mm
            );
        }
    }
    let mut figs = Vec::new();
    for (k, (e, rec)) in evals.iter().zip(recordings).enumerate() {
        for p in &e.paths {
            let name = format!("path_{k}_{}.svg", sanitize(&p.name));
            draw_path(
                &dir.join(&name),
                rec,
                &p.name,
                &format!("{} ({})", p.name, e.label),
            )?;
            figs.push(name);
        }
    }
    if !figs.is_empty() {
        let _ = writeln!(md, "\n## Paths: planned and measured (Fig. 6)\n");
        for f in &figs {
            let _ = writeln!(md, "![{f}]({f})\n");
        }
    }
    if let Some(b) = backlash {
        let _ = writeln!(
            md,
            "\n## Gear backlash and base-plate friction (section III-D)\n\n`{}` (blocks from {}; \
             false-alarm probability {} per block).\n\n| motor | n_S (steps) | step counts: amplitude / threshold (mm) |\n|---|---|---|",
            b.file, b.blocks_from, b.false_alarm
        );
        for m in &b.motors {
            let cells: Vec<String> = m
                .blocks
                .iter()
                .map(|bl| {
                    format!(
                        "{}: {:.3}/{:.3}{}",
                        bl.amplitude_steps,
                        bl.amplitude_mm,
                        bl.threshold_mm,
                        if bl.detected { "" } else { " (not detected)" }
                    )
                })
                .collect();
            let _ = writeln!(
                md,
                "| {} | {} | {} |",
                m.motor,
                m.n_s.map_or("not detected".into(), |n| n.to_string()),
                cells.join("; ")
            );
        }
        let panels: Vec<CurvePanel> = b
            .motors
            .iter()
            .filter(|m| !m.blocks.is_empty())
            .map(|m| CurvePanel {
                title: format!("motor {}", m.motor),
                points: m
                    .blocks
                    .iter()
                    .map(|bl| (bl.amplitude_steps as f64, bl.amplitude_mm))
                    .collect(),
                curves: vec![(
                    "detection threshold".into(),
                    3,
                    m.blocks
                        .iter()
                        .map(|bl| (bl.amplitude_steps as f64, bl.threshold_mm))
                        .collect(),
                )],
            })
            .collect();
        figures::curve_panels(
            &dir.join("backlash.svg"),
            "Amplitude of M_i at the excitation frequency",
            &panels,
            "steps forth and back",
            "amplitude (mm)",
        )?;
        let _ = writeln!(md, "\n![backlash](backlash.svg)\n");
        if let Some(m) = &b.error_map {
            draw_error_map(&dir.join("error_map.svg"), m)?;
            let _ = writeln!(
                md,
                "Eq. 10 over the phi = 0 workspace with n_S = {:?}: maximum **{:.2} mm** at ({:.0}, {:.0}) mm, \
                 mean {:.2} mm; at the square's corner (50, -50): {} mm.\n\n![Fig. 7](error_map.svg)",
                m.n_s.map(|v| v as u32),
                m.max_mm,
                m.max_at[0],
                m.max_at[1],
                m.mean_mm,
                m.at_square_corner_mm
                    .map_or("outside the workspace".into(), |v| format!("{v:.2}"))
            );
        }
    }
    let path = dir.join("report.md");
    std::fs::write(&path, md).map_err(io(&path))?;
    Ok(path)
}

fn sanitize(s: &str) -> String {
    s.chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect()
}

/// Planned and measured platform path of the rows of one `segment` (or all rows).
fn draw_path(file: &Path, rec: &Recording, segment: &str, title: &str) -> Result<(), FigureError> {
    let col = rec.extra_index("segment");
    let rows: Vec<_> = rec
        .rows
        .iter()
        .filter(|r| match col {
            Some(c) => r.extra.get(c).and_then(|v| v.as_deref()) == Some(segment),
            None => true,
        })
        .collect();
    let planned: Vec<(f64, f64)> = rows
        .iter()
        .filter_map(|r| Some((r.planned[0]?, r.planned[1]?)))
        .collect();
    let measured: Vec<(f64, f64)> = rows
        .iter()
        .filter_map(|r| Some((r.pose[0]?, r.pose[1]?)))
        .collect();
    pcr_figures::init();
    let e = |m: &dyn std::fmt::Debug| FigureError {
        file: file.display().to_string(),
        message: format!("{m:?}"),
    };
    let root = SVGBackend::new(file, (600, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let ext = planned
        .iter()
        .chain(&measured)
        .fold(10.0f64, |m, p| m.max(p.0.abs()).max(p.1.abs()))
        * 1.15;
    let mut c = ChartBuilder::on(&root)
        .caption(title, (FONT_FAMILY, 16))
        .margin(12)
        .x_label_area_size(35)
        .y_label_area_size(45)
        .build_cartesian_2d(-ext..ext, -ext..ext)
        .map_err(|x| e(&x))?;
    c.configure_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .label_style((FONT_FAMILY, 12))
        .draw()
        .map_err(|x| e(&x))?;
    c.draw_series(LineSeries::new(planned, PLANNED.stroke_width(2)))
        .map_err(|x| e(&x))?
        .label("planned")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], PLANNED.stroke_width(2)));
    c.draw_series(LineSeries::new(measured, MEASURED.stroke_width(1)))
        .map_err(|x| e(&x))?
        .label("measured")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], MEASURED.stroke_width(2)));
    c.configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT_FAMILY, 12))
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .draw()
        .map_err(|x| e(&x))?;
    root.present().map_err(|x| e(&x))?;
    Ok(())
}
