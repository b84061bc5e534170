//! `pcr plan`: a task-space path into a checked 20 ms setpoint sequence.
//!
//! The motion is built from planner paths (an approach line from the start pose, then the shape),
//! checked finely (every 2 ms along each motion: IK in the working mode, joint and bending
//! limits, singularity margin, drive step-rate limits), and interpolated by the same 20 ms
//! [`Interpolator`] the running system uses. The output CSV has one row per cycle: time, planned
//! pose (xp_mm, yp_mm, phip_deg, which `pcr plant run` copies into its recording), speed along the
//! path, curvatures and motor steps (q1..q3, the setpoints).
//!
//! `pcr plan program --file prog.toml` plans a program of lines, arcs, dwells and joint moves
//! ([`program`]): consecutive lines and arcs form one composite motion
//! ([`pcr_planner::composite`]) that keeps its speed through smooth junctions; joint moves
//! ([`pcr_planner::joint`]) are synchronised motor moves whose poses follow by forward
//! kinematics. `pcr plan joint --steps a,b,c` is a single joint move. Both are checked the same
//! way (every 2 ms) and sampled every 20 ms into the same CSV.

use pcr_planner::program;

use crate::csvio::fmt;
use anyhow::{anyhow, bail, Context, Result};
use clap::{Args as ClapArgs, Subcommand, ValueEnum};
use pcr_kinematics::{CheckOptions, Pose as KPose, Robot};
use pcr_planner::composite::{
    CompositeError, CompositeLimits, CompositeMotion, CompositePath, SegmentSource,
};
use pcr_planner::interpolator::{Interpolator, MotionCommand, Phase, CYCLE_S};
use pcr_planner::joint::{JointError, JointLimits, JointMove};
use pcr_planner::path::{Path, Pose};
use pcr_planner::speed::{SpeedLimits, SpeedProfile};
use pcr_robot::RobotConfig;

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
    /// The paper's test program: the 50 mm circle at 50 mm/s, then the 50 mm square.
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
            ..
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
        Shape::Program { .. } | Shape::Joint { .. } => {
            bail!("programs and joint moves are planned by `run_timeline`")
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
    let (cfg, robot_name) = crate::robot_arg::load(a.robot.as_deref())?;
    let robot = Robot::new(&cfg).with_context(|| format!("robot {robot_name}"))?;
    let from = parse_pose(&a.from, "--from")?;
    if matches!(
        a.shape,
        Shape::Program { .. }
            | Shape::Joint { .. }
            | Shape::Square {
                blend_radius: Some(_),
                ..
            }
    ) {
        return run_timeline(&a, &cfg, &robot, from);
    }
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

/// What one item of a program's timeline does.
enum ItemKind {
    /// A composite path motion.
    Path { motion: Box<CompositeMotion> },
    /// Holding a pose.
    Dwell { pose: Pose },
    /// A synchronised joint move.
    Joint { mv: Box<JointMove> },
}

/// One item of a program's timeline.
struct Item {
    t0: f64,
    duration: f64,
    kind: ItemKind,
}

fn to_pose(p: &KPose) -> Pose {
    Pose::new(p.x, p.y, p.phi)
}

/// Motor steps (not rounded) of a pose in the working mode.
fn steps_of_pose(robot: &Robot, pose: &Pose) -> Result<[f64; 3]> {
    let s = robot
        .ik(&kpose(pose))
        .with_context(|| format!("pose {pose:?} has no IK solution"))?;
    let mut q = [0.0; 3];
    for i in 0..3 {
        q[i] = robot.kappa_to_steps(i, s.kappa[i])?;
    }
    Ok(q)
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

/// Builds and checks the timeline of a program.
struct Timeline<'a> {
    robot: &'a Robot,
    opt: CheckOptions,
    file: String,
    items: Vec<Item>,
    t: f64,
    pose: Pose,
    /// Exact motor positions after a joint move (None after a path: from IK).
    steps: Option<[f64; 3]>,
    joint: JointLimits,
}

fn composite_error(e: &CompositeError) -> String {
    match e {
        CompositeError::ZeroLength { .. } => "it ends where it starts (no length)".into(),
        CompositeError::ZeroRadius { .. } => "the centre is at the start point (radius 0)".into(),
        other => other.to_string(),
    }
}

impl Timeline<'_> {
    /// Plans and checks consecutive lines and arcs (`(program index, step)`) as one composite.
    fn path(&mut self, steps: &[(usize, program::Step)], lim: &program::PathLimits) -> Result<()> {
        use program::Step;
        if steps.is_empty() {
            return Ok(());
        }
        let file = &self.file;
        let mut path = CompositePath::with_rotation_radius(self.pose, lim.rotation_radius)?;
        for (idx, st) in steps {
            let at = |e: CompositeError| {
                anyhow!(
                    "{file}: segment[{idx}] ({}): {}",
                    st.kind(),
                    if matches!(e, CompositeError::TooManySegments) {
                        e.to_string()
                    } else {
                        composite_error(&e)
                    }
                )
            };
            match *st {
                Step::Line { to, phi, speed, .. } => {
                    let phi = phi.unwrap_or(path.end().phi);
                    path.line_to(Pose::new(to[0], to[1], phi), speed)
                        .map_err(at)?
                }
                Step::Arc {
                    center,
                    sweep,
                    phi,
                    speed,
                } => {
                    let phi = phi.unwrap_or(path.end().phi);
                    path.arc_around(center[0], center[1], sweep, phi, speed)
                        .map_err(at)?
                }
                _ => bail!("internal: only lines and arcs form a path"),
            }
        }
        // Junction j joins primitives j - 1 and j; a line's own radius rounds the corner at
        // its end.
        let path = path
            .blend_corners(|j| match steps[j - 1].1 {
                Step::Line {
                    blend_radius: Some(r),
                    ..
                } => r,
                _ => lim.blend_radius,
            })
            .map_err(|e| {
                anyhow!(
                    "{file}: segments[{}..={}]: {e}",
                    steps[0].0,
                    steps[steps.len() - 1].0
                )
            })?;
        let names: Vec<String> = path
            .segments()
            .iter()
            .map(|s| match s.source() {
                SegmentSource::Primitive(k) => {
                    format!("segment[{}] ({})", steps[k].0, steps[k].1.kind())
                }
                SegmentSource::Blend(k) => format!("corner blend after segment[{}]", steps[k].0),
            })
            .collect();
        let motion = CompositeMotion::plan(
            &path,
            &CompositeLimits {
                vmax: lim.speed,
                amax: lim.acceleration,
                jmax: lim.jerk,
            },
        )
        .map_err(|e| {
            anyhow!(
                "{file}: segments[{}..={}]: {e}",
                steps[0].0,
                steps[steps.len() - 1].0
            )
        })?;
        // Check every 2 ms (and at the end).
        let dur = motion.duration();
        let dt = 0.002;
        let n = (dur / dt).ceil().max(1.0) as usize;
        let t0 = self.t;
        let samples = (0..=n).map(|k| {
            let t = if k == n { dur } else { k as f64 * dt };
            (t0 + t, kpose(&motion.sample(t).pose))
        });
        let mut last = f64::NEG_INFINITY;
        let samples: Vec<_> = samples
            .filter(|(t, _)| {
                let keep = *t > last;
                last = last.max(*t);
                keep
            })
            .collect();
        if let Err(e) = self.robot.check_motion(samples, &self.opt) {
            let seg = motion.sample(e.t - t0).segment;
            bail!("motion rejected in `{}`: {e}", names[seg]);
        }
        self.pose = path.end();
        self.steps = None;
        self.t += dur;
        self.items.push(Item {
            t0,
            duration: dur,
            kind: ItemKind::Path {
                motion: Box::new(motion),
            },
        });
        Ok(())
    }

    fn dwell(&mut self, seconds: f64) {
        self.items.push(Item {
            t0: self.t,
            duration: seconds,
            kind: ItemKind::Dwell { pose: self.pose },
        });
        self.t += seconds;
    }

    /// Plans and checks a joint move to `target` steps; `name` names it in messages.
    fn joint(&mut self, name: &str, target: [f64; 3]) -> Result<()> {
        let from = match self.steps {
            Some(s) => s,
            None => steps_of_pose(self.robot, &self.pose)?,
        };
        let mv =
            JointMove::plan(from, target, &self.joint).map_err(|e| anyhow!("`{name}`: {e}"))?;
        let t0 = self.t;
        let samples = mv
            .check(self.robot, 0.002, &kpose(&self.pose), &self.opt)
            .map_err(|e| {
                // Times in the program, not in the move.
                let e = match e {
                    JointError::Rejected(mut r) => {
                        r.t += t0;
                        JointError::Rejected(r)
                    }
                    JointError::Fk { t, q, why } => JointError::Fk { t: t + t0, q, why },
                    other => other,
                };
                anyhow!("motion rejected in `{name}`: {e}")
            })?;
        if let Some((_, p)) = samples.last() {
            self.pose = to_pose(p);
        }
        self.steps = Some(target);
        self.t += mv.duration();
        self.items.push(Item {
            t0,
            duration: mv.duration(),
            kind: ItemKind::Joint { mv: Box::new(mv) },
        });
        Ok(())
    }
}

