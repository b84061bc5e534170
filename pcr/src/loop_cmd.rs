//! `pcr loop --config C --out DIR`: the whole measuring loop on the simulated plant of a
//! supervisor configuration, as a lab would run it on its robot:
//!
//! 1. record the calibration set and the paper's paths with the configuration's (nominal)
//!    robot;
//! 2. calibrate (`pcr calibrate`) and record the paths with the calibrated robot;
//! 3. analyse the residuals of the calibrated model on the calibration recording and the
//!    calibrated paths (`pcr residuals --no-calibrate`), and write the extended robot;
//! 4. re-run with every model: the paths, and a check pose set that neither the calibration
//!    nor the residual analysis saw (other boundary scales and orientations);
//! 5. report the error on the robot, nominal / calibrated / extended (`DIR/loop.md`,
//!    `DIR/loop.json`, `DIR/loop_errors.svg`), with the calibration, residual and evaluation
//!    reports beside it.

use crate::experiment::{record, Sources};
use anyhow::{bail, Context, Result};
use pcr_calibration::calibrate::{self, Options as CalOptions};
use pcr_calibration::evaluate::{evaluate, Evaluation};
use pcr_calibration::figures::bars;
use pcr_calibration::StaticData;
use pcr_experiments::{CalibrationOptions, Design, PathsDesign, StaticDesign, VisitTiming};
use pcr_recording::Recording;
use pcr_residuals::{attribute, Blocks, Options, Series};
use pcr_robot::RobotConfig;
use plotters::style::RGBColor;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Arguments of `pcr loop`.
#[derive(clap::Args)]
pub struct Args {
    /// Supervisor configuration (e.g. configs/sim.toml): its robot is the starting model, its
    /// driver's plant the robot.
    #[arg(long, value_name = "CONFIG.toml")]
    config: PathBuf,
    /// Folder for every recording, robot file and report of the loop.
    #[arg(long, value_name = "DIR", default_value = "out/loop")]
    out: PathBuf,
    /// The plant (default: the configuration's driver's plant).
    #[arg(long, value_name = "PLANT.toml")]
    plant: Option<PathBuf>,
    /// Points per scaled boundary of the calibration set (the paper: 21).
    #[arg(long, default_value_t = 21, value_parser = clap::value_parser!(u32).range(3..))]
    points: u32,
    /// Test poses per (orientation, scale) group of the calibration set (the paper: 7).
    #[arg(long, default_value_t = 7)]
    test_per_group: u32,
    /// Points per scaled boundary of the check set (scales 0.6 and 0.35, phi 0 and +-5 deg).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(2..))]
    check_points: u32,
    /// Seed of the calibration split.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Length of the residual analysis's held-out time blocks, s.
    #[arg(long, default_value_t = 4.0)]
    block_s: f64,
}

/// One model's errors on the robot.
#[derive(Debug, Clone, Serialize)]
struct StageErrors {
    /// `nominal`, `calibrated` or `extended`.
    model: String,
    /// The robot file.
    robot: String,
    /// Check poses: position error mean / max / RMS, mm; orientation RMS, deg.
    check_position_mean_mm: Option<f64>,
    check_position_max_mm: Option<f64>,
    check_position_rms_mm: Option<f64>,
    check_orientation_rms_deg: Option<f64>,
    /// Paths: RMS of the position error per path (circle, square), mm.
    path_rms_mm: Vec<(String, f64)>,
    /// Paths: RMS of the orientation error per path, deg.
    path_rms_deg: Vec<(String, f64)>,
}

fn stage_errors(model: &str, robot: &str, check: &Evaluation, paths: &Evaluation) -> StageErrors {
    let pa = check.pose_accuracy.as_ref();
    StageErrors {
        model: model.into(),
        robot: robot.into(),
        check_position_mean_mm: pa.map(|p| p.position_mm.mean),
        check_position_max_mm: pa.map(|p| p.position_mm.max),
        check_position_rms_mm: pa.map(|p| p.position_mm.rms),
        check_orientation_rms_deg: pa.map(|p| p.orientation_deg.rms),
        path_rms_mm: paths
            .paths
            .iter()
            .map(|p| (p.name.clone(), p.position_mm.rms))
            .collect(),
        path_rms_deg: paths
            .paths
            .iter()
            .map(|p| (p.name.clone(), p.orientation_deg.rms))
            .collect(),
    }
}

