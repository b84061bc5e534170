//! Calls IK 100 000 times (for instruction counting: `valgrind --tool=callgrind`).
use pcr_kinematics::{Pose, Robot};
fn main() {
    let r = Robot::nominal();
    let mut acc = 0.0;
    for k in 0..100_000 {
        let t = k as f64 * 0.7;
        let p = Pose::from_mm_deg(50.0 * t.cos(), 50.0 * t.sin(), 8.0 * (1.3 * t).sin());
        if let Ok(s) = r.ik(std::hint::black_box(&p)) {
            acc += s.kappa[0];
        }
    }
    println!("{acc}");
}
