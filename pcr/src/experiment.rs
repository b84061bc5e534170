//! `pcr experiment`: the paper's experiments on the in-process chain against the simulated
//! plant, and the calibration pose set.
//!
//! - `pcr experiment calibration|repeatability|paths|backlash --config C --out rec.csv
//!   [--robot R] [--plant P] [--seed S] [design options]`: runs the design on
//!   `pcr_control::SimChain` and writes the annotated recording (docs/experiments.md).
//!   `--config` is a supervisor configuration: only its `robot` and the driver process's
//!   `backend` and `plant` are read, paths relative to the working directory (as the supervisor
//!   resolves them). `--robot` replaces the model that drives (e.g. a calibrated robot); the
//!   plant stays built on the configuration's robot. `--plant` replaces the plant.
//! - `pcr experiment design calibration [--robot R] --out poses.csv [--svg fig5.svg]`: the pose
//!   set and its figure.

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use pcr_experiments::{
    calibration_set_svg, run_in_process, BacklashDesign, BacklashOptions, CalibrationOptions,
    CalibrationSet, Design, PathsDesign, StaticDesign, VisitTiming,
};
use pcr_kinematics::Robot;
use pcr_offline::experiment_run;
use pcr_robot::RobotConfig;
use std::path::{Path, PathBuf};

/// Arguments of `pcr experiment`.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: ExperimentCommand,
}

#[derive(clap::Subcommand)]
enum ExperimentCommand {
    /// The calibration set (189 poses, 126 train / 63 test), each approached once from the
    /// origin, settled and measured.
    Calibration {
        #[command(flatten)]
        run: RunArgs,
        #[command(flatten)]
        set: SetArgs,
        #[command(flatten)]
        visit: VisitArgs,
    },
    /// The phi = 0 poses of the calibration set, each approached 20 times in a row.
    Repeatability {
        #[command(flatten)]
        run: RunArgs,
        #[command(flatten)]
        set: SetArgs,
        #[command(flatten)]
        visit: VisitArgs,
        /// Approaches of each pose in a row.
        #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u64).range(1..))]
        reps: u64,
        /// Orientation of the poses, deg (one of --phis-deg).
        #[arg(
            long,
            default_value_t = 0.0,
            allow_hyphen_values = true,
            value_name = "DEG"
        )]
        phi_deg: f64,
    },
    /// The paper's circle (r 50 mm, 50 mm/s) and square (50 mm, rest-to-rest sides).
    Paths {
        #[command(flatten)]
        run: RunArgs,
    },
    /// Forth-and-back moves of 1..N steps on each motor at a fixed frequency.
    Backlash {
        #[command(flatten)]
        run: RunArgs,
        #[command(flatten)]
        backlash: BacklashArgs,
    },
    /// Designs without running them.
    Design {
        #[command(subcommand)]
        what: DesignCommand,
    },
}

#[derive(clap::Subcommand)]
enum DesignCommand {
    /// The calibration pose set as CSV (pose_id, x_mm, y_mm, phi_deg, scale, point, set) and a
    /// Fig. 5-style SVG.
    Calibration {
        /// Robot configuration whose workspace the set is drawn in (default: the nominal
        /// robot, = configs/robot.toml).
        #[arg(long, value_name = "ROBOT.toml")]
        robot: Option<PathBuf>,
        /// The pose set CSV to write.
        #[arg(long, value_name = "POSES.csv")]
        out: PathBuf,
        /// Also draw the set (boundaries, training and test poses) to this SVG.
        #[arg(long, value_name = "FIG.svg")]
        svg: Option<PathBuf>,
        /// Seed of the train/test split.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[command(flatten)]
        set: SetArgs,
    },
}

/// Options of every run.
#[derive(clap::Args)]
struct RunArgs {
    /// Supervisor configuration (e.g. configs/sim.toml): its `robot` and its driver's plant.
    #[arg(long, value_name = "CONFIG.toml")]
    config: PathBuf,
    /// The recording to write.
    #[arg(long, value_name = "REC.csv")]
    out: PathBuf,
    /// The robot model that drives (e.g. a calibrated robot file; default: the config's).
    #[arg(long, value_name = "ROBOT.toml")]
    robot: Option<PathBuf>,
    /// The plant (default: the config's driver's plant).
    #[arg(long, value_name = "PLANT.toml")]
    plant: Option<PathBuf>,
    /// Seed of the train/test split (recorded as `seed`).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Seed of the plant's random effects (default: the plant configuration's `seed`).
    #[arg(long)]
    plant_seed: Option<u64>,
}

