//! Step 2 of the paper's calibration: with the legs of step 1 fixed, the platform joints
//! P_i^E = r_p (cos theta_p, sin theta_p) from the measured platform poses (paper eq. 9).
//!
//! The model of a measured pose is the forward kinematics of the commanded motor positions on
//! the robot with the step-1 legs. The residual of a pose is (dx mm, dy mm, w dphi deg): the
//! paper adds millimetres and orientation without a stated weight; we weight one degree as
//! `w` millimetres, by default the arc a platform joint travels when the platform turns by one
//! degree (w = r_p pi / 180, about 1.03 mm/deg for r_p = 59 mm). `--phi-weight` changes it.
//! [`Step2Params::extended`] frees the link lengths l_st as well.

use crate::lsq::{self, Options};
use crate::params::ParamBox;
use crate::step1::{describe, Correlated, Param};
use pcr_kinematics::{Pose, Robot};
use pcr_robot::RobotConfig;
use serde::Serialize;

/// Which parameters step 2 frees.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Step2Params {
    /// Also free the link lengths l_st,i.
    pub l_st: bool,
}

impl Step2Params {
    /// Number of parameters it frees: r_p and theta_p per joint, and l_st per link when freed.
    pub fn n_params(self) -> usize {
        if self.l_st {
            9
        } else {
            6
        }
    }

    /// The paper's P2 = [r_p, theta_p] per joint.
    pub const PAPER: Step2Params = Step2Params { l_st: false };
    /// P2 plus the link lengths.
    pub const EXTENDED: Step2Params = Step2Params { l_st: true };
}

/// One measured platform pose with its commanded motor positions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseObservation {
    /// Commanded motor positions, steps.
    pub q: [f64; 3],
    /// Measured pose (x mm, y mm, phi deg).
    pub pose: [f64; 3],
}

/// Platform pose errors of a model against measurements.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct PoseErrors {
    /// Poses compared.
    pub n: usize,
    /// Poses the model could not reach (FK failed); not in the figures.
    pub fk_failures: usize,
    /// Mean position error, mm.
    pub position_mean_mm: f64,
    /// Largest position error, mm.
    pub position_max_mm: f64,
    /// RMS position error, mm.
    pub position_rms_mm: f64,
    /// Mean |orientation error|, deg.
    pub orientation_mean_deg: f64,
    /// Largest |orientation error|, deg.
    pub orientation_max_deg: f64,
    /// RMS orientation error, deg.
    pub orientation_rms_deg: f64,
}

/// The predicted pose of a robot for commanded motor positions (x mm, y mm, phi deg), warm
/// started at `near` (e.g. the measured pose), falling back to the cold FK.
pub fn predict_pose(robot: &Robot, q: &[f64; 3], near: &[f64; 3]) -> Option<[f64; 3]> {
    let kappa: [f64; 3] = std::array::from_fn(|i| robot.steps_to_kappa(i, q[i]));
    let guess = Pose::from_mm_deg(near[0], near[1], near[2]);
    let p = robot.fk_warm(&kappa, &guess).ok()?;
    Some([p.x, p.y, p.phi_deg()])
}

/// Signed angle difference a - b in degrees, wrapped to (-180, 180].
pub fn angle_diff_deg(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    if d > 180.0 {
        d - 360.0
    } else {
        d
    }
}

/// Pose errors of `robot` over observations.
pub fn pose_errors(robot: &Robot, obs: &[PoseObservation]) -> PoseErrors {
    let mut e = PoseErrors::default();
    let (mut sp, mut sp2, mut so, mut so2) = (0.0, 0.0, 0.0, 0.0);
    for o in obs {
        let Some(p) = predict_pose(robot, &o.q, &o.pose) else {
            e.fk_failures += 1;
            continue;
        };
        let dr = (p[0] - o.pose[0]).hypot(p[1] - o.pose[1]);
        let dphi = angle_diff_deg(p[2], o.pose[2]).abs();
        e.n += 1;
        sp += dr;
        sp2 += dr * dr;
        so += dphi;
        so2 += dphi * dphi;
        e.position_max_mm = e.position_max_mm.max(dr);
        e.orientation_max_deg = e.orientation_max_deg.max(dphi);
    }
    if e.n > 0 {
        let n = e.n as f64;
        e.position_mean_mm = sp / n;
        e.position_rms_mm = (sp2 / n).sqrt();
        e.orientation_mean_deg = so / n;
        e.orientation_rms_deg = (so2 / n).sqrt();
    }
    e
}

