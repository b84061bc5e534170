//! The true robot the plant simulates: nominal geometry plus deviations, the true tendon map, and
//! the home motor positions (nominal constant-curvature IK of pose (0, 0, 0), whole steps).

use crate::config::{PlantConfig, TrueMapKind};
use pcr_robot::geometry::{add, norm, rot, signed_angle, sub, Vec2};
use pcr_robot::{LegConfig, RobotConfig, WorkingMode};

/// True geometry of one leg (mm, rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LegGeometry {
    /// Base point B_i in the base frame, mm.
    pub base: Vec2,
    /// Base tangent angle theta(0) = psi + 90 deg, rad.
    pub theta0: f64,
    /// Segment length l_C, mm.
    pub l_c: f64,
    /// Tip extension l_CE, mm.
    pub l_ce: f64,
    /// Link length l_st, mm.
    pub l_st: f64,
    /// Platform joint P_i in the platform frame, mm.
    pub p_e: Vec2,
}

impl LegGeometry {
    /// The geometry of a robot-configuration leg (no deviation).
    pub fn from_leg(leg: &LegConfig) -> LegGeometry {
        LegGeometry {
            base: leg.base_point(),
            theta0: (leg.psi_deg + 90.0).to_radians(),
            l_c: leg.l_c_mm,
            l_ce: leg.l_ce_mm,
            l_st: leg.l_st_mm,
            p_e: leg.platform_point(),
        }
    }

    /// Passive joint M_i of the constant-curvature arc with bending `phi_b` (rad), and the tip
    /// tangent angle.
    pub fn arc_tip(&self, phi_b: f64) -> (Vec2, f64) {
        let psi = self.theta0 - std::f64::consts::FRAC_PI_2;
        let kappa = phi_b / self.l_c;
        let local = if kappa.abs() < 1e-9 {
            // Series of (1 - cos k l)/k and sin(k l)/k.
            let l = self.l_c;
            [kappa * l * l / 2.0, l - kappa * kappa * l * l * l / 6.0]
        } else {
            [(1.0 - phi_b.cos()) / kappa, phi_b.sin() / kappa]
        };
        let tip = add(self.base, rot(psi, local));
        let th = self.theta0 - phi_b;
        (add(tip, [self.l_ce * th.cos(), self.l_ce * th.sin()]), th)
    }
}

/// The true tendon map of one leg: effective tendon displacement (mm) to bending (rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TendonMap {
    /// Family.
    pub kind: TrueMapKind,
    /// Nominal tendon offset a, mm.
    pub a: f64,
    /// Relative slope (for dl >= dl0).
    pub gain: f64,
    /// Relative slope for dl < dl0 (the other tendon of the pair).
    pub gain_neg: f64,
    /// Offset, mm.
    pub dl0: f64,
    /// Saturation, rad.
    pub phi_sat: f64,
}

impl TendonMap {
    /// phi_b = g(dl), rad.
    pub fn bending(&self, dl: f64) -> f64 {
        let gain = if dl < self.dl0 {
            self.gain_neg
        } else {
            self.gain
        };
        let lin = gain * (dl - self.dl0) / self.a;
        match self.kind {
            TrueMapKind::Linear => lin,
            TrueMapKind::Tanh => self.phi_sat * (lin / self.phi_sat).tanh(),
        }
    }
}

/// Which parts of the true robot deviate from the robot configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct TrueRobot {
    /// True leg geometry.
    pub legs: [LegGeometry; 3],
    /// True tendon maps.
    pub maps: [TendonMap; 3],
    /// Tendon displacement per motor step, mm.
    pub mm_per_step: [f64; 3],
    /// Nominal tendon offset a per leg, mm (to turn tendon moments into tensions).
    pub tendon_offset: [f64; 3],
    /// Home motor positions, steps.
    pub home_steps: [i32; 3],
    /// Tendon cross-coupling: leg i is also pulled by this share of leg i-1's displacement.
    pub cross_coupling: f64,
    /// Joint range, rad.
    pub joint_range: (f64, f64),
    /// Largest |bending|, rad.
    pub bending_max: f64,
}

