//! The robot: three legs, limits and working mode, ready for IK and FK.

use crate::leg::Leg;
use crate::pose::Pose;
use pcr_robot::{geometry as g, RobotConfig, Vec2, WorkingMode};

/// Number of grid points of the per-leg bending-angle table used to bracket IK roots.
pub(crate) const TABLE_N: usize = 33;

/// Tabulated local tip positions of a leg over the scanned bending range.
#[derive(Debug, Clone)]
pub(crate) struct LegTable {
    pub theta0: f64,
    pub dtheta: f64,
    pub mx: [f64; TABLE_N],
    pub my: [f64; TABLE_N],
    /// |m|^2
    pub nn: [f64; TABLE_N],
    /// d m / d theta
    pub dmx: [f64; TABLE_N],
    pub dmy: [f64; TABLE_N],
    /// m . dm/dtheta
    pub mdm: [f64; TABLE_N],
    /// tip tangent (sin theta, cos theta)
    pub st: [f64; TABLE_N],
    pub ct: [f64; TABLE_N],
}

impl LegTable {
    fn new(leg: &Leg, theta_scan: f64) -> LegTable {
        let theta0 = -theta_scan;
        let dtheta = 2.0 * theta_scan / (TABLE_N - 1) as f64;
        let mut t = LegTable {
            theta0,
            dtheta,
            mx: [0.0; TABLE_N],
            my: [0.0; TABLE_N],
            nn: [0.0; TABLE_N],
            dmx: [0.0; TABLE_N],
            dmy: [0.0; TABLE_N],
            mdm: [0.0; TABLE_N],
            st: [0.0; TABLE_N],
            ct: [0.0; TABLE_N],
        };
        for k in 0..TABLE_N {
            let tip = leg.local_tip(theta0 + dtheta * k as f64);
            let (m, dm) = (tip.m, tip.dm);
            t.mx[k] = m[0];
            t.my[k] = m[1];
            t.nn[k] = m[0] * m[0] + m[1] * m[1];
            t.dmx[k] = dm[0];
            t.dmy[k] = dm[1];
            t.mdm[k] = m[0] * dm[0] + m[1] * dm[1];
            t.st[k] = tip.t[0];
            t.ct[k] = tip.t[1];
        }
        t
    }
}

/// Joint and bending limits in radians.
#[derive(Debug, Clone, Copy)]
pub struct LimitsRad {
    /// Lower passive joint limit, rad.
    pub joint_min: f64,
    /// Upper passive joint limit, rad.
    pub joint_max: f64,
    /// Largest |kappa l_C|, rad.
    pub bending_max: f64,
    /// Conditioning below which a configuration is singular.
    pub singularity_threshold: f64,
}

/// Why a robot cannot be built from a configuration.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// The home pose (0, 0, 0) has no IK solution in the working mode.
    #[error("the home pose (0, 0, 0) is not reachable in working mode {mode}: {why}")]
    NoHome {
        /// Working mode as text.
        mode: String,
        /// The IK failure.
        why: String,
    },
}

/// The constant-curvature model of one robot.
#[derive(Debug, Clone)]
pub struct Robot {
    /// The three legs.
    pub legs: [Leg; 3],
    /// Limits in radians.
    pub limits: LimitsRad,
    /// Working mode: the sign of gamma_i per leg.
    pub mode: [WorkingMode; 3],
    pub(crate) tables: [LegTable; 3],
    /// Characteristic platform radius used to scale the orientation column of A, mm.
    pub(crate) r_char: f64,
    /// Curvatures of the home pose (0, 0, 0) in the working mode, 1/mm.
    pub home_kappa: [f64; 3],
    /// Sign of det A at home: the assembly mode FK keeps.
    pub home_det_sign: f64,
    config: RobotConfig,
}

