//! `pcr calibrate`: the paper's two-step calibration from a recording, refined jointly by
//! default (`--method paper` stops after the two steps), and `pcr calibrate leg` for one
//! continuum segment on its own.
//!
//! - `pcr calibrate --robot R --data rec.csv --out calibrated.toml --report DIR --json out.json`
//! - `pcr calibrate leg --data leg.csv --l-c-mm L [--l-ce-mm E] --json out.json`

use anyhow::{bail, Context};
use pcr_calibration::calibrate::{self, Calibration, Method, Options, ParameterSet, Readings};
use pcr_calibration::report::{opt, write_report};
use pcr_calibration::segment::{self, SegmentOptions};
use pcr_calibration::StaticData;
use pcr_offline::clock::utc_now;
use pcr_recording::Recording;
use pcr_robot::{MapReading, RobotConfig, TendonMapKind};
use std::path::{Path, PathBuf};

/// Arguments of `pcr calibrate`.
#[derive(clap::Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct Args {
    #[command(subcommand)]
    command: Option<CalibrateCommand>,
    #[command(flatten)]
    robot: RobotArgs,
}

#[derive(clap::Subcommand)]
enum CalibrateCommand {
    /// Fit all 13 Table I functions, in both readings, to one continuum segment's measured tip
    /// positions.
    Leg(LegArgs),
}

/// Which readings of the Table I forms are fitted.
#[derive(Clone, Copy, clap::ValueEnum)]
enum ReadingArg {
    /// Both; each leg takes the one with its lower held-out error of M_i.
    PerLeg,
    /// The odd extension only: one set of coefficients for both bending directions (the
    /// paper's forms, as before the asymmetric reading existed).
    Symmetric,
    /// Coefficients per bending direction only (the paper's form for dl >= 0, its own
    /// coefficients for dl < 0).
    Asymmetric,
}

impl From<ReadingArg> for Readings {
    fn from(r: ReadingArg) -> Readings {
        match r {
            ReadingArg::PerLeg => Readings::PerLeg,
            ReadingArg::Symmetric => Readings::Symmetric,
            ReadingArg::Asymmetric => Readings::Asymmetric,
        }
    }
}

/// Which parameters the two steps free.
#[derive(Clone, Copy, clap::ValueEnum)]
enum Params {
    /// Step 1 [l_C, psi, k], step 2 [r_p, theta_p] (the paper).
    Paper,
    /// Also the base points B_i (step 1) and the link lengths l_st (step 2).
    Extended,
}

/// How the parameters are fitted.
#[derive(Clone, Copy, clap::ValueEnum)]
enum MethodArg {
    /// The paper's two steps, then every parameter of both refined jointly on the M_i and the
    /// platform poses.
    Joint,
    /// The paper's two steps alone (for comparison with the paper).
    Paper,
}

#[derive(clap::Args)]
struct RobotArgs {
    /// Robot configuration the recording was made with (the start of the fit); default: the
    /// built-in nominal robot (= configs/robot.toml).
    #[arg(long, value_name = "ROBOT.toml")]
    robot: Option<PathBuf>,
    /// Recording with static poses (settled rows; shared/spec/recording.md).
    #[arg(long, value_name = "REC.csv", required = true)]
    data: Option<PathBuf>,
    /// Calibrated robot configuration to write (same shape as configs/robot.toml).
    #[arg(long, value_name = "CALIBRATED.toml")]
    out: Option<PathBuf>,
    /// Folder for the Markdown report and its figures.
    #[arg(long, value_name = "DIR")]
    report: Option<PathBuf>,
    /// Everything (Table I, parameters with uncertainties, accuracy before and after) as JSON.
    #[arg(long, value_name = "OUT.json")]
    json: Option<PathBuf>,
    /// Parameter set.
    #[arg(long, value_enum, default_value = "paper")]
    params: Params,
    /// Fitting method: the paper's two steps refined jointly (default), or the two steps alone.
    #[arg(long, value_enum, default_value = "joint")]
    method: MethodArg,
    /// Use this Table I function (1..13) instead of selecting by test RMS.
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=13))]
    function: Option<u8>,
    /// Readings of the tendon-map forms: both, each leg taking the better on held-out poses
    /// (default), or only one.
    #[arg(long, value_enum, default_value = "per-leg")]
    reading: ReadingArg,
    /// Weight of one degree of orientation error in step 2, mm (default: r_p pi / 180).
    #[arg(long, value_name = "MM_PER_DEG")]
    phi_weight: Option<f64>,
    /// Seed of the random train/test split (recordings without a `set` column).
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