/// Options of the calibration set.
#[derive(clap::Args)]
struct SetArgs {
    /// Points per scaled boundary.
    #[arg(long, default_value_t = 21, value_parser = clap::value_parser!(u32).range(1..))]
    points: u32,
    /// Scales of the boundaries about the origin, comma separated.
    #[arg(long, value_delimiter = ',', default_values_t = [0.75, 0.5, 0.2])]
    scales: Vec<f64>,
    /// Orientations, deg, comma separated.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true,
          default_values_t = [0.0, 10.0, -10.0])]
    phis_deg: Vec<f64>,
    /// Test poses per (orientation, scale) group.
    #[arg(long, default_value_t = 7)]
    test_per_group: u32,
    /// Conditioning required at every pose, as a multiple of the singularity threshold.
    #[arg(long, default_value_t = 2.0)]
    singularity_margin: f64,
}

impl SetArgs {
    fn options(&self, seed: u64) -> CalibrationOptions {
        CalibrationOptions {
            phis_deg: self.phis_deg.clone(),
            scales: self.scales.clone(),
            points: self.points as usize,
            test_per_group: self.test_per_group as usize,
            seed,
            singularity_margin: self.singularity_margin,
            ..CalibrationOptions::default()
        }
    }
}

/// Timing of each static visit.
#[derive(clap::Args)]
struct VisitArgs {
    /// Peak speed of the approach and return lines, mm/s.
    #[arg(long, default_value_t = 30.0, value_name = "MM_S")]
    speed: f64,
    /// Dwell at the target before measuring (rows not settled), s.
    #[arg(long, default_value_t = 1.0, value_name = "S")]
    settle: f64,
    /// Measurement dwell (rows marked settled = 1), s.
    #[arg(long, default_value_t = 0.5, value_name = "S")]
    measure: f64,
}

impl VisitArgs {
    fn timing(&self) -> VisitTiming {
        VisitTiming {
            speed_mm_s: self.speed,
            settle_s: self.settle,
            measure_s: self.measure,
        }
    }
}

/// Options of the backlash experiment.
#[derive(clap::Args)]
struct BacklashArgs {
    /// Motors to excite, comma separated (1, 2, 3).
    #[arg(long, value_delimiter = ',', default_values_t = [1u8, 2, 3])]
    motors: Vec<u8>,
    /// Largest step count N (blocks of 1, 2, ..., N steps).
    #[arg(long, default_value_t = 8)]
    max_steps: u32,
    /// Forth-and-back periods per block.
    #[arg(long, default_value_t = 8)]
    periods: u32,
    /// Excitation frequency, Hz.
    #[arg(long, default_value_t = 0.5)]
    freq_hz: f64,
    /// Rest at home after each block, s.
    #[arg(long, default_value_t = 1.0, value_name = "S")]
    rest: f64,
    /// Acceleration of the joint moves, steps/s^2.
    #[arg(long, default_value_t = 1.0e6)]
    joint_acceleration: f64,
    /// Jerk of the joint moves, steps/s^3.
    #[arg(long, default_value_t = 1.0e9)]
    joint_jerk: f64,
}

/// Runs `pcr experiment`.
pub fn run(args: Args) -> Result<()> {
    match args.command {
        ExperimentCommand::Calibration { run, set, visit } => {
            let src = load_sources(&run)?;
            let design = StaticDesign::calibration(
                &src.model_robot()?,
                &set.options(run.seed),
                visit.timing(),
            )
            .context("calibration design")?;
            execute(Design::Static(design), &run, src)
        }
        ExperimentCommand::Repeatability {
            run,
            set,
            visit,
            reps,
            phi_deg,
        } => {
            let src = load_sources(&run)?;
            let design = StaticDesign::repeatability(
                &src.model_robot()?,
                &set.options(run.seed),
                phi_deg,
                reps,
                visit.timing(),
            )
            .context("repeatability design")?;
            execute(Design::Static(design), &run, src)
        }
        ExperimentCommand::Paths { run } => {
            let src = load_sources(&run)?;
            execute(Design::Paths(PathsDesign::default()), &run, src)
        }
        ExperimentCommand::Backlash { run, backlash: b } => {
            let src = load_sources(&run)?;
            let design = BacklashDesign::new(
                &src.model_robot()?,
                &BacklashOptions {
                    motors: b.motors,
                    max_steps: b.max_steps,
                    periods: b.periods,
                    freq_hz: b.freq_hz,
                    rest_s: b.rest,
                    joint_acceleration: b.joint_acceleration,
                    joint_jerk: b.joint_jerk,
                },
            )
            .context("backlash design")?;
            execute(Design::Backlash(design), &run, src)
        }
        ExperimentCommand::Design {
            what:
                DesignCommand::Calibration {
                    robot,
                    out,
                    svg,
                    seed,
                    set,
                },
        } => design_calibration(robot.as_deref(), &out, svg.as_deref(), &set.options(seed)),
    }
}

