//! The planner's jerk-limited paths as the chain's [`SetpointSource`].
//!
//! Each [`Move`] becomes a `pcr-planner` path (a line, or an approach line plus a full circle)
//! with a jerk-limited speed profile from rest to rest; dwells hold the pose. `load` checks the
//! whole program with [`Robot::check_motion`] (IK in the working mode, joint and bending limits,
//! distance from singularity, drive step rates) sampled every 2 ms, and refuses a program the
//! robot cannot follow. `sample` evaluates the planned profile: no allocation.
//!
//! Composite programs: each run of [`Move::PathLine`] / [`Move::Arc`] moves that continue each
//! other becomes one [`CompositeMotion`] (continuous speed through tangent junctions, corners
//! rounded by the blend radius), checked every 2 ms; a rejection names the move of the
//! offending segment. A [`Move::Joint`] becomes a synchronised [`JointMove`] of the motors whose
//! poses (FK, every [`JOINT_TABLE_DT_S`]) are tabulated and checked at load time; `sample`
//! interpolates the table.

use crate::setpoint::{active_piece, Braking, Move, PlanError, SetpointSource};
use pcr_kinematics::{CheckOptions, Pose, Robot};
use pcr_planner::composite::{
    CompositeError, CompositeLimits, CompositeMotion, CompositePath, SegmentSource,
};
use pcr_planner::joint::{JointError, JointLimits, JointMove};
use pcr_planner::path::{Path, Pose as PPose};
use pcr_planner::program::JointSettings;
use pcr_planner::speed::{SpeedLimits, SpeedProfile};

/// Path acceleration and jerk limits of the chain's motions (mm/s^2, mm/s^3).
#[derive(Debug, Clone, Copy)]
pub struct MotionLimits {
    /// Path acceleration limit, mm/s^2.
    pub amax: f64,
    /// Path jerk limit, mm/s^3.
    pub jmax: f64,
}

impl Default for MotionLimits {
    fn default() -> Self {
        MotionLimits {
            amax: 200.0,
            jmax: 2000.0,
        }
    }
}

// Pieces live in a Vec built at load time; their size does not matter on the hot path.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy)]
enum Piece {
    Move {
        path: Path,
        profile: SpeedProfile,
    },
    Hold(Pose),
    /// Index into `PlannerSource::composites`.
    Composite(usize),
    /// `n` entries of `PlannerSource::joint_table` from `first`.
    Joint {
        first: usize,
        n: usize,
    },
}

/// Jerk-limited setpoints from the in-house planner.
#[derive(Debug, Clone)]
pub struct PlannerSource {
    robot: Robot,
    limits: MotionLimits,
    /// (start time s, duration s, piece)
    pieces: Vec<(f64, f64, Piece)>,
    /// The composite motions of the program.
    composites: Vec<CompositeMotion>,
    /// The (time in the move s, pose) tables of the joint moves, one after another.
    joint_table: Vec<(f64, Pose)>,
    start: Pose,
    /// Peak path speed of the loaded program, mm/s.
    peak_speed: f64,
    /// What `load` checks (singularity margin, fraction of the step rates).
    check: CheckOptions,
}

fn pp(p: &Pose) -> PPose {
    PPose::new(p.x, p.y, p.phi)
}

fn kp(p: &PPose) -> Pose {
    Pose::new(p.x, p.y, p.phi)
}

impl PlannerSource {
    /// A source for `robot` with the given path limits.
    pub fn new(robot: Robot, limits: MotionLimits) -> Self {
        PlannerSource {
            robot,
            limits,
            pieces: Vec::new(),
            composites: Vec::new(),
            joint_table: Vec::new(),
            start: Pose::default(),
            peak_speed: 0.0,
            check: CheckOptions::default(),
        }
    }

    /// The source checking programs with `check` (singularity margin, fraction of each drive's
    /// step rate; joint moves use that fraction of the step rates too) instead of the defaults.
    pub fn with_check_options(mut self, check: CheckOptions) -> Self {
        self.check = check;
        self
    }

    /// The path speed limit at program time `tau_s` inside a composite motion (its segment's
    /// own limit), mm/s; NaN elsewhere (rest-to-rest moves, dwells, joint moves).
    pub fn speed_limit_at(&self, tau_s: f64) -> f64 {
        if self.pieces.is_empty() || tau_s < 0.0 {
            return f64::NAN;
        }
        let (t0, d, piece) = &self.pieces[active_piece(&self.pieces, tau_s)];
        match piece {
            Piece::Composite(i) if tau_s - t0 < *d => {
                let m = &self.composites[*i];
                m.segment_speed_limit(m.sample(tau_s - t0).segment)
            }
            _ => f64::NAN,
        }
    }

