//! `pcr evaluate`: the paper's evaluation (ISO 9283 repeatability and pose accuracy, path
//! accuracy, Table II, gear backlash and the eq. 10 map) from recordings.
//!
//! `pcr evaluate --robot R --data uncalibrated=eval-nominal.csv --data calibrated=eval-cal.csv
//! [--backlash backlash.csv] --report DIR --json out.json`
//!
//! On the simulated plant it can record what it evaluates: `pcr evaluate --config C
//! --calibrated calibrated.toml --report DIR` runs the test poses of the calibration set and the
//! paper's paths with the configuration's robot and with the calibrated one, and the backlash
//! protocol, on the in-process chain (as `pcr experiment` does), then evaluates them: Table II
//! calibrated against uncalibrated.

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
    #[command(flatten)]
    run: RunArgs,
}

/// Recording the evaluation on the simulated plant.
#[derive(clap::Args)]
struct RunArgs {
    /// Record the evaluation experiments on the simulated plant of this supervisor
    /// configuration (its robot is the uncalibrated model) instead of reading recordings.
    #[arg(long, value_name = "CONFIG.toml")]
    config: Option<PathBuf>,
    /// With --config: the calibrated robot to compare with the configuration's.
    #[arg(long, value_name = "ROBOT.toml", requires = "config")]
    calibrated: Option<PathBuf>,
    /// With --config: the plant (default: the configuration's driver's plant).
    #[arg(long, value_name = "PLANT.toml", requires = "config")]
    plant: Option<PathBuf>,
    /// With --config: where the recordings go (default: the report folder, else
    /// out/evaluation).
    #[arg(long, value_name = "DIR", requires = "config")]
    runs: Option<PathBuf>,
    /// With --config: seed of the calibration set's split (the test poses must be those the
    /// calibration did not fit: use the seed, --points and --test-per-group of the calibration
    /// experiment).
    #[arg(long, default_value_t = 1, requires = "config")]
    seed: u64,
    /// With --config: points per scaled boundary of the calibration set.
    #[arg(long, default_value_t = 21, requires = "config")]
    points: u32,
    /// With --config: test poses per (orientation, scale) group of the calibration set.
    #[arg(long, default_value_t = 7, requires = "config")]
    test_per_group: u32,
    /// With --config: skip the backlash protocol.
    #[arg(long, requires = "config")]
    no_backlash: bool,
}

/// Records the evaluation experiments; returns the `--data` entries and the backlash file.
fn record_runs(
    a: &Args,
    config: &std::path::Path,
) -> anyhow::Result<(Vec<String>, Option<PathBuf>)> {
    use crate::experiment::{record, Sources};
    use pcr_experiments::{
        BacklashDesign, BacklashOptions, CalibrationOptions, Design, PathsDesign, StaticDesign,
        VisitTiming,
    };
    let r = &a.run;
    let dir = r
        .runs
        .clone()
        .or_else(|| a.report.clone())
        .unwrap_or_else(|| PathBuf::from("out/evaluation"));
    std::fs::create_dir_all(&dir)
        .with_context(|| format!("cannot create the folder {}", dir.display()))?;
    let nominal = Sources::from_files(config, None, r.plant.as_deref(), None)?;
    let model = nominal.model_robot()?;
    let options = CalibrationOptions {
        points: r.points as usize,
        test_per_group: r.test_per_group as usize,
        seed: r.seed,
        ..CalibrationOptions::default()
    };
    // The test poses of the calibration set: the poses the calibration did not fit.
    let test_poses = || -> anyhow::Result<Design> {
        let mut d = StaticDesign::calibration(&model, &options, VisitTiming::default())
            .context("calibration design")?;
        d.visits.retain(|v| v.set == pcr_recording::Split::Test);
        if d.visits.is_empty() {
            bail!("--test-per-group 0: the calibration set has no test poses to evaluate");
        }
        Ok(Design::Static(d))
    };
    let mut models = vec![("uncalibrated".to_string(), nominal.clone())];
    if let Some(c) = &r.calibrated {
        let cfg = pcr_robot::RobotConfig::load(c)
            .with_context(|| format!("--calibrated {}", c.display()))?;
        models.push((
            "calibrated".to_string(),
            nominal.with_model(cfg, c.display().to_string()),
        ));
    }
    let mut data = Vec::new();
    for (label, src) in &models {
        let poses = dir.join(format!("{label}-poses.csv"));
        record(test_poses()?, src.clone(), r.seed, &poses)?;
        data.push(format!("{label}={}", poses.display()));
        let paths = dir.join(format!("{label}-paths.csv"));
        record(
            Design::Paths(PathsDesign::default()),
            src.clone(),
            r.seed,
            &paths,
        )?;
        data.push(format!("{label}={}", paths.display()));
    }
    let backlash = if r.no_backlash {
        None
    } else {
        let p = dir.join("backlash.csv");
        let design =
            BacklashDesign::new(&model, &BacklashOptions::default()).context("backlash design")?;
        record(Design::Backlash(design), nominal, r.seed, &p)?;
        Some(p)
    };
    Ok((data, backlash))
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
    if !(a.false_alarm > 0.0 && a.false_alarm < 0.5) {
        bail!("--false-alarm {}: must be in (0, 0.5)", a.false_alarm);
    }
    let (data, mut backlash_file) = match &a.run.config {
        Some(c) => {
            if !a.data.is_empty() || a.backlash.is_some() {
                bail!("--config records the recordings it evaluates: give it or --data, not both");
            }
            record_runs(&a, c)?
        }
        None => (a.data.clone(), a.backlash.clone()),
    };
    if data.is_empty() && backlash_file.is_none() {
        bail!(
            "nothing to evaluate: give --data REC.csv (and/or --backlash REC.csv), or --config C \
             to record on the simulated plant"
        );
    }
    // The model whose predictions are checked: --robot, else (recording on the plant) the
    // calibrated robot, else the nominal one.
    let robot = match (&a.robot, &a.run.calibrated) {
        (None, Some(c)) => load_robot(Some(c))?,
        _ => load_robot(a.robot.as_deref())?,
    };
    let mut evals: Vec<Evaluation> = Vec::new();
    let mut recs: Vec<Recording> = Vec::new();
    for d in &data {
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
