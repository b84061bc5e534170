//! `pcr plan`: a task-space program into a checked 20 ms setpoint sequence, by the chain's own
//! interpolator.
//!
//! Each shape (`circle`, `square`, `line`, `paper`), a program file (`program`) or a joint move
//! (`joint`) becomes the chain's program: a list of [`Move`]s, the same the supervisor sends and
//! the chain runs (`circle --radius 50 --speed 50` is the chain's built-in CIRCLE, `square
//! --side 50 --speed 50` its SQUARE, `paper` its PAPER). It is planned and checked by the
//! chain's [`PlannerSource`] (every 2 ms: IK in the working mode, joint and bending limits,
//! singularity margin, drive step-rate limits) and stepped every 20 ms by the chain's
//! [`InterpolatorStep`] on a simulated clock ([`pcr_control::offline`]): the rows are the poses
//! the running chain (the `pcr-planner` process, or the in-process runtime) commands for the
//! same program, cycle by cycle. `--pause-at`, `--resume-at` and `--stop-at` request the chain's
//! PAUSE, RESUME and STOP at a time, so that the braking is planned as the chain brakes.
//!
//! The output CSV has one row per cycle: time, planned pose (xp_mm, yp_mm, phip_deg, which `pcr
//! plant run` copies into its recording), speed along the path, curvatures and motor steps
//! (q1..q3, the setpoints).
//!
//! `pcr plan program --file prog.toml` plans a program of lines, arcs, dwells and joint moves
//! ([`program`]): consecutive lines and arcs form one composite motion
//! ([`pcr_planner::composite`]) that keeps its speed through smooth junctions; joint moves
//! ([`pcr_planner::joint`]) are synchronised motor moves whose poses follow by forward
//! kinematics. `pcr plan joint --steps a,b,c` is a single joint move.

use crate::csvio::fmt;
use anyhow::{anyhow, bail, Context, Result};
use clap::{Args as ClapArgs, Subcommand};
use pcr_control::{
    circle_program, moves_of_program, plan_moves, square_program, CommandError, MotionLimits, Move,
    PlanError, PlannedCycle, PlannerSource, CYCLE_S,
};
use pcr_kinematics::{CheckOptions, Pose, Robot};
use pcr_messages::command_kind;
use pcr_planner::program::{self, JointSettings, PathLimits};
use std::f64::consts::TAU;

/// Arguments of `pcr plan`.
#[derive(ClapArgs)]
pub struct Args {
    #[command(subcommand)]
    shape: Shape,
    /// Robot configuration (TOML).
    #[arg(long, global = true)]
    robot: Option<String>,
    /// Output CSV (standard output if omitted).
    #[arg(long, global = true)]
    output: Option<String>,
    /// Write a figure of the plan (path and speed profile) here (SVG).
    #[arg(long, global = true)]
    svg: Option<String>,
    /// Start pose "x_mm,y_mm,phi_deg" (the robot's current pose); an approach line leads from it
    /// to the start of the shape.
    #[arg(
        long,
        default_value = "0,0,0",
        global = true,
        allow_hyphen_values = true
    )]
    from: String,
    /// Path acceleration limit, mm/s^2.
    #[arg(long, default_value_t = 200.0, global = true)]
    amax: f64,
    /// Path jerk limit, mm/s^3.
    #[arg(long, default_value_t = 2000.0, global = true)]
    jmax: f64,
    /// Request a pause at this time, s (the chain's PAUSE: it brakes along the path).
    #[arg(long, global = true)]
    pause_at: Option<f64>,
    /// Request a resume at this time, s (after --pause-at).
    #[arg(long, global = true)]
    resume_at: Option<f64>,
    /// Request a stop at this time, s (the chain's STOP: it brakes along the path and ends).
    #[arg(long, global = true)]
    stop_at: Option<f64>,
    /// Required conditioning, as a multiple of the robot's singularity threshold.
    #[arg(long, default_value_t = 1.0, global = true)]
    singularity_margin: f64,
    /// Fraction of each drive's step-rate limit the motion may use.
    #[arg(long, default_value_t = 1.0, global = true)]
    rate_fraction: f64,
}

