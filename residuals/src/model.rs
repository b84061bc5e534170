//! The extended model: the calibrated constant-curvature robot plus the effects its file
//! declares, predicting the measured pose of every row of a recording.
//!
//! The chain of a prediction, in the order the physics runs:
//! 1. latency: the motors are where the command was `latency_s` earlier;
//! 2. periodic transmission errors: the output lags the motor by `A sin(2 pi q / P + phase)`;
//! 3. backlash: the output follows the motor through a play of `b` steps;
//! 4. creep: the tendon lengthens by `e`, `de/dt = (gain dl - e) / T`, so the segment sees
//!    `dl - e`;
//! 5. the tendon map gives the curvatures and the (loaded, with `[effects.compliance]`) forward
//!    kinematics the pose;
//! 6. frame correction: the measurement is corrected by the declared rigid transform before it
//!    is compared.

use crate::series::Series;
use nalgebra::Matrix3;
use pcr_kinematics::statics::Loads;
use pcr_kinematics::{Pose, Robot};
use pcr_robot::effects::{Backlash, Creep, Effects, FrameCorrection, Latency, Periodic};
use pcr_robot::RobotConfig;

/// The prediction for one row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prediction {
    /// Predicted pose (x mm, y mm, phi rad); `None` where the model has no pose.
    pub pose: Option<[f64; 3]>,
    /// Effective motor positions after latency, periodic errors and backlash, steps.
    pub q_eff: [f64; 3],
    /// Effective tendon displacement after creep, mm.
    pub dl_eff: [f64; 3],
    /// Curvatures, 1/mm.
    pub kappa: [f64; 3],
    /// d pose / d q_eff (rows x mm, y mm, phi rad; columns steps).
    pub j_q: Matrix3<f64>,
    /// d pose / d kappa.
    pub j_kappa: Matrix3<f64>,
}

/// The model of one robot file.
#[derive(Debug, Clone)]
pub struct ExtendedModel {
    /// The robot file (legs and effects).
    pub config: RobotConfig,
    /// Its constant-curvature model.
    pub robot: Robot,
    /// Loads of the compliance effect.
    pub loads: Option<Loads>,
}

/// Why a model cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("robot model: {0}")]
pub struct ModelError(pub String);

impl ExtendedModel {
    /// The model of a robot file.
    pub fn new(config: &RobotConfig) -> Result<ExtendedModel, ModelError> {
        let robot = Robot::new(config).map_err(|e| ModelError(e.to_string()))?;
        Ok(ExtendedModel {
            loads: config
                .effects
                .compliance
                .as_ref()
                .map(Loads::from_compliance),
            robot,
            config: config.clone(),
        })
    }

    /// The effects.
    pub fn effects(&self) -> &Effects {
        &self.config.effects
    }

    /// Predictions for every row of a series.
    pub fn predict(&self, s: &Series) -> Vec<Prediction> {
        let e = &self.config.effects;
        let q_eff = effective_steps(s, e.latency.as_ref(), &e.periodic, e.backlash.as_ref());
        let mmps: [f64; 3] = std::array::from_fn(|i| self.config.legs[i].actuation.mm_per_step());
        let dl: Vec<[f64; 3]> = q_eff
            .iter()
            .map(|q| std::array::from_fn(|i| q[i] * mmps[i]))
            .collect();
        let dl_eff = match &e.creep {
            Some(c) => apply_creep(s, &dl, c),
            None => dl,
        };
        let mut out = Vec::with_capacity(s.samples.len());
        let mut guess = s
            .samples
            .iter()
            .find_map(|x| x.pose)
            .map_or(Pose::default(), |p| Pose::new(p[0], p[1], p[2]));
        for (k, smp) in s.samples.iter().enumerate() {
            let kappa: [f64; 3] =
                std::array::from_fn(|i| self.robot.legs[i].map.kappa(dl_eff[k][i]));
            // Warm start at the measured pose where there is one (robust across jumps).
            if let Some(p) = smp.pose {
                guess = Pose::new(p[0], p[1], p[2]);
            }
            let pose = match &self.loads {
                Some(l) => self.robot.fk_loaded(&kappa, l, &guess).ok().map(|e| e.pose),
                None => self.robot.fk_warm(&kappa, &guess).ok(),
            };
            let (j_q, j_kappa) =
                match &pose {
                    Some(p) => {
                        let jk = self
                            .robot
                            .jacobian(p, &kappa)
                            .unwrap_or_else(Matrix3::zeros);
                        let d = Matrix3::from_diagonal(&nalgebra::Vector3::from(
                            std::array::from_fn::<f64, 3, _>(|i| {
                                self.robot.legs[i].map.kappa_and_slope(dl_eff[k][i]).1 * mmps[i]
                            }),
                        ));
                        (jk * d, jk)
                    }
                    None => (Matrix3::zeros(), Matrix3::zeros()),
                };
            if let Some(p) = pose {
                guess = p;
            }
            out.push(Prediction {
                pose: pose.map(|p| [p.x, p.y, p.phi]),
                q_eff: q_eff[k],
                dl_eff: dl_eff[k],
                kappa,
                j_q,
                j_kappa,
            });
        }
        out
    }

