//! The Markdown report of `pcr residuals`: the before/after table, the effects with their
//! evidence, every candidate's score, the verdict, and the residual plots behind each decision.

use crate::attribution::{Attribution, Verdict};
use pcr_calibration::figures::{curve_panels, curve_panels_shared, CurvePanel, FigureError};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Why the report could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// A figure.
    #[error(transparent)]
    Figure(#[from] FigureError),
}

fn fmt_param(p: &crate::fitted::Estimate) -> String {
    p.text("±")
}

/// Writes `report.md` and its figures into `dir`; `inputs` names the recordings.
pub fn write_report(dir: &Path, a: &Attribution, inputs: &str) -> Result<PathBuf, ReportError> {
    std::fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.display().to_string(),
        source,
    })?;
    let mut md = String::from("# Residual analysis\n\n");
    let _ = writeln!(
        md,
        "Data: {inputs}. {} training rows in {} blocks, {} held-out rows in {} blocks; every \
         figure below is on held-out rows.",
        a.rows[0], a.blocks[0], a.rows[1], a.blocks[1]
    );
    if let Some(n) = a.noise {
        let _ = writeln!(
            md,
            "Capture noise of one row (settled rows): {:.3} mm, {:.3} mm, {:.3} deg.",
            n[0], n[1], n[2]
        );
    }
    write_timing(&mut md, a);
    let _ = writeln!(
        md,
        "\n## Before and after (held-out rows)\n\n| | position mean (mm) | position max (mm) | position RMS (mm) | orientation RMS (deg) |\n|---|---|---|---|---|"
    );
    for (label, e) in [("before", &a.before), ("after", &a.after)] {
        let _ = writeln!(
            md,
            "| {label} | {:.3} | {:.3} | {:.3} | {:.3} |",
            e.position_mean_mm, e.position_max_mm, e.position_rms_mm, e.orientation_rms_deg
        );
    }
    let _ = writeln!(
        md,
        "\n**Verdict: {}{}**. Remaining held-out RMS of the weighted residual {:.3} mm, {:.3} mm above \
         what the capture noise explains.\n\n![residual over time](residual_time.svg)\n\n\
         (Each mark is the largest residual of a short run of consecutive held-out rows.)",
        match a.verdict {
            Verdict::Explained => "explained",
            Verdict::PartlyExplained => "partly explained",
            Verdict::Unexplained => "unexplained",
        },
        if a.timing_finding.is_some() {
            ", with a timing declaration error (see Timing)"
        } else {
            ""
        },
        a.remaining_rms_mm,
        a.remaining_excess_mm
    );
    if let Some(f) = &a.timing_finding {
        let _ = writeln!(md, "\n**{f}**");
    }
    if !a.correlated_features.is_empty() {
        let _ = writeln!(
            md,
            "\nThe remaining residual follows (held-out share of its variance a quadratic in the \
             feature explains):\n"
        );
        for f in &a.correlated_features {
            let _ = writeln!(
                md,
                "- `{}`: R² = {:.2}, correlation {:+.2} with the {} residual",
                f.feature, f.held_out_r2, f.correlation, f.component
            );
        }
        for (k, (feat, comp, _)) in a.feature_points.iter().enumerate() {
            let _ = writeln!(
                md,
                "\n![{feat}](feature_{k}.svg) ({comp} residual over {feat})"
            );
        }
    }
    let _ = writeln!(md, "\n## Effects added, in order\n");
    if a.effects.is_empty() {
        let _ = writeln!(md, "None.");
    }
    for (k, e) in a.effects.iter().enumerate() {
        let ev = &e.evidence;
        let _ = writeln!(
            md,
            "{}. **{}**: {}.\n   Parameters: {}.\n   Evidence (round {}): held-out RMS {:.4} -> {:.4} mm \
             against the recalibrated reference (gain {:.4} mm), paired block test p = {:.2e}, \
             BIC {:+.1}; held-out position RMS with it in the full model {:.3} mm.\n\n   \
             ![{}](effect_{k}.svg)\n",
            k + 1,
            e.name,
            e.description,
            e.params.iter().map(fmt_param).collect::<Vec<_>>().join(", "),
            ev.round,
            ev.held_out_rms_before_mm,
            ev.held_out_rms_after_mm,
            ev.effect_mm,
            ev.p_value,
            ev.delta_bic,
            e.held_out_after.position_rms_mm,
            e.name
        );
    }
    if !a.removed.is_empty() {
        let _ = writeln!(md, "\n## Taken out by the backward pass\n");
        for r in &a.removed {
            let _ = writeln!(
                md,
                "- **{}** ({}): with every other effect in, held-out RMS {:.4} mm without it and {:.4} mm with it (p = {:.2e}): {}.",
                r.name,
                r.params.iter().map(fmt_param).collect::<Vec<_>>().join(", "),
                r.held_out_rms_without_mm,
                r.held_out_rms_with_mm,
                r.p_value,
                r.note
            );
        }
    }
    let imitations: Vec<&str> = a
        .candidates
        .iter()
        .filter(|c| c.note.starts_with("acts partly like"))
        .map(|c| c.note.as_str())
        .collect();
    if !imitations.is_empty() {
        let _ = writeln!(
            md,
            "\n## Not named: parameters that disagree between parts of the data\n"
        );
        for n in imitations {
            let _ = writeln!(md, "- {n}.");
        }
    }
    let _ = writeln!(
        md,
        "\n## Every candidate tried\n\n| round | candidate | held-out gain (mm) | p | ΔBIC | accepted | why not |\n|---|---|---|---|---|---|---|"
    );
    for c in &a.candidates {
        let _ = writeln!(
            md,
            "| {} | {} | {:.4} | {:.1e} | {:+.0} | {} | {} |",
            c.round,
            c.name,
            c.effect_mm,
            c.p_value,
            c.delta_bic,
            if c.significant { "yes" } else { "no" },
            c.note.replace('|', "/")
        );
    }
    let path = dir.join("report.md");
    std::fs::write(&path, md).map_err(|source| ReportError::Io {
        path: path.display().to_string(),
        source,
    })?;
    // Figures (at most a few thousand marks each: the largest residual of each run of rows
    // over time, every k-th point of the scatter plots).
    let before: Vec<(f64, f64)> = chunk_max(
        &a.residual_time
            .iter()
            .map(|p| (p.0, p.1))
            .collect::<Vec<_>>(),
    );
    let after: Vec<(f64, f64)> = chunk_max(
        &a.residual_time
            .iter()
            .map(|p| (p.0, p.2))
            .collect::<Vec<_>>(),
    );
    // One scale for both panels, so that the gain shows.
    curve_panels_shared(
        &dir.join("residual_time.svg"),
        "Position residual of held-out rows over time",
        &[
            CurvePanel {
                title: "before".into(),
                points: before,
                curves: vec![],
            },
            CurvePanel {
                title: "after".into(),
                points: after,
                curves: vec![],
            },
        ],
        "time since the start of the recording (s)",
        "|measured - predicted| (mm)",
    )?;
    for (k, (name, pts)) in a.effect_points.iter().enumerate() {
        let m = pts.iter().map(|p| p.0).fold(0.0, f64::max);
        curve_panels(
            &dir.join(format!("effect_{k}.svg")),
            &format!("{name}: held-out residual along its predicted change"),
            &[CurvePanel {
                title: name.clone(),
                points: every_kth(pts),
                curves: vec![("explained exactly".into(), 0, vec![(0.0, 0.0), (m, m)])],
            }],
            "change the effect predicts (mm)",
            "residual along it (mm)",
        )?;
    }
    for (k, (feat, comp, pts)) in a.feature_points.iter().enumerate() {
        curve_panels(
            &dir.join(format!("feature_{k}.svg")),
            &format!("remaining {comp} residual over {feat}"),
            &[CurvePanel {
                title: feat.clone(),
                points: every_kth(pts),
                curves: vec![],
            }],
            feat,
            &format!("{comp} residual (mm)"),
        )?;
    }
    Ok(path)
}