#[derive(Subcommand)]
enum Shape {
    /// A full circle at constant orientation, as the chain's circle program (the paper: radius
    /// 50 mm at 50 mm/s, the chain's built-in CIRCLE): a dwell of 0.2 s, a line to the start
    /// point, the circle, a dwell of 0.2 s and a line back to --from.
    Circle {
        /// Radius, mm (the paper's 50 mm unless given).
        #[arg(long, default_value_t = 50.0, allow_hyphen_values = true)]
        radius: f64,
        /// Speed along the path, mm/s (the paper's 50 mm/s unless given).
        #[arg(long, default_value_t = 50.0, allow_hyphen_values = true)]
        speed: f64,
        /// Centre x, mm.
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        cx: f64,
        /// Centre y, mm.
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        cy: f64,
        /// Platform orientation, degrees.
        #[arg(long = "phi-deg", default_value_t = 0.0, allow_hyphen_values = true)]
        phi_deg: f64,
        /// Polar angle of the start point on the circle, degrees (other than 0, or with --cw,
        /// the circle is planned as one full arc of a composite path, with the same limits).
        #[arg(long = "start-deg", default_value_t = 0.0, allow_hyphen_values = true)]
        start_deg: f64,
        /// Clockwise instead of counter-clockwise.
        #[arg(long)]
        cw: bool,
    },
    /// A square of rest-to-rest sides, as the chain's square program (the paper: 50 mm side at
    /// 50 mm/s, the chain's built-in SQUARE): a dwell of 0.2 s, a line to the corner at
    /// (+side/2, -side/2), counter-clockwise sides with a dwell of 0.1 s after each line, and a
    /// line back to --from.
    Square {
        /// Side length, mm (the paper's 50 mm unless given).
        #[arg(long, default_value_t = 50.0, allow_hyphen_values = true)]
        side: f64,
        /// Speed along each side, mm/s (the paper's 50 mm/s unless given).
        #[arg(long, default_value_t = 50.0, allow_hyphen_values = true)]
        speed: f64,
        /// Centre x, mm.
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        cx: f64,
        /// Centre y, mm.
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        cy: f64,
        /// Platform orientation, degrees.
        #[arg(long = "phi-deg", default_value_t = 0.0, allow_hyphen_values = true)]
        phi_deg: f64,
        /// Round every corner by a tangent arc of this radius (mm) and plan the whole square,
        /// with its approach from and return to --from, as one jerk-limited composite motion
        /// that keeps its speed through the corners (instead of rest-to-rest sides). The square
        /// then starts in the middle of its lower side.
        #[arg(long, allow_hyphen_values = true)]
        blend_radius: Option<f64>,
    },
    /// A straight line to a pose.
    Line {
        /// Target pose "x_mm,y_mm,phi_deg".
        #[arg(long, allow_hyphen_values = true)]
        to: String,
        /// Speed along the path, mm/s.
        #[arg(long)]
        speed: f64,
    },
    /// The paper's test program (the chain's built-in PAPER): the 50 mm circle at 50 mm/s, then
    /// the 50 mm square.
    Paper {
        /// Speed along the paths, mm/s.
        #[arg(long, default_value_t = 50.0)]
        speed: f64,
    },
    /// A program file (TOML): lines, arcs, dwells and joint moves, starting at --from; lines and
    /// arcs in a row are one motion that keeps its speed through smooth (tangent) junctions.
    Program {
        /// The program (see configs/programs/slot.toml and docs/planner.md).
        #[arg(long)]
        file: String,
        /// Joint moves: motor acceleration, steps/s^2 (unless the file's [joint_limits] sets it).
        #[arg(long, default_value_t = DEFAULT_JOINT_AMAX)]
        joint_amax: f64,
        /// Joint moves: motor jerk, steps/s^3 (unless the file's [joint_limits] sets it).
        #[arg(long, default_value_t = DEFAULT_JOINT_JMAX)]
        joint_jmax: f64,
    },
    /// A synchronised joint-space move of the three motors to target steps (step rates from the
    /// robot config times --rate-fraction).
    Joint {
        /// Target motor positions "q1,q2,q3" (steps).
        #[arg(long, allow_hyphen_values = true)]
        steps: String,
        /// Start motor positions "q1,q2,q3" (default: the home pose's steps).
        #[arg(long, allow_hyphen_values = true)]
        from_steps: Option<String>,
        /// Motor acceleration, steps/s^2.
        #[arg(long, default_value_t = DEFAULT_JOINT_AMAX)]
        joint_amax: f64,
        /// Motor jerk, steps/s^3.
        #[arg(long, default_value_t = DEFAULT_JOINT_JMAX)]
        joint_jmax: f64,
    },
}

