//! The four experiments as designs: what is visited or moved, in which order, with which
//! timing. Pure data built from the robot model; the program builder ([`crate::program`]) turns
//! a design into chain commands and the [`crate::Annotator`] labels the rows it produces.

use crate::calibration::{CalibrationOptions, CalibrationSet};
use crate::error::DesignError;
use pcr_kinematics::{Pose, Robot};
use pcr_recording::Split;

/// The experiments of the paper.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ExperimentKind {
    /// The calibration set (189 poses, train and test), each approached from the origin once.
    Calibration,
    /// The phi = 0 poses of the calibration set, each approached 20 times in a row.
    Repeatability,
    /// The paper's circle and square (Table II).
    Paths,
    /// Forth-and-back moves of 1, 2, ... steps per motor (section III-D).
    Backlash,
}

impl ExperimentKind {
    /// The name used on the command line and in the `experiment` metadata.
    pub fn as_str(self) -> &'static str {
        match self {
            ExperimentKind::Calibration => "calibration",
            ExperimentKind::Repeatability => "repeatability",
            ExperimentKind::Paths => "paths",
            ExperimentKind::Backlash => "backlash",
        }
    }
}

impl std::fmt::Display for ExperimentKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for ExperimentKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Ok(match s {
            "calibration" => ExperimentKind::Calibration,
            "repeatability" => ExperimentKind::Repeatability,
            "paths" => ExperimentKind::Paths,
            "backlash" => ExperimentKind::Backlash,
            _ => {
                return Err(format!(
                    "unknown experiment `{s}` (calibration, repeatability, paths, backlash)"
                ))
            }
        })
    }
}

/// How each static target is visited: a rest-to-rest line from the origin, a dwell of
/// `settle_s` (rows not settled) then `measure_s` (rows settled), a line back to the origin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VisitTiming {
    /// Peak speed of the approach and return lines, mm/s.
    pub speed_mm_s: f64,
    /// Dwell before the measurement, s.
    pub settle_s: f64,
    /// Measurement dwell (its rows are marked `settled = 1`), s.
    pub measure_s: f64,
}

impl Default for VisitTiming {
    fn default() -> Self {
        VisitTiming {
            speed_mm_s: 30.0,
            settle_s: 1.0,
            measure_s: 0.5,
        }
    }
}

impl VisitTiming {
    /// Checks the ranges; names the option.
    pub fn validate(&self) -> Result<(), DesignError> {
        let opt = |option, v: f64| DesignError::Option {
            option,
            why: format!("{v}"),
        };
        if !(self.speed_mm_s.is_finite() && self.speed_mm_s > 0.0) {
            return Err(opt("speed_mm_s (> 0)", self.speed_mm_s));
        }
        if !(self.settle_s.is_finite() && self.settle_s >= 0.0) {
            return Err(opt("settle_s (>= 0)", self.settle_s));
        }
        if !(self.measure_s.is_finite() && self.measure_s > 0.0) {
            return Err(opt("measure_s (> 0)", self.measure_s));
        }
        Ok(())
    }
}

/// One visit of a static target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Visit {
    /// Pose id of the target (that of the calibration set).
    pub pose_id: u64,
    /// Repetition index (0 for the calibration experiment).
    pub rep: u64,
    /// The target's split in the calibration set.
    pub set: Split,
    /// The target pose (mm, rad).
    pub target: Pose,
}

/// A static experiment (calibration or repeatability): visits in order, all from `origin`.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticDesign {
    /// Calibration or repeatability.
    pub kind: ExperimentKind,
    /// The calibration set the targets come from.
    pub set: CalibrationSet,
    /// Repetitions per target (1 for calibration).
    pub reps: u64,
    /// The visits in the order they are run.
    pub visits: Vec<Visit>,
    /// Timing of each visit.
    pub timing: VisitTiming,
    /// Where every approach starts and every return ends: the workspace origin (0, 0, 0).
    pub origin: Pose,
    /// Repeatability: the orientation of its poses, deg (None: every orientation).
    pub phi_deg: Option<f64>,
}

impl StaticDesign {
    /// The calibration experiment: every pose of the set once, in pose-id order.
    pub fn calibration(
        robot: &Robot,
        options: &CalibrationOptions,
        timing: VisitTiming,
    ) -> Result<Self, DesignError> {
        timing.validate()?;
        let set = CalibrationSet::design(robot, options)?;
        let visits = set
            .poses
            .iter()
            .map(|p| Visit {
                pose_id: p.pose_id,
                rep: 0,
                set: p.set,
                target: p.pose,
            })
            .collect();
        Ok(StaticDesign {
            kind: ExperimentKind::Calibration,
            set,
            reps: 1,
            visits,
            timing,
            origin: Pose::default(),
            phi_deg: None,
        })
    }

