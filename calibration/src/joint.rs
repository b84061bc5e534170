//! The joint refinement after the paper's two steps: every calibrated parameter (each leg's
//! geometry and tendon-map coefficients of step 1, the platform joints of step 2) fitted
//! together to the measured passive joints M_i and the measured platform poses.
//!
//! Step 1 fits each leg to its own M_i, so the leg parameters never hear what the platform
//! poses say about them; step 2 then moves only the platform joints, so whatever the legs got
//! wrong for the platform stays in the prediction. The joint cost over the training poses j is
//!
//! `sum_j [ sum_i |M^_ij - M_ij|^2 + |p^_j - p_j|^2 + (w dphi_j)^2 ]`
//!
//! with M_i and the platform position p in mm and one degree of platform orientation weighted
//! as `w` mm (step 2's weight, by default the arc r_p pi / 180 a platform joint travels when the
//! platform turns by a degree). Every row is then a length in mm at the capture's noise, so the
//! rows need no further weights. The fit starts at the two-step result and keeps the two steps'
//! bounds around the starting robot; its uncertainties are those of the whole parameter set.

use crate::lsq::{self, Options, Problem};
use crate::params::ParamBox;
use crate::step1::{self, coeff_unit, describe, Correlated, FreeGeometry, LegObservation, Param};
use crate::step2::{self, PoseObservation, Step2Params};
use pcr_kinematics::{Leg, Robot};
use pcr_robot::effects::FrameCorrection;
use pcr_robot::{MapForm, RobotConfig};
use serde::Serialize;
use std::ops::Range;

/// Which parameters the joint fit frees: those of the two steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct JointParams {
    /// The leg geometry of step 1 (the map coefficients are always free).
    pub legs: FreeGeometry,
    /// The platform parameters of step 2.
    pub platform: Step2Params,
    /// The tendon-map function and reading of each leg.
    pub forms: [MapForm; 3],
    /// Also a correction of the capture frame (dx, dy mm, dphi deg; measured M_i and poses
    /// taken through `R(dphi) m + d`): the registration fitted with the robot, where a model
    /// says the capture frame is off ([`JointFit::frame`]).
    pub frame: bool,
}

/// The training observations of the joint fit.
#[derive(Debug, Clone, Copy)]
pub struct JointObservations<'a> {
    /// Measured M_i per leg.
    pub legs: &'a [Vec<LegObservation>; 3],
    /// Measured platform poses.
    pub poses: &'a [PoseObservation],
}

/// The result of the joint refinement.
#[derive(Debug, Clone, Serialize)]
pub struct JointFit {
    /// The refined robot.
    #[serde(skip)]
    pub config: RobotConfig,
    /// Every free parameter with its uncertainty from the joint fit (`start` is the value of
    /// the two steps). Names carry the leg or joint number: `psi_deg[1]`, `k0[2]`, `r_p_mm[3]`.
    pub params: Vec<Param>,
    /// Strongly correlated pairs.
    pub correlated: Vec<Correlated>,
    /// Degrees weighted as this many millimetres.
    pub phi_weight_mm_per_deg: f64,
    /// Residuals from measured M_i (2 per measured joint and pose).
    pub m_residuals: usize,
    /// Residuals from measured platform poses (3 per pose).
    pub pose_residuals: usize,
    /// RMS of all training residuals at the start (the two steps' result), mm.
    pub start_rms_mm: f64,
    /// RMS of all training residuals at the optimum, mm.
    pub rms_mm: f64,
    /// Whether the solver converged.
    pub converged: bool,
    /// Solver status word.
    pub status: String,
    /// The capture-frame correction fitted with the robot, when [`JointParams::frame`] freed it.
    pub frame: Option<FrameCorrection>,
    /// Residual evaluations.
    pub evaluations: usize,
}

/// Why the joint refinement failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum JointError {
    /// Too few residuals for the parameters.
    #[error("joint refinement: {residuals} training residuals for {params} parameters")]
    TooFew {
        /// Residuals.
        residuals: usize,
        /// Parameters.
        params: usize,
    },
    /// A leg of the two-step result does not use the map its form names.
    #[error("joint refinement: leg {leg} uses map {found}, expected {expected}")]
    MixedMaps {
        /// The leg (1..3).
        leg: usize,
        /// Its map.
        found: MapForm,
        /// The map of the fit.
        expected: MapForm,
    },
    /// The model cannot be evaluated at the start or the solver failed.
    #[error("joint refinement: {0}")]
    Solver(String),
}

