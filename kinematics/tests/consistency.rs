//! IK/FK consistency, Jacobians against finite differences, symmetry, limits and singularities.

#![allow(clippy::needless_range_loop)] // loops over the three legs read best with an index

use pcr_kinematics::{IkError, Pose, Robot};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Random poses with an IK solution in the working mode (phi within +-15 deg).
fn random_workspace_poses(r: &Robot, n: usize, seed: u64) -> Vec<(Pose, [f64; 3])> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::new();
    while out.len() < n {
        let p = Pose::from_mm_deg(
            rng.random_range(-90.0..90.0),
            rng.random_range(-90.0..95.0),
            rng.random_range(-15.0..15.0),
        );
        if let Ok(s) = r.ik(&p) {
            if r.conditioning(&p, &s.kappa).value() > 0.02 {
                out.push((p, s.kappa));
            }
        }
    }
    out
}

#[test]
fn ik_then_cold_fk_returns_the_pose() {
    let r = Robot::nominal();
    let mut worst = 0.0f64;
    for (p, k) in random_workspace_poses(&r, 3000, 1) {
        let back = r.fk(&k).unwrap_or_else(|e| panic!("FK of {p:?}: {e}"));
        let err = p
            .position_distance(&back)
            .max((p.phi - back.phi).abs() * 59.0);
        worst = worst.max(err);
        assert!(err < 1e-9, "pose {p:?} came back as {back:?} ({err:e} mm)");
    }
    eprintln!("worst IK->FK round trip {worst:e} mm");
}

#[test]
fn warm_fk_tracks_a_path() {
    let r = Robot::nominal();
    let mut prev = Pose::default();
    for k in 0..=500 {
        let t = k as f64 / 500.0 * std::f64::consts::TAU;
        let p = Pose::new(50.0 * t.cos() - 50.0 + 50.0, 50.0 * t.sin(), 0.0);
        let s = r.ik(&p).unwrap();
        let back = r.fk_warm(&s.kappa, &prev).unwrap();
        assert!(p.position_distance(&back) < 1e-9 && (p.phi - back.phi).abs() < 1e-11);
        prev = back;
    }
}

#[test]
fn jacobians_match_finite_differences() {
    let r = Robot::nominal();
    for (p, k) in random_workspace_poses(&r, 200, 2) {
        let a = r.jacobian_a(&p, &k);
        let b = r.jacobian_b(&p, &k);
        let h = 1e-6;
        for c in 0..3 {
            let mut xp = p.to_array();
            let mut xm = p.to_array();
            xp[c] += h;
            xm[c] -= h;
            let hp = r.constraints(&Pose::from_array(xp), &k);
            let hm = r.constraints(&Pose::from_array(xm), &k);
            for i in 0..3 {
                let fd = (hp[i] - hm[i]) / (2.0 * h);
                assert!(
                    (fd - a[(i, c)]).abs() < 1e-5 * a[(i, c)].abs().max(1.0),
                    "A[{i},{c}]"
                );
            }
        }
        for i in 0..3 {
            let hk = 1e-9;
            let mut kp = k;
            let mut km = k;
            kp[i] += hk;
            km[i] -= hk;
            let fd = (r.constraints(&p, &kp)[i] - r.constraints(&p, &km)[i]) / (2.0 * hk);
            assert!(
                (fd - b[i]).abs() < 1e-5 * b[i].abs().max(1.0),
                "B[{i}] {fd} vs {}",
                b[i]
            );
        }
        // J against finite-difference FK
        let j = r.jacobian(&p, &k).unwrap();
        for c in 0..3 {
            let hk = 1e-8;
            let mut kp = k;
            let mut km = k;
            kp[c] += hk;
            km[c] -= hk;
            let xp = r.fk_warm(&kp, &p).unwrap().to_array();
            let xm = r.fk_warm(&km, &p).unwrap().to_array();
            for row in 0..3 {
                let fd = (xp[row] - xm[row]) / (2.0 * hk);
                assert!(
                    (fd - j[(row, c)]).abs() < 1e-4 * j[(row, c)].abs().max(1.0),
                    "J[{row},{c}] {fd} vs {}",
                    j[(row, c)]
                );
            }
        }
    }
}