    /// Plans the composite motion of `group` (a line or arc, then the lines and arcs that
    /// continue it; `first` is the program index of its first move) from `at` at program time
    /// `t0` s, and checks it every 2 ms. Returns the motion and its peak speed limit, mm/s.
    fn plan_composite(
        &self,
        group: &[Move],
        first: usize,
        at: Pose,
        t0: f64,
    ) -> Result<(CompositeMotion, f64), PlanError> {
        let lim = match group[0] {
            Move::PathLine { limits, .. } | Move::Arc { limits, .. } => limits,
            _ => {
                return Err(PlanError::Invalid {
                    index: first,
                    why: "a composite path starts with a line or an arc".into(),
                })
            }
        };
        let invalid = |index: usize, e: &dyn std::fmt::Display| PlanError::Invalid {
            index,
            why: e.to_string(),
        };
        let last = first + group.len() - 1;
        let mut path = CompositePath::with_rotation_radius(pp(&at), lim.rotation_radius)
            .map_err(|e| invalid(first, &e))?;
        let mut peak = lim.speed;
        for (k, m) in group.iter().enumerate() {
            let err = |e: CompositeError| invalid(first + k, &composite_error(&e));
            match *m {
                Move::PathLine {
                    to,
                    phi,
                    speed_mm_s,
                    ..
                } => {
                    let phi = phi.unwrap_or(path.end().phi);
                    path.line_to(PPose::new(to[0], to[1], phi), speed_mm_s)
                        .map_err(err)?;
                    peak = peak.max(speed_mm_s.unwrap_or(0.0));
                }
                Move::Arc {
                    centre,
                    sweep_rad,
                    phi,
                    speed_mm_s,
                    ..
                } => {
                    let phi = phi.unwrap_or(path.end().phi);
                    path.arc_around(centre[0], centre[1], sweep_rad, phi, speed_mm_s)
                        .map_err(err)?;
                    peak = peak.max(speed_mm_s.unwrap_or(0.0));
                }
                _ => {
                    return Err(PlanError::Invalid {
                        index: first + k,
                        why: "only lines and arcs form a composite path".into(),
                    })
                }
            }
        }
        // Junction j joins primitives j - 1 and j; a line's own radius rounds the corner at its
        // end.
        let path = path
            .blend_corners(|j| match group[j - 1] {
                Move::PathLine {
                    blend_radius_mm: Some(r),
                    ..
                } => r,
                _ => lim.blend_radius,
            })
            .map_err(|e| invalid(first, &format!("moves {first}..={last}: {e}")))?;
        let motion = CompositeMotion::plan(
            &path,
            &CompositeLimits {
                vmax: lim.speed,
                amax: lim.acceleration,
                jmax: lim.jerk,
            },
        )
        .map_err(|e| invalid(first, &format!("moves {first}..={last}: {e}")))?;
        let dur = motion.duration();
        let dt = 0.002;
        let n = (dur / dt).ceil().max(1.0) as usize;
        let mut samples = Vec::with_capacity(n + 1);
        for k in 0..=n {
            let t = if k == n { dur } else { k as f64 * dt };
            if samples.last().is_some_and(|(tp, _)| t0 + t <= *tp) {
                continue;
            }
            samples.push((t0 + t, kp(&motion.sample(t).pose)));
        }
        if let Err(e) = self.robot.check_motion(samples, &self.check) {
            let seg = motion.sample(e.t - t0).segment;
            let index = match path.segments().get(seg).map(|s| s.source()) {
                Some(SegmentSource::Primitive(k)) | Some(SegmentSource::Blend(k)) => first + k,
                None => first,
            };
            return Err(PlanError::Rejected {
                index,
                why: e.to_string(),
            });
        }
        Ok((motion, peak))
    }

