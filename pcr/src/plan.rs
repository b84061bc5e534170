//! `pcr plan`: a task-space path into a checked 20 ms setpoint sequence.
//!
//! The motion is built from planner paths (an approach line from the start pose, then the shape),
//! checked finely (every 2 ms along each motion: IK in the working mode, joint and bending
//! limits, singularity margin, drive step-rate limits), and interpolated by the same 20 ms
//! [`Interpolator`] the running system uses. The output CSV has one row per cycle: time, planned
//! pose (xp_mm, yp_mm, phip_deg, which `pcr plant run` copies into its recording), speed along the
//! path, curvatures and motor steps (q1..q3, the setpoints).

use crate::csvio::fmt;
use anyhow::{bail, Context, Result};
use clap::{Args as ClapArgs, Subcommand, ValueEnum};
use pcr_kinematics::{CheckOptions, Pose as KPose, Robot};
use pcr_planner::interpolator::{Interpolator, MotionCommand, Phase, CYCLE_S};
use pcr_planner::path::{Path, Pose};
use pcr_planner::speed::{SpeedLimits, SpeedProfile};
use pcr_robot::RobotConfig;

/// Arguments of `pcr plan`.
#[derive(ClapArgs)]
pub struct Args {
    #[command(subcommand)]
    shape: Shape,
    /// Robot configuration (TOML).
    #[arg(long, default_value = "configs/robot.toml", global = true)]
    robot: String,
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
    /// Path jerk limit, mm/s^3 (jerk-limited profiles).
    #[arg(long, default_value_t = 2000.0, global = true)]
    jmax: f64,
    /// Speed profile along each motion (default: jerk-limited for circles and lines,
    /// trapezoidal for the square's rest-to-rest sides, as in the paper).
    #[arg(long, global = true)]
    profile: Option<ProfileKind>,
    /// Required conditioning, as a multiple of the robot's singularity threshold.
    #[arg(long, default_value_t = 1.0, global = true)]
    singularity_margin: f64,
    /// Fraction of each drive's step-rate limit the motion may use.
    #[arg(long, default_value_t = 1.0, global = true)]
    rate_fraction: f64,
}

#[derive(Clone, Copy, PartialEq, ValueEnum)]
enum ProfileKind {
    /// Constant speed with jerk-limited start and stop.
    Jerk,
    /// Trapezoidal speed (acceleration-limited).
    Trapezoidal,
}

