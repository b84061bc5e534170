//! Where task-space setpoints come from: the [`SetpointSource`] interface and the interim
//! constant-speed path generator [`InterimPathSource`].
//!
//! The jerk-limited planner ([`crate::PlannerSource`], on `pcr-planner`'s paths, composites
//! and joint moves) implements [`SetpointSource`]: `load` plans a list of [`Move`]s from rest
//! at a start pose and returns the duration, `sample` returns the pose at a program time.
//! Everything else (the 20 ms cycle, pause, resume, stop, run ids, corrections) lives in
//! [`crate::InterpolatorStep`], which wraps any source: it is the one interpolator of the
//! stack (the `pcr-planner` process, the in-process runtime and `pcr plan` through
//! [`crate::offline`]).

use pcr_kinematics::Pose;
use pcr_planner::program::{JointSettings, PathLimits, Program, Step};
use std::f64::consts::TAU;

/// One move of a program (task space, mm, rad, s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Move {
    /// Straight line (and orientation blend) to `to`, from rest to rest; `speed_mm_s` is the
    /// peak speed along the path.
    Line {
        /// Target pose.
        to: Pose,
        /// Peak path speed, mm/s (> 0).
        speed_mm_s: f64,
    },
    /// One full counter-clockwise circle at constant speed, starting and ending at
    /// `centre + (radius, 0)` (a rest-to-rest line leads there first if the program is elsewhere).
    Circle {
        /// Centre (x, y), mm.
        centre: [f64; 2],
        /// Radius, mm (> 0).
        radius_mm: f64,
        /// Path speed, mm/s (> 0).
        speed_mm_s: f64,
        /// Constant orientation, rad.
        phi: f64,
    },
    /// Hold the current pose.
    Dwell {
        /// Duration, s (>= 0).
        duration_s: f64,
    },
    /// A line segment of a composite path: lines and arcs in a row whose later members
    /// `continues` form one motion from rest to rest, with continuous speed through tangent
    /// junctions and corners rounded by the blend radius.
    PathLine {
        /// Target x, y, mm.
        to: [f64; 2],
        /// Target orientation, rad (None: keep the orientation).
        phi: Option<f64>,
        /// Own speed limit, mm/s (None: the group's).
        speed_mm_s: Option<f64>,
        /// Blend radius of the corner at its end, mm (None: the group's).
        blend_radius_mm: Option<f64>,
        /// Continues the previous line or arc without stopping.
        continues: bool,
        /// Limits of the composite motion (those of its first segment count).
        limits: PathLimits,
    },
    /// An arc segment of a composite path (see [`Move::PathLine`]); the radius is the distance
    /// from the current point to the centre.
    Arc {
        /// Centre x, y, mm.
        centre: [f64; 2],
        /// Signed sweep, rad (positive: counter-clockwise).
        sweep_rad: f64,
        /// End orientation, rad (None: keep the orientation).
        phi: Option<f64>,
        /// Own speed limit, mm/s (None: the group's).
        speed_mm_s: Option<f64>,
        /// Continues the previous line or arc without stopping.
        continues: bool,
        /// Limits of the composite motion (those of its first segment count).
        limits: PathLimits,
    },
    /// A synchronised rest-to-rest move of the motors to target positions (the pose follows by
    /// forward kinematics).
    Joint {
        /// Target motor positions, steps.
        steps: [i64; 3],
        /// Motor acceleration (steps/s^2) and jerk (steps/s^3); the step rates come from the
        /// robot configuration.
        limits: JointSettings,
    },
}

impl Move {
    /// True for the segments of composite paths ([`Move::PathLine`], [`Move::Arc`]).
    pub fn is_path_segment(&self) -> bool {
        matches!(self, Move::PathLine { .. } | Move::Arc { .. })
    }
}

/// The moves of a parsed program file: lines and arcs in a row continue each other (one
/// composite motion), dwells and joint moves as they are.
pub fn moves_of_program(p: &Program) -> Vec<Move> {
    let mut out = Vec::with_capacity(p.segments.len());
    let mut prev_path = false;
    for st in &p.segments {
        let m = match *st {
            Step::Line {
                to,
                phi,
                speed,
                blend_radius,
            } => Move::PathLine {
                to,
                phi,
                speed_mm_s: speed,
                blend_radius_mm: blend_radius,
                continues: prev_path,
                limits: p.limits,
            },
            Step::Arc {
                center,
                sweep,
                phi,
                speed,
            } => Move::Arc {
                centre: center,
                sweep_rad: sweep,
                phi,
                speed_mm_s: speed,
                continues: prev_path,
                limits: p.limits,
            },
            Step::Dwell { seconds } => Move::Dwell {
                duration_s: seconds,
            },
            Step::Joint { steps } => Move::Joint {
                steps,
                limits: p.joint,
            },
        };
        prev_path = m.is_path_segment();
        out.push(m);
    }
    out
}