/// The result of step 2.
#[derive(Debug, Clone, Serialize)]
pub struct Step2Fit {
    /// The calibrated robot.
    #[serde(skip)]
    pub config: RobotConfig,
    /// Every free parameter with its uncertainty.
    pub params: Vec<Param>,
    /// Strongly correlated pairs.
    pub correlated: Vec<Correlated>,
    /// Degrees weighted as this many millimetres.
    pub phi_weight_mm_per_deg: f64,
    /// Whether the solver converged.
    pub converged: bool,
    /// Solver status word.
    pub status: String,
    /// Residual evaluations.
    pub evaluations: usize,
}

/// Why step 2 failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Step2Error {
    /// Too few poses.
    #[error("step 2: {have} training poses with a measured platform pose for {params} parameters; at least {need} needed")]
    TooFew {
        /// Poses.
        have: usize,
        /// Parameters.
        params: usize,
        /// Needed.
        need: usize,
    },
    /// The model of the step-1 legs has no home pose or the solver failed.
    #[error("step 2: {0}")]
    Solver(String),
}

struct PlatformProblem<'a> {
    base: &'a RobotConfig,
    free: Step2Params,
    obs: &'a [PoseObservation],
    w: f64,
}

/// The robot `base` with the platform parameters of `x` (r_p, theta_p per joint, then l_st
/// per leg when freed).
pub(crate) fn robot_of(base: &RobotConfig, free: Step2Params, x: &[f64]) -> RobotConfig {
    let mut c = base.clone();
    for i in 0..3 {
        c.legs[i].r_p_mm = x[2 * i];
        c.legs[i].theta_p_deg = x[2 * i + 1];
        if free.l_st {
            c.legs[i].l_st_mm = x[6 + i];
        }
    }
    c
}

impl lsq::SharedProblem for PlatformProblem<'_> {
    fn residual_count(&self) -> usize {
        3 * self.obs.len()
    }

    fn residuals_at(&self, x: &[f64], r: &mut [f64]) -> Result<(), String> {
        let robot = Robot::new(&robot_of(self.base, self.free, x)).map_err(|e| e.to_string())?;
        pose_residuals(&robot, self.obs, self.w, r)
    }
}

/// The residuals of measured platform poses, 3 per pose: (dx mm, dy mm, w dphi) with `w` the
/// weight of a degree in mm; `Err` where the forward kinematics fails.
pub(crate) fn pose_residuals(
    robot: &Robot,
    obs: &[PoseObservation],
    w: f64,
    r: &mut [f64],
) -> Result<(), String> {
    for (k, o) in obs.iter().enumerate() {
        let p = predict_pose(robot, &o.q, &o.pose)
            .ok_or_else(|| format!("no forward kinematics for q = {:?}", o.q))?;
        r[3 * k] = p[0] - o.pose[0];
        r[3 * k + 1] = p[1] - o.pose[1];
        r[3 * k + 2] = w * angle_diff_deg(p[2], o.pose[2]);
    }
    Ok(())
}

/// The platform parameters of step 2 around `base` in vector order, with their bounds:
/// r_p within +-30 %, theta_p within +-15 deg, l_st (when freed) within +-15 mm.
pub(crate) fn platform_box(base: &RobotConfig, free: Step2Params) -> ParamBox {
    let mut b = ParamBox::default();
    for (i, l) in base.legs.iter().enumerate() {
        let (r, t) = (l.r_p_mm, l.theta_p_deg);
        b.push(format!("r_p_mm[{}]", i + 1), "mm", r, 0.7 * r, 1.3 * r);
        b.push(
            format!("theta_p_deg[{}]", i + 1),
            "deg",
            t,
            t - 15.0,
            t + 15.0,
        );
    }
    if free.l_st {
        for (i, l) in base.legs.iter().enumerate() {
            let s = l.l_st_mm;
            b.push(format!("l_st_mm[{}]", i + 1), "mm", s, s - 15.0, s + 15.0);
        }
    }
    b
}