/// Combined-metric distance of two poses, mm.
fn metric(a: &Pose, b: &Pose, r: f64) -> f64 {
    ((a.x - b.x).powi(2) + (a.y - b.y).powi(2) + (r * (a.phi - b.phi)).powi(2)).sqrt()
}

/// Samples the timeline every 20 ms: rows, and the path speed limit per row (NaN outside paths).
fn timeline_rows(
    robot: &Robot,
    items: &[Item],
    start: Pose,
    rot_radius: f64,
) -> Result<(Vec<Row>, Vec<f64>)> {
    let total = items.last().map_or(0.0, |i| i.t0 + i.duration);
    let n = ((total / CYCLE_S) - 1e-9).ceil().max(1.0) as usize;
    let mut rows = Vec::with_capacity(n + 1);
    let mut limits = Vec::with_capacity(n + 1);
    let mut guess = kpose(&start);
    for k in 0..=n {
        let t = k as f64 * CYCLE_S;
        let item = items.iter().rev().find(|i| i.t0 <= t + 1e-12);
        let (pose, speed, kappa, q, limit) = match item {
            None => {
                let q = steps_of_pose(robot, &start)?;
                let s = robot.ik(&kpose(&start))?;
                (start, 0.0, s.kappa, q, f64::NAN)
            }
            Some(item) => {
                let local = t - item.t0;
                match &item.kind {
                    ItemKind::Path { motion, .. } => {
                        let sp = motion.sample(local);
                        let s = robot.ik(&kpose(&sp.pose)).with_context(|| {
                            format!("t = {t:.2} s: the planned pose {:?} has no IK", sp.pose)
                        })?;
                        let mut q = [0.0; 3];
                        for i in 0..3 {
                            q[i] = robot.kappa_to_steps(i, s.kappa[i])?;
                        }
                        let limit = if local < motion.duration() {
                            motion.segment_speed_limit(sp.segment)
                        } else {
                            f64::NAN
                        };
                        (sp.pose, sp.speed, s.kappa, q, limit)
                    }
                    ItemKind::Dwell { pose } => {
                        let s = robot.ik(&kpose(pose))?;
                        (*pose, 0.0, s.kappa, steps_of_pose(robot, pose)?, f64::NAN)
                    }
                    ItemKind::Joint { mv } => {
                        let q = mv.sample(local).q;
                        let kappa = std::array::from_fn(|i| robot.steps_to_kappa(i, q[i]));
                        let p = JointMove::pose_of(robot, &q, &guess)
                            .with_context(|| format!("t = {t:.2} s: no FK for steps {q:?}"))?;
                        let speed = if local < mv.duration() {
                            let h = 1e-3;
                            let q2 = mv.sample(local + h).q;
                            let p2 = JointMove::pose_of(robot, &q2, &p)?;
                            metric(&to_pose(&p), &to_pose(&p2), rot_radius) / h
                        } else {
                            0.0
                        };
                        (to_pose(&p), speed, kappa, q, f64::NAN)
                    }
                }
            }
        };
        guess = kpose(&pose);
        rows.push(Row {
            t,
            pose,
            speed,
            kappa,
            q: std::array::from_fn(|i| q[i].round() as i64),
        });
        limits.push(limit);
    }
    Ok((rows, limits))
}