/// Runs `pcr loop`.
pub fn run(a: Args) -> Result<()> {
    if !(a.block_s > 0.0 && a.block_s.is_finite()) {
        bail!(
            "--block-s {}: must be a positive number of seconds",
            a.block_s
        );
    }
    let dir = &a.out;
    std::fs::create_dir_all(dir)
        .with_context(|| format!("--out {}: cannot create the folder", dir.display()))?;
    let wall = std::time::Instant::now();
    let nominal = Sources::from_files(&a.config, None, a.plant.as_deref(), None)?;
    let start = nominal.plant_robot.clone();
    let model = nominal.model_robot()?;
    let cal_options = CalibrationOptions {
        points: a.points as usize,
        test_per_group: a.test_per_group as usize,
        seed: a.seed,
        ..CalibrationOptions::default()
    };
    // The check set: boundaries scaled by 0.6 and 0.35 at phi = 0 and +-5 deg, none of which
    // the calibration set visits.
    let check_options = CalibrationOptions {
        phis_deg: vec![0.0, 5.0, -5.0],
        scales: vec![0.6, 0.35],
        points: a.check_points as usize,
        test_per_group: 0,
        seed: a.seed,
        ..CalibrationOptions::default()
    };
    let calibration_design = || -> Result<Design> {
        Ok(Design::Static(
            StaticDesign::calibration(&model, &cal_options, VisitTiming::default())
                .context("calibration design")?,
        ))
    };
    let check_design = || -> Result<Design> {
        Ok(Design::Static(
            StaticDesign::calibration(&model, &check_options, VisitTiming::default())
                .context("check design")?,
        ))
    };
    let paths_design = || Design::Paths(PathsDesign::default());
    let file = |name: &str| dir.join(name);

    // 1. Nominal.
    println!(
        "== 1/5 recording with the nominal model ({})",
        a.config.display()
    );
    record(
        calibration_design()?,
        nominal.clone(),
        a.seed,
        &file("1-calibration.csv"),
    )?;
    record(
        paths_design(),
        nominal.clone(),
        a.seed,
        &file("1-paths.csv"),
    )?;
    record(
        check_design()?,
        nominal.clone(),
        a.seed,
        &file("1-check.csv"),
    )?;

    // 2. Calibrate.
    println!("== 2/5 calibrating");
    let cal_rec = Recording::read_path(file("1-calibration.csv"))?;
    let sd = StaticData::from_recording(
        &cal_rec,
        &file("1-calibration.csv").display().to_string(),
        a.seed,
        1.0 / 3.0,
    )?;
    // The calibration's settings, which the residual analysis makes it again with.
    let cal_settings = CalOptions::default();
    let cal = calibrate::calibrate_data(&start, &sd, &cal_settings).context("calibration")?;
    let created = pcr_offline::clock::utc_now();
    let calibrated_path = file("calibrated.toml");
    std::fs::write(&calibrated_path, calibrate::robot_file(&cal, &created))
        .with_context(|| format!("cannot write {}", calibrated_path.display()))?;
    pcr_calibration::report::write_report(&file("calibration"), &cal, &sd, &start)?;
    println!(
        "calibrated: function {}, platform position RMS on the test poses {:.3} -> {:.3} mm -> {}",
        cal.selected,
        cal.before.test.map_or(f64::NAN, |t| t.pose.position_rms_mm),
        cal.after.test.map_or(f64::NAN, |t| t.pose.position_rms_mm),
        calibrated_path.display()
    );
    let calibrated = RobotConfig::load(&calibrated_path)
        .with_context(|| format!("reading back {}", calibrated_path.display()))?;
    let cal_src = nominal.with_model(calibrated.clone(), calibrated_path.display().to_string());
    record(
        paths_design(),
        cal_src.clone(),
        a.seed,
        &file("2-paths.csv"),
    )?;
    record(check_design()?, cal_src, a.seed, &file("2-check.csv"))?;

    // 3. Residuals of the calibrated model.
    println!("== 3/5 residual analysis of the calibrated model");
    let data = [file("1-calibration.csv"), file("2-paths.csv")];
    let series: Vec<Series> = data
        .iter()
        .map(|p| {
            let rec = Recording::read_path(p)?;
            Ok(Series::from_recording(&rec, &p.display().to_string())?)
        })
        .collect::<Result<_>>()?;
    let blocks = Blocks::in_time(&series, a.block_s, 3);
    // The calibration's static poses (the first series), for the analysis to make it again from
    // the drawing with its effects in the model, as `pcr residuals` does. Without them the
    // loop's analysis refined the effects around the calibration they had bent: the plays came
    // out 2.93 / 3.80 / 2.90 +- 0.02 steps for the plant's 3 / 4 / 3.
    let opts = Options {
        recalibration: Some(std::sync::Arc::new(pcr_residuals::options::Recalibration {
            data: sd,
            series: 0,
            options: cal_settings,
        })),
        ..Options::default()
    };
    let res = attribute(&calibrated, &start, &series, &blocks, &opts)?;
    let extended_path = file("extended.toml");
    std::fs::write(
        &extended_path,
        crate::residuals::extended_file(&res, &pcr_offline::clock::utc_now()),
    )
    .with_context(|| format!("cannot write {}", extended_path.display()))?;
    std::fs::write(file("residuals.json"), serde_json::to_string_pretty(&res)?)
        .context("cannot write residuals.json")?;
    let inputs = data
        .iter()
        .map(|p| format!("`{}`", p.display()))
        .collect::<Vec<_>>()
        .join(", ");
    pcr_residuals::report::write_report(&file("residuals"), &res, &inputs)?;
    for e in &res.effects {
        println!(
            "added {} (held-out gain {:.3} mm): {}",
            e.name,
            e.evidence.effect_mm,
            e.params
                .iter()
                .map(|p| format!("{} = {:.4} {}", p.name, p.value, p.unit))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    println!(
        "verdict {:?}: held-out RMS {:.3} -> {:.3} mm -> {}",
        res.verdict,
        res.before.position_rms_mm,
        res.after.position_rms_mm,
        extended_path.display()
    );

    // 4. Re-run with the extended model.
    println!("== 4/5 re-running with the extended model");
    let extended = RobotConfig::load(&extended_path)
        .with_context(|| format!("reading back {}", extended_path.display()))?;
    let ext_src = nominal.with_model(extended, extended_path.display().to_string());
    record(
        paths_design(),
        ext_src.clone(),
        a.seed,
        &file("3-paths.csv"),
    )?;
    record(check_design()?, ext_src, a.seed, &file("3-check.csv"))?;

    // 5. Errors on the robot.
    println!("== 5/5 evaluation");
    let stages = [
        ("nominal", a.config.display().to_string(), "1"),
        ("calibrated", calibrated_path.display().to_string(), "2"),
        ("extended", extended_path.display().to_string(), "3"),
    ];
    let mut evals = Vec::new();
    let mut recs = Vec::new();
    let mut errors = Vec::new();
    for (label, robot, n) in &stages {
        let mut pair = Vec::new();
        for what in ["check", "paths"] {
            let p = file(&format!("{n}-{what}.csv"));
            let rec = Recording::read_path(&p)?;
            let e = evaluate(&rec, &p.display().to_string(), label, &start)?;
            pair.push(e.clone());
            evals.push(e);
            recs.push(rec);
        }
        errors.push(stage_errors(label, robot, &pair[0], &pair[1]));
    }
    let refs: Vec<&Recording> = recs.iter().collect();
    pcr_calibration::evaluation_report::write_evaluation_report(
        &file("evaluation"),
        &evals,
        &refs,
        None,
    )?;
    let summary = LoopSummary {
        config: a.config.display().to_string(),
        calibration_function: cal.selected,
        effects: res.effects.iter().map(|e| e.name.clone()).collect(),
        verdict: format!("{:?}", res.verdict).to_lowercase(),
        residuals_before: res.before,
        residuals_after: res.after,
        robot: errors,
        block_s: a.block_s,
        wall_s: wall.elapsed().as_secs_f64(),
    };
    std::fs::write(file("loop.json"), serde_json::to_string_pretty(&summary)?)
        .context("cannot write loop.json")?;
    draw_errors(&file("loop_errors.svg"), &summary.robot)?;
    let md = loop_markdown(&summary, dir);
    std::fs::write(file("loop.md"), &md).context("cannot write loop.md")?;
    println!("{}", table(&summary.robot));
    println!(
        "loop done in {:.1} s: {}",
        summary.wall_s,
        file("loop.md").display()
    );
    Ok(())
}

/// What `loop.json` holds.
#[derive(Debug, Serialize)]
struct LoopSummary {
    config: String,
    calibration_function: usize,
    effects: Vec<String>,
    verdict: String,
    residuals_before: pcr_residuals::context::Errors,
    residuals_after: pcr_residuals::context::Errors,
    robot: Vec<StageErrors>,
    block_s: f64,
    wall_s: f64,
}

fn cell(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.digits$}"))
}

fn path_rms(s: &StageErrors, name: &str) -> Option<f64> {
    s.path_rms_mm.iter().find(|p| p.0 == name).map(|p| p.1)
}

fn path_rms_deg(s: &StageErrors, name: &str) -> Option<f64> {
    s.path_rms_deg.iter().find(|p| p.0 == name).map(|p| p.1)
}

fn table(stages: &[StageErrors]) -> String {
    let mut t = String::from(
        "| model | check poses mean (mm) | check poses max (mm) | check poses RMS (mm) | check poses RMS (deg) | circle RMS (mm) | circle RMS (deg) | square RMS (mm) | square RMS (deg) |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for s in stages {
        let _ = writeln!(
            t,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            s.model,
            cell(s.check_position_mean_mm, 3),
            cell(s.check_position_max_mm, 3),
            cell(s.check_position_rms_mm, 3),
            cell(s.check_orientation_rms_deg, 3),
            cell(path_rms(s, "circle"), 3),
            cell(path_rms_deg(s, "circle"), 3),
            cell(path_rms(s, "square"), 3),
            cell(path_rms_deg(s, "square"), 3),
        );
    }
    t
}

fn loop_markdown(s: &LoopSummary, dir: &Path) -> String {
    let mut md = String::from("# The measuring loop on the simulated plant\n\n");
    let _ = writeln!(
        md,
        "Configuration `{}`, {:.0} s of wall time. Every number below is measured on the robot \
         (the plant) in a re-run, with the pose measured by motion capture at the time the row \
         is stamped; the check poses (boundaries scaled by 0.6 and 0.35 at phi = 0, +-5 deg) \
         were seen by neither the calibration nor the residual analysis.\n",
        s.config, s.wall_s
    );
    md.push_str("## Error on the robot\n\n");
    md.push_str(&table(&s.robot));
    md.push_str("\n![errors on the robot](loop_errors.svg)\n\n");
    md.push_str("## What the loop did\n\n");
    let _ = writeln!(
        md,
        "1. Recorded the calibration set (`1-calibration.csv`), the paths (`1-paths.csv`) and \
         the check set (`1-check.csv`) with the nominal model.\n\
         2. Calibrated (Table I function {} selected; report: `calibration/report.md`) and \
         recorded the paths and the check set with the calibrated model (`2-*.csv`).\n\
         3. Analysed the residuals of the calibrated model on `1-calibration.csv` and \
         `2-paths.csv` (every third block of about {} s held out): effects added: {}; verdict \
         `{}`; held-out position RMS {:.3} -> {:.3} mm (report: `residuals/report.md`, \
         `residuals.json`).\n\
         4. Re-ran the paths and the check set with the extended model (`extended.toml`, \
         `3-*.csv`).\n\
         5. Evaluated every run (`evaluation/report.md`: Table II and the paths).\n",
        s.calibration_function,
        s.block_s,
        if s.effects.is_empty() {
            "none".to_string()
        } else {
            s.effects.join(", ")
        },
        s.verdict,
        s.residuals_before.position_rms_mm,
        s.residuals_after.position_rms_mm,
    );
    let _ = writeln!(md, "Folder: `{}`.", dir.display());
    md
}

fn draw_errors(path: &Path, stages: &[StageErrors]) -> Result<()> {
    let labels: Vec<String> = vec![
        "check poses RMS (mm)".into(),
        "circle RMS (mm)".into(),
        "square RMS (mm)".into(),
    ];
    let colours = [
        RGBColor(150, 150, 150),
        RGBColor(31, 119, 180),
        RGBColor(214, 39, 40),
    ];
    let series: Vec<(&str, RGBColor, Vec<Option<f64>>)> = stages
        .iter()
        .zip(colours)
        .map(|(s, c)| {
            (
                s.model.as_str(),
                c,
                vec![
                    s.check_position_rms_mm,
                    path_rms(s, "circle"),
                    path_rms(s, "square"),
                ],
            )
        })
        .collect();
    bars(
        path,
        "Error on the robot: nominal, calibrated, extended model",
        &labels,
        &series,
        "mm",
    )?;
    Ok(())
}