    /// The repeatability experiment: the poses of the calibration set at orientation `phi_deg`
    /// (one of `options.phis_deg`; the paper: 0), in pose-id order, each visited `reps` times
    /// in a row (rep 0..reps-1). Pose ids and splits are those of the calibration set built
    /// with the same options.
    pub fn repeatability(
        robot: &Robot,
        options: &CalibrationOptions,
        phi_deg: f64,
        reps: u64,
        timing: VisitTiming,
    ) -> Result<Self, DesignError> {
        timing.validate()?;
        if reps == 0 {
            return Err(DesignError::Option {
                option: "reps",
                why: "0 repetitions".into(),
            });
        }
        if !options.phis_deg.contains(&phi_deg) {
            return Err(DesignError::Option {
                option: "phi_deg",
                why: format!(
                    "{phi_deg} deg is not one of the calibration set's orientations {:?}",
                    options.phis_deg
                ),
            });
        }
        let set = CalibrationSet::design(robot, options)?;
        let visits = set
            .at_phi(phi_deg)
            .flat_map(|p| {
                (0..reps).map(move |rep| Visit {
                    pose_id: p.pose_id,
                    rep,
                    set: p.set,
                    target: p.pose,
                })
            })
            .collect();
        Ok(StaticDesign {
            kind: ExperimentKind::Repeatability,
            set,
            reps,
            visits,
            timing,
            origin: Pose::default(),
            phi_deg: Some(phi_deg),
        })
    }
}

/// A path of the paths experiment, with the geometry the annotator recognises its rows by.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PathShape {
    /// A full circle at constant orientation.
    Circle {
        /// Centre, mm.
        centre: [f64; 2],
        /// Radius, mm.
        radius_mm: f64,
        /// Orientation, deg.
        phi_deg: f64,
    },
    /// An axis-aligned square at constant orientation.
    Square {
        /// Centre, mm.
        centre: [f64; 2],
        /// Side, mm.
        side_mm: f64,
        /// Orientation, deg.
        phi_deg: f64,
    },
}

impl PathShape {
    /// The paper's circle: radius 50 mm at the workspace centre, phi = 0 (run at 50 mm/s by
    /// `pcr_control::paper_circle`).
    pub const PAPER_CIRCLE: PathShape = PathShape::Circle {
        centre: [0.0, 0.0],
        radius_mm: 50.0,
        phi_deg: 0.0,
    };

    /// The paper's square: side 50 mm centred on the origin, phi = 0 (rest-to-rest sides at
    /// up to 50 mm/s by `pcr_control::paper_square`).
    pub const PAPER_SQUARE: PathShape = PathShape::Square {
        centre: [0.0, 0.0],
        side_mm: 50.0,
        phi_deg: 0.0,
    };

    /// The `segment` label of its rows.
    pub fn name(&self) -> &'static str {
        match self {
            PathShape::Circle { .. } => "circle",
            PathShape::Square { .. } => "square",
        }
    }

    /// Where the path starts (x mm, y mm): the circle at `centre + (radius, 0)` (as
    /// `pcr_control::Move::Circle` does), the square at its corner `centre + (side/2, -side/2)`
    /// (as `pcr_control::paper_square` does).
    pub fn start(&self) -> [f64; 2] {
        match *self {
            PathShape::Circle {
                centre, radius_mm, ..
            } => [centre[0] + radius_mm, centre[1]],
            PathShape::Square {
                centre, side_mm, ..
            } => [centre[0] + 0.5 * side_mm, centre[1] - 0.5 * side_mm],
        }
    }

    /// The orientation of the path, deg.
    pub fn phi_deg(&self) -> f64 {
        match *self {
            PathShape::Circle { phi_deg, .. } | PathShape::Square { phi_deg, .. } => phi_deg,
        }
    }

    /// Whether a planned pose (x mm, y mm, phi deg) lies on the path within the tolerances.
    pub fn contains(&self, p: [f64; 3], tol_mm: f64, tol_deg: f64) -> bool {
        match *self {
            PathShape::Circle {
                centre,
                radius_mm,
                phi_deg,
            } => {
                (p[2] - phi_deg).abs() <= tol_deg
                    && ((p[0] - centre[0]).hypot(p[1] - centre[1]) - radius_mm).abs() <= tol_mm
            }
            PathShape::Square {
                centre,
                side_mm,
                phi_deg,
            } => {
                let h = 0.5 * side_mm;
                let (dx, dy) = ((p[0] - centre[0]).abs(), (p[1] - centre[1]).abs());
                // distance from the perimeter of the square
                let d = if dx <= h && dy <= h {
                    (h - dx).min(h - dy)
                } else {
                    (dx - h).max(0.0).hypot((dy - h).max(0.0))
                };
                (p[2] - phi_deg).abs() <= tol_deg && d <= tol_mm
            }
        }
    }
}