/// The default weight of a degree in millimetres: the arc of the mean platform joint radius.
pub fn default_phi_weight(robot: &RobotConfig) -> f64 {
    robot.legs.iter().map(|l| l.r_p_mm).sum::<f64>() / 3.0 * std::f64::consts::PI / 180.0
}

/// Fits the platform joints of `base` (legs from step 1) to the training poses.
pub fn fit_platform(
    base: &RobotConfig,
    free: Step2Params,
    train: &[PoseObservation],
    phi_weight_mm_per_deg: f64,
) -> Result<Step2Fit, Step2Error> {
    let n = if free.l_st { 9 } else { 6 };
    if 3 * train.len() <= n + 2 {
        return Err(Step2Error::TooFew {
            have: train.len(),
            params: n,
            need: n / 3 + 2,
        });
    }
    let b = platform_box(base, free);
    let mut prob = lsq::InParallel(PlatformProblem {
        base,
        free,
        obs: train,
        w: phi_weight_mm_per_deg,
    });
    let fit = lsq::solve(&mut prob, &b.start, &b.lower, &b.upper, &Options::default())
        .map_err(|e| Step2Error::Solver(e.to_string()))?;
    let config = robot_of(base, free, &fit.x);
    let (params, correlated) = describe(&fit, &b.names, &b.start);
    Ok(Step2Fit {
        config,
        params,
        correlated,
        phi_weight_mm_per_deg,
        converged: fit.status.converged(),
        status: format!("{:?}", fit.status).to_lowercase(),
        evaluations: fit.evaluations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_platform_joints_from_exact_poses() {
        let nominal = RobotConfig::nominal();
        let mut truth = nominal.clone();
        let d = [(0.4, -0.3), (-0.2, 0.5), (0.3, 0.2)];
        for (l, (dr, dt)) in truth.legs.iter_mut().zip(d) {
            l.r_p_mm += dr;
            l.theta_p_deg += dt;
        }
        let tr = Robot::new(&truth).unwrap();
        let mut obs = Vec::new();
        for x in [-30.0, 0.0, 30.0] {
            for y in [-25.0, 0.0, 25.0] {
                for phi in [-8.0, 0.0, 8.0] {
                    let pose = Pose::from_mm_deg(x, y, phi);
                    let s = tr.ik(&pose).unwrap();
                    let q = std::array::from_fn(|i| tr.kappa_to_steps(i, s.kappa[i]).unwrap());
                    obs.push(PoseObservation {
                        q,
                        pose: [x, y, phi],
                    });
                }
            }
        }
        let before = pose_errors(&Robot::new(&nominal).unwrap(), &obs);
        assert!(before.position_rms_mm > 0.05, "{before:?}");
        let fit = fit_platform(
            &nominal,
            Step2Params::PAPER,
            &obs,
            default_phi_weight(&nominal),
        )
        .unwrap();
        assert!(fit.converged);
        for (l, t) in fit.config.legs.iter().zip(&truth.legs) {
            assert!(
                (l.r_p_mm - t.r_p_mm).abs() < 1e-6,
                "{} {}",
                l.r_p_mm,
                t.r_p_mm
            );
            assert!((l.theta_p_deg - t.theta_p_deg).abs() < 1e-6);
        }
        let after = pose_errors(&Robot::new(&fit.config).unwrap(), &obs);
        assert!(after.position_max_mm < 1e-6 && after.orientation_max_deg < 1e-6);
        assert_eq!(after.n, obs.len());
    }

    #[test]
    fn angle_differences_wrap() {
        assert!((angle_diff_deg(179.0, -179.0) + 2.0).abs() < 1e-12);
        assert!((angle_diff_deg(-179.0, 179.0) - 2.0).abs() < 1e-12);
        assert!((angle_diff_deg(10.0, 4.0) - 6.0).abs() < 1e-12);
    }

    #[test]
    fn too_few_poses_is_an_error() {
        let nominal = RobotConfig::nominal();
        let obs = [PoseObservation {
            q: [176.0; 3],
            pose: [0.0; 3],
        }; 2];
        assert!(matches!(
            fit_platform(&nominal, Step2Params::PAPER, &obs, 1.0),
            Err(Step2Error::TooFew { .. })
        ));
    }
}
