//! The IK step: task setpoint -> curvatures -> motor steps.

use pcr_kinematics::{Pose, Robot};
use pcr_messages::{JointSetpoint, TaskSetpoint, PROTOCOL_VERSION};

/// The IK step. When a setpoint has no IK solution it repeats the last valid joint setpoint
/// (flagged `ik_failed`) so that the drive holds instead of jumping.
#[derive(Debug)]
pub struct IkStep {
    robot: Robot,
    last_steps: [i32; 3],
    last_kappa: [f64; 3],
    failures: u64,
}

impl IkStep {
    /// A step for `robot`, starting from its home configuration.
    pub fn new(robot: Robot) -> Self {
        let k = robot.home_kappa;
        let mut s = Self {
            robot,
            last_steps: [0; 3],
            last_kappa: k,
            failures: 0,
        };
        s.last_steps = s.steps_of(&k).unwrap_or([0; 3]);
        s
    }

    /// The robot model.
    pub fn robot(&self) -> &Robot {
        &self.robot
    }

    /// Setpoints without IK solution so far.
    pub fn failures(&self) -> u64 {
        self.failures
    }

    fn steps_of(&self, kappa: &[f64; 3]) -> Option<[i32; 3]> {
        let mut q = [0i32; 3];
        for i in 0..3 {
            let s = self.robot.kappa_to_steps(i, kappa[i]).ok()?;
            if !s.is_finite() || s.abs() > i32::MAX as f64 {
                return None;
            }
            q[i] = s.round() as i32;
        }
        Some(q)
    }

    /// One cycle. Allocation-free.
    pub fn step(&mut self, sp: &TaskSetpoint) -> JointSetpoint {
        let pose = Pose::new(sp.x_mm, sp.y_mm, sp.phi_rad);
        let sol = self
            .robot
            .ik(&pose)
            .ok()
            .and_then(|s| self.steps_of(&s.kappa).map(|q| (s.kappa, q)));
        let ik_failed = match sol {
            Some((k, q)) => {
                self.last_kappa = k;
                self.last_steps = q;
                0
            }
            None => {
                self.failures += 1;
                1
            }
        };
        JointSetpoint {
            t_s: sp.t_s,
            steps: self.last_steps,
            enable: 1,
            kappa: self.last_kappa,
            planned: sp.nominal,
            seq: sp.seq,
            run_id: sp.run_id,
            flags: sp.flags,
            ik_failed,
            version: PROTOCOL_VERSION,
            stamps: sp.stamps,
        }
    }
}
