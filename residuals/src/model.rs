//! The extended model: the calibrated constant-curvature robot plus the effects its file
//! declares, predicting the measured pose of every row of a recording.
//!
//! The chain of a prediction, in the order the physics runs (each effect's part of a stage is
//! its [`crate::extension::Extension`], in its own module under [`crate::effects`]):
//! 1. timing: the motors are where the command was the recording's command delay
//!    (`Series::delay_s`: what the file declares, `shared/spec/recording.md` "Timing"; a chain
//!    whose drive executes a setpoint over the following cycle declares one period) plus the
//!    effects' delay (`latency`) earlier;
//! 2. transmission: the output of a motor as a function of its position (`periodic`: the output
//!    lags the motor by `A sin(2 pi q / P + phase)`);
//! 3. play: the output follows the motor through a play (`backlash`: `b` steps);
//! 4. tendons: the tendon lengthens, so the segment sees less displacement (`creep`:
//!    `de/dt = (gain dl - e) / T`, then `drift`: `rate * (t - t0)`, t0 the recording's first
//!    row);
//! 5. the tendon map gives the curvatures and the forward kinematics the pose, loaded when an
//!    effect loads the robot (`joint_springs`, `external_load`: `[effects.compliance]`);
//! 6. measurement: the measurement is corrected before it is compared (`frame`).

use crate::extension::Chain;
use crate::series::Series;
use nalgebra::Matrix3;
use pcr_kinematics::statics::Loads;
use pcr_kinematics::{Pose, Robot};
use pcr_robot::effects::Effects;
use pcr_robot::RobotConfig;
use rayon::prelude::*;

/// Rows of a series solved in one pass (warm-started from row to row) by one thread.
pub const PREDICT_CHUNK: usize = 2048;

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
    /// Every row solved on its own (no reuse of the previous row's configuration or
    /// equilibrium): the reference the fast path is tested against.
    pub exact: bool,
    /// The effects' parts of the prediction ([`crate::effects::chain`]).
    pub chain: Chain,
}

/// Why a model cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("robot model: {0}")]
pub struct ModelError(pub String);

impl ExtendedModel {
    /// The model of a robot file whose effects predict through `chain` (the registered
    /// effects: [`crate::effects::chain`]).
    pub fn new(config: &RobotConfig, chain: Chain) -> Result<ExtendedModel, ModelError> {
        let robot = Robot::new(config).map_err(|e| ModelError(e.to_string()))?;
        Ok(ExtendedModel {
            loads: chain.iter().find_map(|x| x.loads(&config.effects)),
            robot,
            config: config.clone(),
            exact: false,
            chain,
        })
    }

    /// The model of a robot file, solved as `like` is (exact or fast, the same chain).
    pub fn like(config: &RobotConfig, like: &ExtendedModel) -> Result<ExtendedModel, ModelError> {
        let mut m = ExtendedModel::new(config, like.chain)?;
        m.exact = like.exact;
        Ok(m)
    }

    /// The effects.
    pub fn effects(&self) -> &Effects {
        &self.config.effects
    }

    /// Predictions for every row of a series.
    pub fn predict(&self, s: &Series) -> Vec<Prediction> {
        self.predict_where(s, &|_| true)
    }

    /// Predictions for every row of a series; the pose (forward kinematics) only where `want`
    /// says so (the histories of latency, backlash and creep always run over every row).
    ///
    /// The rows are solved in chunks of [`PREDICT_CHUNK`] in parallel, each started from the
    /// last measured pose at or before its first row: the result does not depend on the number
    /// of threads. An exact model ([`ExtendedModel::exact`]) solves the series in one pass.
    pub fn predict_where(
        &self,
        s: &Series,
        want: &(dyn Fn(usize) -> bool + Sync),
    ) -> Vec<Prediction> {
        let e = &self.config.effects;
        let q_eff = self.effective_steps(s, e);
        let mmps: [f64; 3] = std::array::from_fn(|i| self.config.legs[i].actuation.mm_per_step());
        let mut dl_eff: Vec<[f64; 3]> = q_eff
            .iter()
            .map(|q| std::array::from_fn(|i| q[i] * mmps[i]))
            .collect();
        for x in self.chain {
            x.tendons(e, s, &mut dl_eff);
        }
        let n = s.samples.len();
        let chunk = if self.exact { n.max(1) } else { PREDICT_CHUNK };
        let starts: Vec<usize> = (0..n).step_by(chunk).collect();
        let parts: Vec<Vec<Prediction>> = starts
            .par_iter()
            .map(|&k0| self.predict_range(s, k0..(k0 + chunk).min(n), &q_eff, &dl_eff, &mmps, want))
            .collect();
        parts.concat()
    }

