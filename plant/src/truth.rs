//! The static truth model: the true robot, its statics and its home equilibrium. Stateless
//! solves follow the equilibrium path from home (effects without history only).

use crate::config::PlantConfig;
use crate::model::TrueRobot;
use crate::statics::{Equilibrium, Loads, Springs, Statics, StaticsError};
use pcr_robot::RobotConfig;

/// The static plant: true geometry, tendon maps, joint springs, external wrench.
#[derive(Debug, Clone)]
pub struct TruthModel {
    /// The true robot.
    pub robot: TrueRobot,
    /// Its statics (springs relaxed at home).
    pub statics: Statics,
    /// Configured external wrench (Fx N, Fy N, Mz N mm).
    pub wrench: [f64; 3],
    /// Loads at home: home bending, no wrench, no friction.
    pub home_loads: Loads,
    /// The home equilibrium (springs relaxed, unloaded).
    pub home: Equilibrium,
}

impl TruthModel {
    /// Builds the truth model and solves its home equilibrium.
    pub fn new(robot: &RobotConfig, plant: &PlantConfig) -> Result<TruthModel, StaticsError> {
        let tr = TrueRobot::new(robot, plant);
        let mut statics = Statics {
            legs: tr.legs,
            ei: plant.mechanics.ei_n_mm2,
            steps: plant.mechanics.segment_steps,
            springs: Springs::default(),
            joint_range: tr.joint_range,
            bending_max: tr.bending_max,
            tol: 1e-10,
            max_iter: 30,
        };
        let home_loads = Loads {
            phi_b: tr.bending_of_steps(&tr.home_steps.map(f64::from), &[0.0; 3]),
            wrench: [0.0; 3],
            friction: None,
        };
        let guess = statics.arc_guess(&home_loads.phi_b, [0.0; 3]);
        let home = statics.solve_warm(&home_loads, &guess)?;
        statics.springs = Springs {
            k_m: plant.mechanics.k_m_n_mm_per_rad,
            k_p: plant.mechanics.k_p_n_mm_per_rad,
            gamma0: home.gamma,
            zeta0: home.zeta,
        };
        let w = &plant.external_wrench;
        Ok(TruthModel {
            robot: tr,
            statics,
            wrench: [w.fx_n, w.fy_n, w.mz_n_mm],
            home_loads,
            home,
        })
    }

    /// Stateless equilibrium for motor output positions `q` (steps, may be fractional; no
    /// backlash, creep or friction), with the configured wrench.
    pub fn solve_steps(&self, q: &[f64; 3]) -> Result<Equilibrium, StaticsError> {
        self.solve_loads(&Loads {
            phi_b: self.robot.bending_of_steps(q, &[0.0; 3]),
            wrench: self.wrench,
            friction: None,
        })
    }

    /// Stateless equilibrium for arbitrary loads (continuation from home).
    pub fn solve_loads(&self, loads: &Loads) -> Result<Equilibrium, StaticsError> {
        self.statics.solve_path(&self.home_loads, &self.home, loads)
    }
}

impl TrueRobot {
    /// True bending of each segment for motor output positions `q` (steps) and tendon creep
    /// elongations `creep_mm` (mm), rad.
    pub fn bending_of_steps(&self, q: &[f64; 3], creep_mm: &[f64; 3]) -> [f64; 3] {
        std::array::from_fn(|i| {
            let j = (i + 2) % 3;
            let coupled = self.cross_coupling * q[j] * self.mm_per_step[j];
            self.maps[i].bending(q[i] * self.mm_per_step[i] - creep_mm[i] + coupled)
        })
    }
}