#[derive(Subcommand)]
enum Shape {
    /// A full circle at constant orientation (the paper: radius 50 mm at 50 mm/s).
    Circle {
        /// Radius, mm.
        #[arg(long)]
        radius: f64,
        /// Speed along the path, mm/s.
        #[arg(long)]
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
        /// Polar angle of the start point on the circle, degrees.
        #[arg(long = "start-deg", default_value_t = 0.0, allow_hyphen_values = true)]
        start_deg: f64,
        /// Clockwise instead of counter-clockwise.
        #[arg(long)]
        cw: bool,
    },
    /// A square of rest-to-rest sides (the paper: 50 mm side).
    Square {
        /// Side length, mm.
        #[arg(long)]
        side: f64,
        /// Speed along each side, mm/s.
        #[arg(long)]
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
    /// The paper's test program: the 50 mm circle at 50 mm/s, then the 50 mm square.
    Paper {
        /// Speed along the paths, mm/s.
        #[arg(long, default_value_t = 50.0)]
        speed: f64,
    },
}

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

/// One motion of the plan, with a name for messages.
struct Motion {
    name: String,
    cmd: MotionCommand,
}

fn limits(kind: ProfileKind, speed: f64, a: &Args) -> SpeedLimits {
    match kind {
        ProfileKind::Jerk => SpeedLimits::JerkLimited {
            vmax: speed,
            amax: a.amax,
            jmax: a.jmax,
        },
        ProfileKind::Trapezoidal => SpeedLimits::Trapezoidal {
            vmax: speed,
            amax: a.amax,
        },
    }
}

fn circle_path(cx: f64, cy: f64, r: f64, start_deg: f64, ccw: bool, phi: f64) -> Result<Path> {
    Ok(Path::circle(cx, cy, r, start_deg.to_radians(), ccw, phi)?)
}

fn square_sides(cx: f64, cy: f64, side: f64, phi: f64) -> Result<Vec<Path>> {
    if !(side.is_finite() && side > 0.0) {
        bail!("--side must be a length > 0 mm, got {side}");
    }
    let h = side / 2.0;
    let c = [
        Pose::new(cx - h, cy - h, phi),
        Pose::new(cx + h, cy - h, phi),
        Pose::new(cx + h, cy + h, phi),
        Pose::new(cx - h, cy + h, phi),
    ];
    (0..4)
        .map(|k| Ok(Path::line(c[k], c[(k + 1) % 4])?))
        .collect()
}

/// Builds the motions: approach from `from` to each shape's start, then the shape.
fn motions(a: &Args, from: Pose) -> Result<Vec<Motion>> {
    let mut out: Vec<Motion> = Vec::new();
    let mut at = from;
    let push = |name: String,
                path: Path,
                lim: SpeedLimits,
                out: &mut Vec<Motion>,
                at: &mut Pose|
     -> Result<()> {
        let start = path.start();
        if start.max_diff(at) > 1e-9 {
            let approach = Path::line(*at, start)?;
            let lim_a = match lim {
                SpeedLimits::JerkLimited { .. } => lim,
                SpeedLimits::Trapezoidal { vmax, amax } => SpeedLimits::JerkLimited {
                    vmax,
                    amax,
                    jmax: a.jmax,
                },
            };
            out.push(Motion {
                name: format!("approach to {name}"),
                cmd: MotionCommand {
                    path: approach,
                    limits: lim_a,
                },
            });
        }
        *at = path.end();
        out.push(Motion {
            name,
            cmd: MotionCommand { path, limits: lim },
        });
        Ok(())
    };
    let prof = |default: ProfileKind| a.profile.unwrap_or(default);
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
            let p = circle_path(*cx, *cy, *radius, *start_deg, !cw, phi_deg.to_radians())?;
            push(
                "circle".into(),
                p,
                limits(prof(ProfileKind::Jerk), *speed, a),
                &mut out,
                &mut at,
            )?;
        }
        Shape::Square {
            side,
            speed,
            cx,
            cy,
            phi_deg,
        } => {
            for (k, p) in square_sides(*cx, *cy, *side, phi_deg.to_radians())?
                .into_iter()
                .enumerate()
            {
                push(
                    format!("square side {}", k + 1),
                    p,
                    limits(prof(ProfileKind::Trapezoidal), *speed, a),
                    &mut out,
                    &mut at,
                )?;
            }
        }
        Shape::Line { to, speed } => {
            let to = parse_pose(to, "--to")?;
            let p = Path::line(at, to)?;
            push(
                "line".into(),
                p,
                limits(prof(ProfileKind::Jerk), *speed, a),
                &mut out,
                &mut at,
            )?;
        }
        Shape::Paper { speed } => {
            let p = circle_path(0.0, 0.0, 50.0, 0.0, true, 0.0)?;
            push(
                "circle".into(),
                p,
                limits(prof(ProfileKind::Jerk), *speed, a),
                &mut out,
                &mut at,
            )?;
            for (k, p) in square_sides(0.0, 0.0, 50.0, 0.0)?.into_iter().enumerate() {
                push(
                    format!("square side {}", k + 1),
                    p,
                    limits(prof(ProfileKind::Trapezoidal), *speed, a),
                    &mut out,
                    &mut at,
                )?;
            }
        }
    }
    // Back to the start pose.
    if at.max_diff(&from) > 1e-9 {
        let p = Path::line(at, from)?;
        let lim = limits(
            ProfileKind::Jerk,
            out.last().map_or(50.0, |m| speed_of(&m.cmd.limits)),
            a,
        );
        out.push(Motion {
            name: "return".into(),
            cmd: MotionCommand {
                path: p,
                limits: lim,
            },
        });
    }
    Ok(out)
}