/// Joint limits for planning: the configuration's step rates times `rate_fraction`, reduced by
/// 1e-6 relative so that the FK/IK round trip of the check never sees a rate above the limit.
fn joint_limits(
    cfg: &RobotConfig,
    rate_fraction: f64,
    amax: f64,
    jmax: f64,
) -> Result<JointLimits> {
    let mut l = JointLimits::from_config(cfg, rate_fraction, amax, jmax)?;
    for r in &mut l.rate {
        *r *= 1.0 - 1e-6;
    }
    Ok(l)
}

/// `pcr plan program` and `pcr plan joint`.
fn run_timeline(a: &Args, cfg: &RobotConfig, robot: &Robot, from: Pose) -> Result<()> {
    let opt = CheckOptions {
        singularity_margin: a.singularity_margin,
        rate_fraction: a.rate_fraction,
    };
    let mut tl = Timeline {
        robot,
        opt,
        file: String::new(),
        items: Vec::new(),
        t: 0.0,
        pose: from,
        steps: None,
        joint: joint_limits(cfg, a.rate_fraction, DEFAULT_JOINT_AMAX, DEFAULT_JOINT_JMAX)?,
    };
    let mut rot_radius = pcr_planner::path::DEFAULT_ROTATION_RADIUS_MM;
    let mut start = from;
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
            tl.file = file.clone();
            tl.joint = joint_limits(
                cfg,
                a.rate_fraction,
                prog.joint.acceleration,
                prog.joint.jerk,
            )
            .with_context(|| format!("{file}: joint_limits"))?;
            rot_radius = prog.limits.rotation_radius;
            let mut pending: Vec<(usize, program::Step)> = Vec::new();
            for (i, st) in prog.segments.iter().enumerate() {
                match *st {
                    program::Step::Line { .. } | program::Step::Arc { .. } => {
                        pending.push((i, *st));
                        continue;
                    }
                    _ => {}
                }
                tl.path(&pending, &prog.limits)?;
                pending.clear();
                match *st {
                    program::Step::Dwell { seconds } => tl.dwell(seconds),
                    program::Step::Joint { steps } => tl.joint(
                        &format!("segment[{i}] (joint)"),
                        std::array::from_fn(|k| steps[k] as f64),
                    )?,
                    _ => {}
                }
            }
            tl.path(&pending, &prog.limits)?;
        }
        Shape::Joint {
            steps,
            from_steps,
            joint_amax,
            joint_jmax,
        } => {
            let target = parse_steps(steps, "--steps")?;
            tl.joint = joint_limits(cfg, a.rate_fraction, *joint_amax, *joint_jmax)?;
            let q0 = match from_steps {
                Some(s) => parse_steps(s, "--from-steps")?,
                None => {
                    let q = steps_of_pose(robot, &Pose::default())?;
                    q.map(f64::round)
                }
            };
            let kappa = std::array::from_fn(|i| robot.steps_to_kappa(i, q0[i]));
            let p0 = robot
                .fk(&kappa)
                .with_context(|| format!("start steps {q0:?}: no pose in the working mode"))?;
            start = to_pose(&p0);
            tl.pose = start;
            tl.steps = Some(q0);
            tl.joint("joint move", target)?;
        }
        Shape::Square {
            side,
            speed,
            cx,
            cy,
            phi_deg,
            blend_radius: Some(r),
        } => {
            if !(side.is_finite() && *side > 0.0) {
                bail!("--side must be a length > 0 mm, got {side}");
            }
            if !(r.is_finite() && *r >= 0.0) {
                bail!("--blend-radius must be a radius >= 0 mm, got {r}");
            }
            if !(speed.is_finite() && *speed > 0.0) {
                bail!("--speed must be > 0 mm/s, got {speed}");
            }
            let (h, phi) = (side / 2.0, phi_deg.to_radians());
            let line = |x: f64, y: f64, phi: f64| program::Step::Line {
                to: [x, y],
                phi: Some(phi),
                speed: None,
                blend_radius: None,
            };
            let mut steps = Vec::new();
            let start = Pose::new(*cx, cy - h, phi);
            if start.max_diff(&from) > 1e-9 {
                steps.push(line(start.x, start.y, phi));
            }
            for (x, y) in [
                (cx + h, cy - h),
                (cx + h, cy + h),
                (cx - h, cy + h),
                (cx - h, cy - h),
                (*cx, cy - h),
            ] {
                steps.push(line(x, y, phi));
            }
            if start.max_diff(&from) > 1e-9 {
                steps.push(line(from.x, from.y, from.phi));
            }
            let steps: Vec<_> = steps.into_iter().enumerate().collect();
            tl.file = "square".into();
            tl.path(
                &steps,
                &program::PathLimits {
                    speed: *speed,
                    acceleration: a.amax,
                    jerk: a.jmax,
                    blend_radius: *r,
                    rotation_radius: rot_radius,
                },
            )?;
        }
        _ => bail!("internal: not a program, joint move or blended square"),
    }
    let (rows, limits) = timeline_rows(robot, &tl.items, start, rot_radius)?;
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
        tl.items.len(),
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
            robot,
            &rows
                .iter()
                .map(|r| (r.t, r.pose.x, r.pose.y, r.speed))
                .collect::<Vec<_>>(),
            &limits,
        )?;
    }
    Ok(())
}