/// Default motor acceleration of joint moves, steps/s^2.
const DEFAULT_JOINT_AMAX: f64 = 2000.0;
/// Default motor jerk of joint moves, steps/s^3.
const DEFAULT_JOINT_JMAX: f64 = 20000.0;

fn parse_pose(s: &str, what: &str) -> Result<Pose> {
    let v: Vec<f64> = s
        .split(',')
        .map(|c| c.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .with_context(|| format!("{what} `{s}`: expected x_mm,y_mm,phi_deg"))?;
    if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
        bail!("{what} `{s}`: expected three finite numbers x_mm,y_mm,phi_deg");
    }
    Ok(Pose::new(v[0], v[1], v[2].to_radians()))
}

/// The chain's program of a `pcr plan` command.
pub struct PlanProgram {
    /// The moves.
    pub moves: Vec<Move>,
    /// A name of each move, for messages.
    pub names: Vec<String>,
    /// The start pose.
    pub start: Pose,
    /// The program file (prefix of messages), if any.
    pub file: Option<String>,
}

impl PlanProgram {
    fn push(&mut self, name: impl Into<String>, m: Move) {
        self.names.push(name.into());
        self.moves.push(m);
    }

    fn extend(&mut self, moves: Vec<Move>, names: &[&str]) {
        debug_assert_eq!(moves.len(), names.len());
        for (m, n) in moves.into_iter().zip(names) {
            self.push(*n, m);
        }
    }
}

/// Largest coordinate difference of two poses (mm, rad).
fn max_diff(a: &Pose, b: &Pose) -> f64 {
    (a.x - b.x)
        .abs()
        .max((a.y - b.y).abs())
        .max((a.phi - b.phi).abs())
}

fn positive(v: f64, what: &str, unit: &str) -> Result<()> {
    if !(v.is_finite() && v > 0.0) {
        bail!("{what} must be > 0 {unit}, got {v}");
    }
    Ok(())
}

const CIRCLE_NAMES: [&str; 4] = ["dwell", "circle", "dwell", "return"];

fn square_names() -> Vec<&'static str> {
    let mut n = vec!["dwell", "approach to square", "dwell"];
    for s in [
        "square side 1",
        "square side 2",
        "square side 3",
        "square side 4",
    ] {
        n.extend([s, "dwell"]);
    }
    n.push("return");
    n
}

