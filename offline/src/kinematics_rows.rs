//! One row of `pcr ik` and of `pcr fk`: what the model says of a pose or of motor positions,
//! with a status word. The Python package's batch calls run the same function on every row.

use pcr_kinematics::{Pose, Robot};

/// The status words of the kinematic rows, in the order of their codes.
pub const STATUSES: [&str; 5] = [
    "ok",
    "singular",
    "unreachable",
    "joint_limit",
    "bending_limit",
];

/// The code (index in [`STATUSES`]) of a status word.
pub fn status_code(status: &str) -> u8 {
    STATUSES.iter().position(|s| *s == status).unwrap_or(2) as u8
}

/// The joint values of a pose that has an IK solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkValues {
    /// Curvatures kappa_i, 1/mm.
    pub kappa_per_mm: [f64; 3],
    /// Tendon displacements dl_i through the inverse tendon map, mm (0 where the map cannot
    /// reach the curvature: status `bending_limit`).
    pub dl_mm: [f64; 3],
    /// Motor positions, steps (dl_i over the steps' length, rounded).
    pub steps: [i64; 3],
    /// Passive joint angles gamma_i at M_i, rad.
    pub gamma_rad: [f64; 3],
    /// Passive joint angles zeta_i at P_i, rad.
    pub zeta_rad: [f64; 3],
}

/// One row of `pcr ik`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkRow {
    /// The joint values (None without an IK solution in the working mode).
    pub values: Option<IkValues>,
    /// `ok`, `singular` (conditioning below the robot's threshold), `bending_limit`,
    /// `joint_limit` or `unreachable`.
    pub status: &'static str,
}

/// The IK row of a pose: curvatures, tendon displacements, motor steps, joint angles, status.
pub fn ik_row(robot: &Robot, pose: &Pose) -> IkRow {
    match robot.ik(pose) {
        Ok(s) => {
            let mut dl = [0.0; 3];
            let mut status = if robot.conditioning(pose, &s.kappa).value()
                < robot.limits.singularity_threshold
            {
                "singular"
            } else {
                "ok"
            };
            for i in 0..3 {
                match robot.legs[i].map.dl_for_kappa(s.kappa[i]) {
                    Ok(d) => dl[i] = d,
                    Err(_) => status = "bending_limit",
                }
            }
            IkRow {
                values: Some(IkValues {
                    kappa_per_mm: s.kappa,
                    dl_mm: dl,
                    steps: std::array::from_fn(|i| {
                        (dl[i] / robot.legs[i].mm_per_step).round() as i64
                    }),
                    gamma_rad: s.gamma,
                    zeta_rad: s.zeta,
                }),
                status,
            }
        }
        Err(e) => IkRow {
            values: None,
            status: e.status(),
        },
    }
}

/// One row of `pcr fk`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FkRow {
    /// The platform pose (None where no pose in the working and assembly mode closes the loops).
    pub pose: Option<Pose>,
    /// `ok`, `singular`, or the limit the closed loops violate (`joint_limit`,
    /// `bending_limit`), or `unreachable`.
    pub status: &'static str,
}

/// The FK row of curvatures (1/mm).
pub fn fk_row(robot: &Robot, kappa: &[f64; 3]) -> FkRow {
    match robot.fk(kappa) {
        Ok(p) => {
            // The loops close; report a limit that is violated there, or a singularity.
            let status = match robot.ik(&p) {
                Err(e) => e.status(),
                Ok(_)
                    if robot.conditioning(&p, kappa).value()
                        < robot.limits.singularity_threshold =>
                {
                    "singular"
                }
                Ok(_) => "ok",
            };
            FkRow {
                pose: Some(p),
                status,
            }
        }
        Err(e) => FkRow {
            pose: None,
            status: e.status(),
        },
    }
}

/// The curvatures (1/mm) of motor positions (steps), through the tendon maps.
pub fn kappa_of_steps(robot: &Robot, q: &[f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| robot.steps_to_kappa(i, q[i]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn home_is_ok_and_fk_returns_it() {
        let r = Robot::nominal();
        let row = ik_row(&r, &Pose::default());
        assert_eq!(row.status, "ok");
        let v = row.values.unwrap();
        let back = fk_row(&r, &v.kappa_per_mm);
        assert_eq!(back.status, "ok");
        assert!(back.pose.unwrap().position_distance(&Pose::default()) < 1e-9);
        assert_eq!(status_code("joint_limit"), 3);
    }

    #[test]
    fn far_poses_are_unreachable() {
        let row = ik_row(&Robot::nominal(), &Pose::from_mm_deg(500.0, 0.0, 0.0));
        assert_eq!(row.status, "unreachable");
        assert!(row.values.is_none());
    }
}
