//! A plan request (a shape, a program file or a joint move, with the path limits and the
//! pause, resume and stop requests) into the chain's 20 ms setpoints: what `pcr plan` writes
//! and `pcr.plan` returns.
//!
//! Each request becomes the chain's program, a list of [`Move`]s, the same the supervisor sends
//! and the chain runs (a circle of 50 mm at 50 mm/s is the chain's built-in CIRCLE, a square of
//! 50 mm its SQUARE, `Paper` its PAPER). It is planned and checked by the chain's
//! [`PlannerSource`] (every 2 ms: IK in the working mode, joint and bending limits, singularity
//! margin, drive step-rate limits) and stepped every 20 ms by the chain's interpolator on a
//! simulated clock ([`pcr_control::offline`]): the rows are the poses the running chain
//! commands for the same program, cycle by cycle.

use crate::error::{ErrorKind, OfflineError};
use pcr_control::{
    circle_program, moves_of_program, plan_moves, square_program, CommandError, MotionLimits, Move,
    PlanError, PlannedCycle, PlannerSource, CYCLE_S,
};
use pcr_kinematics::{CheckOptions, Pose, Robot};
use pcr_messages::command_kind;
use pcr_planner::program::{self, JointSettings, PathLimits};
use std::f64::consts::TAU;

/// Default motor acceleration of joint moves, steps/s^2.
pub const DEFAULT_JOINT_AMAX: f64 = 2000.0;
/// Default motor jerk of joint moves, steps/s^3.
pub const DEFAULT_JOINT_JMAX: f64 = 20000.0;

/// What to plan.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// A full circle at constant orientation, as the chain's circle program: a dwell of 0.2 s,
    /// a line to the start point, the circle, a dwell of 0.2 s and a line back to the start
    /// pose. With a start angle other than 0, or clockwise, the circle is one full arc of a
    /// composite path.
    Circle {
        /// Radius, mm.
        radius_mm: f64,
        /// Speed along the path, mm/s.
        speed_mm_s: f64,
        /// Centre, mm.
        centre_mm: [f64; 2],
        /// Platform orientation, degrees.
        phi_deg: f64,
        /// Polar angle of the start point on the circle, degrees.
        start_deg: f64,
        /// Clockwise instead of counter-clockwise.
        cw: bool,
    },
    /// A square of rest-to-rest sides, as the chain's square program; with a blend radius, the
    /// whole square (from the middle of its lower side) as one composite motion whose corners
    /// are rounded by tangent arcs of that radius.
    Square {
        /// Side length, mm.
        side_mm: f64,
        /// Speed along each side, mm/s.
        speed_mm_s: f64,
        /// Centre, mm.
        centre_mm: [f64; 2],
        /// Platform orientation, degrees.
        phi_deg: f64,
        /// Corner radius, mm (None: rest-to-rest sides).
        blend_radius_mm: Option<f64>,
    },
    /// A straight line to a pose, and back to the start pose.
    Line {
        /// Target pose.
        to: Pose,
        /// Speed along the path, mm/s.
        speed_mm_s: f64,
    },
    /// The paper's test program (the chain's PAPER): the 50 mm circle, then the 50 mm square.
    Paper {
        /// Speed along the paths, mm/s.
        speed_mm_s: f64,
    },
    /// A program file (TOML): lines, arcs, dwells and joint moves (docs/planner.md).
    Program {
        /// The file.
        file: String,
        /// Joint moves: motor acceleration, steps/s^2 (unless the file sets it).
        joint_amax: f64,
        /// Joint moves: motor jerk, steps/s^3 (unless the file sets it).
        joint_jmax: f64,
    },
    /// A synchronised joint-space move of the three motors.
    Joint {
        /// Target motor positions, steps.
        steps: [f64; 3],
        /// Start motor positions, steps (None: the home pose's).
        from_steps: Option<[f64; 3]>,
        /// Motor acceleration, steps/s^2.
        joint_amax: f64,
        /// Motor jerk, steps/s^3.
        joint_jmax: f64,
    },
}

