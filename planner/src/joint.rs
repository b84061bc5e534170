//! Joint-space moves: the three motors from their current positions (steps) to target positions,
//! time-synchronised (all motors start and finish together), jerk-limited per motor.
//!
//! [`JointMove::plan`] uses the profiler ([`crate::profiler::calculate`], 3 DoFs,
//! [`Synchronization::Time`]) with per-motor step-rate, acceleration and jerk limits
//! ([`JointLimits`], the step rates from the robot configuration's actuation section).
//! [`JointMove::sample`] evaluates it without allocation. The platform pose along the move
//! follows by forward kinematics (tendon map, then FK warm-started at the previous pose):
//! [`JointMove::check`] samples the move and runs the same checks as task-space paths
//! ([`Robot::check_motion`]: IK in the working mode, joint and bending limits, singularity margin,
//! step rates).

use crate::profiler::{calculate, Input, Limits, ProfileError, State, Synchronization, Trajectory};
use pcr_kinematics::{CheckOptions, FkError, MotionRejected, Pose as KPose, Robot};
use pcr_robot::RobotConfig;

/// Number of motors.
pub const MOTORS: usize = 3;

/// Per-motor limits of a joint move.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointLimits {
    /// Step rate, steps/s.
    pub rate: [f64; MOTORS],
    /// Acceleration, steps/s^2.
    pub accel: [f64; MOTORS],
    /// Jerk, steps/s^3.
    pub jerk: [f64; MOTORS],
}

impl JointLimits {
    /// Limits from the robot configuration: each motor's `max_step_rate` times `rate_fraction`
    /// (in (0, 1]), and the same acceleration (steps/s^2) and jerk (steps/s^3) for every motor.
    pub fn from_config(
        cfg: &RobotConfig,
        rate_fraction: f64,
        accel: f64,
        jerk: f64,
    ) -> Result<JointLimits, JointError> {
        if !(rate_fraction.is_finite() && rate_fraction > 0.0 && rate_fraction <= 1.0) {
            return Err(JointError::BadLimit {
                what: "rate fraction",
                motor: 0,
                value: rate_fraction,
            });
        }
        if cfg.legs.len() != MOTORS {
            return Err(JointError::Motors(cfg.legs.len()));
        }
        let lim = JointLimits {
            rate: std::array::from_fn(|i| cfg.legs[i].actuation.max_step_rate * rate_fraction),
            accel: [accel; MOTORS],
            jerk: [jerk; MOTORS],
        };
        lim.validate()?;
        Ok(lim)
    }

    /// Checks that every limit is a finite number > 0.
    pub fn validate(&self) -> Result<(), JointError> {
        for i in 0..MOTORS {
            for (what, value) in [
                ("step rate", self.rate[i]),
                ("acceleration", self.accel[i]),
                ("jerk", self.jerk[i]),
            ] {
                if !(value.is_finite() && value > 0.0) {
                    return Err(JointError::BadLimit {
                        what,
                        motor: i + 1,
                        value,
                    });
                }
            }
        }
        Ok(())
    }
}

/// Why a joint move could not be planned or checked.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum JointError {
    /// A limit is not a finite number > 0 (motor 0: all motors).
    #[error("joint limit {what} of motor {motor} must be a finite number > 0 (got {value})")]
    BadLimit {
        /// Which limit.
        what: &'static str,
        /// 1-based motor number (0: all).
        motor: usize,
        /// The offending value.
        value: f64,
    },
    /// A start or target position is not finite.
    #[error("{what} position of motor {motor} is not a finite number ({value})")]
    NotFinite {
        /// "start" or "target".
        what: &'static str,
        /// 1-based motor number.
        motor: usize,
        /// The offending value.
        value: f64,
    },
    /// The robot configuration does not have three legs.
    #[error("a joint move needs 3 motors, the configuration has {0}")]
    Motors(usize),
    /// Check sampling period not a finite number > 0.
    #[error("sampling period must be a finite number > 0 s (got {0})")]
    BadPeriod(f64),
    /// The profiler rejected the move.
    #[error(transparent)]
    Profile(#[from] ProfileError),
    /// No platform pose for the motor positions at a sample.
    #[error("at t = {t:.3} s, steps ({:.1}, {:.1}, {:.1}): {why}", q[0], q[1], q[2])]
    Fk {
        /// Time in the move, s.
        t: f64,
        /// Motor positions, steps.
        q: [f64; MOTORS],
        /// The FK failure.
        why: FkError,
    },
    /// A pose along the move violates a limit.
    #[error(transparent)]
    Rejected(#[from] MotionRejected),
}

/// Motor positions, rates and accelerations at one instant of a joint move.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointSample {
    /// Positions, steps (not rounded).
    pub q: [f64; MOTORS],
    /// Rates, steps/s.
    pub rate: [f64; MOTORS],
    /// Accelerations, steps/s^2.
    pub accel: [f64; MOTORS],
    /// Jerks, steps/s^3.
    pub jerk: [f64; MOTORS],
}

/// A synchronised rest-to-rest move of the three motors.
#[derive(Clone, Copy, Debug)]
pub struct JointMove {
    from: [f64; MOTORS],
    to: [f64; MOTORS],
    traj: Trajectory,
    limits: JointLimits,
}

