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
use anyhow::{bail, Context, Result};
use clap::{Args as ClapArgs, Subcommand};
use pcr_control::CYCLE_S;
use pcr_kinematics::{Pose, Robot};
#[cfg(test)]
use pcr_messages::command_kind;
use pcr_offline::plan_request::{self, PlanRow, PlanSettings, Shape as ReqShape};

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
const DEFAULT_JOINT_AMAX: f64 = plan_request::DEFAULT_JOINT_AMAX;
/// Default motor jerk of joint moves, steps/s^3.
const DEFAULT_JOINT_JMAX: f64 = plan_request::DEFAULT_JOINT_JMAX;

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

fn positive(v: f64, what: &str, unit: &str) -> Result<()> {
    if !(v.is_finite() && v > 0.0) {
        bail!("{what} must be > 0 {unit}, got {v}");
    }
    Ok(())
}

/// The library's request of `a`, its numbers checked under the options' names.
fn request(a: &Args) -> Result<(ReqShape, PlanSettings)> {
    let from = parse_pose(&a.from, "--from")?;
    let shape = match &a.shape {
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
            ReqShape::Circle {
                radius_mm: *radius,
                speed_mm_s: *speed,
                centre_mm: [*cx, *cy],
                phi_deg: *phi_deg,
                start_deg: *start_deg,
                cw: *cw,
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
            if let Some(r) = blend_radius {
                if !(r.is_finite() && *r >= 0.0) {
                    bail!("--blend-radius must be a radius >= 0 mm, got {r}");
                }
            }
            ReqShape::Square {
                side_mm: *side,
                speed_mm_s: *speed,
                centre_mm: [*cx, *cy],
                phi_deg: *phi_deg,
                blend_radius_mm: *blend_radius,
            }
        }
        Shape::Line { to, speed } => {
            let to = parse_pose(to, "--to")?;
            positive(*speed, "--speed", "mm/s")?;
            ReqShape::Line {
                to,
                speed_mm_s: *speed,
            }
        }
        Shape::Paper { speed } => {
            positive(*speed, "--speed", "mm/s")?;
            ReqShape::Paper { speed_mm_s: *speed }
        }
        Shape::Program {
            file,
            joint_amax,
            joint_jmax,
        } => ReqShape::Program {
            file: file.clone(),
            joint_amax: *joint_amax,
            joint_jmax: *joint_jmax,
        },
        Shape::Joint {
            steps,
            from_steps,
            joint_amax,
            joint_jmax,
        } => ReqShape::Joint {
            steps: parse_steps(steps, "--steps")?,
            from_steps: from_steps
                .as_deref()
                .map(|s| parse_steps(s, "--from-steps"))
                .transpose()?,
            joint_amax: *joint_amax,
            joint_jmax: *joint_jmax,
        },
    };
    for (t, what) in [
        (a.pause_at, "--pause-at"),
        (a.resume_at, "--resume-at"),
        (a.stop_at, "--stop-at"),
    ] {
        if let Some(t) = t {
            if !(t.is_finite() && t >= 0.0) {
                bail!("{what} must be a time >= 0 s, got {t}");
            }
        }
    }
    positive(a.amax, "--amax", "mm/s^2")?;
    positive(a.jmax, "--jmax", "mm/s^3")?;
    let settings = PlanSettings {
        from,
        amax: a.amax,
        jmax: a.jmax,
        pause_at: a.pause_at,
        resume_at: a.resume_at,
        stop_at: a.stop_at,
        singularity_margin: a.singularity_margin,
        rate_fraction: a.rate_fraction,
    };
    Ok((shape, settings))
}

/// Runs `pcr plan`.
pub fn run(a: Args) -> Result<()> {
    let (cfg, robot_name) = crate::robot_arg::load(a.robot.as_deref())?;
    let robot = Robot::new(&cfg).with_context(|| format!("robot {robot_name}"))?;
    let (shape, settings) = request(&a)?;
    let plan = plan_request::plan(&robot, &shape, &settings)?;
    let rows = &plan.rows;
    write_csv(a.output.as_deref(), rows)?;
    let max_rate: Vec<f64> = (0..3)
        .map(|i| {
            rows.windows(2)
                .map(|w| (w[1].q[i] - w[0].q[i]).abs() as f64 / (w[1].t_s - w[0].t_s))
                .fold(0.0, f64::max)
        })
        .collect();
    eprintln!(
        "plan: {} moves, {:.2} s, {} setpoints every {:.0} ms; max step rate per motor {:.0} / {:.0} / {:.0} steps/s (limit {:.0})",
        plan.moves,
        rows.last().map_or(0.0, |r| r.t_s),
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
                .map(|r| (r.t_s, r.pose.x, r.pose.y, r.speed_mm_s))
                .collect::<Vec<_>>(),
            &plan.speed_limits,
        )?;
    }
    Ok(())
}

fn write_csv(path: Option<&str>, rows: &[PlanRow]) -> Result<()> {
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
            format!("{:.2}", r.t_s),
            fmt(r.pose.x),
            fmt(r.pose.y),
            fmt(r.pose.phi.to_degrees()),
            fmt(r.speed_mm_s),
        ];
        rec.extend(r.kappa_per_mm.iter().map(|k| fmt(*k)));
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

    fn program_of(args: &[&str]) -> plan_request::PlanProgram {
        let cli = Cli::try_parse_from(std::iter::once("plan").chain(args.iter().copied()))
            .unwrap_or_else(|e| panic!("{e}"));
        let (shape, settings) = request(&cli.a).unwrap();
        plan_request::program(&Robot::nominal(), &shape, &settings).unwrap()
    }

    #[test]
    fn the_papers_shapes_are_the_chains_built_in_programs() {
        assert_eq!(
            program_of(&["circle", "--radius", "50", "--speed", "50"]).moves,
            paper_circle()
        );
        assert_eq!(
            program_of(&["square", "--side", "50", "--speed", "50"]).moves,
            paper_square()
        );
        assert_eq!(program_of(&["paper"]).moves, paper_program());
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
        let (_, settings) = request(&cli.a).unwrap();
        assert_eq!(
            plan_request::requests(&settings).unwrap(),
            [(50, command_kind::PAUSE), (150, command_kind::STOP)]
        );
    }
}