fn speed_of(l: &SpeedLimits) -> f64 {
    match l {
        SpeedLimits::JerkLimited { vmax, .. } | SpeedLimits::Trapezoidal { vmax, .. } => *vmax,
    }
}

fn kpose(p: &Pose) -> KPose {
    KPose::new(p.x, p.y, p.phi)
}

/// Samples every motion every `dt` s and checks it; the first violation names the motion.
fn check(robot: &Robot, motions: &[Motion], dt: f64, opt: &CheckOptions) -> Result<()> {
    let mut t0 = 0.0;
    for m in motions {
        let profile = SpeedProfile::plan(m.cmd.path.length(), &m.cmd.limits)?;
        let dur = profile.duration();
        let n = (dur / dt).ceil().max(1.0) as usize;
        let samples = (0..=n).map(|k| {
            let t = (k as f64 * dt).min(dur);
            let t = if k == n { dur } else { t };
            (t0 + t, kpose(&m.cmd.path.sample(profile.at(t).p).0))
        });
        // Consecutive equal times (a zero-length motion) carry nothing to check.
        let mut last = f64::NEG_INFINITY;
        let samples: Vec<_> = samples
            .filter(|(t, _)| {
                let keep = *t > last;
                last = last.max(*t);
                keep
            })
            .collect();
        robot
            .check_motion(samples, opt)
            .map_err(|e| anyhow::anyhow!("motion rejected in `{}`: {e}", m.name))?;
        t0 += dur;
    }
    Ok(())
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
    let cfg = RobotConfig::load(&a.robot)?;
    let robot = Robot::new(&cfg).with_context(|| format!("robot {}", a.robot))?;
    let from = parse_pose(&a.from, "--from")?;
    let motions = motions(&a, from)?;
    let opt = CheckOptions {
        singularity_margin: a.singularity_margin,
        rate_fraction: a.rate_fraction,
    };
    check(&robot, &motions, 0.002, &opt)?;
    let mut interp = Interpolator::new(from, a.amax, a.jmax)?;
    for m in &motions {
        interp
            .push(m.cmd)
            .with_context(|| format!("cannot queue `{}`", m.name))?;
    }
    let mut rows = Vec::new();
    let mut pose = from;
    let mut t = 0.0;
    let mut speed = 0.0;
    loop {
        let s = robot.ik(&kpose(&pose)).with_context(|| {
            format!("t = {t:.2} s: the interpolated pose {pose:?} has no IK solution")
        })?;
        let mut q = [0i64; 3];
        for i in 0..3 {
            q[i] = robot.kappa_to_steps(i, s.kappa[i])?.round() as i64;
        }
        rows.push(Row {
            t,
            pose,
            speed,
            kappa: s.kappa,
            q,
        });
        if interp.is_idle() && rows.len() > 1 {
            break;
        }
        let sp = interp.step();
        t = sp.t;
        pose = sp.pose;
        speed = sp.speed;
        if sp.phase == Phase::Idle && interp.is_idle() {
            let s = robot.ik(&kpose(&pose))?;
            let mut q = [0i64; 3];
            for i in 0..3 {
                q[i] = robot.kappa_to_steps(i, s.kappa[i])?.round() as i64;
            }
            rows.push(Row {
                t,
                pose,
                speed,
                kappa: s.kappa,
                q,
            });
            break;
        }
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
        "plan: {} motions, {:.2} s, {} setpoints every {:.0} ms; max step rate per motor {:.0} / {:.0} / {:.0} steps/s (limit {:.0})",
        motions.len(),
        rows.last().map_or(0.0, |r| r.t),
        rows.len(),
        CYCLE_S * 1e3,
        max_rate[0],
        max_rate[1],
        max_rate[2],
        robot.legs[0].max_step_rate
    );
    if let Some(svg) = &a.svg {
        crate::figures_plan::plan_svg(
            svg,
            &robot,
            &rows
                .iter()
                .map(|r| (r.t, r.pose.x, r.pose.y, r.speed))
                .collect::<Vec<_>>(),
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
