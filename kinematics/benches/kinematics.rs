//! Benchmarks of the kinematic model: IK of one pose, FK warm and cold, a 1 mm workspace.
//! Run: `cargo bench -p pcr-kinematics --bench kinematics`.

use criterion::{criterion_group, criterion_main, Criterion};
use pcr_kinematics::{workspace, Pose, Robot};
use std::hint::black_box;

fn poses(r: &Robot) -> Vec<(Pose, [f64; 3])> {
    let mut v = Vec::new();
    for k in 0..64 {
        let t = k as f64 * 0.7;
        let p = Pose::from_mm_deg(50.0 * t.cos(), 50.0 * t.sin(), 8.0 * (1.3 * t).sin());
        if let Ok(s) = r.ik(&p) {
            v.push((p, s.kappa));
        }
    }
    v
}

fn bench(c: &mut Criterion) {
    let r = Robot::nominal();
    let ps = poses(&r);
    let mut k = 0;
    c.bench_function("ik_one_pose_3_legs", |b| {
        b.iter(|| {
            k = (k + 1) % ps.len();
            black_box(r.ik(black_box(&ps[k].0)).ok())
        })
    });
    // Warm FK: the guess is the pose 0.2 mm / 0.05 deg away, as in a 20 ms control cycle.
    c.bench_function("fk_warm", |b| {
        b.iter(|| {
            k = (k + 1) % ps.len();
            let (p, kappa) = ps[k];
            let guess = Pose::new(p.x + 0.2, p.y - 0.1, p.phi + 0.001);
            black_box(r.fk_warm(black_box(&kappa), &guess).ok())
        })
    });
    c.bench_function("fk_cold", |b| {
        b.iter(|| {
            k = (k + 1) % ps.len();
            black_box(r.fk(black_box(&ps[k].1)).ok())
        })
    });
    let mut g = c.benchmark_group("workspace");
    g.sample_size(10);
    g.bench_function("grid_1mm_phi0", |b| {
        b.iter(|| black_box(workspace::grid_workspace(&r, 0.0, 1.0, &|_| {}).area()))
    });
    g.bench_function("alpha_1deg_1mm_phi0", |b| {
        b.iter(|| {
            black_box(
                workspace::alpha_workspace(&r, 0.0, 1.0, 5.0, 1.0)
                    .workspace
                    .area(),
            )
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