/// The chain's program of `a` (not of `program` and `joint`, which need the files and the robot).
fn shape_program(a: &Args, from: Pose) -> Result<PlanProgram> {
    let mut p = PlanProgram {
        moves: Vec::new(),
        names: Vec::new(),
        start: from,
        file: None,
    };
    let path_limits = |speed: f64, blend_radius: f64| PathLimits {
        speed,
        acceleration: a.amax,
        jerk: a.jmax,
        blend_radius,
        rotation_radius: pcr_planner::path::DEFAULT_ROTATION_RADIUS_MM,
    };
    match &a.shape {
        Shape::Circle {
            radius,
            speed,
            cx,
            cy,
            phi_deg,
            start_deg,
            cw,
        } => {
            positive(*radius, "--radius", "mm")?;
            positive(*speed, "--speed", "mm/s")?;
            let phi = phi_deg.to_radians();
            if *start_deg == 0.0 && !cw {
                p.extend(
                    circle_program([*cx, *cy], *radius, *speed, phi, from),
                    &CIRCLE_NAMES,
                );
            } else {
                let th = start_deg.to_radians();
                let p0 = Pose::new(cx + radius * th.cos(), cy + radius * th.sin(), phi);
                p.push("dwell", Move::Dwell { duration_s: 0.2 });
                p.push(
                    "approach to circle",
                    Move::Line {
                        to: p0,
                        speed_mm_s: *speed,
                    },
                );
                p.push(
                    "circle",
                    Move::Arc {
                        centre: [*cx, *cy],
                        sweep_rad: if *cw { -TAU } else { TAU },
                        phi: Some(phi),
                        speed_mm_s: None,
                        continues: false,
                        limits: path_limits(*speed, 0.0),
                    },
                );
                p.push("dwell", Move::Dwell { duration_s: 0.2 });
                p.push(
                    "return",
                    Move::Line {
                        to: from,
                        speed_mm_s: *speed,
                    },
                );
            }
        }
        Shape::Square {
            side,
            speed,
            cx,
            cy,
            phi_deg,
            blend_radius,
        } => {
            positive(*side, "--side", "mm")?;
            positive(*speed, "--speed", "mm/s")?;
            let phi = phi_deg.to_radians();
            match blend_radius {
                None => p.extend(
                    square_program([*cx, *cy], *side, *speed, phi, from),
                    &square_names(),
                ),
                Some(r) => {
                    if !(r.is_finite() && *r >= 0.0) {
                        bail!("--blend-radius must be a radius >= 0 mm, got {r}");
                    }
                    // One composite from --from around the square (starting in the middle of
                    // its lower side) and back.
                    let h = side / 2.0;
                    let start = Pose::new(*cx, cy - h, phi);
                    let mut pts = Vec::new();
                    if max_diff(&start, &from) > 1e-9 {
                        pts.push(("approach to square", start));
                    }
                    for (name, x, y) in [
                        ("square side 1", cx + h, cy - h),
                        ("square side 2", cx + h, cy + h),
                        ("square side 3", cx - h, cy + h),
                        ("square side 4", cx - h, cy - h),
                        ("square side 1", *cx, cy - h),
                    ] {
                        pts.push((name, Pose::new(x, y, phi)));
                    }
                    if max_diff(&start, &from) > 1e-9 {
                        pts.push(("return", from));
                    }
                    for (k, (name, to)) in pts.into_iter().enumerate() {
                        p.push(
                            name,
                            Move::PathLine {
                                to: [to.x, to.y],
                                phi: Some(to.phi),
                                speed_mm_s: None,
                                blend_radius_mm: None,
                                continues: k > 0,
                                limits: path_limits(*speed, *r),
                            },
                        );
                    }
                }
            }
        }
        Shape::Line { to, speed } => {
            let to = parse_pose(to, "--to")?;
            positive(*speed, "--speed", "mm/s")?;
            p.push(
                "line",
                Move::Line {
                    to,
                    speed_mm_s: *speed,
                },
            );
            if max_diff(&to, &from) > 1e-9 {
                p.push(
                    "return",
                    Move::Line {
                        to: from,
                        speed_mm_s: *speed,
                    },
                );
            }
        }
        Shape::Paper { speed } => {
            positive(*speed, "--speed", "mm/s")?;
            p.extend(
                circle_program([0.0, 0.0], 50.0, *speed, 0.0, from),
                &CIRCLE_NAMES,
            );
            p.extend(
                square_program([0.0, 0.0], 50.0, *speed, 0.0, from),
                &square_names(),
            );
        }
        Shape::Program { .. } | Shape::Joint { .. } => {
            bail!("internal: programs and joint moves are built by `build_program`")
        }
    }
    Ok(p)
}

/// The chain's program of `pcr plan` with these arguments.
pub fn build_program(a: &Args, robot: &Robot, from: Pose) -> Result<PlanProgram> {
    match &a.shape {
        Shape::Program {
            file,
            joint_amax,
            joint_jmax,
        } => {
            let prog = program::load(
                file,
                &program::Defaults {
                    acceleration: a.amax,
                    jerk: a.jmax,
                    joint_acceleration: *joint_amax,
                    joint_jerk: *joint_jmax,
                },
            )?;
            let moves = moves_of_program(&prog);
            let names = prog
                .segments
                .iter()
                .enumerate()
                .map(|(i, s)| format!("segment[{i}] ({})", s.kind()))
                .collect();
            Ok(PlanProgram {
                moves,
                names,
                start: from,
                file: Some(file.clone()),
            })
        }
        Shape::Joint {
            steps,
            from_steps,
            joint_amax,
            joint_jmax,
        } => {
            let target = parse_steps(steps, "--steps")?;
            let q0 = match from_steps {
                Some(s) => parse_steps(s, "--from-steps")?,
                None => {
                    let s = robot.ik(&Pose::default())?;
                    let mut q = [0.0; 3];
                    for i in 0..3 {
                        q[i] = robot.kappa_to_steps(i, s.kappa[i])?.round();
                    }
                    q
                }
            };
            let kappa = std::array::from_fn(|i| robot.steps_to_kappa(i, q0[i]));
            let start = robot
                .fk(&kappa)
                .with_context(|| format!("start steps {q0:?}: no pose in the working mode"))?;
            Ok(PlanProgram {
                moves: vec![Move::Joint {
                    steps: target.map(|q| q as i64),
                    limits: JointSettings {
                        acceleration: *joint_amax,
                        jerk: *joint_jmax,
                    },
                }],
                names: vec!["joint move".into()],
                start,
                file: None,
            })
        }
        _ => shape_program(a, from),
    }
}

