//! Compensation of the effects a robot file declares (`[effects]`, found by `pcr residuals`):
//! the inverse of the extended model's prediction chain, applied to what the chain commands.
//!
//! - motor side, after the IK ([`MotorCompensation`]): creep and drift (the predicted tendon
//!   elongation is added to the commanded displacement; drift's grows with the time since the
//!   first command), periodic transmission errors (the motor is commanded
//!   where its output reaches the target), backlash (half the play added in the direction of
//!   motion, so that a reversal takes the slack up at once);
//! - compliance: the IK of the loaded model (`Robot::ik_loaded`) instead of the rigid one;
//! - latency: the interpolator commands the pose of `t + period + latency`
//!   (`InterpolatorStep::set_lead`, [`command_lead`]: the drive's own segment plus the measured
//!   latency);
//! - capture frame: the measured pose is corrected before it is used
//!   (`FrameCorrection::apply`, in the driver step).

use pcr_robot::effects::Effects;
use pcr_robot::RobotConfig;

/// The lead of the commanded pose over the nominal one, s: one control period, because the
/// drive executes each setpoint as one segment over the following cycle (driver/PROTOCOL.md: the
/// steps evenly spaced over `cycle_ms`) and reaches it at its end, plus the further
/// command-to-motion latency the robot file declares (`[effects.latency]`, measured by
/// `pcr residuals`).
pub fn command_lead(robot: &RobotConfig, period_s: f64) -> f64 {
    period_s + robot.effects.latency.as_ref().map_or(0.0, |l| l.latency_s)
}

/// The motor-side compensation state of one chain. Allocation-free per cycle.
#[derive(Debug, Clone)]
pub struct MotorCompensation {
    effects: Effects,
    mm_per_step: [f64; 3],
    /// Direction of the last motion of each commanded output (+1, -1; 0 before any motion).
    dir: [f64; 3],
    last_target: Option<[f64; 3]>,
    /// Predicted tendon elongation, mm.
    creep: [f64; 3],
    last_t: Option<f64>,
    /// Time of the first command, s (drift's origin).
    first_t: Option<f64>,
}

impl MotorCompensation {
    /// The compensation of a robot file's effects (nothing to do when it declares none).
    pub fn new(robot: &RobotConfig) -> Self {
        MotorCompensation {
            effects: robot.effects.clone(),
            mm_per_step: std::array::from_fn(|i| robot.legs[i].actuation.mm_per_step()),
            dir: [0.0; 3],
            last_target: None,
            creep: [0.0; 3],
            last_t: None,
            first_t: None,
        }
    }

    /// Whether any motor-side effect is compensated.
    pub fn is_active(&self) -> bool {
        let e = &self.effects;
        e.backlash.is_some() || e.creep.is_some() || e.drift.is_some() || !e.periodic.is_empty()
    }