/// Where each leg's and the platform's parameters sit in the joint vector: leg 1, 2, 3 (free
/// geometry, then map coefficients), then the platform parameters in step 2's order.
#[derive(Debug, Clone, Copy)]
struct Layout {
    free: JointParams,
    /// Start of each leg's parameters, and of the platform's.
    starts: [usize; 4],
}

impl Layout {
    fn new(free: JointParams, start: &RobotConfig) -> Layout {
        let geometry = free.legs.params(&start.legs[0]).len();
        let mut starts = [0; 4];
        for i in 0..3 {
            starts[i + 1] = starts[i] + geometry + free.forms[i].n_coeffs();
        }
        Layout { free, starts }
    }

    fn leg(&self, i: usize) -> Range<usize> {
        self.starts[i]..self.starts[i + 1]
    }

    fn platform(&self) -> Range<usize> {
        self.starts[3]..self.frame_start()
    }

    /// Where the frame's three parameters start (after the platform's), when freed.
    fn frame_start(&self) -> usize {
        self.starts[3] + self.free.platform.n_params()
    }

    /// The frame correction of `x`, when freed.
    fn frame(&self, x: &[f64]) -> Option<FrameCorrection> {
        let f = self.frame_start();
        self.free.frame.then(|| FrameCorrection {
            dx_mm: x[f],
            dy_mm: x[f + 1],
            dphi_deg: x[f + 2],
        })
    }

    /// `base` with the parameters of `x`.
    fn robot(&self, base: &RobotConfig, x: &[f64]) -> RobotConfig {
        let mut c = base.clone();
        for i in 0..3 {
            c.legs[i] = step1::leg_of(
                &base.legs[i],
                self.free.legs,
                self.free.forms[i],
                &x[self.leg(i)],
            );
        }
        step2::robot_of(&c, self.free.platform, &x[self.platform()])
    }

    /// Names, values of `from` and bounds around `bounds_of` (the two steps' bounds).
    fn param_box(&self, from: &RobotConfig, bounds_of: &RobotConfig) -> ParamBox {
        let mut b = ParamBox::default();
        for i in 0..3 {
            leg_box(&mut b, i, self.free, &from.legs[i], &bounds_of.legs[i]);
        }
        let values = step2::platform_box(from, self.free.platform);
        let bounds = step2::platform_box(bounds_of, self.free.platform);
        for k in 0..values.len() {
            let (name, unit) = &bounds.names[k];
            b.push(
                name.clone(),
                unit,
                values.start[k],
                bounds.lower[k],
                bounds.upper[k],
            );
        }
        if self.free.frame {
            for (name, unit) in [
                ("frame_dx_mm", "mm"),
                ("frame_dy_mm", "mm"),
                ("frame_dphi_deg", "deg"),
            ] {
                b.push(name.to_string(), unit, 0.0, -FRAME_BOUND, FRAME_BOUND);
            }
        }
        b
    }
}

/// Appends leg `i`'s geometry (bounds of step 1 around `bounds_of`) and map coefficients (free).
fn leg_box(
    b: &mut ParamBox,
    i: usize,
    free: JointParams,
    from: &pcr_robot::LegConfig,
    bounds_of: &pcr_robot::LegConfig,
) {
    let values = free.legs.params(from);
    for (v, g) in values.iter().zip(free.legs.params(bounds_of)) {
        b.push(format!("{}[{}]", g.0, i + 1), g.1, v.2, g.3, g.4);
    }
    let form = free.forms[i];
    for (j, c) in from.tendon_map.flat_coeffs().iter().enumerate() {
        b.push(
            format!("{}[{}]", form.coeff_name(j), i + 1),
            &coeff_unit(form.kind, form.mirrored(j)),
            *c,
            f64::NEG_INFINITY,
            f64::INFINITY,
        );
    }
}

/// Largest frame correction the joint fit moves to, mm or deg: far beyond a registration error.
const FRAME_BOUND: f64 = 50.0;

