//! The Markdown report of a calibration with its figures.

use crate::calibrate::{leg_observations, Calibration, ModelAccuracy};
use crate::data::StaticData;
use crate::figures::{self, CurvePanel, FigureError, Group};
use crate::step1::{theta_of_m, Param};
use crate::step2::predict_pose;
use pcr_figures::LEG_COLOURS;
use pcr_kinematics::{Leg, Robot};
use pcr_recording::Split;
use pcr_robot::{MapReading, RobotConfig};
use plotters::style::RGBColor;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The paper's Table I test RMS (mm), in function order.
pub const PAPER_TABLE1_MM: [f64; 13] = [
    1.57, 1.31, 1.32, 1.31, 1.24, 1.24, 1.22, 1.26, 1.26, 8.30, 7.90, 1.24, 1.24,
];

/// Why a report could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A file could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// A figure failed.
    #[error(transparent)]
    Figure(#[from] FigureError),
}

/// A strongly correlated pair of parameters of one fit of a calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct CorrelatedPair {
    /// The fit: `leg 1` .. `leg 3` (step 1) or `platform` (step 2).
    pub fit: String,
    /// First parameter.
    pub a: String,
    /// Second parameter.
    pub b: String,
    /// Their correlation coefficient.
    pub rho: f64,
}

/// The strongly correlated parameter pairs of a calibration (|rho| above
/// [`crate::step1::CORRELATION_WARNING`]), step 1 per leg, step 2, then the joint refinement.
pub fn correlated_pairs(cal: &Calibration) -> Vec<CorrelatedPair> {
    let legs = cal.step1.iter().enumerate().map(|(k, f)| {
        (
            format!("leg {}", f.leg.unwrap_or(k) + 1),
            f.correlated.as_slice(),
        )
    });
    legs.chain(std::iter::once((
        "platform".to_string(),
        cal.step2.correlated.as_slice(),
    )))
    .chain(
        cal.joint
            .iter()
            .map(|j| ("joint fit".to_string(), j.fit.correlated.as_slice())),
    )
    .flat_map(|(fit, pairs)| {
        pairs.iter().map(move |c| CorrelatedPair {
            fit: fit.clone(),
            a: c.a.clone(),
            b: c.b.clone(),
            rho: c.rho,
        })
    })
    .collect()
}

/// The calibration's warnings: parameters on their bounds, a fit that did not converge ...
/// (the correlated pairs are not among them: [`correlated_pairs`] lists those).
pub fn other_warnings(cal: &Calibration) -> Vec<&str> {
    cal.warnings.iter().map(String::as_str).collect()
}

/// One line naming the strongly correlated pairs, grouped by fit, e.g. `leg 1: a/b, c/d;
/// platform: e/f` (`None` when there are none).
pub fn correlated_summary(cal: &Calibration) -> Option<String> {
    let pairs = correlated_pairs(cal);
    if pairs.is_empty() {
        return None;
    }
    let mut groups: Vec<(String, Vec<String>)> = Vec::new();
    for p in &pairs {
        let pair = format!("{}/{}", p.a, p.b);
        match groups.iter_mut().find(|g| g.0 == p.fit) {
            Some(g) => g.1.push(pair),
            None => groups.push((p.fit.clone(), vec![pair])),
        }
    }
    let text: Vec<String> = groups
        .iter()
        .map(|(fit, v)| format!("{fit}: {}", v.join(", ")))
        .collect();
    Some(format!(
        "{} strongly correlated parameter pairs (|rho| > {}; the data hardly separate them): {}",
        pairs.len(),
        crate::step1::CORRELATION_WARNING,
        text.join("; ")
    ))
}

/// Formats an optional number.
pub fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.digits$}"))
}

fn params_table(out: &mut String, title: &str, params: &[Param]) {
    let _ = writeln!(
        out,
        "\n| {title} | start | fitted | std. error | unit |\n|---|---|---|---|---|"
    );
    for p in params {
        let _ = writeln!(
            out,
            "| {}{} | {:.6e} | {:.6e} | {} | {} |",
            p.name,
            if p.at_bound { " (on bound)" } else { "" },
            p.start,
            p.value,
            p.std.map_or("-".into(), |s| format!("{s:.2e}")),
            p.unit
        );
    }
}

fn accuracy_rows(out: &mut String, label: &str, a: Option<&ModelAccuracy>) {
    let Some(a) = a else {
        let _ = writeln!(out, "| {label} | - | - | - | - | - | - | - | - |");
        return;
    };
    let p = &a.pose;
    let _ = writeln!(
        out,
        "| {label} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
        a.m_rms_mm,
        a.m_max_mm,
        p.position_mean_mm,
        p.position_max_mm,
        p.position_rms_mm,
        p.orientation_mean_deg,
        p.orientation_max_deg,
        p.orientation_rms_deg
    );
}

