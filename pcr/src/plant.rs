//! `pcr plant`: static poses, time-stepped runs and drawings of the simulated plant.
//!
//! - `pcr plant pose --input steps.csv`: static equilibrium for rows of motor positions
//!   (q1, q2, q3); effects without history only (geometry, tendon map, springs, wrench).
//! - `pcr plant run --input setpoints.csv --output rec.csv`: a time series of 20 ms setpoints
//!   (t_s, q1, q2, q3) through the time-stepped plant, written in the recording format with the
//!   true state in extra columns.
//! - `pcr plant draw --q 176,176,176 --output shape.svg`: the robot's shape for a static state.

use anyhow::{bail, Context};
use pcr_offline::clock::utc_now;
use pcr_offline::plant_run::{self, PASS_THROUGH};
use pcr_plant::{Equilibrium, Plant, PlantConfig, TruthModel};
use pcr_recording::{RecordingWriter, Row};
use pcr_robot::RobotConfig;
use std::path::{Path, PathBuf};

/// Arguments of `pcr plant`.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: PlantCommand,
}

/// Options shared by every `pcr plant` command.
#[derive(clap::Args)]
struct Common {
    /// Plant configuration (effects); default: the built-in prototype-like plant
    /// (= configs/plant.toml).
    #[arg(long, value_name = "PLANT.toml")]
    plant: Option<PathBuf>,
    /// Robot configuration with the nominal geometry (the plant's deviations apply on top);
    /// default: the nominal robot (= configs/robot.toml).
    #[arg(long, value_name = "ROBOT.toml")]
    robot: Option<PathBuf>,
}

#[derive(clap::Subcommand)]
enum PlantCommand {
    /// Static equilibrium for each row (q1, q2, q3 in steps) of a CSV file.
    Pose {
        #[command(flatten)]
        common: Common,
        /// CSV with columns q1, q2, q3 (other columns are copied through).
        #[arg(long)]
        input: PathBuf,
        /// Output CSV (default: standard output).
        #[arg(long)]
        output: Option<PathBuf>,
    },
    /// Run 20 ms setpoints through the time-stepped plant and write a recording.
    Run {
        #[command(flatten)]
        common: Common,
        /// CSV with columns t_s, q1, q2, q3 (one row per control cycle).
        #[arg(long)]
        input: PathBuf,
        /// Recording to write (shared/spec/recording.md).
        #[arg(long)]
        output: PathBuf,
        /// Write x_mm, ..., m3y_mm in the capture frame (as the capture system reports them,
        /// for registration) instead of the robot base frame.
        #[arg(long)]
        capture_frame: bool,
        /// Seed of the random effects (overrides the plant configuration's `seed`).
        #[arg(long)]
        seed: Option<u64>,
        /// Stop at the first setpoint the plant cannot follow (default: the plant holds its
        /// position, the row's `fault` column is 1 and the run goes on).
        #[arg(long)]
        stop_on_fault: bool,
        /// Write a frame sequence of the run (SVG of the robot's true shape) into this folder.
        #[arg(long, value_name = "DIR")]
        frames: Option<PathBuf>,
        /// With --frames: one frame every N control cycles.
        #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..))]
        frame_every: u32,
    },
    /// Draw the robot's shape (segments, extensions, links, platform) as SVG.
    Draw {
        #[command(flatten)]
        common: Common,
        /// Motor positions "q1,q2,q3" in steps (default: home).
        #[arg(long, allow_hyphen_values = true)]
        q: Option<String>,
        /// SVG file to write.
        #[arg(long)]
        output: PathBuf,
        /// Overlay, in grey, the nominal constant-curvature arcs of the same motor positions
        /// (nominal geometry, linear tendon map): the model error the plant holds.
        #[arg(long)]
        cc: bool,
    },
}

/// Runs `pcr plant`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        PlantCommand::Pose {
            common,
            input,
            output,
        } => {
            let (robot, plant) = load(&common)?;
            pose(&robot, &plant, &input, output.as_deref())
        }
        PlantCommand::Run {
            common,
            input,
            output,
            capture_frame,
            seed,
            stop_on_fault,
            frames,
            frame_every,
        } => {
            let (robot, mut plant) = load(&common)?;
            if let Some(seed) = seed {
                plant.seed = seed;
            }
            run_series(
                &robot,
                &plant,
                &common,
                &input,
                &output,
                RunOptions {
                    capture_frame,
                    stop_on_fault,
                    frames: frames.as_deref().map(|d| (d, frame_every as usize)),
                },
            )
        }
        PlantCommand::Draw {
            common,
            q,
            output,
            cc,
        } => {
            let (robot, plant) = load(&common)?;
            draw(&robot, &plant, q, &output, cc)
        }
    }
}