struct JointProblem<'a> {
    layout: Layout,
    base: &'a RobotConfig,
    obs: JointObservations<'a>,
    w: f64,
}

impl JointProblem<'_> {
    fn m_count(&self) -> usize {
        self.obs.legs.iter().map(|o| 2 * o.len()).sum()
    }
}

impl lsq::SharedProblem for JointProblem<'_> {
    fn residual_count(&self) -> usize {
        self.m_count() + 3 * self.obs.poses.len()
    }

    fn residuals_at(&self, x: &[f64], r: &mut [f64]) -> Result<(), String> {
        let cfg = self.layout.robot(self.base, x);
        // The observations through the frame correction, when it is freed.
        let framed = self.layout.frame(x).map(|f| framed(&f, self.obs));
        let (legs, poses) = match &framed {
            Some((l, p)) => (l, p.as_slice()),
            None => (self.obs.legs, self.obs.poses),
        };
        let mut at = 0;
        for (leg, obs) in cfg.legs.iter().zip(legs) {
            let n = 2 * obs.len();
            step1::m_residuals(&Leg::from_config(leg), obs, &mut r[at..at + n]);
            at += n;
        }
        let robot = Robot::new(&cfg).map_err(|e| e.to_string())?;
        step2::pose_residuals(&robot, poses, self.w, &mut r[at..])
    }
}

/// The observations `obs` (M_i and platform poses) through the frame correction `f`.
fn framed(
    f: &FrameCorrection,
    obs: JointObservations<'_>,
) -> ([Vec<LegObservation>; 3], Vec<PoseObservation>) {
    let point = |m: [f64; 2]| {
        let c = f.apply([m[0], m[1], 0.0]);
        [c[0], c[1]]
    };
    let legs = std::array::from_fn(|i| {
        obs.legs[i]
            .iter()
            .map(|o| LegObservation {
                dl_mm: o.dl_mm,
                m: point(o.m),
            })
            .collect()
    });
    let poses = obs
        .poses
        .iter()
        .map(|p| {
            let c = f.apply([p.pose[0], p.pose[1], p.pose[2].to_radians()]);
            PoseObservation {
                q: p.q,
                pose: [c[0], c[1], c[2].to_degrees()],
            }
        })
        .collect();
    (legs, poses)
}

fn rms(r: &[f64]) -> f64 {
    (r.iter().map(|v| v * v).sum::<f64>() / r.len().max(1) as f64).sqrt()
}