/// The limits, checks and requests of a plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanSettings {
    /// Start pose (the robot's current pose; shapes lead from it and back).
    pub from: Pose,
    /// Path acceleration limit, mm/s^2.
    pub amax: f64,
    /// Path jerk limit, mm/s^3.
    pub jmax: f64,
    /// A pause requested at this time, s.
    pub pause_at: Option<f64>,
    /// A resume requested at this time, s.
    pub resume_at: Option<f64>,
    /// A stop requested at this time, s.
    pub stop_at: Option<f64>,
    /// Required conditioning, as a multiple of the robot's singularity threshold.
    pub singularity_margin: f64,
    /// Fraction of each drive's step-rate limit the motion may use.
    pub rate_fraction: f64,
}

impl Default for PlanSettings {
    fn default() -> Self {
        PlanSettings {
            from: Pose::default(),
            amax: 200.0,
            jmax: 2000.0,
            pause_at: None,
            resume_at: None,
            stop_at: None,
            singularity_margin: 1.0,
            rate_fraction: 1.0,
        }
    }
}

/// The chain's program of a request.
#[derive(Debug, Clone)]
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

/// One 20 ms row of a plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanRow {
    /// Time, s.
    pub t_s: f64,
    /// Planned pose (the chain's `xp_mm, yp_mm, phip_deg`).
    pub pose: Pose,
    /// Speed along the path, mm/s.
    pub speed_mm_s: f64,
    /// Curvatures of the planned pose, 1/mm.
    pub kappa_per_mm: [f64; 3],
    /// Motor setpoints, steps.
    pub q: [i64; 3],
}

/// A plan: every 20 ms cycle from t = 0 to rest.
#[derive(Debug, Clone)]
pub struct Plan {
    /// The rows.
    pub rows: Vec<PlanRow>,
    /// The composite speed limit of each row, mm/s (NaN outside composites).
    pub speed_limits: Vec<f64>,
    /// Number of moves of the chain's program.
    pub moves: usize,
}

/// Largest coordinate difference of two poses (mm, rad).
fn max_diff(a: &Pose, b: &Pose) -> f64 {
    (a.x - b.x)
        .abs()
        .max((a.y - b.y).abs())
        .max((a.phi - b.phi).abs())
}

