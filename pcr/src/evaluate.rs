//! `pcr evaluate`: the paper's evaluation (ISO 9283 repeatability and pose accuracy, path
//! accuracy, Table II, gear backlash and the eq. 10 map) from recordings.
//!
//! `pcr evaluate --robot R --data uncalibrated=eval-nominal.csv --data calibrated=eval-cal.csv
//! [--backlash backlash.csv] --report DIR --json out.json`

use crate::calibrate::load_robot;
use anyhow::{bail, Context};
use pcr_calibration::backlash;
use pcr_calibration::evaluate::{evaluate, Evaluation};
use pcr_calibration::evaluation_report::{table_two_markdown, write_evaluation_report};
use pcr_recording::Recording;
use std::path::PathBuf;

/// Arguments of `pcr evaluate`.
#[derive(clap::Args)]
pub struct Args {
    /// Robot configuration: l_C for percentages, the model whose predictions are checked, and
    /// the geometry of the backlash analysis; default: the built-in nominal robot.
    #[arg(long, value_name = "ROBOT.toml")]
    robot: Option<PathBuf>,
    /// A recording to evaluate, optionally labelled (`calibrated=eval.csv`); the label names its
    /// columns in Table II (default: the file name). Repeat for several recordings.
    #[arg(long, value_name = "[LABEL=]REC.csv")]
    data: Vec<String>,
    /// A recording of the backlash protocol (also recognised among --data by its `motor` and
    /// `amplitude_steps` columns).
    #[arg(long, value_name = "REC.csv")]
    backlash: Option<PathBuf>,
    /// False-alarm probability of the backlash detection per block.
    #[arg(long, default_value_t = 1e-3)]
    false_alarm: f64,
    /// Folder for the Markdown report and its figures.
    #[arg(long, value_name = "DIR")]
    report: Option<PathBuf>,
    /// Everything as JSON.
    #[arg(long, value_name = "OUT.json")]
    json: Option<PathBuf>,
}

fn is_backlash(rec: &Recording) -> bool {
    let labelled = match (rec.extra_index("motor"), rec.extra_index("amplitude_steps")) {
        (Some(m), Some(_)) => rec.rows.iter().any(|r| {
            r.extra
                .get(m)
                .is_some_and(|v| v.as_deref().is_some_and(|v| !v.is_empty()))
        }),
        _ => false,
    };
    labelled || rec.meta("experiment") == Some("backlash")
}

/// Runs `pcr evaluate`.
pub fn run(a: Args) -> anyhow::Result<()> {
    if a.data.is_empty() && a.backlash.is_none() {
        bail!("nothing to evaluate: give --data REC.csv (and/or --backlash REC.csv)");
    }
    if !(a.false_alarm > 0.0 && a.false_alarm < 0.5) {
        bail!("--false-alarm {}: must be in (0, 0.5)", a.false_alarm);
    }
    let robot = load_robot(a.robot.as_deref())?;
    let mut evals: Vec<Evaluation> = Vec::new();
    let mut recs: Vec<Recording> = Vec::new();
    let mut backlash_file = a.backlash.clone();
    for d in &a.data {
        let (label, path) = match d.split_once('=') {
            Some((l, p)) if !l.is_empty() && !p.is_empty() => (l.to_string(), PathBuf::from(p)),
            _ => {
                let p = PathBuf::from(d);
                let stem = p
                    .file_stem()
                    .map_or(d.clone(), |s| s.to_string_lossy().into_owned());
                (stem, p)
            }
        };
        let rec = Recording::read_path(&path)?;
        if is_backlash(&rec) && backlash_file.is_none() {
            backlash_file = Some(path);
            continue;
        }
        let e = evaluate(&rec, &path.display().to_string(), &label, &robot)?;
        evals.push(e);
        recs.push(rec);
    }
    let backlash = match &backlash_file {
        Some(p) => {
            let rec = Recording::read_path(p)?;
            Some(
                backlash::analyse(&rec, &p.display().to_string(), &robot, a.false_alarm, 2.0)
                    .with_context(|| format!("backlash analysis of {}", p.display()))?,
            )
        }
        None => None,
    };
    print_summary(&evals, backlash.as_ref());
    if let Some(j) = &a.json {
        let v = serde_json::json!({
            "evaluations": evals,
            "table2": pcr_calibration::evaluate::table_two(&evals),
            "backlash": backlash,
        });
        if let Some(d) = j.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(d).with_context(|| format!("cannot create {}", d.display()))?;
        }
        std::fs::write(j, serde_json::to_string_pretty(&v)?)
            .with_context(|| format!("cannot write {}", j.display()))?;
        println!("json: {}", j.display());
    }
    if let Some(dir) = &a.report {
        let refs: Vec<&Recording> = recs.iter().collect();
        let p = write_evaluation_report(dir, &evals, &refs, backlash.as_ref())?;
        println!("report: {}", p.display());
    }
    Ok(())
}

fn print_summary(evals: &[Evaluation], b: Option<&backlash::Backlash>) {
    if evals
        .iter()
        .any(|e| e.pose_accuracy.is_some() || !e.paths.is_empty())
    {
        println!("Table II\n{}", table_two_markdown(evals));
    }
    for e in evals {
        if let Some(r) = &e.repeatability {
            println!(
                "repeatability ({}): 2-sigma {:.3} mm ({:.2} % of l_C), {:.3} deg; ISO RP max {:.3} mm over {} targets",
                e.label, r.two_sigma_mm, r.two_sigma_percent_l_c, r.two_sigma_deg, r.iso_rp_max_mm, r.targets
            );
        }
        if let Some(m) = &e.model {
            println!(
                "model prediction ({}): position RMS {:.3} mm, orientation RMS {:.3} deg on {} static poses",
                e.label, m.pose.position_rms_mm, m.pose.orientation_rms_deg, m.pose.n
            );
        }
    }
    if let Some(b) = b {
        for m in &b.motors {
            println!(
                "backlash motor {}: n_S = {}",
                m.motor,
                m.n_s
                    .map_or("not detected".into(), |n| format!("{n} steps"))
            );
        }
        if let Some(m) = &b.error_map {
            println!(
                "eq. 10 map (phi = 0): max {:.2} mm at ({:.0}, {:.0}) mm, mean {:.2} mm",
                m.max_mm, m.max_at[0], m.max_at[1], m.mean_mm
            );
        }
    }
}