    /// Plans the joint move `index` to `target` steps from the pose `at` (motor positions
    /// `at_steps` if known, else from IK), checks it every 2 ms and appends its (time in the
    /// move s, pose) table to `table`. Returns the duration, s, and the peak position speed,
    /// mm/s.
    fn plan_joint(
        &self,
        index: usize,
        at: Pose,
        at_steps: Option<[f64; 3]>,
        target: [f64; 3],
        settings: &JointSettings,
        table: &mut Vec<(f64, Pose)>,
    ) -> Result<(f64, f64), PlanError> {
        let invalid = |e: &dyn std::fmt::Display| PlanError::Invalid {
            index,
            why: e.to_string(),
        };
        let from = match at_steps {
            Some(q) => q,
            None => {
                let s = self.robot.ik(&at).map_err(|e| PlanError::Rejected {
                    index,
                    why: format!("the start pose has no IK solution: {e}"),
                })?;
                let mut q = [0.0; 3];
                for i in 0..3 {
                    q[i] = self
                        .robot
                        .kappa_to_steps(i, s.kappa[i])
                        .map_err(|e| invalid(&e))?;
                }
                q
            }
        };
        let mut limits = JointLimits::from_config(
            self.robot.config(),
            self.check.rate_fraction,
            settings.acceleration,
            settings.jerk,
        )
        .map_err(|e| invalid(&e))?;
        // The FK/IK round trip of the check must never see a rate above the limit.
        for r in &mut limits.rate {
            *r *= 1.0 - 1e-6;
        }
        let mv = JointMove::plan(from, target, &limits).map_err(|e| invalid(&e))?;
        let samples = mv
            .check(&self.robot, JOINT_TABLE_DT_S, &at, &self.check)
            .map_err(|e| match e {
                JointError::Rejected(r) => PlanError::Rejected {
                    index,
                    why: r.to_string(),
                },
                other => invalid(&other),
            })?;
        let mut peak: f64 = 0.0;
        for w in samples.windows(2) {
            let dt = w[1].0 - w[0].0;
            if dt > 0.0 {
                peak = peak.max(w[1].1.position_distance(&w[0].1) / dt);
            }
        }
        table.extend(samples);
        Ok((mv.duration(), peak))
    }
}

/// Sampling period of the pose tables of joint moves (FK at load time), s.
pub const JOINT_TABLE_DT_S: f64 = 0.002;

fn composite_error(e: &CompositeError) -> String {
    match e {
        CompositeError::ZeroLength { .. } => "it ends where it starts (no length)".into(),
        CompositeError::ZeroRadius { .. } => "the centre is at the start point (radius 0)".into(),
        other => other.to_string(),
    }
}

/// The pose of `piece` at `t` s into it. Does not allocate.
fn piece_pose(
    composites: &[CompositeMotion],
    joint_table: &[(f64, Pose)],
    piece: &Piece,
    t: f64,
) -> Pose {
    match piece {
        Piece::Move { path, profile } => kp(&path.sample(profile.at(t).p).0),
        Piece::Hold(p) => *p,
        Piece::Composite(i) => kp(&composites[*i].sample(t).pose),
        Piece::Joint { first, n } => {
            let table = &joint_table[*first..*first + *n];
            if table.len() < 2 {
                return table[0].1;
            }
            // Samples every JOINT_TABLE_DT_S from 0, the last at the end of the move.
            let k = ((t / JOINT_TABLE_DT_S).max(0.0) as usize).min(table.len() - 2);
            let (t0, a) = table[k];
            let (t1, b) = table[k + 1];
            let w = if t1 > t0 {
                ((t - t0) / (t1 - t0)).clamp(0.0, 1.0)
            } else {
                1.0
            };
            Pose::new(
                a.x + w * (b.x - a.x),
                a.y + w * (b.y - a.y),
                a.phi + w * (b.phi - a.phi),
            )
        }
    }
}

impl SetpointSource for PlannerSource {
    fn name(&self) -> &str {
        "pcr-planner"
    }