/// The joint refinement's parameters (start: the two steps' values) with their uncertainties.
fn joint_section(out: &mut String, cal: &Calibration) {
    let Some(j) = &cal.joint else {
        return;
    };
    let f = &j.fit;
    let _ = writeln!(
        out,
        "\n## Joint refinement (every parameter of both steps on the M_i and the platform poses)\n\n\
         {} M_i and {} platform residuals (one degree weighted as {:.3} mm); training residual RMS \
         {:.4} mm at the two steps' result, {:.4} mm refined ({}, {} evaluations). The start column \
         is the two steps' value; the standard errors are those of the joint fit.",
        f.m_residuals,
        f.pose_residuals,
        f.phi_weight_mm_per_deg,
        f.start_rms_mm,
        f.rms_mm,
        f.status,
        f.evaluations
    );
    params_table(out, "parameter", &f.params);
}

/// The paper's two steps and the joint refinement side by side (with `Method::Joint`).
fn method_rows(out: &mut String, cal: &Calibration) {
    let Some(j) = &cal.joint else {
        return;
    };
    accuracy_rows(out, "paper's two steps, train", Some(&cal.paper.train));
    accuracy_rows(out, "joint, train", Some(&j.accuracy.train));
    accuracy_rows(out, "paper's two steps, **test**", cal.paper.test.as_ref());
    accuracy_rows(out, "joint, **test**", j.accuracy.test.as_ref());
    let _ = writeln!(
        out,
        "\nThe calibrated robot (\"after\") is {}.",
        match cal.used {
            crate::calibrate::Method::Joint => "the joint refinement's",
            crate::calibrate::Method::Paper => "the paper's two steps' (see the warnings)",
        }
    );
}

