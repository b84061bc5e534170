//! The planner's jerk-limited paths as the chain's [`SetpointSource`].
//!
//! Each [`Move`] becomes a `pcr-planner` path (a line, or an approach line plus a full circle)
//! with a jerk-limited speed profile from rest to rest; dwells hold the pose. `load` checks the
//! whole program with [`Robot::check_motion`] (IK in the working mode, joint and bending limits,
//! distance from singularity, drive step rates) sampled every 2 ms, and refuses a program the
//! robot cannot follow. `sample` evaluates the planned profile: no allocation.

use crate::setpoint::{active_piece, Braking, Move, PlanError, SetpointSource};
use pcr_kinematics::{CheckOptions, Pose, Robot};
use pcr_planner::path::{Path, Pose as PPose};
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
    Move { path: Path, profile: SpeedProfile },
    Hold(Pose),
}

/// Jerk-limited setpoints from the in-house planner.
#[derive(Debug, Clone)]
pub struct PlannerSource {
    robot: Robot,
    limits: MotionLimits,
    /// (start time s, duration s, piece)
    pieces: Vec<(f64, f64, Piece)>,
    start: Pose,
    /// Peak path speed of the loaded program, mm/s.
    peak_speed: f64,
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
            start: Pose::default(),
            peak_speed: 0.0,
        }
    }

    fn piece_pose(piece: &Piece, t: f64) -> Pose {
        match piece {
            Piece::Move { path, profile } => kp(&path.sample(profile.at(t).p).0),
            Piece::Hold(p) => *p,
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
        let mut t = 0.0;
        let mut at = start;
        for (index, m) in moves.iter().enumerate() {
            let bad = |what| PlanError::InvalidMove { index, what };
            let mut add = |path: Path, v: f64, t: &mut f64| -> Result<(), PlanError> {
                let profile =
                    SpeedProfile::plan(path.length(), &lim(v)).map_err(|_| bad("speed_mm_s"))?;
                let d = profile.duration();
                pieces.push((*t, d, Piece::Move { path, profile }, index));
                *t += d;
                Ok(())
            };
            match *m {
                Move::Line { to, speed_mm_s } => {
                    if !(speed_mm_s.is_finite() && speed_mm_s > 0.0) {
                        return Err(bad("speed_mm_s"));
                    }
                    let path = Path::line(pp(&at), pp(&to)).map_err(|_| bad("to"))?;
                    add(path, speed_mm_s, &mut t)?;
                    at = to;
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
                }
                Move::Dwell { duration_s } => {
                    if !(duration_s.is_finite() && duration_s >= 0.0) {
                        return Err(bad("duration_s"));
                    }
                    pieces.push((t, duration_s, Piece::Hold(at), index));
                    t += duration_s;
                }
            }
        }
        pieces.push((t, 0.0, Piece::Hold(at), moves.len() - 1));
        // Check the whole program finely before accepting it.
        let dt = 0.002;
        for (t0, d, piece, index) in &pieces {
            if matches!(piece, Piece::Hold(_)) {
                continue;
            }
            let n = (d / dt).ceil().max(1.0) as usize;
            let samples = (0..=n).map(|k| {
                let tk = (k as f64 * dt).min(*d);
                (t0 + tk, Self::piece_pose(piece, tk))
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
                .check_motion(samples, &CheckOptions::default())
                .map_err(|e| PlanError::Rejected {
                    index: *index,
                    why: e.to_string(),
                })?;
        }
        self.peak_speed = moves
            .iter()
            .map(|m| match *m {
                Move::Line { speed_mm_s, .. } | Move::Circle { speed_mm_s, .. } => speed_mm_s,
                Move::Dwell { .. } => 0.0,
            })
            .fold(0.0, f64::max);
        self.pieces = pieces.into_iter().map(|(a, b, c, _)| (a, b, c)).collect();
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
        Self::piece_pose(piece, (tau_s - t0).clamp(0.0, *d))
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
}