fn load(c: &Common) -> anyhow::Result<(RobotConfig, PlantConfig)> {
    let robot = match &c.robot {
        Some(p) => RobotConfig::load(p)?,
        None => RobotConfig::nominal(),
    };
    let plant = match &c.plant {
        Some(p) => PlantConfig::load(p)?,
        None => PlantConfig::prototype(),
    };
    Ok((robot, plant))
}

/// A CSV input with its header; rows are parsed by column name.
struct Table {
    header: Vec<String>,
    rows: Vec<(u64, Vec<String>)>,
    origin: String,
}

impl Table {
    fn read(path: &Path) -> anyhow::Result<Table> {
        let origin = path.display().to_string();
        let mut r = csv::ReaderBuilder::new()
            .comment(Some(b'#'))
            .trim(csv::Trim::All)
            .from_path(path)
            .with_context(|| format!("cannot open {origin}"))?;
        let header: Vec<String> = r
            .headers()
            .with_context(|| format!("{origin}: no header row"))?
            .iter()
            .map(str::to_string)
            .collect();
        let mut rows = Vec::new();
        for rec in r.records() {
            let rec = rec.with_context(|| format!("{origin}: malformed CSV"))?;
            let line = rec.position().map_or(0, |p| p.line());
            rows.push((line, rec.iter().map(str::to_string).collect()));
        }
        Ok(Table {
            header,
            rows,
            origin,
        })
    }

    fn col(&self, name: &str) -> anyhow::Result<usize> {
        self.header
            .iter()
            .position(|h| h == name)
            .with_context(|| format!("{}: required column `{name}` is missing", self.origin))
    }

    fn num(&self, row: &(u64, Vec<String>), col: usize) -> anyhow::Result<f64> {
        let cell = &row.1[col];
        let v: f64 = cell
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite())
            .with_context(|| {
                format!(
                    "{}: line {}, column `{}`: {cell:?} is not a finite number",
                    self.origin, row.0, self.header[col]
                )
            })?;
        Ok(v)
    }
}

fn fmt(v: f64) -> String {
    // Rounded first so that tiny negative values do not print as "-0.000000".
    format!("{:.6}", (v * 1e6).round() / 1e6 + 0.0)
}

fn pose(
    robot: &RobotConfig,
    plant: &PlantConfig,
    input: &Path,
    output: Option<&Path>,
) -> anyhow::Result<()> {
    let truth = TruthModel::new(robot, plant).context("the plant has no home equilibrium")?;
    let table = Table::read(input)?;
    let cols = [table.col("q1")?, table.col("q2")?, table.col("q3")?];
    let out: Box<dyn std::io::Write> = match output {
        Some(p) => Box::new(
            std::fs::File::create(p).with_context(|| format!("cannot create {}", p.display()))?,
        ),
        None => Box::new(std::io::stdout().lock()),
    };
    let mut w = csv::Writer::from_writer(out);
    let added = [
        "x_mm", "y_mm", "phi_deg", "m1x_mm", "m1y_mm", "m2x_mm", "m2y_mm", "m3x_mm", "m3y_mm",
        "f1_n", "f2_n", "f3_n",
    ];
    let mut header = table.header.clone();
    header.extend(added.iter().map(|s| s.to_string()));
    w.write_record(&header)?;
    for row in &table.rows {
        let q = [
            table.num(row, cols[0])?,
            table.num(row, cols[1])?,
            table.num(row, cols[2])?,
        ];
        let eq = truth.solve_steps(&q).with_context(|| {
            format!(
                "{}: line {}: no static equilibrium for q = {q:?}",
                table.origin, row.0
            )
        })?;
        let mut cells = row.1.clone();
        cells.extend(equilibrium_cells(&eq));
        w.write_record(&cells)?;
        w.flush()?;
    }
    Ok(())
}