#[test]
fn three_fold_symmetry_permutes_curvatures() {
    let r = Robot::nominal();
    for (p, k) in random_workspace_poses(&r, 100, 3) {
        // Rotating the pose by +120 deg about the origin maps leg i onto leg i+1.
        let a = 120f64.to_radians();
        let q = Pose::new(
            a.cos() * p.x - a.sin() * p.y,
            a.sin() * p.x + a.cos() * p.y,
            p.phi + a,
        );
        if let Ok(s) = r.ik(&q) {
            for i in 0..3 {
                assert!((s.kappa[(i + 1) % 3] - k[i]).abs() < 1e-12);
            }
        }
    }
    // A pose on the symmetry axis through leg 1's base (mirror symmetry): legs 2 and 3 mirror.
    let s = r.ik(&Pose::default()).unwrap();
    assert!((s.kappa[0] - s.kappa[1]).abs() < 1e-14 && (s.kappa[1] - s.kappa[2]).abs() < 1e-14);
}

#[test]
fn statuses_for_limits() {
    let r = Robot::nominal();
    assert!(matches!(
        r.ik(&Pose::from_mm_deg(400.0, 0.0, 0.0)),
        Err(IkError::Unreachable { .. })
    ));
    // Far-bent legs hit the bending limit before the loop opens when the limit is tight.
    let mut c = r.config().clone();
    c.limits.bending_max_deg = 30.0;
    let tight = Robot::new(&c).unwrap();
    let e = tight.ik(&Pose::from_mm_deg(20.0, -10.0, 5.0)).unwrap_err();
    assert!(matches!(e, IkError::BendingLimit { leg: 1, .. }), "{e}");
    assert_eq!(e.status(), "bending_limit");
    let mut c = r.config().clone();
    c.limits.joint_min_deg = -80.0;
    let tight = Robot::new(&c);
    // the home pose has gamma = -82.9 deg: with a -80 deg limit the home pose is out of range
    assert!(tight.is_err());
    c.limits.joint_min_deg = -95.0;
    let tight = Robot::new(&c).unwrap();
    let e = tight
        .ik(&Pose::from_mm_deg(-40.0, 30.0, -10.0))
        .unwrap_err();
    assert!(
        matches!(
            e,
            IkError::JointLimit {
                leg: 1,
                joint: 'M',
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn singularity_measure_vanishes_where_the_link_is_tangent() {
    let r = Robot::nominal();
    let home = r.conditioning(&Pose::default(), &r.home_kappa).value();
    assert!(home > 0.1, "home conditioning {home}");
    // Place P_1 so that link 1 is perpendicular to the direction in which M_1 moves: det B = 0.
    let mut k = r.home_kappa;
    k[0] = 0.004;
    let h = 1e-7;
    let m = r.joint_m(0, k[0]);
    let dm = {
        let (a, b) = (r.joint_m(0, k[0] + h), r.joint_m(0, k[0] - h));
        [(a[0] - b[0]) / (2.0 * h), (a[1] - b[1]) / (2.0 * h)]
    };
    let n = (dm[0].hypot(dm[1]), 164.0);
    for tilt in [0.3f64, 0.1, 0.01, 0.0] {
        // link direction: perpendicular to dM, tilted by `tilt` rad
        let base = (-dm[1] / n.0, dm[0] / n.0);
        let (s, c) = tilt.sin_cos();
        let u = (c * base.0 - s * base.1, s * base.0 + c * base.1);
        let p1 = [m[0] + n.1 * u.0, m[1] + n.1 * u.1];
        let pe = r.legs[0].p_e;
        let pose = Pose::new(p1[0] - pe[0], p1[1] - pe[1], 0.0);
        let b = r.conditioning(&pose, &k).b;
        assert!((b - tilt.sin().abs()).abs() < 1e-6, "tilt {tilt}: b = {b}");
    }
    // det A = 0: all three links parallel to each other (their lines meet at infinity).
    let pose = Pose::default();
    let mut kk = r.home_kappa;
    // Move the M_i so that every link points along +y, keeping the P_i fixed.
    {
        for i in 0..3 {
            let p = r.joint_p(i, &pose);
            // choose kappa_i so that M_i is as close as possible to P_i - (0, 164)
            let target = [p[0], p[1] - 164.0];
            let mut best = (f64::INFINITY, kk[i]);
            for j in -3000..3000 {
                let kap = j as f64 * 1e-5;
                let mm = r.joint_m(i, kap);
                let d = (mm[0] - target[0]).hypot(mm[1] - target[1]);
                if d < best.0 {
                    best = (d, kap);
                }
            }
            kk[i] = best.1;
        }
    }
    let c = r.conditioning(&pose, &kk);
    assert!(
        c.a < 0.1 * home,
        "parallel links: A-measure {} vs home {home}",
        c.a
    );
}

#[test]
fn table_scan_finds_every_root_a_fine_scan_finds() {
    let r = Robot::nominal();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for _ in 0..400 {
        let p = Pose::from_mm_deg(
            rng.random_range(-150.0..150.0),
            rng.random_range(-150.0..150.0),
            rng.random_range(-40.0..40.0),
        );
        for i in 0..3 {
            let leg = &r.legs[i];
            let pb = r.joint_p(i, &p);
            let h = |theta: f64| {
                let m = leg.joint_m(theta / leg.l_c);
                (pb[0] - m[0]).powi(2) + (pb[1] - m[1]).powi(2) - leg.l_st * leg.l_st
            };
            // brute force over the bending range with 0.01 deg steps
            let lim = r.limits.bending_max;
            let n = 36_000;
            let mut brute = Vec::new();
            let mut prev = h(-lim);
            for k in 1..=n {
                let th = -lim + 2.0 * lim * k as f64 / n as f64;
                let v = h(th);
                if prev * v <= 0.0 && prev != 0.0 {
                    brute.push(th);
                }
                prev = v;
            }
            let found: Vec<f64> = r
                .leg_roots(i, &p)
                .as_slice()
                .iter()
                .map(|x| x.theta)
                .filter(|t| t.abs() <= lim)
                .collect();
            for b in &brute {
                assert!(
                    found.iter().any(|f| (f - b).abs() < 1e-3),
                    "pose {p:?} leg {i}: root at {b} missed (found {found:?})"
                );
            }
        }
    }
}

/// `in_mode` and `jacobian` share each leg's tip and the platform's sin_cos: they must be bit
/// for bit what their building blocks (`jacobian_a`, `jacobian_b`, `joint_angles`) say, on
/// poses in and out of the working mode (mirrored curvatures, flipped orientations).
#[test]
fn in_mode_and_the_jacobian_are_their_building_blocks_bit_for_bit() {
    use nalgebra::{Matrix3, Vector3};
    let r = Robot::nominal();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (mut inside, mut outside) = (0, 0);
    for (p, k) in random_workspace_poses(&r, 300, 3) {
        for trial in 0..4 {
            let (p, k) = match trial {
                0 => (p, k),
                1 => (Pose::new(p.x, p.y, -p.phi), k),
                2 => (p, [-k[0], k[1], -k[2]]),
                _ => (
                    Pose::new(
                        p.x + rng.random_range(-30.0..30.0),
                        p.y + rng.random_range(-30.0..30.0),
                        p.phi + rng.random_range(-1.0..1.0),
                    ),
                    k,
                ),
            };
            let det = r.jacobian_a(&p, &k).determinant();
            let blocks = det.signum() == r.home_det_sign
                && (0..3).all(|i| r.joint_angles(i, &p, k[i]).0 * r.mode[i].sign() > 0.0);
            assert_eq!(r.in_mode(&p, &k), blocks, "{p:?} {k:?}");
            if blocks {
                inside += 1;
            } else {
                outside += 1;
            }
            let b = Matrix3::from_diagonal(&Vector3::from(r.jacobian_b(&p, &k)));
            let j = r.jacobian_a(&p, &k).lu().solve(&b).map(|m| -m);
            let got = r.jacobian(&p, &k);
            assert_eq!(
                got.map(|m| m.as_slice().iter().map(|x| x.to_bits()).collect::<Vec<_>>()),
                j.map(|m| m.as_slice().iter().map(|x| x.to_bits()).collect::<Vec<_>>()),
                "{p:?} {k:?}"
            );
        }
    }
    assert!(inside > 100 && outside > 30, "{inside} in, {outside} out");
}
