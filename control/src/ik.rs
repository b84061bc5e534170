//! The IK step: task setpoint -> curvatures -> motor steps.

use crate::compensation::MotorCompensation;
use pcr_kinematics::friction::{Friction, FrictionState};
use pcr_kinematics::statics::Loads;
use pcr_kinematics::{Pose, Robot};
use pcr_messages::{JointSetpoint, TaskSetpoint, PROTOCOL_VERSION};

/// The IK step. When a setpoint has no IK solution it repeats the last valid joint setpoint
/// (flagged `ik_failed`) so that the drive holds instead of jumping.
///
/// The effects the robot file declares are compensated here: the loaded IK with
/// `[effects.compliance]`, the friction's deflection fed forward (`[effects.friction]`: the
/// path commanded so far leaves the joints and their supports stuck or slipping, which moves
/// the platform; the setpoint is moved against the deflection predicted there, and the
/// friction's state follows the configuration commanded), and the motor side (creep, periodic
/// errors, backlash) after it ([`MotorCompensation`]).
#[derive(Debug)]
pub struct IkStep {
    robot: Robot,
    loads: Option<Loads>,
    friction: Option<(Friction, FrictionState)>,
    comp: MotorCompensation,
    last_steps: [i32; 3],
    last_kappa: [f64; 3],
    failures: u64,
}

impl IkStep {
    /// A step for `robot`, starting from its home configuration.
    pub fn new(robot: Robot) -> Self {
        let k = robot.home_kappa;
        let e = &robot.config().effects;
        let loads = e.compliance.as_ref().map(Loads::from_compliance);
        let comp = MotorCompensation::new(robot.config());
        let friction = e
            .friction
            .as_ref()
            .map(Friction::from_effect)
            .filter(|f| !f.is_off())
            .map(|f| {
                // The segments' compliance table is built here, not in the first cycle
                // (`step` allocates nothing).
                let _ = robot.tip_compliance_tabulated(0, 0.0, f.ei);
                (f, FrictionState::default())
            });
        let mut s = Self {
            robot,
            loads,
            friction,
            comp,
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

    fn targets_of(&self, kappa: &[f64; 3]) -> Option<[f64; 3]> {
        let mut q = [0.0; 3];
        for i in 0..3 {
            let s = self.robot.kappa_to_steps(i, kappa[i]).ok()?;
            if !s.is_finite() || s.abs() > 1e9 {
                return None;
            }
            q[i] = s;
        }
        Some(q)
    }

    fn steps_of(&self, kappa: &[f64; 3]) -> Option<[i32; 3]> {
        self.targets_of(kappa).map(|q| q.map(|v| v.round() as i32))
    }

    /// The curvatures that put the platform at `pose` (the loaded IK where the file declares
    /// a compliance).
    fn curvatures(&self, pose: &Pose) -> Option<[f64; 3]> {
        match &self.loads {
            Some(l) => self.robot.ik_loaded(pose, l).ok(),
            None => self.robot.ik(pose).ok().map(|s| s.kappa),
        }
    }

    /// The curvatures for `pose` with the friction's deflection fed forward: the deflection the
    /// friction's state predicts at the configuration of `pose` is subtracted from the target,
    /// once more at the configuration that gives (a fixed-point step: the deflection changes
    /// little over its own size), and the state then follows the configuration commanded.
    fn curvatures_through_friction(&mut self, pose: &Pose) -> Option<[f64; 3]> {
        let kappa = self.curvatures(pose)?;
        let Some((f, mut state)) = self.friction else {
            return Some(kappa);
        };
        // The rigid pose of curvatures `k` (the friction's configuration; under a compliance
        // the loaded IK's curvatures put the rigid platform elsewhere).
        let rigid = |k: &[f64; 3]| self.robot.fk_warm(k, pose).ok();
        let mut target = kappa;
        for _ in 0..2 {
            let mut trial = state;
            let Some(d) = rigid(&target)
                .and_then(|r| self.robot.friction_step(&f, &r, &target, &mut trial).ok())
            else {
                break;
            };
            let moved = Pose::new(pose.x - d[0], pose.y - d[1], pose.phi - d[2]);
            match self.curvatures(&moved) {
                Some(k) => target = k,
                None => break,
            }
        }
        if let Some(r) = rigid(&target) {
            let _ = self.robot.friction_step(&f, &r, &target, &mut state);
        }
        self.friction = Some((f, state));
        Some(target)
    }

    /// One cycle. Allocation-free.
    pub fn step(&mut self, sp: &TaskSetpoint) -> JointSetpoint {
        let pose = Pose::new(sp.x_mm, sp.y_mm, sp.phi_rad);
        let kappa = self.curvatures_through_friction(&pose);
        let sol = kappa.and_then(|k| self.targets_of(&k).map(|q| (k, q)));
        let sol = sol.map(|(k, q)| {
            let q = if self.comp.is_active() {
                self.comp.command(sp.t_s, q)
            } else {
                q
            };
            (k, q.map(|v| v.round() as i32))
        });
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
