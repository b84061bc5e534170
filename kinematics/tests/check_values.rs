//! The check values of geometry.md, computed independently of the project.

#![allow(clippy::needless_range_loop)] // loops over the three legs read best with an index

use pcr_kinematics::{Pose, Robot};

#[test]
fn ik_check_values() {
    let r = Robot::nominal();
    let cases = [
        (
            (0.0, 0.0, 0.0),
            [0.00307872, 0.00307872, 0.00307872],
            (-82.899, -44.949),
        ),
        (
            (20.0, -10.0, 5.0),
            [0.00521470, 0.00227929, 0.00289048],
            (-69.049, -51.396),
        ),
        (
            (-40.0, 30.0, -10.0),
            [-0.00101109, 0.00642225, 0.00354467],
            (-100.058, -22.817),
        ),
    ];
    for ((x, y, p), kappa, (gamma, zeta)) in cases {
        let s = r.ik(&Pose::from_mm_deg(x, y, p)).unwrap();
        for i in 0..3 {
            assert!(
                (s.kappa[i] - kappa[i]).abs() < 5e-9,
                "pose {x},{y},{p} leg {i}: {} vs {}",
                s.kappa[i],
                kappa[i]
            );
        }
        assert!(
            (s.gamma[0].to_degrees() - gamma).abs() < 5e-4,
            "{}",
            s.gamma[0].to_degrees()
        );
        assert!(
            (s.zeta[0].to_degrees() - zeta).abs() < 5e-4,
            "{}",
            s.zeta[0].to_degrees()
        );
    }
    // 22.050 deg bending at home
    let s = r.ik(&Pose::default()).unwrap();
    assert!(((s.kappa[0] * 125.0).to_degrees() - 22.050).abs() < 5e-4);
}

#[test]
fn second_branch_at_home() {
    let r = Robot::nominal();
    for i in 0..3 {
        let roots = r.leg_roots(i, &Pose::default());
        let other: Vec<_> = roots
            .as_slice()
            .iter()
            .filter(|r| r.gamma > 0.0 && r.valid())
            .collect();
        assert_eq!(other.len(), 1, "leg {i}: {:?}", roots.as_slice());
        let o = other[0];
        assert!((o.kappa - 0.0224255).abs() < 5e-8, "{}", o.kappa);
        // geometry.md rounds this to 160.7 deg; 0.0224255 * 125 rad is 160.61 deg.
        assert!(((o.kappa * 125.0).to_degrees() - 160.65).abs() < 0.1);
        assert!(
            (o.gamma.to_degrees() - 124.300).abs() < 5e-4,
            "{}",
            o.gamma.to_degrees()
        );
        assert!(
            (o.zeta.to_degrees() - 23.689).abs() < 5e-4,
            "{}",
            o.zeta.to_degrees()
        );
    }
}

#[test]
fn det_a_at_home() {
    let r = Robot::nominal();
    let s = r.ik(&Pose::default()).unwrap();
    let det = r.jacobian_a(&Pose::default(), &s.kappa).determinant();
    assert!((det / 3.82e9 - 1.0).abs() < 5e-3, "det A = {det:e}");
    assert_eq!(r.home_det_sign, 1.0);
}