#[derive(clap::Args)]
struct LegArgs {
    /// CSV with `dl_mm` (or `q1` with --robot), `mx_mm`, `my_mm` in the segment frame and
    /// optionally `set` (train/test).
    #[arg(long, value_name = "LEG.csv")]
    data: PathBuf,
    /// Segment length l_C, mm.
    #[arg(long)]
    l_c_mm: f64,
    /// Rigid extension from the segment tip to the measured point, mm.
    #[arg(long, default_value_t = 0.0)]
    l_ce_mm: f64,
    /// Robot configuration whose actuation converts `q1` (motor steps) to tendon displacement.
    #[arg(long, value_name = "ROBOT.toml")]
    robot: Option<PathBuf>,
    /// Which leg's actuation of --robot (1..3).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=3))]
    leg: u8,
    /// Also fit the base orientation psi (a measurement frame off by a few degrees).
    #[arg(long)]
    fit_psi: bool,
    /// Also fit the segment length.
    #[arg(long)]
    fit_l_c: bool,
    /// Seed of the random 2/3 : 1/3 split by row (files without a `set` column).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Readings of the forms fitted: both (default) or one.
    #[arg(long, value_enum, default_value = "per-leg")]
    reading: ReadingArg,
    /// Result as JSON.
    #[arg(long, value_name = "OUT.json")]
    json: Option<PathBuf>,
}

/// Runs `pcr calibrate`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        Some(CalibrateCommand::Leg(a)) => run_leg(a),
        None => run_robot(args.robot),
    }
}

/// The robot configuration of `--robot`, or the built-in nominal robot (said on stderr).
pub fn load_robot(path: Option<&Path>) -> anyhow::Result<RobotConfig> {
    match path {
        Some(p) => RobotConfig::load(p).map_err(anyhow::Error::from),
        None => {
            eprintln!("robot: the built-in nominal robot (geometry.md; --robot to choose one)");
            Ok(RobotConfig::nominal())
        }
    }
}

fn write_file(path: &Path, text: &str) -> anyhow::Result<()> {
    if let Some(d) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).with_context(|| format!("cannot create {}", d.display()))?;
    }
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

fn run_robot(a: RobotArgs) -> anyhow::Result<()> {
    let data = a.data.context("--data is required")?;
    let start = load_robot(a.robot.as_deref())?;
    let origin = data.display().to_string();
    let rec = Recording::read_path(&data)?;
    let opts = Options {
        parameters: match a.params {
            Params::Paper => ParameterSet::Paper,
            Params::Extended => ParameterSet::Extended,
        },
        method: match a.method {
            MethodArg::Joint => Method::Joint,
            MethodArg::Paper => Method::Paper,
        },
        function: a
            .function
            .and_then(|f| TendonMapKind::from_table_index(f as usize)),
        reading: a.reading.into(),
        phi_weight_mm_per_deg: a.phi_weight,
        seed: a.seed,
        ..Options::default()
    };
    if let Some(w) = a.phi_weight {
        if !(w.is_finite() && w >= 0.0) {
            bail!("--phi-weight {w}: must be a number of mm per degree >= 0");
        }
    }
    let static_data = StaticData::from_recording(&rec, &origin, opts.seed, opts.test_fraction)?;
    let cal = calibrate::calibrate_data(&start, &static_data, &opts)?;
    print_summary(&cal, a.report.as_deref());
    if let Some(out) = &a.out {
        write_file(out, &calibrate::robot_file(&cal, &utc_now()))?;
        println!("calibrated robot: {}", out.display());
    }
    if let Some(j) = &a.json {
        write_file(j, &serde_json::to_string_pretty(&cal)?)?;
        println!("json: {}", j.display());
    }
    if let Some(dir) = &a.report {
        let p = write_report(dir, &cal, &static_data, &start)?;
        println!("report: {}", p.display());
    }
    Ok(())
}

