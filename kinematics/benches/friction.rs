//! Timing of the friction's history (`Robot::friction_step`) along a series of 2000 consecutive
//! rows that reverse direction (a Lissajous path of 40 mm and 6 deg), at a tenth, once, three
//! and ten times the prototype's friction (2 N mm per joint, 0.04 N per support), and of its
//! derivatives at zero friction (`Robot::friction_onset`), with a checksum of the deflections to
//! compare builds; then the same configurations as rows every fourth, the three between passed
//! (`Robot::friction_pass`, the configurations a stair of steps passes between two rows), per
//! configuration. Per row: the minimum over 8 repeats. Run:
//! `cargo bench -p pcr-kinematics --bench friction`.

use pcr_kinematics::friction::{Friction, FrictionState};
use pcr_kinematics::{Pose, Robot};
use std::hint::black_box;
use std::time::Instant;

/// The best of 8 runs of `run` (from a new state; it returns a checksum), seconds, and the
/// checksum.
fn best_of(mut run: impl FnMut(&mut FrictionState) -> f64) -> (f64, f64) {
    let mut best = f64::INFINITY;
    let mut sum = 0.0;
    for _ in 0..8 {
        let t0 = Instant::now();
        sum = run(&mut FrictionState::default());
        best = best.min(t0.elapsed().as_secs_f64());
    }
    (best, sum)
}

fn main() {
    let r = Robot::nominal();
    let s: Vec<([f64; 3], Pose)> = (0..2000)
        .filter_map(|k| {
            let t = k as f64 * 0.004;
            let p = Pose::from_mm_deg(
                40.0 * (1.1 * t).cos(),
                40.0 * (1.7 * t).sin(),
                6.0 * (1.3 * t).sin(),
            );
            r.ik(&p).ok().map(|ik| (ik.kappa, p))
        })
        .collect();
    let per_row = |best: f64| 1e6 * best / s.len() as f64;
    let prototype = Friction {
        joint_torque: 2.0,
        joint_presliding: 1e-3,
        support_force: 0.04,
        support_presliding: 5e-3,
        ei: 6.5e4,
    };
    let scaled = |scale: f64| Friction {
        joint_torque: 2.0 * scale,
        support_force: 0.04 * scale,
        ..prototype
    };
    for scale in [0.1, 1.0, 3.0, 10.0] {
        let f = scaled(scale);
        let (best, sum) = best_of(|st| {
            s.iter()
                .map(|(kappa, p)| {
                    let d = r.friction_step(&f, p, black_box(kappa), st).unwrap();
                    d[0].abs() + d[1].abs() + d[2].abs()
                })
                .sum()
        });
        println!(
            "friction_step {:>4}x: {:6.2} us/row (checksum {sum:.9e})",
            scale,
            per_row(best)
        );
    }
    let (best, sum) = best_of(|st| {
        s.iter()
            .map(|(kappa, p)| {
                let d = r
                    .friction_onset(&prototype, p, black_box(kappa), st)
                    .unwrap();
                d.iter().flatten().map(|v| v.abs()).sum::<f64>()
            })
            .sum()
    });
    println!(
        "friction_onset     : {:6.2} us/row (checksum {sum:.9e})",
        per_row(best)
    );
    for scale in [1.0, 3.0] {
        let f = scaled(scale);
        let (best, sum) = best_of(|st| {
            let mut sum = 0.0;
            for (k, (kappa, p)) in s.iter().enumerate() {
                if k % 4 == 0 {
                    let d = r.friction_step(&f, p, black_box(kappa), st).unwrap();
                    sum += d[0].abs() + d[1].abs() + d[2].abs();
                } else {
                    r.friction_pass(&f, p, black_box(kappa), st, None).unwrap();
                }
            }
            sum
        });
        println!(
            "a row, 3 passed {:>4}x: {:6.2} us/configuration (checksum {sum:.9e})",
            scale,
            per_row(best)
        );
    }
}