/// Why the chain refuses the program, naming the move.
fn refusal(e: CommandError, p: &PlanProgram) -> anyhow::Error {
    let name = |i: usize| p.names.get(i).map_or("?", |s| s.as_str()).to_string();
    let file = p.file.as_ref().map_or(String::new(), |f| format!("{f}: "));
    match e {
        CommandError::Plan(PlanError::Rejected { index, why }) => {
            anyhow!("{file}motion rejected in `{}`: {why}", name(index))
        }
        CommandError::Plan(PlanError::Invalid { index, why }) => {
            anyhow!("{file}`{}`: {why}", name(index))
        }
        CommandError::Plan(PlanError::InvalidMove { index, what }) => {
            anyhow!("{file}`{}`: invalid {what}", name(index))
        }
        other => anyhow!("{file}{other}"),
    }
}

/// The pause, resume and stop requests of `a` as (cycle, command kind), in cycle order.
fn requests(a: &Args) -> Result<Vec<(usize, u32)>> {
    let mut r = Vec::new();
    for (t, kind, what) in [
        (a.pause_at, command_kind::PAUSE, "--pause-at"),
        (a.resume_at, command_kind::RESUME, "--resume-at"),
        (a.stop_at, command_kind::STOP, "--stop-at"),
    ] {
        if let Some(t) = t {
            if !(t.is_finite() && t >= 0.0) {
                bail!("{what} must be a time >= 0 s, got {t}");
            }
            r.push(((t / CYCLE_S).round() as usize, kind));
        }
    }
    r.sort_by_key(|&(k, _)| k);
    Ok(r)
}

/// Plans `p` with the chain's planner and interpolator ([`plan_moves`]): every 20 ms cycle from
/// t = 0 to rest, with the requests `commands` (cycle, PAUSE/RESUME/STOP). Also returns the
/// composite speed limit of each cycle (NaN outside composites).
pub fn plan_cycles(
    robot: &Robot,
    limits: MotionLimits,
    check: CheckOptions,
    p: &PlanProgram,
    commands: &[(usize, u32)],
) -> Result<(Vec<PlannedCycle>, Vec<f64>)> {
    let source = PlannerSource::new(robot.clone(), limits).with_check_options(check);
    let plan =
        plan_moves(source, p.start, &p.moves, commands, CYCLE_S).map_err(|e| refusal(e, p))?;
    let lim = plan
        .cycles
        .iter()
        .map(|c| plan.interp.source().speed_limit_at(c.progress_s))
        .collect();
    Ok((plan.cycles, lim))
}

/// One 20 ms row of the plan.
struct Row {
    t: f64,
    pose: Pose,
    speed: f64,
    kappa: [f64; 3],
    q: [i64; 3],
}

/// Runs `pcr plan`.
pub fn run(a: Args) -> Result<()> {
    let (cfg, robot_name) = crate::robot_arg::load(a.robot.as_deref())?;
    let robot = Robot::new(&cfg).with_context(|| format!("robot {robot_name}"))?;
    let from = parse_pose(&a.from, "--from")?;
    let check = CheckOptions {
        singularity_margin: a.singularity_margin,
        rate_fraction: a.rate_fraction,
    };
    let prog = build_program(&a, &robot, from)?;
    let commands = requests(&a)?;
    let limits = MotionLimits {
        amax: a.amax,
        jmax: a.jmax,
    };
    positive(a.amax, "--amax", "mm/s^2")?;
    positive(a.jmax, "--jmax", "mm/s^3")?;
    let (cycles, speed_limits) = plan_cycles(&robot, limits, check, &prog, &commands)?;
    let mut rows = Vec::with_capacity(cycles.len());
    for c in &cycles {
        let pose = c.pose();
        let t = c.task.t_s;
        let s = robot.ik(&pose).with_context(|| {
            format!("t = {t:.2} s: the planned pose {pose:?} has no IK solution")
        })?;
        let mut q = [0i64; 3];
        for i in 0..3 {
            q[i] = robot.kappa_to_steps(i, s.kappa[i])?.round() as i64;
        }
        rows.push(Row {
            t,
            pose,
            speed: c.speed_mm_s,
            kappa: s.kappa,
            q,
        });
    }
    write_csv(a.output.as_deref(), &rows)?;
    let max_rate: Vec<f64> = (0..3)
        .map(|i| {
            rows.windows(2)
                .map(|w| (w[1].q[i] - w[0].q[i]).abs() as f64 / (w[1].t - w[0].t))
                .fold(0.0, f64::max)
        })
        .collect();
    eprintln!(
        "plan: {} moves, {:.2} s, {} setpoints every {:.0} ms; max step rate per motor {:.0} / {:.0} / {:.0} steps/s (limit {:.0})",
        prog.moves.len(),
        rows.last().map_or(0.0, |r| r.t),
        rows.len(),
        CYCLE_S * 1e3,
        max_rate[0],
        max_rate[1],
        max_rate[2],
        robot.legs[0].max_step_rate
    );
    if let Some(svg) = &a.svg {
        crate::figures_plan::plan_svg_with_limit(
            svg,
            &robot,
            &rows
                .iter()
                .map(|r| (r.t, r.pose.x, r.pose.y, r.speed))
                .collect::<Vec<_>>(),
            &speed_limits,
        )?;
    }
    Ok(())
}