fn equilibrium_cells(eq: &Equilibrium) -> Vec<String> {
    let mut c = vec![
        fmt(eq.pose[0]),
        fmt(eq.pose[1]),
        fmt(eq.pose[2].to_degrees()),
    ];
    for m in &eq.m {
        c.push(fmt(m[0]));
        c.push(fmt(m[1]));
    }
    for l in &eq.lambda {
        c.push(fmt(*l));
    }
    c
}

/// Options of `pcr plant run` beyond its files.
struct RunOptions<'a> {
    capture_frame: bool,
    stop_on_fault: bool,
    /// Folder and cycle interval of the frame sequence.
    frames: Option<(&'a Path, usize)>,
}

fn run_series(
    robot: &RobotConfig,
    cfg: &PlantConfig,
    common: &Common,
    input: &Path,
    output: &Path,
    opts: RunOptions<'_>,
) -> anyhow::Result<()> {
    let RunOptions {
        capture_frame,
        stop_on_fault,
        frames,
    } = opts;
    let mut plant = Plant::new(robot, cfg).context("cannot build the plant")?;
    if let Some((dir, _)) = frames {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let table = Table::read(input)?;
    let ct = table.col("t_s")?;
    let cols = [table.col("q1")?, table.col("q2")?, table.col("q3")?];
    let mut setpoints: Vec<Row> = Vec::with_capacity(table.rows.len());
    let mut lines = Vec::with_capacity(table.rows.len());
    for row in &table.rows {
        let t = table.num(row, ct)?;
        let mut q = [0i32; 3];
        for (k, &c) in cols.iter().enumerate() {
            let v = table.num(row, c)?;
            if v.fract() != 0.0 || v.abs() > 1e9 {
                bail!(
                    "{}: line {}, column `q{}`: {v} is not a whole number of steps",
                    table.origin,
                    row.0,
                    k + 1
                );
            }
            q[k] = v as i32;
        }
        // Planned pose and experiment bookkeeping, copied through when the input has them.
        let mut base = Row::new(t, q);
        for (k, name) in PASS_THROUGH.iter().enumerate() {
            let Some(c) = table.header.iter().position(|h| h == name) else {
                continue;
            };
            if row.1[c].is_empty() {
                continue;
            }
            let v = table.num(row, c)?;
            let whole = || -> anyhow::Result<u64> {
                if v.fract() != 0.0 || v < 0.0 || (k == 5 && v > 1.0) {
                    bail!(
                        "{}: line {}, column `{name}`: {v} is not a valid value",
                        table.origin,
                        row.0
                    );
                }
                Ok(v as u64)
            };
            match k {
                0..=2 => base.planned[k] = Some(v),
                3 => base.pose_id = Some(whole()?),
                4 => base.rep = Some(whole()?),
                _ => base.settled = Some(whole()? == 1),
            }
        }
        setpoints.push(base);
        lines.push(row.0);
    }
    let at = |k: usize| format!("{}: line {}", table.origin, lines[k]);
    plant_run::check_setpoints(&setpoints, &at)?;
    let run_opts = plant_run::RunOptions {
        capture_frame,
        stop_on_fault,
    };
    let meta = plant_run::metadata(
        &common
            .robot
            .as_ref()
            .map_or("nominal (built-in)".into(), |p| p.display().to_string()),
        &common
            .plant
            .as_ref()
            .map_or("prototype (built-in)".into(), |p| p.display().to_string()),
        cfg.seed,
        run_opts,
        &input.display().to_string(),
        plant_run::command_delay_s(setpoints.iter().map(|s| s.t_s), cfg.simulation.cycle_s),
        &utc_now(),
    );
    let known = plant_run::known_columns(&|c| table.header.iter().any(|h| h == c));
    let mut w = RecordingWriter::create(output, &meta, &known, &plant_run::RUN_EXTRA)
        .with_context(|| format!("cannot create {}", output.display()))?;
    let faults = plant_run::run_setpoints(
        &mut plant,
        &setpoints,
        run_opts,
        &at,
        &mut |c: plant_run::Cycle<'_>| -> anyhow::Result<()> {
            w.write_row(c.row, c.extra)?;
            if let Some((dir, every)) = frames {
                if c.index.is_multiple_of(every) {
                    let (t, q, eq) = (c.row.t_s, c.row.q, &c.state.eq);
                    let title = format!(
                        "t = {t:.2} s, q = ({}, {}, {}): x = {:.2} mm, y = {:.2} mm, phi = {:.2} deg",
                        q[0],
                        q[1],
                        q[2],
                        eq.pose[0],
                        eq.pose[1],
                        eq.pose[2].to_degrees()
                    );
                    let path = dir.join(format!("frame_{:05}.svg", c.index / every));
                    draw_state(&path, robot, c.plant.truth(), eq, &title, None)?;
                }
            }
            Ok(())
        },
    )?;
    if faults > 0 {
        tracing::warn!(
            "{faults} setpoint(s) of {} could not be followed (column `fault`)",
            table.origin
        );
    }
    Ok(())
}

