//! The extended model: the calibrated constant-curvature robot plus the effects its file
//! declares, predicting the measured pose of every row of a recording.
//!
//! The chain of a prediction, in the order the physics runs:
//! 1. the timing contract and the latency: the motors are where the command was the recording's
//!    command delay (`Series::delay_s`: what the file declares, `shared/spec/recording.md`
//!    "Timing"; a chain whose drive executes a setpoint over the following cycle declares one
//!    period) plus `latency_s` earlier;
//! 2. periodic transmission errors: the output lags the motor by `A sin(2 pi q / P + phase)`;
//! 3. backlash: the output follows the motor through a play of `b` steps;
//! 4. creep: the tendon lengthens by `e`, `de/dt = (gain dl - e) / T`, so the segment sees
//!    `dl - e`;
//!    drift: the tendon lengthens by `rate * (t - t0)` (t0 the recording's first row);
//! 5. the tendon map gives the curvatures and the (loaded, with `[effects.compliance]`) forward
//!    kinematics the pose;
//! 6. frame correction: the measurement is corrected by the declared rigid transform before it
//!    is compared.

use crate::series::Series;
use nalgebra::Matrix3;
use pcr_kinematics::statics::Loads;
use pcr_kinematics::{Pose, Robot};
use pcr_robot::effects::{Backlash, Creep, Drift, Effects, Latency, Periodic};
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
            exact: false,
        })
    }

    /// The model of a robot file, solved as `like` is (exact or fast).
    pub fn like(config: &RobotConfig, like: &ExtendedModel) -> Result<ExtendedModel, ModelError> {
        let mut m = ExtendedModel::new(config)?;
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
        let q_eff = effective_steps(s, e.latency.as_ref(), &e.periodic, e.backlash.as_ref());
        let mmps: [f64; 3] = std::array::from_fn(|i| self.config.legs[i].actuation.mm_per_step());
        let dl: Vec<[f64; 3]> = q_eff
            .iter()
            .map(|q| std::array::from_fn(|i| q[i] * mmps[i]))
            .collect();
        let mut dl_eff = match &e.creep {
            Some(c) => apply_creep(s, &dl, c),
            None => dl,
        };
        if let Some(d) = &e.drift {
            apply_drift(s, &mut dl_eff, d);
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

    /// The measured pose of a row with the frame correction applied.
    pub fn corrected(&self, m: [f64; 3]) -> [f64; 3] {
        match &self.config.effects.frame {
            Some(f) => f.apply(m),
            None => m,
        }
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

/// Motor outputs after latency and periodic transmission errors (before backlash).
pub fn steps_before_backlash(
    s: &Series,
    latency: Option<&Latency>,
    periodic: &[Periodic],
) -> Vec<[f64; 3]> {
    let mut q = delayed_steps(s, s.delay_s + latency.map_or(0.0, |l| l.latency_s));
    for p in periodic {
        let i = (p.motor as usize).clamp(1, 3) - 1;
        let ph = p.phase_deg.to_radians();
        for v in &mut q {
            v[i] -= p.amplitude_steps * (std::f64::consts::TAU * v[i] / p.period_steps + ph).sin();
        }
    }
    q
}

/// Backlash on motor outputs, in place.
pub fn apply_backlash(q: &mut [[f64; 3]], b: &Backlash) {
    for i in 0..3 {
        if b.steps[i] == 0.0 {
            continue;
        }
        let h = 0.5 * b.steps[i];
        let mut out = q.first().map_or(0.0, |v| v[i]);
        for v in q.iter_mut() {
            out = out.clamp(v[i] - h, v[i] + h);
            v[i] = out;
        }
    }
}

/// Motor outputs after latency, periodic transmission errors and backlash.
pub fn effective_steps(
    s: &Series,
    latency: Option<&Latency>,
    periodic: &[Periodic],
    backlash: Option<&Backlash>,
) -> Vec<[f64; 3]> {
    let mut q = steps_before_backlash(s, latency, periodic);
    if let Some(b) = backlash {
        apply_backlash(&mut q, b);
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

/// Tendon drift: the effective displacement shortened by `rate * (t - t0)`, in place.
pub fn apply_drift(s: &Series, dl: &mut [[f64; 3]], d: &Drift) {
    let t0 = s.samples.first().map_or(0.0, |x| x.t_s);
    for (v, x) in dl.iter_mut().zip(&s.samples) {
        for i in 0..3 {
            v[i] -= d.rate_mm_per_s[i] * (x.t_s - t0);
        }
    }
}

/// The configuration a fraction `s` of the way from `old` to `new`: every continuous parameter
/// (leg geometry, map coefficients of the same family, effect parameters; an effect absent from
/// `old` counts as zero) interpolated; structural differences (another map family, other
/// periodic terms) taken from `new`. Used to damp a linearised step.
pub fn blend(old: &RobotConfig, new: &RobotConfig, s: f64) -> RobotConfig {
    let lerp = |a: f64, b: f64| a + s * (b - a);
    let mut out = new.clone();
    for (o, (a, b)) in out.legs.iter_mut().zip(old.legs.iter().zip(&new.legs)) {
        o.r_base_mm = lerp(a.r_base_mm, b.r_base_mm);
        o.beta_deg = lerp(a.beta_deg, b.beta_deg);
        o.psi_deg = lerp(a.psi_deg, b.psi_deg);
        o.l_c_mm = lerp(a.l_c_mm, b.l_c_mm);
        o.l_ce_mm = lerp(a.l_ce_mm, b.l_ce_mm);
        o.l_st_mm = lerp(a.l_st_mm, b.l_st_mm);
        o.r_p_mm = lerp(a.r_p_mm, b.r_p_mm);
        o.theta_p_deg = lerp(a.theta_p_deg, b.theta_p_deg);
        let (fa, fb) = (a.tendon_map.flat_coeffs(), b.tendon_map.flat_coeffs());
        if a.tendon_map.form() == b.tendon_map.form() && fa.len() == fb.len() {
            let flat: Vec<f64> = fa.iter().zip(&fb).map(|(x, y)| lerp(*x, *y)).collect();
            o.tendon_map = pcr_robot::TendonMapSpec::from_flat(a.tendon_map.form(), &flat);
        }
    }
    let (eo, en) = (&old.effects, &new.effects);
    let e = &mut out.effects;
    if let Some(l) = e.latency.as_mut() {
        l.latency_s = lerp(
            eo.latency.as_ref().map_or(0.0, |x| x.latency_s),
            l.latency_s,
        );
    }
    if let Some(b) = e.backlash.as_mut() {
        let o = eo.backlash.as_ref().map_or([0.0; 3], |x| x.steps);
        b.steps = std::array::from_fn(|i| lerp(o[i], b.steps[i]));
    }
    if let Some(c) = e.creep.as_mut() {
        let o = eo.creep.as_ref().map_or([0.0; 3], |x| x.gain);
        c.gain = std::array::from_fn(|i| lerp(o[i], c.gain[i]));
        if let Some(oc) = &eo.creep {
            c.time_constant_s = lerp(oc.time_constant_s, c.time_constant_s);
        }
    }
    if let Some(d) = e.drift.as_mut() {
        let o = eo.drift.as_ref().map_or([0.0; 3], |x| x.rate_mm_per_s);
        d.rate_mm_per_s = std::array::from_fn(|i| lerp(o[i], d.rate_mm_per_s[i]));
    }
    if let Some(c) = e.compliance.as_mut() {
        let z = Default::default();
        let o: &pcr_robot::effects::Compliance = eo.compliance.as_ref().unwrap_or(&z);
        c.force_n = [
            lerp(o.force_n[0], c.force_n[0]),
            lerp(o.force_n[1], c.force_n[1]),
        ];
        c.couple_n_mm = lerp(o.couple_n_mm, c.couple_n_mm);
        c.k_m_n_mm_per_rad = lerp(o.k_m_n_mm_per_rad, c.k_m_n_mm_per_rad);
        c.k_p_n_mm_per_rad = lerp(o.k_p_n_mm_per_rad, c.k_p_n_mm_per_rad);
    }
    if let Some(f) = e.frame.as_mut() {
        let z = pcr_robot::effects::FrameCorrection {
            dx_mm: 0.0,
            dy_mm: 0.0,
            dphi_deg: 0.0,
        };
        let o = eo.frame.as_ref().unwrap_or(&z);
        f.dx_mm = lerp(o.dx_mm, f.dx_mm);
        f.dy_mm = lerp(o.dy_mm, f.dy_mm);
        f.dphi_deg = lerp(o.dphi_deg, f.dphi_deg);
    }
    if eo.periodic.len() <= en.periodic.len() {
        for (k, p) in e.periodic.iter_mut().enumerate() {
            let a0 = eo.periodic.get(k).map_or(0.0, |x| x.amplitude_steps);
            p.amplitude_steps = lerp(a0, p.amplitude_steps);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backlash_is_a_dead_band() {
        let mut q: Vec<[f64; 3]> = [0.0, 1.0, 3.0, 2.0, 1.0, 0.0, 3.0]
            .iter()
            .map(|v| [*v, *v, 0.0])
            .collect();
        apply_backlash(
            &mut q,
            &Backlash {
                steps: [2.0, 0.0, 0.0],
            },
        );
        let out: Vec<f64> = q.iter().map(|v| v[0]).collect();
        assert_eq!(out, vec![0.0, 0.0, 2.0, 2.0, 2.0, 1.0, 2.0]);
        assert_eq!(q[2][1], 3.0, "no play on motor 2");
    }

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