/// Why a program cannot be planned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// A move has a non-finite or non-positive parameter.
    #[error("move {index}: invalid parameter {what}")]
    InvalidMove {
        /// 0-based move index.
        index: usize,
        /// Which parameter.
        what: &'static str,
    },
    /// The program is empty.
    #[error("empty program")]
    Empty,
    /// A move cannot be planned (bad geometry or limits); the message says why.
    #[error("move {index}: {why}")]
    Invalid {
        /// 0-based move index.
        index: usize,
        /// Why.
        why: String,
    },
    /// The program is valid but the robot cannot follow it (workspace, limits, singularity,
    /// step rate); the message names the move, time, pose and the first violation.
    #[error("move {index}: {why}")]
    Rejected {
        /// 0-based move index.
        index: usize,
        /// The first violation.
        why: String,
    },
}

/// Index of the last piece of a timed program (start time first in each tuple, ordered) that
/// starts at or before `tau_s`; 0 if none does. A linear scan: programs have few pieces, and it
/// does not allocate.
pub fn active_piece<T>(pieces: &[(f64, f64, T)], tau_s: f64) -> usize {
    pieces
        .iter()
        .take_while(|p| p.0 <= tau_s)
        .count()
        .saturating_sub(1)
}

/// A source of task-space setpoints (the interpolator's core).
///
/// Implementations: [`InterimPathSource`] (here, interim) and the planner's jerk-limited
/// paths ([`crate::PlannerSource`]). `sample` is called once per control cycle and must not
/// allocate.
pub trait SetpointSource: Clone {
    /// A short name for logs.
    fn name(&self) -> &str;
    /// Plans `moves` starting at rest at `start`; returns the program's duration, s. May
    /// allocate (it runs between cycles, on a command).
    fn load(&mut self, moves: &[Move], start: Pose) -> Result<f64, PlanError>;
    /// The setpoint at program time `tau_s` (0 = start of the program); before 0 the start pose,
    /// after the end the final pose. Must not allocate.
    fn sample(&self, tau_s: f64) -> Pose;

    /// Peak path speed of the loaded program, mm/s, and the path acceleration (mm/s^2) and
    /// jerk (mm/s^3) a pause or stop may add when it slows the program down. The interpolator
    /// brakes by scaling program time, so the path is kept exactly.
    fn braking(&self) -> Braking {
        Braking::default()
    }

    /// Path speed at program time `tau_s` (at program-time rate 1), mm/s (combined metric where
    /// the source has one). The default differentiates [`SetpointSource::sample`] numerically.
    /// Must not allocate.
    fn speed(&self, tau_s: f64) -> f64 {
        let h = 1e-4;
        let (a, b) = (self.sample(tau_s - h), self.sample(tau_s + h));
        (b.x - a.x).hypot(b.y - a.y) / (2.0 * h)
    }
}

/// How hard a pause or stop may slow a program down (see [`SetpointSource::braking`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Braking {
    /// Peak path speed of the program, mm/s.
    pub peak_speed: f64,
    /// Added path acceleration, mm/s^2.
    pub amax: f64,
    /// Added path jerk, mm/s^3.
    pub jmax: f64,
}

impl Default for Braking {
    fn default() -> Self {
        Braking {
            peak_speed: 100.0,
            amax: 100.0,
            jmax: 1000.0,
        }
    }
}

#[derive(Debug, Clone, Copy)]
enum Segment {
    Line {
        from: Pose,
        to: Pose,
    },
    Arc {
        centre: [f64; 2],
        radius: f64,
        a0: f64,
        sweep: f64,
        phi: f64,
    },
    Hold(Pose),
}

/// INTERIM setpoint source until `pcr-planner` lands: rest-to-rest lines with a quintic
/// (minimum-jerk) time scaling, constant-speed circles and dwells. Not jerk-limited at the
/// circle's ends (the speed steps from 0 to the circle speed there).
#[derive(Debug, Clone, Default)]
pub struct InterimPathSource {
    segs: Vec<(f64, f64, Segment)>,
    start: Pose,
}