/// Refines every parameter of `free` jointly, starting at `two_step` (the paper's two steps'
/// robot) with the bounds of the two steps around `start` (the robot the data were recorded
/// with). `phi_weight_mm_per_deg` weights the platform orientation as in step 2.
pub fn refine(
    start: &RobotConfig,
    two_step: &RobotConfig,
    free: JointParams,
    obs: JointObservations<'_>,
    phi_weight_mm_per_deg: f64,
) -> Result<JointFit, JointError> {
    for (i, l) in two_step.legs.iter().enumerate() {
        if l.tendon_map.form() != free.forms[i] {
            return Err(JointError::MixedMaps {
                leg: i + 1,
                found: l.tendon_map.form(),
                expected: free.forms[i],
            });
        }
    }
    let layout = Layout::new(free, start);
    let b = layout.param_box(two_step, start);
    let mut prob = lsq::InParallel(JointProblem {
        layout,
        base: two_step,
        obs,
        w: phi_weight_mm_per_deg,
    });
    let m = prob.residual_count();
    if m <= b.len() + 2 {
        return Err(JointError::TooFew {
            residuals: m,
            params: b.len(),
        });
    }
    let mut r0 = vec![0.0; m];
    prob.residuals(&b.start, &mut r0)
        .map_err(JointError::Solver)?;
    let fit = lsq::solve(&mut prob, &b.start, &b.lower, &b.upper, &Options::default())
        .map_err(|e| JointError::Solver(e.to_string()))?;
    let (params, correlated) = describe(&fit, &b.names, &b.start);
    Ok(JointFit {
        config: layout.robot(two_step, &fit.x),
        params,
        correlated,
        phi_weight_mm_per_deg,
        m_residuals: prob.0.m_count(),
        pose_residuals: 3 * obs.poses.len(),
        start_rms_mm: rms(&r0),
        rms_mm: fit.rms(),
        converged: fit.status.converged(),
        status: format!("{:?}", fit.status).to_lowercase(),
        evaluations: fit.evaluations,
        frame: layout.frame(&fit.x),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use pcr_kinematics::Pose;
    use pcr_robot::{TendonMapKind, TendonMapSpec};

    /// A robot whose paper parameters are off the nominal, with an affine map.
    fn truth() -> RobotConfig {
        let mut t = RobotConfig::nominal();
        let d = [
            (0.3, -0.4, 0.2, -0.3),
            (-0.2, 0.5, -0.1, 0.2),
            (0.1, 0.3, 0.3, -0.1),
        ];
        for (i, (l, (dpsi, dlc, drp, dth))) in t.legs.iter_mut().zip(d).enumerate() {
            l.psi_deg += dpsi;
            l.l_c_mm += dlc;
            l.r_p_mm += drp;
            l.theta_p_deg += dth;
            l.tendon_map = TendonMapSpec::symmetric(
                TendonMapKind::Affine,
                vec![1e-4 * (i as f64 - 1.0), 1.05e-3 + 2e-5 * i as f64],
            );
        }
        t
    }

    /// Exact observations of `truth` at poses of a grid.
    fn observations(truth: &RobotConfig) -> ([Vec<LegObservation>; 3], Vec<PoseObservation>) {
        let robot = Robot::new(truth).unwrap();
        let (mut legs, mut poses) = (<[Vec<LegObservation>; 3]>::default(), Vec::new());
        for x in [-30.0, 0.0, 30.0] {
            for y in [-25.0, 0.0, 25.0] {
                for phi in [-8.0, 0.0, 8.0] {
                    let s = robot.ik(&Pose::from_mm_deg(x, y, phi)).unwrap();
                    let q = std::array::from_fn(|i| robot.kappa_to_steps(i, s.kappa[i]).unwrap());
                    for (i, obs) in legs.iter_mut().enumerate() {
                        let dl_mm = q[i] * truth.legs[i].actuation.mm_per_step();
                        let m = step1::predict_m(&Leg::from_config(&truth.legs[i]), dl_mm);
                        obs.push(LegObservation { dl_mm, m });
                    }
                    poses.push(PoseObservation {
                        q,
                        pose: [x, y, phi],
                    });
                }
            }
        }
        (legs, poses)
    }

    /// `truth` off in every leg's angle, length and map slope (as a two-step result would be),
    /// and in its platform joints when `platform`.
    fn off(truth: &RobotConfig, platform: bool) -> RobotConfig {
        let mut start = truth.clone();
        for l in &mut start.legs {
            l.psi_deg -= 0.2;
            l.l_c_mm += 0.3;
            if platform {
                l.r_p_mm -= 0.2;
                l.theta_p_deg += 0.2;
            }
            l.tendon_map.coeffs[1] *= 1.02;
        }
        start
    }

    fn paper_affine() -> JointParams {
        JointParams {
            legs: FreeGeometry::PAPER,
            platform: Step2Params::PAPER,
            forms: [MapForm::symmetric(TendonMapKind::Affine); 3],
            frame: false,
        }
    }

    #[test]
    fn recovers_every_parameter_from_exact_data() {
        let truth = truth();
        let (legs, poses) = observations(&truth);
        // Start off the truth in every parameter (as a two-step result would be).
        let start = off(&truth, true);
        let obs = JointObservations {
            legs: &legs,
            poses: &poses,
        };
        let fit = refine(&RobotConfig::nominal(), &start, paper_affine(), obs, 1.0).unwrap();
        assert!(fit.converged, "{}", fit.status);
        assert!(fit.start_rms_mm > 0.05 && fit.rms_mm < 1e-7, "{fit:?}");
        assert_eq!(fit.params.len(), 3 * 4 + 6);
        assert_eq!((fit.m_residuals, fit.pose_residuals), (6 * 27, 3 * 27));
        for (l, t) in fit.config.legs.iter().zip(&truth.legs) {
            assert!(
                (l.psi_deg - t.psi_deg).abs() < 1e-5,
                "{} {}",
                l.psi_deg,
                t.psi_deg
            );
            assert!((l.l_c_mm - t.l_c_mm).abs() < 1e-5);
            assert!((l.r_p_mm - t.r_p_mm).abs() < 1e-5);
            assert!((l.theta_p_deg - t.theta_p_deg).abs() < 1e-5);
            for (a, b) in l.tendon_map.coeffs.iter().zip(&t.tendon_map.coeffs) {
                assert!((a - b).abs() < 1e-9, "{a} {b}");
            }
        }
        let names: Vec<&str> = fit.params.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(&names[..4], &["psi_deg[1]", "l_c_mm[1]", "k0[1]", "k1[1]"]);
        assert_eq!(names[12], "r_p_mm[1]");
    }

    /// A capture frame off by (1.5, -0.8) mm and 0.6 deg: the measurements of `truth` taken
    /// into it. The joint fit with the frame freed finds the correction that takes them back
    /// (and every robot parameter) from a start off in all of them; without it, the fit cannot
    /// reach the measurements.
    #[test]
    fn the_frame_is_fitted_with_the_robot() {
        let truth = truth();
        let (mut legs, mut poses) = observations(&truth);
        let c: [f64; 3] = [1.5, -0.8, 0.6];
        let (s, co) = (-c[2]).to_radians().sin_cos();
        let into = |m: [f64; 2]| {
            let (x, y) = (m[0] - c[0], m[1] - c[1]);
            [co * x - s * y, s * x + co * y]
        };
        for o in legs.iter_mut().flatten() {
            o.m = into(o.m);
        }
        for p in &mut poses {
            let m = into([p.pose[0], p.pose[1]]);
            p.pose = [m[0], m[1], p.pose[2] - c[2]];
        }
        let start = off(&truth, false);
        let obs = JointObservations {
            legs: &legs,
            poses: &poses,
        };
        let free = JointParams {
            frame: true,
            ..paper_affine()
        };
        let fit = refine(&RobotConfig::nominal(), &start, free, obs, 1.0).unwrap();
        assert!(fit.converged && fit.rms_mm < 1e-6, "{fit:?}");
        let f = fit.frame.unwrap();
        for (a, b) in [f.dx_mm, f.dy_mm, f.dphi_deg].iter().zip(c) {
            assert!((a - b).abs() < 1e-5, "{f:?} against {c:?}");
        }
        assert_eq!(fit.params.len(), 3 * 4 + 6 + 3);
        assert_eq!(fit.params[18].name, "frame_dx_mm");
        for (l, t) in fit.config.legs.iter().zip(&truth.legs) {
            assert!((l.psi_deg - t.psi_deg).abs() < 1e-5);
            assert!((l.r_p_mm - t.r_p_mm).abs() < 1e-5);
        }
        // The same data without the frame: the robot alone does not reach them (it takes up
        // most of the frame: 0.02 mm RMS are left of 1.5 mm and 0.6 deg).
        let fixed = refine(&RobotConfig::nominal(), &start, paper_affine(), obs, 1.0).unwrap();
        assert!(
            fixed.frame.is_none() && fixed.rms_mm > 0.01,
            "{}",
            fixed.rms_mm
        );
    }

    #[test]
    fn a_start_with_another_map_or_too_few_residuals_is_an_error() {
        let truth = truth();
        let (legs, poses) = observations(&truth);
        let obs = JointObservations {
            legs: &legs,
            poses: &poses,
        };
        let free = JointParams {
            forms: [MapForm::symmetric(TendonMapKind::Poly2); 3],
            ..paper_affine()
        };
        let e = refine(&RobotConfig::nominal(), &truth, free, obs, 1.0).unwrap_err();
        assert!(matches!(e, JointError::MixedMaps { leg: 1, .. }), "{e}");
        let few: [Vec<LegObservation>; 3] = std::array::from_fn(|i| legs[i][..1].to_vec());
        let obs = JointObservations {
            legs: &few,
            poses: &poses[..1],
        };
        let e = refine(&RobotConfig::nominal(), &truth, paper_affine(), obs, 1.0).unwrap_err();
        assert!(matches!(e, JointError::TooFew { params: 18, .. }), "{e}");
    }
}