impl JointMove {
    /// Plans the time-optimal move from `from` to `to` (steps) with every motor finishing at the
    /// same time.
    pub fn plan(
        from: [f64; MOTORS],
        to: [f64; MOTORS],
        limits: &JointLimits,
    ) -> Result<JointMove, JointError> {
        limits.validate()?;
        for i in 0..MOTORS {
            for (what, value) in [("start", from[i]), ("target", to[i])] {
                if !value.is_finite() {
                    return Err(JointError::NotFinite {
                        what,
                        motor: i + 1,
                        value,
                    });
                }
            }
        }
        let mut input = Input::new(MOTORS);
        for i in 0..MOTORS {
            input.current[i] = State::new(from[i], 0.0, 0.0);
            input.target[i] = State::new(to[i], 0.0, 0.0);
            input.limits[i] = Limits::symmetric(limits.rate[i], limits.accel[i], limits.jerk[i]);
        }
        input.synchronization = Synchronization::Time;
        let traj = calculate(&input)?;
        Ok(JointMove {
            from,
            to,
            traj,
            limits: *limits,
        })
    }

    /// Duration in s.
    pub fn duration(&self) -> f64 {
        self.traj.duration()
    }

    /// Start positions, steps.
    pub fn from(&self) -> [f64; MOTORS] {
        self.from
    }

    /// Target positions, steps.
    pub fn to(&self) -> [f64; MOTORS] {
        self.to
    }

    /// The limits it was planned with.
    pub fn limits(&self) -> &JointLimits {
        &self.limits
    }

    /// The motors at time `t` s (at the start before 0, exactly at the target, at rest, from the
    /// duration on). Does not allocate.
    pub fn sample(&self, t: f64) -> JointSample {
        if t >= self.duration() {
            return JointSample {
                q: self.to,
                rate: [0.0; MOTORS],
                accel: [0.0; MOTORS],
                jerk: [0.0; MOTORS],
            };
        }
        let t = t.max(0.0);
        let mut out = JointSample {
            q: [0.0; MOTORS],
            rate: [0.0; MOTORS],
            accel: [0.0; MOTORS],
            jerk: [0.0; MOTORS],
        };
        for i in 0..MOTORS {
            let (st, j) = self.traj.at_dof(i, t);
            out.q[i] = st.p;
            out.rate[i] = st.v;
            out.accel[i] = st.a;
            out.jerk[i] = j;
        }
        out
    }

    /// Motor setpoints (steps, rounded to the nearest step) at time `t` s.
    pub fn steps_at(&self, t: f64) -> [i64; MOTORS] {
        let q = self.sample(t).q;
        std::array::from_fn(|i| q[i].round() as i64)
    }

    /// Platform pose for motor positions `q` (steps): curvatures through the tendon maps, then FK
    /// warm-started at `guess` (cold continuation from home if that fails).
    pub fn pose_of(robot: &Robot, q: &[f64; MOTORS], guess: &KPose) -> Result<KPose, FkError> {
        let kappa: [f64; MOTORS] = std::array::from_fn(|i| robot.steps_to_kappa(i, q[i]));
        robot.fk_warm(&kappa, guess)
    }

    /// Samples the move every `dt` s (and at its end), finds the pose of every sample by FK (each
    /// warm-started at the previous one, the first at `start_guess`) and checks the sampled
    /// motion like a task-space path ([`Robot::check_motion`]). Returns the (time, pose) samples.
    pub fn check(
        &self,
        robot: &Robot,
        dt: f64,
        start_guess: &KPose,
        opt: &CheckOptions,
    ) -> Result<Vec<(f64, KPose)>, JointError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(JointError::BadPeriod(dt));
        }
        let dur = self.duration();
        let n = (dur / dt).ceil().max(1.0) as usize;
        let mut out: Vec<(f64, KPose)> = Vec::with_capacity(n + 1);
        let mut guess = *start_guess;
        for k in 0..=n {
            let t = if k == n { dur } else { k as f64 * dt };
            if out.last().is_some_and(|(tp, _)| t <= *tp) {
                continue;
            }
            let q = self.sample(t).q;
            let pose =
                Self::pose_of(robot, &q, &guess).map_err(|why| JointError::Fk { t, q, why })?;
            guess = pose;
            out.push((t, pose));
        }
        robot.check_motion(out.iter().copied(), opt)?;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lim() -> JointLimits {
        JointLimits {
            rate: [600.0; 3],
            accel: [3000.0; 3],
            jerk: [30000.0; 3],
        }
    }

    #[test]
    fn zero_move_has_no_duration() {
        let m = JointMove::plan([5.0; 3], [5.0; 3], &lim()).unwrap();
        assert_eq!(m.duration(), 0.0);
        assert_eq!(m.steps_at(0.0), [5; 3]);
    }

    #[test]
    fn bad_inputs_name_the_motor() {
        let mut l = lim();
        l.accel[1] = 0.0;
        let e = JointMove::plan([0.0; 3], [1.0; 3], &l).unwrap_err();
        assert!(e.to_string().contains("motor 2"), "{e}");
        let e = JointMove::plan([0.0, 0.0, f64::NAN], [1.0; 3], &lim()).unwrap_err();
        assert!(e.to_string().contains("motor 3"), "{e}");
        assert!(JointLimits::from_config(&RobotConfig::nominal(), 1.5, 1.0, 1.0).is_err());
    }
}