fn positive(v: f64, what: &str, unit: &str) -> Result<(), OfflineError> {
    if !(v.is_finite() && v > 0.0) {
        return Err(OfflineError::invalid(format!(
            "{what} must be > 0 {unit}, got {v}"
        )));
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

/// The chain's program of a request, starting at `s.from` (a joint move starts where its start
/// steps put the robot).
pub fn program(
    robot: &Robot,
    shape: &Shape,
    s: &PlanSettings,
) -> Result<PlanProgram, OfflineError> {
    let from = s.from;
    let mut p = PlanProgram {
        moves: Vec::new(),
        names: Vec::new(),
        start: from,
        file: None,
    };
    let path_limits = |speed: f64, blend_radius: f64| PathLimits {
        speed,
        acceleration: s.amax,
        jerk: s.jmax,
        blend_radius,
        rotation_radius: pcr_planner::path::DEFAULT_ROTATION_RADIUS_MM,
    };
    match shape {
        Shape::Circle {
            radius_mm: radius,
            speed_mm_s: speed,
            centre_mm: [cx, cy],
            phi_deg,
            start_deg,
            cw,
        } => {
            positive(*radius, "the circle's radius", "mm")?;
            positive(*speed, "the speed", "mm/s")?;
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
            side_mm: side,
            speed_mm_s: speed,
            centre_mm: [cx, cy],
            phi_deg,
            blend_radius_mm,
        } => {
            positive(*side, "the square's side", "mm")?;
            positive(*speed, "the speed", "mm/s")?;
            let phi = phi_deg.to_radians();
            match blend_radius_mm {
                None => p.extend(
                    square_program([*cx, *cy], *side, *speed, phi, from),
                    &square_names(),
                ),
                Some(r) => {
                    if !(r.is_finite() && *r >= 0.0) {
                        return Err(OfflineError::invalid(format!(
                            "the blend radius must be a radius >= 0 mm, got {r}"
                        )));
                    }
                    // One composite from the start pose around the square (starting in the
                    // middle of its lower side) and back.
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
        Shape::Line { to, speed_mm_s } => {
            if ![to.x, to.y, to.phi].iter().all(|v| v.is_finite()) {
                return Err(OfflineError::invalid(
                    "the line's target pose must be three finite numbers x_mm, y_mm, phi_deg",
                ));
            }
            positive(*speed_mm_s, "the speed", "mm/s")?;
            p.push(
                "line",
                Move::Line {
                    to: *to,
                    speed_mm_s: *speed_mm_s,
                },
            );
            if max_diff(to, &from) > 1e-9 {
                p.push(
                    "return",
                    Move::Line {
                        to: from,
                        speed_mm_s: *speed_mm_s,
                    },
                );
            }
        }
        Shape::Paper { speed_mm_s } => {
            positive(*speed_mm_s, "the speed", "mm/s")?;
            p.extend(
                circle_program([0.0, 0.0], 50.0, *speed_mm_s, 0.0, from),
                &CIRCLE_NAMES,
            );
            p.extend(
                square_program([0.0, 0.0], 50.0, *speed_mm_s, 0.0, from),
                &square_names(),
            );
        }
        Shape::Program {
            file,
            joint_amax,
            joint_jmax,
        } => {
            let prog = program::load(
                file,
                &program::Defaults {
                    acceleration: s.amax,
                    jerk: s.jmax,
                    joint_acceleration: *joint_amax,
                    joint_jerk: *joint_jmax,
                },
            )?;
            p.moves = moves_of_program(&prog);
            p.names = prog
                .segments
                .iter()
                .enumerate()
                .map(|(i, s)| format!("segment[{i}] ({})", s.kind()))
                .collect();
            p.file = Some(file.clone());
        }
        Shape::Joint {
            steps,
            from_steps,
            joint_amax,
            joint_jmax,
        } => {
            for q in steps.iter().chain(from_steps.iter().flatten()) {
                if q.fract() != 0.0 || q.abs() > 1e9 {
                    return Err(OfflineError::invalid(format!(
                        "motor positions must be whole numbers of steps, got {q}"
                    )));
                }
            }
            let q0 = match from_steps {
                Some(q) => *q,
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
            p.start = robot.fk(&kappa).map_err(|e| {
                OfflineError::from(e)
                    .context(format!("start steps {q0:?}: no pose in the working mode"))
            })?;
            p.push(
                "joint move",
                Move::Joint {
                    steps: steps.map(|q| q as i64),
                    limits: JointSettings {
                        acceleration: *joint_amax,
                        jerk: *joint_jmax,
                    },
                },
            );
        }
    }
    Ok(p)
}

/// Why the chain refuses the program, naming the move.
fn refusal(e: CommandError, p: &PlanProgram) -> OfflineError {
    let name = |i: usize| p.names.get(i).map_or("?", |s| s.as_str()).to_string();
    let file = p.file.as_ref().map_or(String::new(), |f| format!("{f}: "));
    let message = match e {
        CommandError::Plan(PlanError::Rejected { index, why }) => {
            format!("{file}motion rejected in `{}`: {why}", name(index))
        }
        CommandError::Plan(PlanError::Invalid { index, why }) => {
            format!("{file}`{}`: {why}", name(index))
        }
        CommandError::Plan(PlanError::InvalidMove { index, what }) => {
            format!("{file}`{}`: invalid {what}", name(index))
        }
        other => format!("{file}{other}"),
    };
    OfflineError::new(ErrorKind::Planning, message)
}

/// The pause, resume and stop requests of `s` as (cycle, command kind), in cycle order.
pub fn requests(s: &PlanSettings) -> Result<Vec<(usize, u32)>, OfflineError> {
    let mut r = Vec::new();
    for (t, kind, what) in [
        (s.pause_at, command_kind::PAUSE, "the pause"),
        (s.resume_at, command_kind::RESUME, "the resume"),
        (s.stop_at, command_kind::STOP, "the stop"),
    ] {
        if let Some(t) = t {
            if !(t.is_finite() && t >= 0.0) {
                return Err(OfflineError::invalid(format!(
                    "{what} must be requested at a time >= 0 s, got {t}"
                )));
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
) -> Result<(Vec<PlannedCycle>, Vec<f64>), OfflineError> {
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

/// Plans a request: the chain's program of `shape`, checked and stepped every 20 ms, with the
/// motor setpoints of every row.
pub fn plan(robot: &Robot, shape: &Shape, s: &PlanSettings) -> Result<Plan, OfflineError> {
    let prog = program(robot, shape, s)?;
    let commands = requests(s)?;
    positive(s.amax, "the path acceleration limit", "mm/s^2")?;
    positive(s.jmax, "the path jerk limit", "mm/s^3")?;
    let check = CheckOptions {
        singularity_margin: s.singularity_margin,
        rate_fraction: s.rate_fraction,
    };
    let limits = MotionLimits {
        amax: s.amax,
        jmax: s.jmax,
    };
    let (cycles, speed_limits) = plan_cycles(robot, limits, check, &prog, &commands)?;
    let mut rows = Vec::with_capacity(cycles.len());
    for c in &cycles {
        let pose = c.pose();
        let t = c.task.t_s;
        let sol = robot.ik(&pose).map_err(|e| {
            OfflineError::from(e).context(format!(
                "t = {t:.2} s: the planned pose {pose:?} has no IK solution"
            ))
        })?;
        let mut q = [0i64; 3];
        for i in 0..3 {
            q[i] = robot.kappa_to_steps(i, sol.kappa[i])?.round() as i64;
        }
        rows.push(PlanRow {
            t_s: t,
            pose,
            speed_mm_s: c.speed_mm_s,
            kappa_per_mm: sol.kappa,
            q,
        });
    }
    Ok(Plan {
        rows,
        speed_limits,
        moves: prog.moves.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use pcr_control::{paper_circle, paper_program, paper_square};

    fn program_of(shape: Shape) -> PlanProgram {
        program(&Robot::nominal(), &shape, &PlanSettings::default()).unwrap()
    }

    #[test]
    fn the_papers_shapes_are_the_chains_built_in_programs() {
        let c = program_of(Shape::Circle {
            radius_mm: 50.0,
            speed_mm_s: 50.0,
            centre_mm: [0.0, 0.0],
            phi_deg: 0.0,
            start_deg: 0.0,
            cw: false,
        });
        assert_eq!(c.moves, paper_circle());
        assert_eq!(c.names.len(), c.moves.len());
        let s = program_of(Shape::Square {
            side_mm: 50.0,
            speed_mm_s: 50.0,
            centre_mm: [0.0, 0.0],
            phi_deg: 0.0,
            blend_radius_mm: None,
        });
        assert_eq!(s.moves, paper_square());
        assert_eq!(s.names.len(), s.moves.len());
        let p = program_of(Shape::Paper { speed_mm_s: 50.0 });
        assert_eq!(p.moves, paper_program());
        assert_eq!(p.names.len(), p.moves.len());
    }

    #[test]
    fn stop_requests_are_cycles_of_the_chain() {
        let s = PlanSettings {
            stop_at: Some(3.001),
            pause_at: Some(1.0),
            ..PlanSettings::default()
        };
        assert_eq!(
            requests(&s).unwrap(),
            [(50, command_kind::PAUSE), (150, command_kind::STOP)]
        );
        let shape = Shape::Circle {
            radius_mm: 50.0,
            speed_mm_s: 50.0,
            centre_mm: [0.0, 0.0],
            phi_deg: 0.0,
            start_deg: 0.0,
            cw: false,
        };
        let plan = plan(&Robot::nominal(), &shape, &s).unwrap();
        // paused at rest (the stop while paused ends it at once)
        assert_eq!(plan.rows.len(), 151);
        assert_eq!(plan.speed_limits.len(), 151);
    }

    #[test]
    fn bad_numbers_are_refused_with_their_name() {
        let e = plan(
            &Robot::nominal(),
            &Shape::Square {
                side_mm: -1.0,
                speed_mm_s: 50.0,
                centre_mm: [0.0, 0.0],
                phi_deg: 0.0,
                blend_radius_mm: None,
            },
            &PlanSettings::default(),
        )
        .unwrap_err();
        assert_eq!(e.kind, ErrorKind::Invalid);
        assert!(e.message.contains("side"), "{e}");
    }
}