pub(crate) use pcr_offline::experiment_run::Sources;

fn load_sources(run: &RunArgs) -> Result<Sources> {
    Ok(Sources::from_files(
        &run.config,
        run.robot.as_deref(),
        run.plant.as_deref(),
        run.plant_seed,
    )?)
}

fn execute(design: Design, run: &RunArgs, src: Sources) -> Result<()> {
    record(design, src, run.seed, &run.out).map(|_| ())
}

/// Runs `design` on the in-process chain against the sources' plant and writes the annotated
/// recording to `out` (progress bar on stderr, one summary line on stdout).
pub(crate) fn record(
    design: Design,
    src: Sources,
    seed: u64,
    out: &Path,
) -> Result<pcr_experiments::RunSummary> {
    let kind = design.kind();
    let setup = experiment_run::setup(
        &design,
        src,
        seed,
        concat!("pcr ", env!("CARGO_PKG_VERSION")),
    )?;
    let out_name = out.display().to_string();
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("--out {out_name}: cannot create its folder"))?;
    }
    let file = std::fs::File::create(out)
        .with_context(|| format!("--out {out_name}: cannot create the file"))?;
    let pb = ProgressBar::new(1000);
    pb.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {percent}% ({elapsed} < {eta})")
            .expect("valid template")
            .progress_chars("=> "),
    );
    pb.set_message(format!("{kind}"));
    let wall = std::time::Instant::now();
    let result = run_in_process(&design, &setup, file, &mut |f| {
        pb.set_position((f * 1000.0) as u64)
    });
    pb.finish_and_clear();
    let s = result.with_context(|| format!("{kind} run (recording so far in {out_name})"))?;
    println!(
        "{kind}: {} items, {} commands, {} rows ({:.1} s simulated) in {:.2} s; settled rows {}, \
         rows without a measured pose {} -> {out_name}",
        s.found,
        s.commands,
        s.rows,
        s.duration_s,
        wall.elapsed().as_secs_f64(),
        s.settled_rows,
        s.pose_dropouts
    );
    Ok(s)
}

fn design_calibration(
    robot: Option<&Path>,
    out: &Path,
    svg: Option<&Path>,
    opt: &CalibrationOptions,
) -> Result<()> {
    let (cfg, name) = match robot {
        Some(p) => (
            RobotConfig::load(p).with_context(|| format!("--robot {}", p.display()))?,
            p.display().to_string(),
        ),
        None => (RobotConfig::nominal(), "nominal (built-in)".to_string()),
    };
    let model = Robot::new(&cfg).with_context(|| format!("robot model {name}"))?;
    let set = CalibrationSet::design(&model, opt).context("calibration design")?;
    std::fs::write(out, set.to_csv())
        .with_context(|| format!("--out {}: cannot write", out.display()))?;
    for (b, phi) in set.boundaries.iter().zip(&opt.phis_deg) {
        let c = b.check.expect("traced boundaries are checked");
        let cmin = set
            .at_phi(*phi)
            .map(|p| p.conditioning)
            .fold(f64::INFINITY, f64::min);
        println!(
            "phi {phi:+} deg: boundary {:.1} mm long, {:.0} mm^2 (grid mask {:.0} mm^2, {:.0} mm^2 \
             beyond the boundary); smallest conditioning of its poses {cmin:.3}",
            b.perimeter(),
            c.polygon_area_mm2,
            c.grid_area_mm2,
            c.outside_area_mm2
        );
    }
    let test = set
        .poses
        .iter()
        .filter(|p| p.set == pcr_recording::Split::Test)
        .count();
    println!(
        "{} poses ({} train, {test} test, seed {}) of robot {name} -> {}",
        set.poses.len(),
        set.poses.len() - test,
        opt.seed,
        out.display()
    );
    if let Some(svg) = svg {
        calibration_set_svg(&set, svg)?;
        println!("figure -> {}", svg.display());
    }
    Ok(())
}