fn write_csv(path: Option<&str>, rows: &[Row]) -> Result<()> {
    let mut w = crate::csvio::writer(path)?;
    let mut h = vec!["t_s", "xp_mm", "yp_mm", "phip_deg", "speed_mm_s"];
    h.extend([
        "kappa1_per_mm",
        "kappa2_per_mm",
        "kappa3_per_mm",
        "q1",
        "q2",
        "q3",
    ]);
    w.write_record(&h)?;
    for r in rows {
        let mut rec = vec![
            format!("{:.2}", r.t),
            fmt(r.pose.x),
            fmt(r.pose.y),
            fmt(r.pose.phi.to_degrees()),
            fmt(r.speed),
        ];
        rec.extend(r.kappa.iter().map(|k| fmt(*k)));
        rec.extend(r.q.iter().map(|q| q.to_string()));
        w.write_record(&rec)?;
    }
    w.flush()?;
    Ok(())
}

fn parse_steps(s: &str, what: &str) -> Result<[f64; 3]> {
    let v: Vec<i64> = s
        .split(',')
        .map(|c| c.trim().parse::<i64>())
        .collect::<std::result::Result<_, _>>()
        .with_context(|| format!("{what} `{s}`: expected three integers q1,q2,q3 (motor steps)"))?;
    if v.len() != 3 {
        bail!("{what} `{s}`: expected three integers q1,q2,q3 (motor steps)");
    }
    Ok([v[0] as f64, v[1] as f64, v[2] as f64])
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use pcr_control::{paper_circle, paper_program, paper_square};

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        a: Args,
    }

    fn program_of(args: &[&str]) -> PlanProgram {
        let cli = Cli::try_parse_from(std::iter::once("plan").chain(args.iter().copied()))
            .unwrap_or_else(|e| panic!("{e}"));
        build_program(&cli.a, &Robot::nominal(), Pose::default()).unwrap()
    }

    #[test]
    fn the_papers_shapes_are_the_chains_built_in_programs() {
        let c = program_of(&["circle", "--radius", "50", "--speed", "50"]);
        assert_eq!(c.moves, paper_circle());
        assert_eq!(c.names.len(), c.moves.len());
        let s = program_of(&["square", "--side", "50", "--speed", "50"]);
        assert_eq!(s.moves, paper_square());
        assert_eq!(s.names.len(), s.moves.len());
        let p = program_of(&["paper"]);
        assert_eq!(p.moves, paper_program());
        assert_eq!(p.names.len(), p.moves.len());
    }

    #[test]
    fn stop_requests_are_cycles_of_the_chain() {
        let cli = Cli::try_parse_from([
            "plan",
            "circle",
            "--radius",
            "50",
            "--speed",
            "50",
            "--stop-at",
            "3.001",
            "--pause-at",
            "1",
        ])
        .unwrap();
        assert_eq!(
            requests(&cli.a).unwrap(),
            [(50, command_kind::PAUSE), (150, command_kind::STOP)]
        );
        let p = build_program(&cli.a, &Robot::nominal(), Pose::default()).unwrap();
        let (cycles, lim) = plan_cycles(
            &Robot::nominal(),
            MotionLimits::default(),
            CheckOptions::default(),
            &p,
            &requests(&cli.a).unwrap(),
        )
        .unwrap();
        assert_eq!(cycles.len(), lim.len());
        // paused at rest (the stop while paused ends it at once)
        assert_eq!(cycles[150].state, pcr_messages::planner_state::STOPPED);
        assert_eq!(cycles.len(), 151);
    }
}