/// Marks per figure.
const MAX_MARKS: usize = 3000;

/// The point of largest value of each run of consecutive points, so that at most
/// [`MAX_MARKS`] remain and no peak is lost.
fn chunk_max(pts: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let k = pts.len().div_ceil(MAX_MARKS).max(1);
    pts.chunks(k)
        .filter_map(|c| c.iter().copied().max_by(|a, b| a.1.total_cmp(&b.1)))
        .collect()
}

/// Every k-th point, so that at most [`MAX_MARKS`] remain.
fn every_kth(pts: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let k = pts.len().div_ceil(MAX_MARKS).max(1);
    pts.iter().step_by(k).copied().collect()
}

/// The timing section: each recording's declared command delay against the one its moving rows
/// show (`crate::alignment`).
fn write_timing(md: &mut String, a: &Attribution) {
    if a.timing.is_empty() {
        return;
    }
    let _ = writeln!(
        md,
        "\n## Timing: command delay declared and shown by the data\n\n\
         The pose of a row answers the command of D seconds earlier (`# command_delay_s = D`, 0 \
         when the file says nothing). The delay the data show is estimated from the moving \
         training rows (profile of the residual over the delay, block-jackknife standard error).\n\n\
         | recording | declared D (s) | data (s) | +- (s) | data - D (s) | moving rows | finding | delay used (s) |\n\
         |---|---|---|---|---|---|---|---|"
    );
    let opt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.4}"));
    for t in &a.timing {
        let _ = writeln!(
            md,
            "| `{}` | {}{} | {} | {} | {} | {} | {} | {:.4} |",
            t.origin,
            t.declared_s,
            if t.declared { "" } else { " (not declared)" },
            opt(t.estimated_s),
            opt(t.std_s),
            opt(t.excess_s),
            t.moving_rows,
            match t.finding {
                crate::alignment::TimingFinding::Consistent => "consistent",
                crate::alignment::TimingFinding::LaterThanDeclared => "later than declared",
                crate::alignment::TimingFinding::DeclarationError => "**declaration error**",
                crate::alignment::TimingFinding::NotEstimable => "not estimable",
            },
            t.delay_used_s
        );
    }
    for t in &a.timing {
        let _ = writeln!(md, "\n{}", t.message);
    }
}