impl InterimPathSource {
    /// An empty source (holds the origin until a program is loaded).
    pub fn new() -> Self {
        Self::default()
    }
}

fn finite_pos(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

/// Quintic rest-to-rest time scaling s(u), u in [0, 1]; peak ds/du = 1.875.
fn smoothstep5(u: f64) -> f64 {
    let u = u.clamp(0.0, 1.0);
    u * u * u * (10.0 + u * (-15.0 + 6.0 * u))
}

const QUINTIC_PEAK: f64 = 1.875;

fn lerp_pose(a: &Pose, b: &Pose, s: f64) -> Pose {
    Pose::new(
        a.x + s * (b.x - a.x),
        a.y + s * (b.y - a.y),
        a.phi + s * (b.phi - a.phi),
    )
}

/// Duration of a rest-to-rest line whose peak speed is `v` (orientation counts 1 rad = 100 mm
/// so that pure rotations take time too).
fn line_duration(a: &Pose, b: &Pose, v: f64) -> f64 {
    let d = a.position_distance(b).max((b.phi - a.phi).abs() * 100.0);
    QUINTIC_PEAK * d / v
}

impl SetpointSource for InterimPathSource {
    fn name(&self) -> &str {
        "interim-path"
    }

    fn load(&mut self, moves: &[Move], start: Pose) -> Result<f64, PlanError> {
        if moves.is_empty() {
            return Err(PlanError::Empty);
        }
        let mut segs = Vec::with_capacity(moves.len() * 2);
        let mut t = 0.0;
        let mut at = start;
        for (index, m) in moves.iter().enumerate() {
            let bad = |what| PlanError::InvalidMove { index, what };
            match *m {
                Move::Line { to, speed_mm_s } => {
                    if !finite_pos(speed_mm_s) {
                        return Err(bad("speed_mm_s"));
                    }
                    if !(to.x.is_finite() && to.y.is_finite() && to.phi.is_finite()) {
                        return Err(bad("to"));
                    }
                    let d = line_duration(&at, &to, speed_mm_s);
                    segs.push((t, d, Segment::Line { from: at, to }));
                    t += d;
                    at = to;
                }
                Move::Circle {
                    centre,
                    radius_mm,
                    speed_mm_s,
                    phi,
                } => {
                    if !finite_pos(radius_mm) {
                        return Err(bad("radius_mm"));
                    }
                    if !finite_pos(speed_mm_s) {
                        return Err(bad("speed_mm_s"));
                    }
                    if !(centre[0].is_finite() && centre[1].is_finite() && phi.is_finite()) {
                        return Err(bad("centre"));
                    }
                    let p0 = Pose::new(centre[0] + radius_mm, centre[1], phi);
                    if at.position_distance(&p0) > 1e-9 || (at.phi - phi).abs() > 1e-12 {
                        let d = line_duration(&at, &p0, speed_mm_s);
                        segs.push((t, d, Segment::Line { from: at, to: p0 }));
                        t += d;
                    }
                    let d = TAU * radius_mm / speed_mm_s;
                    segs.push((
                        t,
                        d,
                        Segment::Arc {
                            centre,
                            radius: radius_mm,
                            a0: 0.0,
                            sweep: TAU,
                            phi,
                        },
                    ));
                    t += d;
                    at = p0;
                }
                Move::Dwell { duration_s } => {
                    if !(duration_s.is_finite() && duration_s >= 0.0) {
                        return Err(bad("duration_s"));
                    }
                    segs.push((t, duration_s, Segment::Hold(at)));
                    t += duration_s;
                }
                Move::PathLine { .. } | Move::Arc { .. } | Move::Joint { .. } => {
                    return Err(bad(
                        "move kind (composite paths and joint moves need the planner source)",
                    ))
                }
            }
        }
        // A final zero-length hold so that sampling past the end returns the last pose.
        segs.push((t, 0.0, Segment::Hold(at)));
        self.segs = segs;
        self.start = start;
        Ok(t)
    }

    fn sample(&self, tau_s: f64) -> Pose {
        if self.segs.is_empty() || tau_s <= 0.0 {
            return self.start;
        }
        let (t0, d, seg) = self.segs[active_piece(&self.segs, tau_s)];
        let u = if d > 0.0 { (tau_s - t0) / d } else { 1.0 };
        let u = u.clamp(0.0, 1.0);
        match seg {
            Segment::Line { from, to } => lerp_pose(&from, &to, smoothstep5(u)),
            Segment::Arc {
                centre,
                radius,
                a0,
                sweep,
                phi,
            } => {
                let a = a0 + sweep * u;
                Pose::new(
                    centre[0] + radius * a.cos(),
                    centre[1] + radius * a.sin(),
                    phi,
                )
            }
            Segment::Hold(p) => p,
        }
    }
}

/// The paper's circle: from the current pose to (50, 0) mm, one circle of radius 50 mm around
/// the origin at 50 mm/s (phi = 0), back to the origin.
pub fn paper_circle() -> Vec<Move> {
    circle_program([0.0, 0.0], 50.0, 50.0, 0.0, Pose::default())
}

/// A circle program as the paper's: a dwell of 0.2 s, a line to `centre + (radius, 0)` and one
/// counter-clockwise circle at `speed_mm_s` (orientation `phi` rad), a dwell of 0.2 s and a line
/// to `back`.
pub fn circle_program(
    centre: [f64; 2],
    radius_mm: f64,
    speed_mm_s: f64,
    phi: f64,
    back: Pose,
) -> Vec<Move> {
    vec![
        Move::Dwell { duration_s: 0.2 },
        Move::Circle {
            centre,
            radius_mm,
            speed_mm_s,
            phi,
        },
        Move::Dwell { duration_s: 0.2 },
        Move::Line {
            to: back,
            speed_mm_s,
        },
    ]
}

/// The paper's square: 50 mm side centred on the origin, rest-to-rest sides at 50 mm/s peak,
/// from and back to the origin.
pub fn paper_square() -> Vec<Move> {
    square_program([0.0, 0.0], 50.0, 50.0, 0.0, Pose::default())
}

/// A square program as the paper's: a dwell of 0.2 s, a line to the corner
/// `centre + (side/2, -side/2)`, then counter-clockwise rest-to-rest sides at `speed_mm_s` peak
/// (orientation `phi` rad) with a dwell of 0.1 s after each line, and a line to `back`.
pub fn square_program(
    centre: [f64; 2],
    side_mm: f64,
    speed_mm_s: f64,
    phi: f64,
    back: Pose,
) -> Vec<Move> {
    let h = side_mm / 2.0;
    let [cx, cy] = centre;
    let c = [
        (cx + h, cy - h),
        (cx + h, cy + h),
        (cx - h, cy + h),
        (cx - h, cy - h),
        (cx + h, cy - h),
    ];
    let mut v = vec![Move::Dwell { duration_s: 0.2 }];
    for (x, y) in c {
        v.push(Move::Line {
            to: Pose::new(x, y, phi),
            speed_mm_s,
        });
        v.push(Move::Dwell { duration_s: 0.1 });
    }
    v.push(Move::Line {
        to: back,
        speed_mm_s,
    });
    v
}

/// The paper's program: circle then square.
pub fn paper_program() -> Vec<Move> {
    let mut v = paper_circle();
    v.extend(paper_square());
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn circle_is_round_and_closed() {
        let mut s = InterimPathSource::new();
        let d = s.load(&paper_circle(), Pose::default()).unwrap();
        assert!(d > TAU * 50.0 / 50.0);
        assert_eq!(s.sample(0.0), Pose::default());
        assert!(s.sample(d + 1.0).position_distance(&Pose::default()) < 1e-9);
        // On the arc the radius is 50 mm.
        let p = s.sample(0.2 + 1.875 + 1.0);
        assert!((p.x.hypot(p.y) - 50.0).abs() < 1e-9, "{p:?}");
    }

    #[test]
    fn lines_are_rest_to_rest_and_speed_bounded() {
        let mut s = InterimPathSource::new();
        let d = s.load(&paper_square(), Pose::default()).unwrap();
        let dt = 1e-3;
        let mut t = 0.0;
        let mut vmax: f64 = 0.0;
        while t < d {
            let v = s.sample(t + dt).position_distance(&s.sample(t)) / dt;
            vmax = vmax.max(v);
            t += dt;
        }
        assert!(vmax <= 50.0 * 1.001, "{vmax}");
        assert!(vmax > 45.0);
    }

    #[test]
    fn bad_moves_are_refused() {
        let mut s = InterimPathSource::new();
        assert_eq!(s.load(&[], Pose::default()), Err(PlanError::Empty));
        let e = s
            .load(
                &[Move::Line {
                    to: Pose::default(),
                    speed_mm_s: 0.0,
                }],
                Pose::default(),
            )
            .unwrap_err();
        assert!(e.to_string().contains("speed_mm_s"));
    }
}