impl TrueRobot {
    /// Builds the true robot from the nominal robot configuration and the plant configuration.
    pub fn new(robot: &RobotConfig, plant: &PlantConfig) -> TrueRobot {
        let g = &plant.geometry;
        let t = &plant.tendon_map;
        let legs: [LegGeometry; 3] = std::array::from_fn(|i| {
            let mut leg = robot.legs[i].clone();
            if g.enabled {
                leg.r_base_mm += g.d_r_base_mm[i];
                leg.beta_deg += g.d_beta_deg[i];
                leg.psi_deg += g.d_psi_deg[i];
                leg.l_c_mm += g.d_l_c_mm[i];
                leg.l_ce_mm += g.d_l_ce_mm[i];
                leg.l_st_mm += g.d_l_st_mm[i];
                leg.r_p_mm += g.d_r_p_mm[i];
                leg.theta_p_deg += g.d_theta_p_deg[i];
            }
            LegGeometry::from_leg(&leg)
        });
        let maps = std::array::from_fn(|i| TendonMap {
            kind: t.model,
            a: robot.legs[i].actuation.tendon_offset_mm,
            gain: t.gain[i],
            gain_neg: t.gain_neg.map_or(t.gain[i], |g| g[i]),
            dl0: t.dl0_mm[i],
            phi_sat: t.phi_sat_deg[i].to_radians(),
        });
        TrueRobot {
            legs,
            maps,
            mm_per_step: std::array::from_fn(|i| robot.legs[i].actuation.mm_per_step()),
            tendon_offset: std::array::from_fn(|i| robot.legs[i].actuation.tendon_offset_mm),
            home_steps: home_steps(robot),
            cross_coupling: t.cross_coupling,
            joint_range: (
                robot.limits.joint_min_deg.to_radians(),
                robot.limits.joint_max_deg.to_radians(),
            ),
            bending_max: robot.limits.bending_max_deg.to_radians(),
        }
    }
}

/// Bending of leg `leg` whose loop closes at `pose` in the constant-curvature model with the
/// nominal geometry, on the branch gamma < 0 (the prototype's working mode). None if no root.
pub fn cc_ik_bending(leg: &LegConfig, pose: [f64; 3]) -> Option<f64> {
    cc_ik_bending_in_mode(leg, pose, WorkingMode::Negative)
}

/// As [`cc_ik_bending`] on the branch of the given working mode (sign of gamma); the root of
/// smallest |bending| if several.
pub fn cc_ik_bending_in_mode(leg: &LegConfig, pose: [f64; 3], mode: WorkingMode) -> Option<f64> {
    let g = LegGeometry::from_leg(leg);
    let p = add([pose[0], pose[1]], rot(pose[2], g.p_e));
    let h = |phi: f64| {
        let (m, _) = g.arc_tip(phi);
        norm(sub(p, m)) - g.l_st
    };
    let gamma = |phi: f64| {
        let (m, th) = g.arc_tip(phi);
        signed_angle([th.cos(), th.sin()], sub(p, m))
    };
    let n = 720;
    let (lo, hi) = (-std::f64::consts::PI, std::f64::consts::PI);
    let mut best: Option<f64> = None;
    let mut a = lo;
    let mut ha = h(a);
    for k in 1..=n {
        let b = lo + (hi - lo) * k as f64 / n as f64;
        let hb = h(b);
        if ha == 0.0 || ha * hb < 0.0 {
            let (mut x0, mut x1, mut h0) = (a, b, ha);
            for _ in 0..200 {
                let xm = 0.5 * (x0 + x1);
                let hm = h(xm);
                if h0 * hm <= 0.0 {
                    x1 = xm;
                } else {
                    x0 = xm;
                    h0 = hm;
                }
            }
            let r = 0.5 * (x0 + x1);
            if gamma(r) * mode.sign() > 0.0 && best.is_none_or(|b: f64| r.abs() < b.abs()) {
                best = Some(r);
            }
        }
        a = b;
        ha = hb;
    }
    best
}

/// Home motor positions: the nominal CC IK of pose (0, 0, 0) in the robot's working mode with
/// the linear map kappa = dl / (a l_C), rounded to whole steps (0 if a leg has no root).
pub fn home_steps(robot: &RobotConfig) -> [i32; 3] {
    std::array::from_fn(|i| {
        let leg = &robot.legs[i];
        let phi = cc_ik_bending_in_mode(leg, [0.0, 0.0, 0.0], robot.working_mode[i]).unwrap_or(0.0);
        let dl = phi * leg.actuation.tendon_offset_mm;
        (dl / leg.actuation.mm_per_step()).round() as i32
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn home_matches_the_reference() {
        let robot = RobotConfig::nominal();
        for leg in &robot.legs {
            let phi = cc_ik_bending(leg, [0.0, 0.0, 0.0]).unwrap();
            assert!(
                (phi.to_degrees() - 22.0497).abs() < 1e-3,
                "{}",
                phi.to_degrees()
            );
            assert!((phi / leg.l_c_mm - 0.00307872).abs() < 1e-8);
        }
        assert_eq!(home_steps(&robot), [176, 176, 176]);
        // The other branch at home: 160.7 deg bending (geometry.md).
        let phi = cc_ik_bending_in_mode(&robot.legs[0], [0.0; 3], WorkingMode::Positive).unwrap();
        assert!(
            (phi / robot.legs[0].l_c_mm - 0.0224255).abs() < 1e-7,
            "{phi}"
        );
    }

    #[test]
    fn ik_check_values() {
        let robot = RobotConfig::nominal();
        let pose = [20.0, -10.0, 5f64.to_radians()];
        let want = [0.00521470, 0.00227929, 0.00289048];
        for (leg, w) in robot.legs.iter().zip(want) {
            let k = cc_ik_bending(leg, pose).unwrap() / leg.l_c_mm;
            assert!((k - w).abs() < 1e-8, "{k} vs {w}");
        }
    }
}