    fn load(&mut self, moves: &[Move], start: Pose) -> Result<f64, PlanError> {
        if moves.is_empty() {
            return Err(PlanError::Empty);
        }
        let lim = |v: f64| SpeedLimits::JerkLimited {
            vmax: v,
            amax: self.limits.amax,
            jmax: self.limits.jmax,
        };
        let mut pieces: Vec<(f64, f64, Piece, usize)> = Vec::new();
        let mut composites: Vec<CompositeMotion> = Vec::new();
        let mut joint_table: Vec<(f64, Pose)> = Vec::new();
        let mut t = 0.0;
        let mut at = start;
        // Exact motor positions after a joint move (None: from IK of `at`).
        let mut at_steps: Option<[f64; 3]> = None;
        let mut peak_speed: f64 = 0.0;
        let mut index = 0;
        while index < moves.len() {
            let m = &moves[index];
            let bad = |what| PlanError::InvalidMove { index, what };
            let mut add = |path: Path, v: f64, t: &mut f64| -> Result<(), PlanError> {
                let profile =
                    SpeedProfile::plan(path.length(), &lim(v)).map_err(|_| bad("speed_mm_s"))?;
                let d = profile.duration();
                pieces.push((*t, d, Piece::Move { path, profile }, index));
                *t += d;
                Ok(())
            };
            if m.is_path_segment() {
                let mut end = index + 1;
                while end < moves.len()
                    && matches!(
                        moves[end],
                        Move::PathLine {
                            continues: true,
                            ..
                        } | Move::Arc {
                            continues: true,
                            ..
                        }
                    )
                {
                    end += 1;
                }
                let (motion, speed) = self.plan_composite(&moves[index..end], index, at, t)?;
                let d = motion.duration();
                at = kp(&motion.path().end());
                at_steps = None;
                peak_speed = peak_speed.max(speed);
                pieces.push((t, d, Piece::Composite(composites.len()), index));
                composites.push(motion);
                t += d;
                index = end;
                continue;
            }
            match *m {
                Move::Line { to, speed_mm_s } => {
                    if !(speed_mm_s.is_finite() && speed_mm_s > 0.0) {
                        return Err(bad("speed_mm_s"));
                    }
                    let path = Path::line(pp(&at), pp(&to)).map_err(|_| bad("to"))?;
                    add(path, speed_mm_s, &mut t)?;
                    at = to;
                    at_steps = None;
                    peak_speed = peak_speed.max(speed_mm_s);
                }
                Move::Circle {
                    centre,
                    radius_mm,
                    speed_mm_s,
                    phi,
                } => {
                    if !(speed_mm_s.is_finite() && speed_mm_s > 0.0) {
                        return Err(bad("speed_mm_s"));
                    }
                    let circle = Path::circle(centre[0], centre[1], radius_mm, 0.0, true, phi)
                        .map_err(|_| bad("radius_mm"))?;
                    let p0 = kp(&circle.start());
                    if at.position_distance(&p0) > 1e-9 || (at.phi - p0.phi).abs() > 1e-12 {
                        let approach =
                            Path::line(pp(&at), circle.start()).map_err(|_| bad("centre"))?;
                        add(approach, speed_mm_s, &mut t)?;
                    }
                    add(circle, speed_mm_s, &mut t)?;
                    at = p0;
                    at_steps = None;
                    peak_speed = peak_speed.max(speed_mm_s);
                }
                Move::Dwell { duration_s } => {
                    if !(duration_s.is_finite() && duration_s >= 0.0) {
                        return Err(bad("duration_s"));
                    }
                    pieces.push((t, duration_s, Piece::Hold(at), index));
                    t += duration_s;
                }
                Move::Joint { steps, limits } => {
                    let target = steps.map(|s| s as f64);
                    let first = joint_table.len();
                    let (d, speed) =
                        self.plan_joint(index, at, at_steps, target, &limits, &mut joint_table)?;
                    let n = joint_table.len() - first;
                    at = joint_table[joint_table.len() - 1].1;
                    at_steps = Some(target);
                    peak_speed = peak_speed.max(speed);
                    pieces.push((t, d, Piece::Joint { first, n }, index));
                    t += d;
                }
                Move::PathLine { .. } | Move::Arc { .. } => unreachable!("handled above"),
            }
            index += 1;
        }
        pieces.push((t, 0.0, Piece::Hold(at), moves.len() - 1));
        // Check the rest-to-rest moves finely before accepting the program (composites and
        // joint moves were checked when planned).
        let dt = 0.002;
        for (t0, d, piece, index) in &pieces {
            if !matches!(piece, Piece::Move { .. }) {
                continue;
            }
            let n = (d / dt).ceil().max(1.0) as usize;
            let samples = (0..=n).map(|k| {
                let tk = (k as f64 * dt).min(*d);
                (t0 + tk, piece_pose(&composites, &joint_table, piece, tk))
            });
            let mut last = f64::NEG_INFINITY;
            let samples: Vec<_> = samples
                .filter(|(tt, _)| {
                    let keep = *tt > last;
                    last = last.max(*tt);
                    keep
                })
                .collect();
            self.robot
                .check_motion(samples, &self.check)
                .map_err(|e| PlanError::Rejected {
                    index: *index,
                    why: e.to_string(),
                })?;
        }
        self.peak_speed = peak_speed;
        self.pieces = pieces.into_iter().map(|(a, b, c, _)| (a, b, c)).collect();
        self.composites = composites;
        self.joint_table = joint_table;
        self.start = start;
        Ok(t)
    }

