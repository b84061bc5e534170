//! Joint-space moves: synchronised, exact targets, per-motor limits at 1 ms sampling, and the
//! task-space check of the poses along the move (FK).

#![allow(clippy::needless_range_loop)]

use pcr_kinematics::{CheckOptions, Pose as KPose, Robot};
use pcr_planner::joint::{JointError, JointLimits, JointMove};
use pcr_robot::RobotConfig;

fn limits() -> JointLimits {
    JointLimits::from_config(&RobotConfig::nominal(), 1.0, 2000.0, 20000.0).unwrap()
}

fn home_steps(robot: &Robot) -> [f64; 3] {
    std::array::from_fn(|i| {
        robot
            .kappa_to_steps(i, robot.home_kappa[i])
            .unwrap()
            .round()
    })
}

#[test]
fn limits_come_from_the_actuation_section() {
    let l = limits();
    assert_eq!(l.rate, [600.0; 3]);
    let half = JointLimits::from_config(&RobotConfig::nominal(), 0.5, 1.0, 2.0).unwrap();
    assert_eq!(half.rate, [300.0; 3]);
    assert_eq!(half.accel, [1.0; 3]);
    assert_eq!(half.jerk, [2.0; 3]);
}

#[test]
fn motors_finish_together_at_the_target_within_their_limits() {
    let l = limits();
    let from = [176.0, 176.0, 176.0];
    let to = [1176.0, -50.0, 400.0];
    let m = JointMove::plan(from, to, &l).unwrap();
    let dur = m.duration();
    // Motor 1 moves most: at least its own time-optimal duration (1000 steps at 600 steps/s).
    assert!(dur > 1000.0 / 600.0);
    let dt = 1e-3;
    let n = (dur / dt).ceil() as usize;
    let mut peak = [0.0f64; 3];
    for k in 0..=n {
        let t = (k as f64 * dt).min(dur);
        let s = m.sample(t);
        for i in 0..3 {
            assert!(
                s.rate[i].abs() <= l.rate[i] * (1.0 + 1e-9),
                "rate {i} at {t}"
            );
            assert!(
                s.accel[i].abs() <= l.accel[i] * (1.0 + 1e-9),
                "accel {i} at {t}"
            );
            assert!(
                s.jerk[i].abs() <= l.jerk[i] * (1.0 + 1e-9),
                "jerk {i} at {t}"
            );
            // Never beyond the target (rest to rest, monotone).
            let (lo, hi) = (from[i].min(to[i]), from[i].max(to[i]));
            assert!(s.q[i] >= lo - 1e-9 && s.q[i] <= hi + 1e-9);
            peak[i] = peak[i].max(s.rate[i].abs());
        }
    }
    // The limiting motor runs at its rate limit; the others are slowed down to finish together.
    assert!(peak[0] > 0.999 * l.rate[0]);
    assert!(peak[1] < l.rate[1] && peak[2] < l.rate[2]);
    // Every motor is still moving shortly before the end and all arrive at the same time.
    let before = m.sample(dur - 0.05);
    for i in 0..3 {
        assert!(
            (before.q[i] - to[i]).abs() > 1e-6,
            "motor {i} arrived early"
        );
        assert!((m.sample(dur - 1e-9).q[i] - to[i]).abs() < 1e-6);
    }
    assert_eq!(m.sample(dur).q, to);
    assert_eq!(m.steps_at(dur + 1.0), [1176, -50, 400]);
    assert_eq!(m.steps_at(0.0), [176, 176, 176]);
}

#[test]
fn the_poses_along_a_move_are_found_by_fk_and_checked() {
    let robot = Robot::nominal();
    let home = home_steps(&robot);
    let to = [home[0] + 150.0, home[1] - 100.0, home[2] + 20.0];
    let m = JointMove::plan(home, to, &limits()).unwrap();
    let samples = m
        .check(&robot, 0.002, &KPose::default(), &CheckOptions::default())
        .unwrap();
    assert!(samples.len() > 100);
    // The pose at the start is (close to) home; the last one reproduces the target steps by IK.
    assert!(samples[0].1.position_distance(&KPose::default()) < 0.5);
    let last = samples.last().unwrap().1;
    let ik = robot.ik(&last).unwrap();
    for i in 0..3 {
        let q = robot.kappa_to_steps(i, ik.kappa[i]).unwrap();
        assert!((q - to[i]).abs() < 1e-6, "{q} vs {}", to[i]);
    }
    // A far move leaves the workspace: the error names the time.
    let far = [home[0] + 3000.0, home[1] - 3000.0, home[2]];
    let m = JointMove::plan(home, far, &limits()).unwrap();
    let e = m
        .check(&robot, 0.002, &KPose::default(), &CheckOptions::default())
        .unwrap_err();
    assert!(
        matches!(e, JointError::Fk { .. } | JointError::Rejected(_)),
        "{e}"
    );
    assert!(e.to_string().contains("at t = "), "{e}");
}