/// Writes `report.md` and its figures into `dir` (created if needed); returns the report path.
pub fn write_report(
    dir: &Path,
    cal: &Calibration,
    data: &StaticData,
    start: &RobotConfig,
) -> Result<PathBuf, ReportError> {
    std::fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.display().to_string(),
        source,
    })?;
    let mut md = String::new();
    let _ = writeln!(md, "# Calibration report\n");
    let _ = writeln!(
        md,
        "Data: `{}`, {} static poses ({} train, {} test; split: {}). Parameters freed: {:?}.",
        cal.data.file,
        cal.data.poses,
        cal.data.train,
        cal.data.test,
        match &cal.data.split {
            crate::SplitSource::Column => "the recording's `set` column".to_string(),
            crate::SplitSource::Seeded {
                seed,
                test_fraction,
            } => format!("seeded by target, seed {seed}, {test_fraction:.3} held out"),
        },
        cal.options.parameters
    );
    if let Some(n) = cal.data.row_noise {
        let _ = writeln!(
            md,
            "Capture noise of one row, from the spread of the settled rows: {:.3} mm, {:.3} mm, {:.3} deg (x, y, phi).",
            n[0], n[1], n[2]
        );
    }
    // Table I.
    let _ = writeln!(
        md,
        "\n## Table I: the 13 tendon-map functions in both readings (RMS of M_i, mm)\n\n\
         Symmetric: the odd extension of the paper's form (one set of coefficients for both \
         bending directions). Asymmetric: the paper's form for dl >= 0 and its own coefficients \
         for dl < 0, sharing k0. Each leg takes the reading with its lower test RMS.\n\n\
         | # | paper's form | symmetric train | symmetric test | asymmetric train | asymmetric test | readings (legs 1, 2, 3) | test | paper's test |\n\
         |---|---|---|---|---|---|---|---|---|"
    );
    for r in &cal.table1 {
        let of = |reading: MapReading, train: bool| {
            opt(
                r.reading(reading)
                    .and_then(|f| if train { f.train_rms_mm } else { f.test_rms_mm }),
                3,
            )
        };
        let chosen = if r.chosen.len() == 3 {
            r.chosen
                .iter()
                .map(|c| match c {
                    MapReading::Symmetric => "s",
                    MapReading::Asymmetric => "a",
                })
                .collect::<Vec<_>>()
                .join(" ")
        } else {
            "-".into()
        };
        let _ = writeln!(
            md,
            "| {}{} | `{}` | {} | {} | {} | {} | {} | {} | {:.2} |",
            r.index,
            if r.index == cal.selected {
                " **(selected)**"
            } else {
                ""
            },
            r.form,
            of(MapReading::Symmetric, true),
            of(MapReading::Symmetric, false),
            of(MapReading::Asymmetric, true),
            of(MapReading::Asymmetric, false),
            chosen,
            opt(r.test_rms_mm, 3),
            PAPER_TABLE1_MM[r.index - 1]
        );
        if let Some(e) = &r.error {
            let _ = writeln!(md, "| | not selectable: {e} | | | | | | | |");
        }
    }
    let _ = writeln!(
        md,
        "\nSelected: function {} ({}; {}), {}. The paper's column is the prototype's (for comparison of shapes, not values).\n\n![Table I](table1.svg)",
        cal.selected,
        cal.table1[cal.selected - 1].name,
        cal.table1[cal.selected - 1].chosen_text(),
        cal.selected_by
    );
    // Parameters.
    let _ = writeln!(md, "\n## Step 1: legs (paper eq. 8)");
    for f in &cal.step1 {
        params_table(
            &mut md,
            &format!("leg {}", f.leg.map_or(0, |i| i + 1)),
            &f.params,
        );
    }
    let _ = writeln!(
        md,
        "\n## Step 2: platform joints (paper eq. 9; one degree weighted as {:.3} mm)",
        cal.step2.phi_weight_mm_per_deg
    );
    params_table(&mut md, "parameter", &cal.step2.params);
    joint_section(&mut md, cal);
    // Accuracy.
    let _ = writeln!(
        md,
        "\n## Model accuracy on the static poses\n\n\
         Forward kinematics of the commanded motor positions against the measurement.\n\n\
         | model, poses | M_i RMS (mm) | M_i max (mm) | pos. mean (mm) | pos. max (mm) | pos. RMS (mm) | orient. mean (deg) | orient. max (deg) | orient. RMS (deg) |\n\
         |---|---|---|---|---|---|---|---|---|"
    );
    accuracy_rows(&mut md, "before, train", Some(&cal.before.train));
    accuracy_rows(&mut md, "after, train", Some(&cal.after.train));
    accuracy_rows(&mut md, "before, **test**", cal.before.test.as_ref());
    accuracy_rows(&mut md, "after, **test**", cal.after.test.as_ref());
    method_rows(&mut md, cal);
    if let Some(d) = &cal.diagnosis {
        let _ = writeln!(md, "\n**Why:** {}.", d.line);
    }
    let others = other_warnings(cal);
    if !others.is_empty() {
        let _ = writeln!(md, "\n## Warnings\n");
        for w in others {
            let _ = writeln!(md, "- {w}");
        }
    }
    let pairs = correlated_pairs(cal);
    if !pairs.is_empty() {
        let _ = writeln!(
            md,
            "\n## Strongly correlated parameters\n\n\
             Pairs whose estimates correlate with |rho| > {}: the data hardly separate them, so \
             each value of a pair is uncertain along the other (a combination of the two is \
             well determined).\n\n| fit | parameters | rho |\n|---|---|---|",
            crate::step1::CORRELATION_WARNING
        );
        for p in &pairs {
            let _ = writeln!(md, "| {} | {}, {} | {:+.3} |", p.fit, p.a, p.b, p.rho);
        }
    }
    let _ = writeln!(
        md,
        "\n## Figures\n\n![poses](poses.svg)\n\n![maps](maps.svg)\n\n![errors](errors.svg)"
    );
    let path = dir.join("report.md");
    std::fs::write(&path, md).map_err(|source| ReportError::Io {
        path: path.display().to_string(),
        source,
    })?;
    draw_table1(dir, cal)?;
    draw_poses(dir, data)?;
    draw_maps(dir, cal, data, start)?;
    draw_errors(dir, cal, data, start)?;
    Ok(path)
}

fn draw_table1(dir: &Path, cal: &Calibration) -> Result<(), FigureError> {
    let test_of = |reading: MapReading| -> Vec<Option<f64>> {
        cal.table1
            .iter()
            .map(|r| r.reading(reading).and_then(|f| f.test_rms_mm))
            .collect()
    };
    let labels: Vec<String> = cal
        .table1
        .iter()
        .map(|r| format!("{} {}", r.index, r.name))
        .collect();
    figures::bars(
        &dir.join("table1.svg"),
        "Table I: RMS of M_i per function",
        &labels,
        &[
            (
                "train",
                RGBColor(0x99, 0x99, 0x99),
                cal.table1.iter().map(|r| r.train_rms_mm).collect(),
            ),
            (
                "test, symmetric",
                LEG_COLOURS[0],
                test_of(MapReading::Symmetric),
            ),
            (
                "test, asymmetric",
                LEG_COLOURS[1],
                test_of(MapReading::Asymmetric),
            ),
        ],
        "RMS of |M^ - M| (mm, log scale)",
    )
}

