//! The Rust loop the Python bindings' batch IK is measured against (BENCHMARKS.md, "Python
//! bindings"): the IK row of `pcr ik` (`kinematics_rows::ik_row`: IK, singularity measure,
//! tendon displacements, steps) for every pose of a file, repeated, timed per pose.
//!
//! `cargo run --release -p pcr-offline --example ik_rows -- POSES.csv [RUNS]`: POSES.csv has
//! the columns x_mm, y_mm, phi_deg (nothing else, no comments); prints the median and the
//! minimum over RUNS (default 7) of the wall time per pose, ns.

use pcr_kinematics::{Pose, Robot};
use pcr_offline::kinematics_rows::ik_row;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: ik_rows POSES.csv [RUNS]");
    let runs: usize = args
        .get(2)
        .map_or(7, |r| r.parse().expect("RUNS is a number"));
    let text = std::fs::read_to_string(path).expect("readable poses file");
    let poses: Vec<Pose> = text
        .lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l
                .split(',')
                .map(|c| c.trim().parse().expect("a number"))
                .collect();
            Pose::from_mm_deg(v[0], v[1], v[2])
        })
        .collect();
    let robot = Robot::nominal();
    let mut per_pose = Vec::with_capacity(runs);
    let mut ok = 0usize;
    for _ in 0..runs {
        let t = Instant::now();
        ok = 0;
        for p in &poses {
            let r = std::hint::black_box(ik_row(&robot, std::hint::black_box(p)));
            ok += usize::from(r.status == "ok");
        }
        per_pose.push(t.elapsed().as_secs_f64() * 1e9 / poses.len() as f64);
    }
    per_pose.sort_by(f64::total_cmp);
    println!(
        "rust loop: {} poses ({ok} ok), {runs} runs: median {:.1} ns/pose, min {:.1} ns/pose",
        poses.len(),
        per_pose[runs / 2],
        per_pose[0]
    );
}
