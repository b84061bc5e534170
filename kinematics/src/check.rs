//! Feasibility of a sampled motion: the checks a motion must pass before it is accepted.
//!
//! A motion is given as poses at increasing times (sampled finely, e.g. every 20 ms or finer).
//! Each sample must have an IK solution in the working mode within the joint and bending limits,
//! keep the conditioning above the singularity threshold (times an optional margin), and every
//! pair of consecutive samples must keep each motor below its step-rate limit. The first
//! violation is reported with its time, pose and what was violated.

use crate::ik::IkError;
use crate::model::Robot;
use crate::pose::Pose;

/// What a sample violated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Violation {
    /// No valid IK in the working mode (unreachable, joint or bending limit).
    Ik(IkError),
    /// The conditioning fell below the required value.
    Singular {
        /// Conditioning at the sample.
        conditioning: f64,
        /// Required minimum.
        required: f64,
    },
    /// A motor would have to step faster than its limit.
    StepRate {
        /// 1-based motor (leg) number.
        motor: usize,
        /// Required rate, steps/s.
        rate: f64,
        /// Limit, steps/s.
        limit: f64,
    },
    /// The curvature cannot be produced by the tendon map.
    TendonMap {
        /// 1-based leg number.
        leg: usize,
    },
    /// Times are not strictly increasing or not finite.
    Time,
}

impl std::fmt::Display for Violation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Violation::Ik(e) => write!(f, "{e}"),
            Violation::Singular {
                conditioning,
                required,
            } => {
                write!(
                    f,
                    "too close to a singularity (conditioning {conditioning:.2e} < {required:.2e})"
                )
            }
            Violation::StepRate { motor, rate, limit } => {
                write!(
                    f,
                    "motor {motor} would need {rate:.0} steps/s (limit {limit:.0})"
                )
            }
            Violation::TendonMap { leg } => {
                write!(f, "leg {leg}: curvature outside the tendon map's range")
            }
            Violation::Time => write!(f, "sample times must be finite and strictly increasing"),
        }
    }
}

/// The first violation of a motion.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("at t = {t:.3} s, pose ({:.2} mm, {:.2} mm, {:.2} deg): {what}", pose.x, pose.y, pose.phi.to_degrees())]
pub struct MotionRejected {
    /// Time of the offending sample, s.
    pub t: f64,
    /// The offending pose.
    pub pose: Pose,
    /// What it violated.
    pub what: Violation,
}

/// Options of the motion check.
#[derive(Debug, Clone, Copy)]
pub struct CheckOptions {
    /// The conditioning must stay above `singularity_margin` times the robot's threshold.
    pub singularity_margin: f64,
    /// Fraction of each motor's step-rate limit the motion may use (0, 1].
    pub rate_fraction: f64,
}

impl Default for CheckOptions {
    fn default() -> Self {
        CheckOptions {
            singularity_margin: 1.0,
            rate_fraction: 1.0,
        }
    }
}

/// Motor positions (steps, not rounded) of one sample.
pub fn steps_of(robot: &Robot, kappa: &[f64; 3]) -> Result<[f64; 3], usize> {
    let mut q = [0.0; 3];
    for i in 0..3 {
        q[i] = robot.kappa_to_steps(i, kappa[i]).map_err(|_| i + 1)?;
    }
    Ok(q)
}

impl Robot {
    /// Checks a sampled motion; `samples` yields (t in s, pose). Returns the motor positions of
    /// every sample (steps, not rounded) or the first violation.
    pub fn check_motion(
        &self,
        samples: impl IntoIterator<Item = (f64, Pose)>,
        opt: &CheckOptions,
    ) -> Result<Vec<[f64; 3]>, MotionRejected> {
        let required = self.limits.singularity_threshold * opt.singularity_margin;
        let mut out = Vec::new();
        let mut prev: Option<(f64, [f64; 3])> = None;
        for (t, pose) in samples {
            let reject = |what| MotionRejected { t, pose, what };
            if !t.is_finite() || prev.is_some_and(|(tp, _)| t <= tp) {
                return Err(reject(Violation::Time));
            }
            let s = self.ik(&pose).map_err(|e| reject(Violation::Ik(e)))?;
            let c = self.conditioning(&pose, &s.kappa).value();
            if c < required {
                return Err(reject(Violation::Singular {
                    conditioning: c,
                    required,
                }));
            }
            let q = steps_of(self, &s.kappa).map_err(|leg| reject(Violation::TendonMap { leg }))?;
            if let Some((tp, qp)) = prev {
                for i in 0..3 {
                    let rate = (q[i] - qp[i]).abs() / (t - tp);
                    let limit = self.legs[i].max_step_rate * opt.rate_fraction;
                    if rate > limit {
                        return Err(reject(Violation::StepRate {
                            motor: i + 1,
                            rate,
                            limit,
                        }));
                    }
                }
            }
            prev = Some((t, q));
            out.push(q);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn circle(radius: f64, speed: f64, dt: f64) -> Vec<(f64, Pose)> {
        let period = std::f64::consts::TAU * radius / speed;
        let n = (period / dt).ceil() as usize;
        (0..=n)
            .map(|k| {
                let t = k as f64 * dt;
                let a = speed * t / radius;
                (t, Pose::new(radius * a.cos(), radius * a.sin(), 0.0))
            })
            .collect()
    }

    #[test]
    fn the_papers_circle_passes_and_a_fast_one_is_rejected() {
        let r = Robot::nominal();
        let q = r
            .check_motion(circle(50.0, 50.0, 0.02), &CheckOptions::default())
            .unwrap();
        assert!(q.len() > 300);
        let e = r
            .check_motion(circle(50.0, 400.0, 0.02), &CheckOptions::default())
            .unwrap_err();
        assert!(matches!(e.what, Violation::StepRate { .. }), "{e}");
        assert!(e.to_string().contains("steps/s"));
    }

    #[test]
    fn leaving_the_workspace_names_time_and_pose() {
        let r = Robot::nominal();
        let line = (0..=100).map(|k| (k as f64 * 0.1, Pose::new(2.0 * k as f64, 0.0, 0.0)));
        let e = r.check_motion(line, &CheckOptions::default()).unwrap_err();
        // the (---) workspace ends at x = 77.85 mm along +x: the first sample beyond is x = 78
        assert!((e.pose.x - 78.0).abs() < 1e-9, "{e}");
        assert!((e.t - 3.9).abs() < 1e-9);
        assert!(matches!(
            e.what,
            Violation::Ik(IkError::Unreachable { leg: 1 })
        ));
        let bad_time = [(0.0, Pose::default()), (0.0, Pose::default())];
        assert!(matches!(
            r.check_motion(bad_time, &CheckOptions::default())
                .unwrap_err()
                .what,
            Violation::Time
        ));
    }
}