    /// Predictions for the rows `range` of a series from their effective motor positions and
    /// tendon displacements.
    fn predict_range(
        &self,
        s: &Series,
        range: std::ops::Range<usize>,
        q_eff: &[[f64; 3]],
        dl_eff: &[[f64; 3]],
        mmps: &[f64; 3],
        want: &(dyn Fn(usize) -> bool + Sync),
    ) -> Vec<Prediction> {
        let mut out: Vec<Prediction> = Vec::with_capacity(range.len());
        let mut warm = pcr_kinematics::statics::LoadedWarm::default();
        // Started at the last measured pose at or before the range (the first of the series).
        let mut guess = s.samples[..=range.start.min(s.samples.len().saturating_sub(1))]
            .iter()
            .rev()
            .find_map(|x| x.pose)
            .or_else(|| s.samples.iter().find_map(|x| x.pose))
            .map_or(Pose::default(), |p| Pose::new(p[0], p[1], p[2]));
        for k in range {
            let smp = &s.samples[k];
            let kappa: [f64; 3] =
                std::array::from_fn(|i| self.robot.legs[i].map.kappa(dl_eff[k][i]));
            // Warm start at the measured pose where there is one (robust across jumps).
            if let Some(p) = smp.pose {
                guess = Pose::new(p[0], p[1], p[2]);
            }
            if !want(k) {
                out.push(Prediction {
                    pose: None,
                    q_eff: q_eff[k],
                    dl_eff: dl_eff[k],
                    kappa,
                    j_q: Matrix3::zeros(),
                    j_kappa: Matrix3::zeros(),
                });
                continue;
            }
            // A row whose configuration is the previous one's (at rest) has its prediction.
            if !self.exact {
                if let Some(prev) = out.last().filter(|p: &&Prediction| {
                    p.pose.is_some() && p.kappa == kappa && p.dl_eff == dl_eff[k]
                }) {
                    let mut same = *prev;
                    same.q_eff = q_eff[k];
                    out.push(same);
                    continue;
                }
            }
            let pose = match &self.loads {
                Some(l) if self.exact => {
                    self.robot.fk_loaded(&kappa, l, &guess).ok().map(|e| e.pose)
                }
                Some(l) => self
                    .robot
                    .fk_loaded_warm(&kappa, l, &guess, &mut warm)
                    .or_else(|_| self.robot.fk_loaded(&kappa, l, &guess))
                    .ok()
                    .map(|e| e.pose),
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
                                // The slope over one motor step: the root maps' slope is
                                // infinite at dl = 0, a step is the smallest change there is.
                                let m = &self.robot.legs[i].map;
                                let h = 0.5 * mmps[i];
                                let dl = dl_eff[k][i];
                                (m.kappa(dl + h) - m.kappa(dl - h)) / (2.0 * h) * mmps[i]
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

    /// The measured pose of a row (x mm, y mm, phi rad) with the effects' corrections of the
    /// measurement applied (stage 6).
    pub fn corrected(&self, m: [f64; 3]) -> [f64; 3] {
        self.chain
            .iter()
            .fold(m, |m, x| x.corrected(&self.config.effects, m))
    }

    /// The motor outputs of every row of a series (steps) before the play, when the model's
    /// effects are `effects`: the commands delayed (stage 1) and through the transmission
    /// (stage 2).
    pub fn steps_before_play(&self, s: &Series, effects: &Effects) -> Vec<[f64; 3]> {
        let delay: f64 = self.chain.iter().map(|x| x.delay_s(effects)).sum();
        let mut q = delayed_steps(s, s.delay_s + delay);
        for x in self.chain {
            x.transmission(effects, &mut q);
        }
        q
    }

    /// The motor outputs of every row of a series (steps) when the model's effects are
    /// `effects`: stages 1 to 3 (timing, transmission, play).
    pub fn effective_steps(&self, s: &Series, effects: &Effects) -> Vec<[f64; 3]> {
        let mut q = self.steps_before_play(s, effects);
        for x in self.chain {
            x.play(effects, &mut q);
        }
        q
    }
}

/// The commanded motor positions of every row shifted back by `delay` (interpolated; one pass).
pub fn delayed_steps(s: &Series, delay: f64) -> Vec<[f64; 3]> {
    let x = &s.samples;
    let mut out = Vec::with_capacity(x.len());
    let mut j = 0usize;
    for r in x {
        let t = r.t_s - delay;
        while j + 1 < x.len() && x[j + 1].t_s <= t {
            j += 1;
        }
        while j > 0 && x[j].t_s > t {
            j -= 1;
        }
        let q = if t <= x[0].t_s {
            x[0].q
        } else if j + 1 >= x.len() {
            x[x.len() - 1].q
        } else {
            let (a, b) = (&x[j], &x[j + 1]);
            let f = (t - a.t_s) / (b.t_s - a.t_s);
            std::array::from_fn(|i| a.q[i] + f * (b.q[i] - a.q[i]))
        };
        out.push(q);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delayed_steps_interpolate_in_one_pass() {
        let mut rec = pcr_recording::Recording::default();
        for k in 0..10 {
            let mut r = pcr_recording::Row::new(k as f64 * 0.02, [k * 10, 0, -k]);
            r.pose = [Some(0.0); 3];
            rec.rows.push(r);
        }
        let s = Series::from_recording(&rec, "t").unwrap();
        let d = delayed_steps(&s, 0.03);
        assert_eq!(d[0], [0.0, 0.0, 0.0]);
        assert!(
            (d[5][0] - 35.0).abs() < 1e-9 && (d[5][2] + 3.5).abs() < 1e-9,
            "{:?}",
            d[5]
        );
        assert_eq!(delayed_steps(&s, -1.0)[3], [90.0, 0.0, -9.0]);
    }
}