fn draw(
    robot: &RobotConfig,
    cfg: &PlantConfig,
    q: Option<String>,
    output: &Path,
    cc: bool,
) -> anyhow::Result<()> {
    let truth = TruthModel::new(robot, cfg).context("the plant has no home equilibrium")?;
    let q: [f64; 3] = match q {
        Some(text) => {
            let v: Vec<f64> = text
                .split(',')
                .map(|c| c.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .with_context(|| format!("--q {text:?}: expected three numbers q1,q2,q3"))?;
            if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
                bail!("--q {text:?}: expected three finite numbers q1,q2,q3");
            }
            [v[0], v[1], v[2]]
        }
        None => truth.robot.home_steps.map(f64::from),
    };
    let eq = truth
        .solve_steps(&q)
        .with_context(|| format!("no static equilibrium for q = {q:?}"))?;
    let title = format!(
        "q = ({}, {}, {}) steps: x = {:.2} mm, y = {:.2} mm, phi = {:.2} deg",
        q[0],
        q[1],
        q[2],
        eq.pose[0],
        eq.pose[1],
        eq.pose[2].to_degrees()
    );
    draw_state(output, robot, &truth, &eq, &title, cc.then_some(q))
}

/// Draws one equilibrium of the plant (segments, extensions, links, platform); with `cc_q`, the
/// nominal constant-curvature arcs of those motor positions in grey.
fn draw_state(
    output: &Path,
    robot: &RobotConfig,
    truth: &TruthModel,
    eq: &Equilibrium,
    title: &str,
    cc_q: Option<[f64; 3]>,
) -> anyhow::Result<()> {
    use plotters::prelude::*;
    pcr_figures::init();
    let shapes = pcr_plant::sim::segment_shapes(truth, eq);
    let root = SVGBackend::new(output, (800, 800)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut builder = ChartBuilder::on(&root);
    builder.margin(10);
    builder
        .caption(title, (pcr_figures::FONT_FAMILY, 16))
        .x_label_area_size(30)
        .y_label_area_size(40);
    let mut chart = builder.build_cartesian_2d(-320.0..320.0, -320.0..320.0)?;
    chart
        .configure_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .label_style((pcr_figures::FONT_FAMILY, 12))
        .draw()?;
    for i in 0..3 {
        let c = pcr_figures::LEG_COLOURS[i];
        let base = truth.statics.legs[i].base;
        chart.draw_series(std::iter::once(Circle::new(
            (base[0], base[1]),
            5,
            BLACK.filled(),
        )))?;
        let seg: Vec<(f64, f64)> = shapes[i].iter().map(|p| (p[0], p[1])).collect();
        chart
            .draw_series(LineSeries::new(seg, c.stroke_width(3)))?
            .label(format!("leg {}", i + 1))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
        let tip = eq.tip[i];
        let m = eq.m[i];
        let p = eq.p[i];
        chart.draw_series(LineSeries::new(
            vec![(tip[0], tip[1]), (m[0], m[1])],
            BLACK.stroke_width(2),
        ))?;
        chart.draw_series(LineSeries::new(
            vec![(m[0], m[1]), (p[0], p[1])],
            RGBColor(120, 120, 120).stroke_width(2),
        ))?;
        for j in [m, p] {
            chart.draw_series(std::iter::once(Circle::new(
                (j[0], j[1]),
                4,
                ShapeStyle::from(&BLACK).stroke_width(1),
            )))?;
        }
    }
    if let Some(q) = cc_q {
        // Nominal CC arcs: geometry.md eq. 4 with kappa = dl / (a l_C).
        for (i, leg) in robot.legs.iter().enumerate() {
            let g = pcr_plant::model::LegGeometry::from_leg(leg);
            let phi = q[i] * leg.actuation.mm_per_step() / leg.actuation.tendon_offset_mm;
            let pts: Vec<(f64, f64)> = std::iter::once((g.base[0], g.base[1]))
                .chain((1..=40).map(|k| {
                    let f = k as f64 / 40.0;
                    let part = pcr_plant::model::LegGeometry {
                        l_c: g.l_c * f,
                        l_ce: 0.0,
                        ..g
                    };
                    let (p, _) = part.arc_tip(phi * f);
                    (p[0], p[1])
                }))
                .collect();
            let (m, _) = g.arc_tip(phi);
            let tip = *pts.last().expect("41 points");
            chart.draw_series(LineSeries::new(
                pts,
                RGBColor(150, 150, 150).stroke_width(1),
            ))?;
            chart.draw_series(LineSeries::new(
                vec![tip, (m[0], m[1])],
                RGBColor(150, 150, 150).stroke_width(1),
            ))?;
        }
    }
    let tri: Vec<(f64, f64)> =
        eq.p.iter()
            .chain([&eq.p[0]])
            .map(|p| (p[0], p[1]))
            .collect();
    chart.draw_series(LineSeries::new(tri, BLACK.stroke_width(2)))?;
    chart.draw_series(std::iter::once(Cross::new(
        (eq.pose[0], eq.pose[1]),
        5,
        BLACK,
    )))?;
    {
        chart
            .configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE.mix(0.8))
            .draw()?;
    }
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every effect off: the recording's measured pose at row k is the static model at the
    /// setpoint of row k - 1 (reached within its cycle), and equals the true columns.
    #[test]
    fn ideal_recording_equals_the_static_model() {
        let robot = RobotConfig::nominal();
        let cfg = PlantConfig::ideal();
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("setpoints.csv");
        let mut text = String::from("t_s,q1,q2,q3,pose_id,settled\n");
        for k in 0..40 {
            let q = [176 + k, 176 - k / 2, 176 + k / 3];
            let settled = if k % 10 == 9 { "1" } else { "" };
            text += &format!(
                "{:.2},{},{},{},{},{settled}\n",
                k as f64 * 0.02,
                q[0],
                q[1],
                q[2],
                k / 10
            );
        }
        std::fs::write(&input, text).unwrap();
        let output = dir.path().join("rec.csv");
        let common = Common {
            plant: None,
            robot: None,
        };
        let opts = RunOptions {
            capture_frame: false,
            stop_on_fault: true,
            frames: None,
        };
        run_series(&robot, &cfg, &common, &input, &output, opts).unwrap();
        let rec = pcr_recording::Recording::read_path(&output).unwrap();
        assert_eq!(rec.rows.len(), 40);
        assert_eq!(rec.rows[19].pose_id, Some(1));
        assert_eq!(rec.rows[19].settled, Some(true));
        assert_eq!(rec.rows[18].settled, None);
        let truth = TruthModel::new(&robot, &cfg).unwrap();
        let ix = rec.extra_index("x_true_mm").unwrap();
        for k in 1..rec.rows.len() {
            let q = rec.rows[k - 1].q.map(f64::from);
            let eq = truth.solve_steps(&q).unwrap();
            let p = rec.rows[k].measured_pose().unwrap();
            assert!((p[0] - eq.pose[0]).abs() < 1e-6, "row {k}");
            assert!((p[1] - eq.pose[1]).abs() < 1e-6, "row {k}");
            assert!((p[2] - eq.pose[2].to_degrees()).abs() < 1e-6, "row {k}");
            let xt: f64 = rec.rows[k].extra[ix].as_deref().unwrap().parse().unwrap();
            assert!((xt - p[0]).abs() < 1e-9);
        }
    }

    #[test]
    fn pose_names_the_bad_line() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("steps.csv");
        std::fs::write(&input, "q1,q2,q3\n176,176,176\n176,x,176\n").unwrap();
        let out = dir.path().join("pose.csv");
        let e = pose(
            &RobotConfig::nominal(),
            &PlantConfig::ideal(),
            &input,
            Some(&out),
        )
        .unwrap_err();
        let e = format!("{e:#}");
        assert!(e.contains("line 3") && e.contains("q2"), "{e}");
        let text = std::fs::read_to_string(&out).unwrap();
        assert!(text.starts_with("q1,q2,q3,x_mm"), "{text}");
    }
}