    /// The measured pose of a row with the frame correction applied.
    pub fn corrected(&self, m: [f64; 3]) -> [f64; 3] {
        match &self.config.effects.frame {
            Some(f) => apply_frame(f, m),
            None => m,
        }
    }
}

/// R(dphi) p + d on a pose (x mm, y mm, phi rad).
pub fn apply_frame(f: &FrameCorrection, m: [f64; 3]) -> [f64; 3] {
    let a = f.dphi_deg.to_radians();
    let (s, c) = a.sin_cos();
    [
        c * m[0] - s * m[1] + f.dx_mm,
        s * m[0] + c * m[1] + f.dy_mm,
        m[2] + a,
    ]
}

/// The commanded motor positions of a series interpolated at time `t`.
pub fn steps_at(s: &Series, t: f64) -> [f64; 3] {
    let x = &s.samples;
    if x.is_empty() {
        return [0.0; 3];
    }
    if t <= x[0].t_s {
        return x[0].q;
    }
    let k = x.partition_point(|r| r.t_s <= t);
    if k >= x.len() {
        return x[x.len() - 1].q;
    }
    let (a, b) = (&x[k - 1], &x[k]);
    let f = (t - a.t_s) / (b.t_s - a.t_s);
    std::array::from_fn(|i| a.q[i] + f * (b.q[i] - a.q[i]))
}

/// The play operator: the output follows `input` through a dead band of `width`.
pub fn play(input: &[f64], width: f64, start: f64) -> Vec<f64> {
    let h = 0.5 * width.max(0.0);
    let mut out = start;
    input
        .iter()
        .map(|&x| {
            out = out.clamp(x - h, x + h);
            out
        })
        .collect()
}

/// Motor outputs after latency, periodic transmission errors and backlash.
pub fn effective_steps(
    s: &Series,
    latency: Option<&Latency>,
    periodic: &[Periodic],
    backlash: Option<&Backlash>,
) -> Vec<[f64; 3]> {
    let mut q: Vec<[f64; 3]> = match latency {
        Some(l) => s
            .samples
            .iter()
            .map(|x| steps_at(s, x.t_s - l.latency_s))
            .collect(),
        None => s.samples.iter().map(|x| x.q).collect(),
    };
    for p in periodic {
        let i = (p.motor as usize).clamp(1, 3) - 1;
        let ph = p.phase_deg.to_radians();
        for v in &mut q {
            v[i] -= p.amplitude_steps * (std::f64::consts::TAU * v[i] / p.period_steps + ph).sin();
        }
    }
    if let Some(b) = backlash {
        for i in 0..3 {
            let col: Vec<f64> = q.iter().map(|v| v[i]).collect();
            let start = col.first().copied().unwrap_or(0.0);
            for (v, o) in q.iter_mut().zip(play(&col, b.steps[i], start)) {
                v[i] = o;
            }
        }
    }
    q
}

/// Tendon creep: the elongation state over the series and the effective displacement.
pub fn apply_creep(s: &Series, dl: &[[f64; 3]], c: &Creep) -> Vec<[f64; 3]> {
    let mut e = [0.0f64; 3];
    let mut prev_t = s.samples.first().map_or(0.0, |x| x.t_s);
    dl.iter()
        .zip(&s.samples)
        .map(|(d, x)| {
            let dt = (x.t_s - prev_t).max(0.0);
            prev_t = x.t_s;
            let a = 1.0 - (-dt / c.time_constant_s).exp();
            std::array::from_fn(|i| {
                e[i] += (c.gain[i] * d[i] - e[i]) * a;
                d[i] - e[i]
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn play_has_a_dead_band() {
        let out = play(&[0.0, 1.0, 3.0, 2.0, 1.0, 0.0, 3.0], 2.0, 0.0);
        assert_eq!(out, vec![0.0, 0.0, 2.0, 2.0, 2.0, 1.0, 2.0]);
    }
}