fn draw_poses(dir: &Path, data: &StaticData) -> Result<(), FigureError> {
    // One panel per orientation (rounded to a degree).
    let mut phis: Vec<i64> = data
        .poses
        .iter()
        .filter_map(|p| p.settled.pose.map(|q| q[2].round() as i64))
        .collect();
    phis.sort_unstable();
    phis.dedup();
    if phis.len() > 6 {
        phis = vec![i64::MIN];
    }
    let panels: Vec<(String, Vec<Group>)> = phis
        .iter()
        .map(|&phi| {
            let sel = |set: Split| -> Vec<(f64, f64)> {
                data.of(set)
                    .filter_map(|p| p.settled.pose)
                    .filter(|q| phi == i64::MIN || q[2].round() as i64 == phi)
                    .map(|q| (q[0], q[1]))
                    .collect()
            };
            (
                if phi == i64::MIN {
                    "all orientations".into()
                } else {
                    format!("phi = {phi} deg")
                },
                vec![
                    Group {
                        label: "train",
                        colour: LEG_COLOURS[0],
                        filled: true,
                        points: sel(Split::Train),
                    },
                    Group {
                        label: "test",
                        colour: LEG_COLOURS[1],
                        filled: false,
                        points: sel(Split::Test),
                    },
                ],
            )
        })
        .collect();
    figures::scatter_panels(
        &dir.join("poses.svg"),
        "Measured static poses (Fig. 5)",
        &panels,
        "x (mm)",
        "y (mm)",
    )
}

fn draw_maps(
    dir: &Path,
    cal: &Calibration,
    data: &StaticData,
    start: &RobotConfig,
) -> Result<(), FigureError> {
    let panels: Vec<CurvePanel> = (0..3)
        .map(|i| {
            let leg_cfg = &cal.robot.legs[i];
            let leg = Leg::from_config(leg_cfg);
            let mut obs = leg_observations(start, data, i, Split::Train);
            obs.extend(leg_observations(start, data, i, Split::Test));
            let points: Vec<(f64, f64)> = obs
                .iter()
                .map(|o| (o.dl_mm, theta_of_m(&leg, o.m) / leg.l_c * 1e3))
                .collect();
            let (lo, hi) = points
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |a, p| {
                    (a.0.min(p.0), a.1.max(p.0))
                });
            let (lo, hi) = if lo.is_finite() {
                (lo, hi)
            } else {
                (-1.0, 1.0)
            };
            let grid = |leg: &Leg| -> Vec<(f64, f64)> {
                (0..=120)
                    .map(|k| {
                        let dl = lo + (hi - lo) * k as f64 / 120.0;
                        (dl, leg.map.kappa(dl) * 1e3)
                    })
                    .collect()
            };
            let nominal = Leg::from_config(&start.legs[i]);
            CurvePanel {
                title: format!("leg {}", i + 1),
                points,
                curves: vec![
                    ("start model".into(), 3, grid(&nominal)),
                    (
                        format!("function {} ({})", cal.selected, leg_cfg.tendon_map.form()),
                        i,
                        grid(&leg),
                    ),
                ],
            }
        })
        .collect();
    figures::curve_panels(
        &dir.join("maps.svg"),
        "Tendon maps: curvature from the measured M_i (calibrated geometry) and the fitted function",
        &panels,
        "tendon displacement dl (mm)",
        "curvature (1/m)",
    )
}

fn draw_errors(
    dir: &Path,
    cal: &Calibration,
    data: &StaticData,
    start: &RobotConfig,
) -> Result<(), FigureError> {
    let vectors = |cfg: &RobotConfig| -> Vec<((f64, f64), (f64, f64))> {
        let Ok(robot) = Robot::new(cfg) else {
            return Vec::new();
        };
        let set = if cal.data.test > 0 {
            Split::Test
        } else {
            Split::Train
        };
        data.of(set)
            .filter_map(|p| {
                let m = p.settled.pose?;
                let q = predict_pose(&robot, &p.q(), &m)?;
                Some(((m[0], m[1]), (q[0] - m[0], q[1] - m[1])))
            })
            .collect()
    };
    let (b, a) = (vectors(start), vectors(&cal.robot));
    let typical = b
        .iter()
        .map(|v| v.1 .0.hypot(v.1 .1))
        .fold(0.0, f64::max)
        .max(1e-6);
    let gain = (8.0 / typical).clamp(1.0, 1000.0).round();
    figures::error_vectors(
        &dir.join("errors.svg"),
        "Platform position error of the model on held-out poses",
        &b,
        &a,
        gain,
    )
}