/// The paths experiment: the paper's circle, then its square.
#[derive(Debug, Clone, PartialEq)]
pub struct PathsDesign {
    /// The paths in the order they are run.
    pub paths: Vec<PathShape>,
}

impl Default for PathsDesign {
    fn default() -> Self {
        PathsDesign {
            paths: vec![PathShape::PAPER_CIRCLE, PathShape::PAPER_SQUARE],
        }
    }
}

/// Options of the backlash experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct BacklashOptions {
    /// Motors excited, 1..=3, in order.
    pub motors: Vec<u8>,
    /// Largest step count N: blocks of n = 1, 2, ..., N steps per motor.
    pub max_steps: u32,
    /// Forth-and-back periods per block.
    pub periods: u32,
    /// Excitation frequency, Hz: forth at t, back at t + 1/(2 f), forth again at t + 1/f.
    pub freq_hz: f64,
    /// Rest at home after each block, s.
    pub rest_s: f64,
    /// Acceleration of the joint moves, steps/s^2 (default 1e6: with the jerk of 1e9 steps/s^3
    /// a move of n = 1..8 steps takes 3 to 15 ms, i.e. runs at the step-rate limit and ends
    /// within one 20 ms cycle).
    pub joint_acceleration: f64,
    /// Jerk of the joint moves, steps/s^3.
    pub joint_jerk: f64,
}

impl Default for BacklashOptions {
    fn default() -> Self {
        BacklashOptions {
            motors: vec![1, 2, 3],
            max_steps: 8,
            periods: 8,
            freq_hz: 0.5,
            rest_s: 1.0,
            joint_acceleration: 1.0e6,
            joint_jerk: 1.0e9,
        }
    }
}

/// One block of the backlash experiment: `periods` forth-and-back moves of `amplitude_steps`
/// on `motor`, the others at home.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BacklashBlock {
    /// Motor, 1..=3.
    pub motor: u8,
    /// Step count n of the forth move (the back move returns to home).
    pub amplitude_steps: u32,
}

/// The backlash experiment: blocks motor by motor, n = 1..N each, from the home motor
/// positions.
#[derive(Debug, Clone, PartialEq)]
pub struct BacklashDesign {
    /// The options.
    pub options: BacklashOptions,
    /// Home motor positions of the model (IK of (0, 0, 0), rounded), steps.
    pub home_steps: [i32; 3],
    /// The blocks in order.
    pub blocks: Vec<BacklashBlock>,
}

impl BacklashDesign {
    /// The design for the model `robot`.
    pub fn new(robot: &Robot, options: &BacklashOptions) -> Result<Self, DesignError> {
        let opt = |option, why: String| Err(DesignError::Option { option, why });
        if options.motors.is_empty() || options.motors.iter().any(|m| !(1..=3).contains(m)) {
            return opt("motors", format!("{:?} (1, 2 or 3)", options.motors));
        }
        if options.max_steps == 0 {
            return opt("max_steps", "0 (>= 1)".into());
        }
        if options.periods == 0 {
            return opt("periods", "0 (>= 1)".into());
        }
        if !(options.freq_hz.is_finite() && options.freq_hz > 0.0) {
            return opt("freq_hz", format!("{} (> 0)", options.freq_hz));
        }
        if !(options.rest_s.is_finite() && options.rest_s >= 0.0) {
            return opt("rest_s", format!("{} (>= 0)", options.rest_s));
        }
        for (o, v) in [
            ("joint_acceleration", options.joint_acceleration),
            ("joint_jerk", options.joint_jerk),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return opt(o, format!("{v} (> 0)"));
            }
        }
        let mut home_steps = [0i32; 3];
        for i in 0..3 {
            let q = robot
                .kappa_to_steps(i, robot.home_kappa[i])
                .map_err(|e| DesignError::Robot(format!("home steps of motor {}: {e}", i + 1)))?;
            home_steps[i] = q.round() as i32;
        }
        let blocks = options
            .motors
            .iter()
            .flat_map(|&motor| {
                (1..=options.max_steps).map(move |n| BacklashBlock {
                    motor,
                    amplitude_steps: n,
                })
            })
            .collect();
        Ok(BacklashDesign {
            options: options.clone(),
            home_steps,
            blocks,
        })
    }
}