impl Robot {
    /// Builds the model of a validated configuration; finds the home configuration.
    pub fn new(config: &RobotConfig) -> Result<Robot, ModelError> {
        let legs: [Leg; 3] = std::array::from_fn(|i| Leg::from_config(&config.legs[i]));
        let l = &config.limits;
        let limits = LimitsRad {
            joint_min: l.joint_min_deg.to_radians(),
            joint_max: l.joint_max_deg.to_radians(),
            bending_max: l.bending_max_deg.to_radians(),
            singularity_threshold: l.singularity_threshold,
        };
        // Scan 30 deg beyond the bending limit so that a root just outside it is reported as a
        // bending limit, not as unreachable.
        let scan = (limits.bending_max + 30f64.to_radians()).min(std::f64::consts::TAU);
        let tables = std::array::from_fn(|i| LegTable::new(&legs[i], scan));
        let r_char = legs.iter().map(|l| g::norm(l.p_e)).sum::<f64>() / 3.0;
        let mut robot = Robot {
            legs,
            limits,
            mode: config.working_mode,
            tables,
            r_char: r_char.max(1.0),
            home_kappa: [0.0; 3],
            home_det_sign: 1.0,
            config: config.clone(),
        };
        let home = Pose::default();
        let sol = robot.ik(&home).map_err(|e| ModelError::NoHome {
            mode: WorkingMode::triple_to_string(&config.working_mode),
            why: e.to_string(),
        })?;
        robot.home_kappa = sol.kappa;
        robot.home_det_sign = robot.jacobian_a(&home, &sol.kappa).determinant().signum();
        Ok(robot)
    }

    /// The nominal robot of geometry.md.
    pub fn nominal() -> Robot {
        Robot::new(&RobotConfig::nominal()).expect("the nominal robot has a home pose")
    }

    /// The configuration this model was built from.
    pub fn config(&self) -> &RobotConfig {
        &self.config
    }

    /// Platform joint P_i in the base frame for a pose.
    #[inline]
    pub fn joint_p(&self, i: usize, pose: &Pose) -> Vec2 {
        g::add([pose.x, pose.y], g::rot(pose.phi, self.legs[i].p_e))
    }

    /// Joint M_i in the base frame for curvature kappa_i.
    #[inline]
    pub fn joint_m(&self, i: usize, kappa: f64) -> Vec2 {
        self.legs[i].joint_m(kappa)
    }

    /// The constraints h_i = |P_i - M_i|^2 - l_st^2 (mm^2) of geometry.md eq. 5.
    pub fn constraints(&self, pose: &Pose, kappa: &[f64; 3]) -> [f64; 3] {
        std::array::from_fn(|i| {
            let d = g::sub(self.joint_p(i, pose), self.joint_m(i, kappa[i]));
            g::dot(d, d) - self.legs[i].l_st * self.legs[i].l_st
        })
    }

    /// Passive joint angles (gamma_i at M_i, zeta_i at P_i), rad, of leg i.
    pub fn joint_angles(&self, i: usize, pose: &Pose, kappa: f64) -> (f64, f64) {
        let leg = &self.legs[i];
        let p = self.joint_p(i, pose);
        let m = leg.joint_m(kappa);
        let t = leg.tangent(kappa);
        let pe = g::rot(pose.phi, leg.p_e);
        (
            g::signed_angle(t, g::sub(p, m)),
            g::signed_angle(pe, g::sub(m, p)),
        )
    }

    /// Motor steps (not rounded) for a curvature of leg i, through the inverse tendon map.
    pub fn kappa_to_steps(&self, i: usize, kappa: f64) -> Result<f64, crate::TendonMapError> {
        let leg = &self.legs[i];
        Ok(leg.map.dl_for_kappa(kappa)? / leg.mm_per_step)
    }

    /// Curvature (1/mm) of leg i for a motor position in steps.
    pub fn steps_to_kappa(&self, i: usize, q: f64) -> f64 {
        let leg = &self.legs[i];
        leg.map.kappa(q * leg.mm_per_step)
    }

    /// d kappa / d q of leg i at motor position q, 1/(mm step).
    pub fn dkappa_dsteps(&self, i: usize, q: f64) -> f64 {
        let leg = &self.legs[i];
        leg.map.kappa_and_slope(q * leg.mm_per_step).1 * leg.mm_per_step
    }
}