fn print_summary(cal: &Calibration, report: Option<&Path>) {
    println!(
        "{}: {} static poses ({} train, {} test)",
        cal.data.file, cal.data.poses, cal.data.train, cal.data.test
    );
    println!(
        " #  function      RMS of M_i (mm): symmetric train / test, asymmetric train / test, readings (legs 1 2 3)"
    );
    for r in &cal.table1 {
        let of = |reading: MapReading| {
            r.reading(reading).map_or(" ".repeat(19), |f| {
                format!("{:>9} {:>9}", opt(f.train_rms_mm, 3), opt(f.test_rms_mm, 3))
            })
        };
        let chosen: String = r
            .chosen
            .iter()
            .map(|c| match c {
                MapReading::Symmetric => " s",
                MapReading::Asymmetric => " a",
            })
            .collect();
        println!(
            "{:2}{} {:12} {}  {}  {}{}",
            r.index,
            if r.index == cal.selected { '*' } else { ' ' },
            r.name,
            of(MapReading::Symmetric),
            of(MapReading::Asymmetric),
            if r.error.is_none() {
                chosen
            } else {
                " -".into()
            },
            match &r.error {
                Some(e) => format!("  not selectable: {e}"),
                None => String::new(),
            }
        );
    }
    println!(
        "selected: function {} ({}; {})",
        cal.selected,
        cal.selected_by,
        cal.table1[cal.selected - 1].chosen_text()
    );
    let line = |label: &str,
                b: Option<&calibrate::ModelAccuracy>,
                a: Option<&calibrate::ModelAccuracy>| {
        if let (Some(b), Some(a)) = (b, a) {
            println!(
                "{label}: platform position RMS {:.3} -> {:.3} mm, orientation RMS {:.3} -> {:.3} deg, M_i RMS {:.3} -> {:.3} mm",
                b.pose.position_rms_mm,
                a.pose.position_rms_mm,
                b.pose.orientation_rms_deg,
                a.pose.orientation_rms_deg,
                b.m_rms_mm,
                a.m_rms_mm
            );
        }
    };
    if let Some(j) = &cal.joint {
        let pos = |a: Option<&calibrate::ModelAccuracy>| opt(a.map(|a| a.pose.position_rms_mm), 3);
        println!(
            "paper's two steps: platform position RMS train {} mm, test {} mm; joint refinement: train {} mm, test {} mm ({} parameters, {})",
            pos(Some(&cal.paper.train)),
            pos(cal.paper.test.as_ref()),
            pos(Some(&j.accuracy.train)),
            pos(j.accuracy.test.as_ref()),
            j.fit.params.len(),
            j.fit.status
        );
    }
    println!(
        "calibrated robot: {}",
        match cal.used {
            Method::Joint => "the joint refinement",
            Method::Paper => "the paper's two steps",
        }
    );
    line("train", Some(&cal.before.train), Some(&cal.after.train));
    line("test ", cal.before.test.as_ref(), cal.after.test.as_ref());
    if let Some(d) = &cal.diagnosis {
        println!("why: {}", d.line);
    }
    for w in pcr_calibration::report::other_warnings(cal) {
        eprintln!("warning: {w}");
    }
    // The correlated pairs in one line; their coefficients are in the report.
    if let Some(line) = pcr_calibration::report::correlated_summary(cal) {
        let detail = match report {
            Some(dir) => format!("rho in {}", dir.join("report.md").display()),
            None => "rho with --report DIR or --json FILE".into(),
        };
        eprintln!("warning: {line} ({detail})");
    }
}

fn run_leg(a: LegArgs) -> anyhow::Result<()> {
    let actuation = match &a.robot {
        Some(p) => Some(
            RobotConfig::load(p)?.legs[a.leg as usize - 1]
                .actuation
                .clone(),
        ),
        None => None,
    };
    let points = segment::read_points(&a.data, actuation.as_ref())?;
    let opts = SegmentOptions {
        l_c_mm: a.l_c_mm,
        l_ce_mm: a.l_ce_mm,
        fit_psi: a.fit_psi,
        fit_l_c: a.fit_l_c,
        seed: a.seed,
        test_fraction: 1.0 / 3.0,
        reading: a.reading.into(),
    };
    let r = segment::fit_segment(&a.data.display().to_string(), &points, &opts)?;
    println!(
        "{}: {} rows ({} train, {} test; split {}), dl from {:.3} to {:.3} mm",
        r.file, r.points, r.n_train, r.n_test, r.split, r.dl_range_mm[0], r.dl_range_mm[1]
    );
    println!(" #   function      train RMS  test RMS (mm)  form");
    for f in &r.functions {
        println!(
            "{:3}{} {:12} {:>9} {:>9}     {}{}",
            f.label,
            if Some(&f.label) == r.best.as_ref() {
                '*'
            } else {
                ' '
            },
            f.name,
            opt(f.train_rms_mm, 4),
            opt(f.test_rms_mm, 4),
            f.extended_form,
            f.error
                .as_deref()
                .map_or(String::new(), |e| format!("  failed: {e}"))
        );
    }
    match &r.best {
        Some(b) => {
            let f = r.functions.iter().find(|f| f.label == *b);
            println!(
                "best: function {b} ({})",
                f.map_or(String::new(), |f| format!("{}, {}", f.name, f.reading))
            )
        }
        None => bail!("{}: no function could be fitted", r.file),
    }
    if let Some(j) = &a.json {
        write_file(j, &serde_json::to_string_pretty(&r)?)?;
        println!("json: {}", j.display());
    }
    Ok(())
}