/// A design of any of the four experiments.
#[derive(Debug, Clone, PartialEq)]
pub enum Design {
    /// Calibration or repeatability.
    Static(StaticDesign),
    /// The circle and the square.
    Paths(PathsDesign),
    /// The backlash blocks.
    Backlash(BacklashDesign),
}

fn list(v: impl IntoIterator<Item = String>) -> String {
    v.into_iter().collect::<Vec<_>>().join(" ")
}

impl Design {
    /// Which experiment.
    pub fn kind(&self) -> ExperimentKind {
        match self {
            Design::Static(d) => d.kind,
            Design::Paths(_) => ExperimentKind::Paths,
            Design::Backlash(_) => ExperimentKind::Backlash,
        }
    }

    /// The recording's metadata of the design: `experiment`, `seed` (of the split; also written
    /// for the experiments without one) and the design parameters (keys in docs/experiments.md).
    pub fn metadata(&self, seed: u64) -> Vec<(String, String)> {
        let num = pcr_recording::number;
        let mut m = vec![
            ("experiment".to_string(), self.kind().as_str().to_string()),
            ("seed".to_string(), seed.to_string()),
        ];
        let mut add = |k: &str, v: String| m.push((k.to_string(), v));
        match self {
            Design::Static(d) => {
                let o = &d.set.options;
                add("phis_deg", list(o.phis_deg.iter().map(|v| num(*v))));
                add("scales", list(o.scales.iter().map(|v| num(*v))));
                add("points_per_boundary", o.points.to_string());
                add("test_per_group", o.test_per_group.to_string());
                add("split_seed", o.seed.to_string());
                add("singularity_margin", num(o.singularity_margin));
                add(
                    "boundary",
                    format!(
                        "own workspace per orientation, {} rays from the origin, step {} mm, \
                         bisected to {} mm; points from polar angle 0, counter-clockwise",
                        o.boundary.rays, o.boundary.step_mm, o.boundary.tol_mm
                    ),
                );
                add("poses", d.set.poses.len().to_string());
                if let Some(phi) = d.phi_deg {
                    add("repeatability_phi_deg", num(phi));
                }
                add("reps", d.reps.to_string());
                add("visits", d.visits.len().to_string());
                add("speed_mm_s", num(d.timing.speed_mm_s));
                add("settle_s", num(d.timing.settle_s));
                add("measure_s", num(d.timing.measure_s));
                add(
                    "origin",
                    format!(
                        "{} {} {}",
                        num(d.origin.x),
                        num(d.origin.y),
                        num(d.origin.phi.to_degrees())
                    ),
                );
            }
            Design::Paths(p) => {
                add("paths", list(p.paths.iter().map(|s| s.name().to_string())));
                for s in &p.paths {
                    match *s {
                        PathShape::Circle {
                            centre,
                            radius_mm,
                            phi_deg,
                        } => add(
                            "circle",
                            format!(
                                "centre {} {} mm, radius {} mm, phi {} deg, 50 mm/s",
                                num(centre[0]),
                                num(centre[1]),
                                num(radius_mm),
                                num(phi_deg)
                            ),
                        ),
                        PathShape::Square {
                            centre,
                            side_mm,
                            phi_deg,
                        } => add(
                            "square",
                            format!(
                                "centre {} {} mm, side {} mm, phi {} deg, rest-to-rest sides at \
                                 up to 50 mm/s",
                                num(centre[0]),
                                num(centre[1]),
                                num(side_mm),
                                num(phi_deg)
                            ),
                        ),
                    }
                }
            }
            Design::Backlash(b) => {
                let o = &b.options;
                add(
                    "home_steps",
                    list(b.home_steps.iter().map(ToString::to_string)),
                );
                add("motors", list(o.motors.iter().map(ToString::to_string)));
                add("max_steps", o.max_steps.to_string());
                add("periods", o.periods.to_string());
                add("freq_hz", num(o.freq_hz));
                add("rest_s", num(o.rest_s));
                add("joint_acceleration_steps_s2", num(o.joint_acceleration));
                add("joint_jerk_steps_s3", num(o.joint_jerk));
                add("blocks", b.blocks.len().to_string());
            }
        }
        m
    }
}