    fn braking(&self) -> Braking {
        // Half the path limits: the program's own acceleration adds to the braking.
        Braking {
            peak_speed: self.peak_speed.max(1.0),
            amax: 0.5 * self.limits.amax,
            jmax: 0.5 * self.limits.jmax,
        }
    }

    fn sample(&self, tau_s: f64) -> Pose {
        if self.pieces.is_empty() || tau_s <= 0.0 {
            return self.start;
        }
        let (t0, d, piece) = &self.pieces[active_piece(&self.pieces, tau_s)];
        piece_pose(
            &self.composites,
            &self.joint_table,
            piece,
            (tau_s - t0).clamp(0.0, *d),
        )
    }

    fn speed(&self, tau_s: f64) -> f64 {
        if self.pieces.is_empty() || tau_s <= 0.0 {
            return 0.0;
        }
        let (t0, d, piece) = &self.pieces[active_piece(&self.pieces, tau_s)];
        let t = tau_s - t0;
        if t >= *d {
            return 0.0;
        }
        match piece {
            Piece::Move { profile, .. } => profile.at(t).v,
            Piece::Hold(_) => 0.0,
            Piece::Composite(i) => self.composites[*i].sample(t).speed,
            Piece::Joint { first, n } => {
                // The table's slope (combined metric, the path's rotation radius of 50 mm/rad).
                let table = &self.joint_table[*first..*first + *n];
                if table.len() < 2 {
                    return 0.0;
                }
                let k = ((t / JOINT_TABLE_DT_S).max(0.0) as usize).min(table.len() - 2);
                let ((ta, a), (tb, b)) = (table[k], table[k + 1]);
                let r = pcr_planner::path::DEFAULT_ROTATION_RADIUS_MM;
                let dist =
                    ((b.x - a.x).powi(2) + (b.y - a.y).powi(2) + (r * (b.phi - a.phi)).powi(2))
                        .sqrt();
                if tb > ta {
                    dist / (tb - ta)
                } else {
                    0.0
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::setpoint::paper_program;

    #[test]
    fn the_papers_program_is_planned_and_checked() {
        let mut s = PlannerSource::new(Robot::nominal(), MotionLimits::default());
        let d = s.load(&paper_program(), Pose::default()).unwrap();
        assert!(d > 2.0 * std::f64::consts::PI);
        assert_eq!(s.sample(0.0), Pose::default());
        assert!(s.sample(d + 1.0).position_distance(&Pose::default()) < 1e-9);
        // jerk-limited: the speed rises gradually from rest
        let v0 = s.sample(0.2 + 0.02).position_distance(&s.sample(0.2));
        assert!(v0 < 0.05, "{v0}");
    }

    #[test]
    fn a_program_outside_the_workspace_is_rejected_with_the_move() {
        let mut s = PlannerSource::new(Robot::nominal(), MotionLimits::default());
        let moves = [
            Move::Dwell { duration_s: 0.1 },
            Move::Line {
                to: Pose::new(150.0, 0.0, 0.0),
                speed_mm_s: 20.0,
            },
        ];
        let e = s.load(&moves, Pose::default()).unwrap_err();
        assert!(matches!(e, PlanError::Rejected { index: 1, .. }), "{e}");
        assert!(e.to_string().contains("unreachable"), "{e}");
    }

    fn slot_moves() -> Vec<Move> {
        let file = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/programs/slot.toml");
        let p = pcr_planner::program::load(file, &Default::default()).unwrap();
        crate::setpoint::moves_of_program(&p)
    }

    #[test]
    fn the_slot_program_runs_without_stopping_and_ends_home() {
        let moves = slot_moves();
        // one composite of six segments, a dwell, a line, two joint moves
        assert!(moves[1..6].iter().all(|m| matches!(
            m,
            Move::PathLine {
                continues: true,
                ..
            } | Move::Arc {
                continues: true,
                ..
            }
        )));
        // and through the wire format unchanged
        let cmd = crate::command_of_moves(7, &moves).unwrap();
        assert_eq!(crate::moves_of(&cmd).unwrap(), moves);
        let mut s = PlannerSource::new(Robot::nominal(), MotionLimits::default());
        let d = s.load(&moves, Pose::default()).unwrap();
        let (t0, dc, piece) = s.pieces[0];
        assert!(matches!(piece, Piece::Composite(0)) && t0 == 0.0);
        // 20 ms samples: moving all the way through the composite (tangent junctions and the
        // blended corner), at rest only at its ends
        let n = (dc / 0.02).floor() as usize;
        let mut vmin = f64::INFINITY;
        for k in 1..n - 1 {
            let (a, b) = (k as f64 * 0.02, (k + 1) as f64 * 0.02);
            let v = s.sample(b).position_distance(&s.sample(a)) / 0.02;
            vmin = vmin.min(v);
            assert!(v > 0.0, "stopped at {a} s");
            assert!(v < 40.0 * 1.01, "{v} mm/s at {a} s");
        }
        // inside the slot (after the approach) the speed stays high
        let slot_start = (15.0 / 40.0 + 0.5) / 0.02;
        let mut vslot = f64::INFINITY;
        for k in slot_start as usize..n - 60 {
            let (a, b) = (k as f64 * 0.02, (k + 1) as f64 * 0.02);
            vslot = vslot.min(s.sample(b).position_distance(&s.sample(a)) / 0.02);
        }
        assert!(vslot > 20.0, "{vslot}");
        assert!(s.sample(dc).position_distance(&Pose::new(0.0, -15.0, 0.0)) < 1e-9);
        // the end: the joint move back to 176 steps on each motor, i.e. home
        let home = JointMove::pose_of(&Robot::nominal(), &[176.0; 3], &Pose::default()).unwrap();
        let end = s.sample(d + 1.0);
        assert!(end.position_distance(&home) < 1e-6, "{end:?} {home:?}");
        assert!(end.position_distance(&Pose::default()) < 0.5, "{end:?}");
        assert!(s.braking().peak_speed >= 40.0);
    }

    #[test]
    fn a_joint_move_reaches_the_pose_of_its_target_steps() {
        let robot = Robot::nominal();
        let limits = JointSettings {
            acceleration: 2000.0,
            jerk: 20000.0,
        };
        let moves = [Move::Joint {
            steps: [260, 140, 176],
            limits,
        }];
        let mut s = PlannerSource::new(robot.clone(), MotionLimits::default());
        let d = s.load(&moves, Pose::default()).unwrap();
        assert!(d > 0.1);
        let want = JointMove::pose_of(&robot, &[260.0, 140.0, 176.0], &Pose::default()).unwrap();
        assert!(s.sample(d).position_distance(&want) < 1e-9);
        assert!((s.sample(d).phi - want.phi).abs() < 1e-9);
        // continuous: no jump between 2 ms samples
        let mut t = 0.0;
        while t < d {
            assert!(s.sample(t + 0.002).position_distance(&s.sample(t)) < 0.5);
            t += 0.002;
        }
        // an unreachable joint target is refused naming the move
        let moves = [
            Move::Dwell { duration_s: 0.1 },
            Move::Joint {
                steps: [100_000, 0, 0],
                limits,
            },
        ];
        let e = s.load(&moves, Pose::default()).unwrap_err();
        assert!(e.to_string().starts_with("move 1:"), "{e}");
    }

    #[test]
    fn a_composite_outside_the_workspace_names_the_segment() {
        let lim = pcr_planner::program::PathLimits {
            speed: 20.0,
            acceleration: 200.0,
            jerk: 2000.0,
            blend_radius: 0.0,
            rotation_radius: 50.0,
        };
        let line = |x: f64, continues| Move::PathLine {
            to: [x, 0.0],
            phi: None,
            speed_mm_s: None,
            blend_radius_mm: None,
            continues,
            limits: lim,
        };
        let moves = [line(10.0, false), line(20.0, true), line(150.0, true)];
        let mut s = PlannerSource::new(Robot::nominal(), MotionLimits::default());
        let e = s.load(&moves, Pose::default()).unwrap_err();
        assert!(matches!(e, PlanError::Rejected { index: 2, .. }), "{e}");
        // a zero-length segment is invalid, named
        let moves = [line(10.0, false), line(10.0, true)];
        let e = s.load(&moves, Pose::default()).unwrap_err();
        assert!(matches!(e, PlanError::Invalid { index: 1, .. }), "{e}");
    }
}
