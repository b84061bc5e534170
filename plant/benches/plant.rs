//! Speed of the plant: a warm-started static solve, and 60 s of simulated motion with capture
//! at 100 Hz. Run with `cargo bench -p pcr-plant --bench plant`.

use criterion::{criterion_group, criterion_main, Criterion};
use pcr_driver::{Driver, MotorCommand};
use pcr_plant::statics::Loads;
use pcr_plant::{Plant, PlantConfig, TruthModel};
use pcr_robot::RobotConfig;
use std::hint::black_box;

fn wave(home: [i32; 3], t: f64) -> [i32; 3] {
    std::array::from_fn(|i| {
        let ph = i as f64 * 2.1;
        home[i] + (150.0 * ((std::f64::consts::TAU * 0.2 * t + ph).sin() - ph.sin())).round() as i32
    })
}

fn static_solve(c: &mut Criterion) {
    let robot = RobotConfig::nominal();
    for (name, cfg) in [
        ("ideal", PlantConfig::ideal()),
        ("prototype", PlantConfig::prototype()),
    ] {
        let t = TruthModel::new(&robot, &cfg).unwrap();
        let eq0 = t.solve_steps(&[200.0, 150.0, 180.0]).unwrap();
        // A warm start from the neighbouring solution one motor step away (one cycle's change).
        let loads = Loads {
            phi_b: t.robot.bending_of_steps(&[203.0, 148.0, 181.0], &[0.0; 3]),
            wrench: [0.0; 3],
            friction: None,
        };
        c.bench_function(&format!("warm static solve ({name})"), |b| {
            b.iter(|| black_box(t.statics.solve_warm(black_box(&loads), &eq0.z).unwrap()))
        });
    }
}

fn simulate_60s(c: &mut Criterion) {
    let robot = RobotConfig::nominal();
    let mut g = c.benchmark_group("simulate 60 s");
    g.sample_size(10);
    for (name, cfg) in [
        ("ideal", PlantConfig::ideal()),
        ("prototype", PlantConfig::prototype()),
    ] {
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut p = Plant::new(&robot, &cfg).unwrap();
                let home = p.home_steps();
                let mut n = 0;
                for k in 0..3000 {
                    let t = k as f64 * 0.02;
                    let cmd = MotorCommand {
                        steps: wave(home, t),
                        enable: true,
                    };
                    p.write(t, 0.02, &cmd).unwrap();
                    n += p.drain_measurements().len();
                }
                black_box(n)
            })
        });
    }
    g.finish();
}

criterion_group!(benches, static_solve, simulate_60s);
criterion_main!(benches);
