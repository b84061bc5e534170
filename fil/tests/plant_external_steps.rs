//! The plant driven by externally given motor steps (`Plant::advance_with_steps`, what the FIL
//! feeds it) behaves like the plant driven by its own stepper model when the steps are the
//! same. No emulator needed.

use std::path::Path;

use pcr_driver::MotorCommand;
use pcr_plant::sim::MotorStep;
use pcr_plant::{Plant, PlantConfig};
use pcr_robot::RobotConfig;

fn cfg(name: &str) -> PlantConfig {
    PlantConfig::load(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../configs")
            .join(name),
    )
    .unwrap()
}

/// Steps of one 20 ms cycle spread evenly (step k at t0 + k T / n), as the plant's own model.
fn even_steps(t0: f64, from: [i32; 3], to: [i32; 3]) -> Vec<MotorStep> {
    let mut v = Vec::new();
    for m in 0..3 {
        let n = (to[m] - from[m]).abs();
        for k in 1..=n {
            v.push(MotorStep {
                t_s: t0 + 0.02 * f64::from(k) / f64::from(n),
                motor: m,
                pos: from[m] + (to[m] - from[m]).signum() * k,
            });
        }
    }
    v.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    v
}

fn compare(plant_cfg: &PlantConfig) {
    // Without missed steps the two drives make the same steps; the rest is the same plant.
    let mut c = plant_cfg.clone();
    c.stepper.missed_steps = false;
    let robot = RobotConfig::nominal();
    let mut own = Plant::new(&robot, &c).unwrap();
    let mut ext = Plant::new(&robot, &c).unwrap();
    let home = own.home_steps();
    let mut q = home;
    for k in 0..60 {
        let a = k as f64 * 0.15;
        let next = [
            home[0] + (40.0 * a.sin()).round() as i32,
            home[1] + (30.0 * (1.3 * a).sin()).round() as i32,
            home[2] - (35.0 * (0.7 * a).sin()).round() as i32,
        ];
        let t0 = own.time();
        own.step_cycle(
            0.02,
            &MotorCommand {
                steps: next,
                enable: true,
            },
        )
        .unwrap();
        ext.advance_with_steps(t0 + 0.02, &even_steps(t0, q, next), true)
            .unwrap();
        q = next;
        let (a, b) = (own.true_state(), ext.true_state());
        assert_eq!(a.counter, b.counter, "cycle {k}");
        assert_eq!(a.motor, b.motor, "cycle {k}");
        assert_eq!(a.output, b.output, "cycle {k}");
        for j in 0..3 {
            assert!((a.eq.pose[j] - b.eq.pose[j]).abs() < 1e-9, "cycle {k}");
        }
    }
    let (ma, mb) = (own.drain_measurements(), ext.drain_measurements());
    assert_eq!(ma.len(), mb.len());
    for (x, y) in ma.iter().zip(&mb) {
        assert_eq!(x.t_s, y.t_s);
        assert_eq!(x.pose.is_some(), y.pose.is_some());
        if let (Some(p), Some(q)) = (x.pose, y.pose) {
            for j in 0..3 {
                assert!((p[j] - q[j]).abs() < 1e-9, "sample at {} s", x.t_s);
            }
        }
    }
}

#[test]
fn external_steps_equal_the_plant_own_stepper_ideal() {
    compare(&cfg("plant-ideal.toml"));
}

/// Backlash, creep, friction, capture noise and latency stay the plant's.
#[test]
fn external_steps_equal_the_plant_own_stepper_prototype() {
    let mut c = cfg("plant.toml");
    // Its own rate limit would cap moves above 12 steps per cycle: keep the moves below.
    c.stepper.rate_limit = false;
    compare(&c);
}

/// Idle time passes without steps; a step dated before the plant's time is applied at once.
#[test]
fn idle_time_and_late_steps() {
    let robot = RobotConfig::nominal();
    let mut p = Plant::new(&robot, &cfg("plant-ideal.toml")).unwrap();
    let home = p.home_steps();
    p.advance_with_steps(0.5, &[], true).unwrap();
    assert!((p.time() - 0.5).abs() < 1e-12);
    assert_eq!(p.drain_measurements().len(), 51);
    let late = MotorStep {
        t_s: 0.1,
        motor: 1,
        pos: home[1] + 1,
    };
    p.advance_with_steps(0.5, &[late], true).unwrap();
    assert_eq!(p.true_state().counter, [home[0], home[1] + 1, home[2]]);
    assert!((p.time() - 0.5).abs() < 1e-12);
}