    /// The motor positions (steps, not rounded) to command at time `t_s` so that the outputs
    /// reach `target`.
    pub fn command(&mut self, t_s: f64, target: [f64; 3]) -> [f64; 3] {
        let mut q = target;
        // Creep: the tendon is longer by e, pull e further.
        if let Some(c) = &self.effects.creep {
            let dt = self.last_t.map_or(0.0, |l| (t_s - l).max(0.0));
            let a = 1.0 - (-dt / c.time_constant_s).exp();
            for i in 0..3 {
                let dl = target[i] * self.mm_per_step[i];
                self.creep[i] += (c.gain[i] * dl - self.creep[i]) * a;
                q[i] += self.creep[i] / self.mm_per_step[i];
            }
        }
        self.last_t = Some(t_s);
        // Drift: the tendon is longer by rate * (t - t_first), pull that further.
        let t0 = *self.first_t.get_or_insert(t_s);
        if let Some(d) = &self.effects.drift {
            for i in 0..3 {
                q[i] += d.rate_mm_per_s[i] * (t_s - t0).max(0.0) / self.mm_per_step[i];
            }
        }
        // Periodic: output = m - A sin(2 pi m / P + ph); solve for the motor m by fixed point.
        for p in &self.effects.periodic {
            let i = (p.motor as usize).clamp(1, 3) - 1;
            let (w, ph) = (
                std::f64::consts::TAU / p.period_steps,
                p.phase_deg.to_radians(),
            );
            let want = q[i];
            let mut m = want;
            for _ in 0..4 {
                m = want + p.amplitude_steps * (w * m + ph).sin();
            }
            q[i] = m;
        }
        // Backlash: command half the play ahead in the direction of motion.
        if let Some(b) = &self.effects.backlash {
            if let Some(last) = self.last_target {
                for i in 0..3 {
                    let d = target[i] - last[i];
                    if d.abs() > 1e-9 {
                        self.dir[i] = d.signum();
                    }
                }
            }
            for i in 0..3 {
                q[i] += 0.5 * b.steps[i] * self.dir[i];
            }
        }
        self.last_target = Some(target);
        q
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pcr_robot::effects::{Backlash, Creep, FrameCorrection, Periodic};

    fn robot(effects: Effects) -> RobotConfig {
        let mut r = RobotConfig::nominal();
        r.effects = effects;
        r
    }

    /// The play operator of the extended model (a dead band of `width`).
    fn play(out: &mut f64, x: f64, width: f64) {
        *out = out.clamp(x - 0.5 * width, x + 0.5 * width);
    }

    #[test]
    fn backlash_compensation_makes_the_output_follow_through_reversals() {
        let mut c = MotorCompensation::new(&robot(Effects {
            backlash: Some(Backlash {
                steps: [4.0, 0.0, 0.0],
            }),
            ..Effects::default()
        }));
        let mut out = 100.0;
        let targets = [
            100.0, 101.0, 103.0, 106.0, 106.0, 104.0, 101.0, 100.0, 102.0,
        ];
        let mut errs = Vec::new();
        for (k, t) in targets.iter().enumerate() {
            let q = c.command(k as f64 * 0.02, [*t, 0.0, 0.0]);
            play(&mut out, q[0], 4.0);
            errs.push((out - t).abs());
        }
        // After the first motion the output is on target, through both reversals.
        assert!(errs[2..].iter().all(|e| *e < 1e-9), "{errs:?}");
    }

    #[test]
    fn periodic_and_creep_compensation_invert_the_model() {
        let p = Periodic {
            motor: 2,
            period_steps: 32.0,
            amplitude_steps: 0.8,
            phase_deg: 40.0,
        };
        let mut c = MotorCompensation::new(&robot(Effects {
            periodic: vec![p.clone()],
            ..Effects::default()
        }));
        for target in [0.0, 5.3, 17.0, 250.5] {
            let q = c.command(0.0, [0.0, target, 0.0]);
            let out = q[1]
                - p.amplitude_steps
                    * (std::f64::consts::TAU * q[1] / 32.0 + 40f64.to_radians()).sin();
            assert!((out - target).abs() < 1e-3, "{target}: {out}");
        }
        // Creep: after a long hold the command exceeds the target by the final elongation.
        let r = robot(Effects {
            creep: Some(Creep {
                gain: [0.02, 0.0, 0.0],
                time_constant_s: 10.0,
            }),
            ..Effects::default()
        });
        let mmps = r.legs[0].actuation.mm_per_step();
        let mut c = MotorCompensation::new(&r);
        let mut q = [0.0; 3];
        for k in 0..5000 {
            q = c.command(k as f64 * 0.02, [300.0, 0.0, 0.0]);
        }
        assert!((q[0] - (300.0 + 0.02 * 300.0)).abs() < 1e-3, "{q:?} {mmps}");
    }

    #[test]
    fn drift_compensation_pulls_the_elongation_grown_since_the_first_command() {
        let r = robot(Effects {
            drift: Some(pcr_robot::effects::Drift {
                rate_mm_per_s: [0.0, 0.002, -0.001],
            }),
            ..Effects::default()
        });
        let mmps: [f64; 3] = std::array::from_fn(|i| r.legs[i].actuation.mm_per_step());
        let mut c = MotorCompensation::new(&r);
        assert!(c.is_active());
        let q0 = c.command(5.0, [200.0, 200.0, 200.0]);
        assert_eq!(
            q0,
            [200.0, 200.0, 200.0],
            "nothing has grown at the first command"
        );
        let q = c.command(105.0, [200.0, 200.0, 200.0]);
        assert!((q[0] - 200.0).abs() < 1e-12);
        assert!((q[1] - (200.0 + 0.2 / mmps[1])).abs() < 1e-9, "{q:?}");
        assert!((q[2] - (200.0 - 0.1 / mmps[2])).abs() < 1e-9, "{q:?}");
    }

    #[test]
    fn frame_correction_is_a_rigid_transform() {
        let f = FrameCorrection {
            dx_mm: 1.0,
            dy_mm: -2.0,
            dphi_deg: 90.0,
        };
        let m = f.apply([10.0, 0.0, 0.1]);
        assert!((m[0] - 1.0).abs() < 1e-12 && (m[1] - 8.0).abs() < 1e-12);
        assert!((m[2] - (0.1 + std::f64::consts::FRAC_PI_2)).abs() < 1e-12);
    }
}
