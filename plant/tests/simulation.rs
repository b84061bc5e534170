//! The time-stepped plant: every effect visible in its own signature, and every effect off
//! equal to the static model.

#![allow(clippy::needless_range_loop)]

use pcr_driver::{Driver, MotorCommand};
use pcr_plant::{Plant, PlantConfig, TruthModel};
use pcr_robot::RobotConfig;

const CYCLE: f64 = 0.02;

fn cmd(steps: [i32; 3]) -> MotorCommand {
    MotorCommand {
        steps,
        enable: true,
    }
}

/// A smooth 3-leg motion around home, steps.
fn wave(home: [i32; 3], t: f64, amp: f64) -> [i32; 3] {
    std::array::from_fn(|i| {
        let ph = i as f64 * 2.1;
        home[i]
            + (amp * (std::f64::consts::TAU * 0.25 * t + ph).sin() - amp * ph.sin()).round() as i32
    })
}

fn ideal_with(f: impl FnOnce(&mut PlantConfig)) -> Plant {
    let mut c = PlantConfig::ideal();
    f(&mut c);
    Plant::new(&RobotConfig::nominal(), &c).unwrap()
}

#[test]
fn every_effect_off_equals_the_static_model() {
    let mut plant = ideal_with(|_| {});
    let truth = TruthModel::new(&RobotConfig::nominal(), &PlantConfig::ideal()).unwrap();
    let home = plant.home_steps();
    let mut worst: f64 = 0.0;
    for k in 0..150 {
        let t = k as f64 * CYCLE;
        plant.write(t, CYCLE, &cmd(wave(home, t, 80.0))).unwrap();
        let s = plant.true_state().clone();
        let q = s.counter.map(f64::from);
        assert_eq!(s.output, q);
        if k % 10 == 0 {
            let eq = truth.solve_steps(&q).unwrap();
            for i in 0..3 {
                worst = worst.max((eq.pose[i] - s.eq.pose[i]).abs());
            }
        }
        // Noise, latency, frame off: the capture reports the true state of its sample time.
        for m in plant.drain_measurements() {
            if (m.t_s - s.t_s).abs() < 1e-9 {
                let p = m.pose.unwrap();
                for i in 0..3 {
                    assert!((p[i] - s.eq.pose[i]).abs() < 1e-12);
                }
            }
        }
    }
    assert!(worst < 1e-8, "{worst}");
}

#[test]
fn rate_limit_caps_steps_per_cycle() {
    let mut plant = ideal_with(|c| c.stepper.rate_limit = true);
    let home = plant.home_steps();
    plant
        .write(0.0, CYCLE, &cmd([home[0] + 100, home[1], home[2]]))
        .unwrap();
    let st = plant.read(CYCLE, CYCLE).unwrap();
    assert_eq!(st.steps[0] - home[0], 12); // 600 steps/s * 20 ms
    assert!(st.limited && st.moving);
}

#[test]
fn missed_steps_above_pull_out_rate() {
    let mut plant = ideal_with(|c| {
        c.stepper.missed_steps = true;
        c.stepper.miss_probability = 0.1;
        c.stepper.pull_out_rate = 400.0;
    });
    let home = plant.home_steps();
    // 10 steps per cycle = 500 steps/s: above pull-out.
    for k in 0..20 {
        let q = [home[0] + 10 * (k + 1), home[1], home[2]];
        plant.write(k as f64 * CYCLE, CYCLE, &cmd(q)).unwrap();
    }
    let s = plant.true_state();
    let lost = s.counter[0] - s.motor[0];
    assert!(lost > 5 && lost < 40, "{lost}");
    // 5 steps per cycle = 250 steps/s: none lost.
    let mut plant = ideal_with(|c| {
        c.stepper.missed_steps = true;
        c.stepper.miss_probability = 0.1;
        c.stepper.pull_out_rate = 400.0;
    });
    for k in 0..20 {
        let q = [home[0] + 5 * (k + 1), home[1], home[2]];
        plant.write(k as f64 * CYCLE, CYCLE, &cmd(q)).unwrap();
    }
    let s = plant.true_state();
    assert_eq!(s.counter[0], s.motor[0]);
}

#[test]
fn backlash_is_a_dead_band_on_reversal() {
    let b = 4.0;
    let mut plant = ideal_with(|c| {
        c.stepper.backlash = true;
        c.stepper.backlash_steps = [b; 3];
    });
    let home = plant.home_steps();
    let mut t = 0.0;
    for q in home[0] + 1..=home[0] + 20 {
        plant.write(t, CYCLE, &cmd([q, home[1], home[2]])).unwrap();
        t += CYCLE;
    }
    let x_fwd = plant.true_state().eq.pose;
    let mut reversal = Vec::new();
    for q in (home[0] + 10..home[0] + 20).rev() {
        plant.write(t, CYCLE, &cmd([q, home[1], home[2]])).unwrap();
        t += CYCLE;
        reversal.push(plant.true_state().eq.pose);
    }
    // The first b steps back do not move the platform.
    for p in &reversal[..b as usize] {
        assert_eq!(*p, x_fwd);
    }
    assert!((reversal[b as usize][0] - x_fwd[0]).abs() > 1e-3);
}

#[test]
fn latency_is_a_time_shift() {
    let lat = 0.03;
    let mut plant = ideal_with(|c| c.capture.latency_s = lat);
    let mut reference = ideal_with(|_| {});
    let home = plant.home_steps();
    let mut truth = Vec::new();
    let mut meas = Vec::new();
    for k in 0..100 {
        let t = k as f64 * CYCLE;
        let c = cmd(wave(home, t, 80.0));
        plant.write(t, CYCLE, &c).unwrap();
        reference.write(t, CYCLE, &c).unwrap();
        truth.extend(reference.drain_measurements());
        meas.extend(plant.drain_measurements());
    }
    for m in &meas {
        if m.t_s < lat + 0.05 {
            continue;
        }
        let r = truth
            .iter()
            .find(|r| (r.t_s - (m.t_s - lat)).abs() < 1e-9)
            .unwrap();
        assert!((m.pose.unwrap()[0] - r.pose.unwrap()[0]).abs() < 1e-12);
    }
}

#[test]
fn noise_has_the_configured_sigma_and_dropouts_their_rate() {
    let mut plant = ideal_with(|c| {
        c.capture.noise = true;
        c.capture.sigma_mm = 0.05;
        c.capture.sigma_deg = 0.05;
        c.capture.dropout_probability = 0.1;
    });
    let home = plant.home_steps();
    let truth = plant.true_state().eq.pose;
    for k in 0..1000 {
        plant.write(k as f64 * CYCLE, CYCLE, &cmd(home)).unwrap();
    }
    let ms = plant.drain_measurements();
    let seen: Vec<[f64; 3]> = ms.iter().filter_map(|m| m.pose).collect();
    let drop_rate = 1.0 - seen.len() as f64 / ms.len() as f64;
    assert!((drop_rate - 0.1).abs() < 0.02, "{drop_rate}");
    let n = seen.len() as f64;
    let sd = |k: usize, center: f64| {
        (seen.iter().map(|p| (p[k] - center).powi(2)).sum::<f64>() / n).sqrt()
    };
    let (sx, sy, sphi) = (
        sd(0, truth[0]),
        sd(1, truth[1]),
        sd(2, truth[2]).to_degrees(),
    );
    eprintln!("noise sd: x {sx:.4} mm, y {sy:.4} mm, phi {sphi:.4} deg, dropouts {drop_rate:.3}");
    for s in [sx, sy, sphi] {
        assert!((s - 0.05).abs() < 0.004, "{s}");
    }
}

#[test]
fn capture_frame_is_a_rigid_transform() {
    let mut plant = ideal_with(|c| {
        c.capture.frame_dx_mm = 12.5;
        c.capture.frame_dy_mm = -7.3;
        c.capture.frame_dphi_deg = 1.7;
    });
    let home = plant.home_steps();
    plant.write(0.0, CYCLE, &cmd(home)).unwrap();
    let s = plant.true_state().clone();
    let frame = plant.capture_model().frame;
    let latest = plant.latest_measurement().unwrap();
    let m = *plant.drain_measurements().last().unwrap();
    assert_eq!(m, latest);
    assert_eq!(plant.latest_measurement(), Some(m));
    let pc = m.pose.unwrap();
    assert!((pc[2] - s.eq.pose[2] - 1.7f64.to_radians()).abs() < 1e-12);
    let r = m.in_robot_frame(&frame);
    for i in 0..3 {
        assert!((r.pose.unwrap()[i] - s.eq.pose[i]).abs() < 1e-9);
        let mi = r.m[i].unwrap();
        assert!((mi[0] - s.eq.m[i][0]).abs() < 1e-9 && (mi[1] - s.eq.m[i][1]).abs() < 1e-9);
    }
}

#[test]
fn creep_drifts_with_its_time_constant() {
    let mut plant = ideal_with(|c| {
        c.creep.enabled = true;
        c.creep.compliance_mm_per_n = 2e-3;
        c.creep.time_constant_s = 2.0;
    });
    let home = plant.home_steps();
    let q = [home[0] + 150, home[1], home[2]];
    plant.write(0.0, CYCLE, &cmd(q)).unwrap();
    let mut t = CYCLE;
    let e0 = plant.true_state().creep_mm[0];
    plant.idle_until(t + 2.0).unwrap();
    t += 2.0;
    let e1 = plant.true_state().creep_mm[0];
    plant.idle_until(t + 20.0).unwrap();
    let e2 = plant.true_state().creep_mm[0];
    assert!(e0 < 0.1 * e2 && e2 > 0.0);
    // After one time constant about 63 % of the final elongation.
    let frac = (e1 - e0) / (e2 - e0);
    assert!((frac - 0.632).abs() < 0.03, "{frac}");
}

#[test]
fn drift_lengthens_a_tendon_steadily_with_time_and_moves_the_platform() {
    let rate = 0.01;
    let mut plant = ideal_with(|c| {
        c.drift.enabled = true;
        c.drift.rate_mm_per_s = [0.0, rate, 0.0];
    });
    let home = plant.home_steps();
    plant.write(0.0, CYCLE, &cmd(home)).unwrap();
    plant.idle_until(1.0).unwrap();
    let s1 = plant.true_state().clone();
    plant.idle_until(21.0).unwrap();
    let s2 = plant.true_state().clone();
    // The commanded outputs do not move; the tendon of leg 2 is longer by rate * 20 s, linearly
    // (no saturation), and the others are unchanged.
    assert_eq!(s1.output, s2.output);
    let d: Vec<f64> = (0..3).map(|i| s1.tendon_mm[i] - s2.tendon_mm[i]).collect();
    assert!((d[1] - rate * 20.0).abs() < 1e-9, "{d:?}");
    assert!(d[0].abs() < 1e-12 && d[2].abs() < 1e-12, "{d:?}");
    let moved = (s2.eq.pose[0] - s1.eq.pose[0]).hypot(s2.eq.pose[1] - s1.eq.pose[1]);
    assert!(
        moved > 0.05,
        "0.2 mm of tendon moves the platform: {moved} mm"
    );
}

/// With friction on, the statics are solved at every step's time: the answer is the same
/// whatever the sub-steps per cycle (at two a cycle, without the steps' own times, it missed the
/// converged answer by 0.01 mm RMS on the sweep's recordings).
#[test]
fn friction_follows_every_step_whatever_the_sub_steps() {
    let run = |substeps: usize| {
        let mut plant = ideal_with(|c| {
            c.friction.joints = true;
            c.friction.joint_torque_n_mm = 2.0;
            c.friction.supports = true;
            c.friction.support_force_n = 0.04;
            c.simulation.substeps_per_cycle = substeps;
        });
        let home = plant.home_steps();
        let mut t = 0.0;
        let mut poses = Vec::new();
        // Legs at different rates, reversing: 5, 3 and 1 steps a cycle, then back.
        for k in 0..40i32 {
            let s = if k < 20 { k } else { 40 - k };
            let q = [home[0] + 5 * s, home[1] - 3 * s, home[2] + s];
            plant.write(t, CYCLE, &cmd(q)).unwrap();
            t += CYCLE;
            poses.push(plant.true_state().eq.pose);
        }
        poses
    };
    let (a, b) = (run(2), run(8));
    let worst = a
        .iter()
        .zip(&b)
        .map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1]))
        .fold(0.0f64, f64::max);
    assert!(worst < 1e-6, "2 against 8 sub-steps: {worst:.2e} mm");
}

#[test]
fn friction_makes_the_error_depend_on_the_approach_direction() {
    let run = |friction: bool| {
        let mut plant = ideal_with(|c| {
            c.friction.joints = friction;
            c.friction.joint_torque_n_mm = 2.0;
            c.friction.supports = friction;
            c.friction.support_force_n = 0.08;
        });
        let home = plant.home_steps();
        let target = [home[0] + 30, home[1] - 20, home[2]];
        let mut t = 0.0;
        let mut go = |plant: &mut Plant, q: [i32; 3]| {
            for _ in 0..30 {
                plant.write(t, CYCLE, &cmd(q)).unwrap();
                t += CYCLE;
            }
            plant.true_state().eq.pose
        };
        go(&mut plant, [home[0] + 80, home[1] - 70, home[2]]);
        let a = go(&mut plant, target);
        go(&mut plant, [home[0] - 20, home[1] + 30, home[2]]);
        let b = go(&mut plant, target);
        ((a[0] - b[0]).hypot(a[1] - b[1]), a)
    };
    let (d_off, _) = run(false);
    let (d_on, _) = run(true);
    eprintln!("approach-direction difference: friction off {d_off:.2e} mm, on {d_on:.3} mm");
    assert!(d_off < 1e-9);
    assert!(d_on > 0.05, "{d_on}");
}

#[test]
fn same_seed_same_run() {
    let run = || {
        let mut plant = Plant::new(&RobotConfig::nominal(), &PlantConfig::prototype()).unwrap();
        let home = plant.home_steps();
        for k in 0..100 {
            let t = k as f64 * CYCLE;
            plant.write(t, CYCLE, &cmd(wave(home, t, 150.0))).unwrap();
        }
        plant.drain_measurements()
    };
    assert_eq!(run(), run());
}

/// ISO 9283 pose repeatability of the prototype-like plant: one target approached from random
/// directions; RP = mean distance to the barycentre + 3 standard deviations. The prototype's is
/// about 1.2 mm.
#[test]
fn prototype_repeatability_resembles_the_prototype() {
    use rand::{Rng, SeedableRng};
    let mut plant = Plant::new(&RobotConfig::nominal(), &PlantConfig::prototype()).unwrap();
    let home = plant.home_steps();
    let target = [home[0] + 40, home[1] - 30, home[2] + 10];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let mut t = 0.0;
    let mut pts = Vec::new();
    for _ in 0..30 {
        let via: [i32; 3] = std::array::from_fn(|i| target[i] + rng.random_range(-120..=120));
        for q in [via, target] {
            // Move at up to 8 steps per cycle, then settle for 0.5 s.
            loop {
                let cur = plant.true_state().counter;
                let next: [i32; 3] = std::array::from_fn(|i| cur[i] + (q[i] - cur[i]).clamp(-8, 8));
                plant.write(t, CYCLE, &cmd(next)).unwrap();
                t += CYCLE;
                if next == q {
                    break;
                }
            }
            plant.idle_until(t + 0.5).unwrap();
            t += 0.5;
        }
        let p = plant.true_state().eq.pose;
        pts.push([p[0], p[1]]);
    }
    let n = pts.len() as f64;
    let c = [
        pts.iter().map(|p| p[0]).sum::<f64>() / n,
        pts.iter().map(|p| p[1]).sum::<f64>() / n,
    ];
    let l: Vec<f64> = pts
        .iter()
        .map(|p| (p[0] - c[0]).hypot(p[1] - c[1]))
        .collect();
    let lm = l.iter().sum::<f64>() / n;
    let sl = (l.iter().map(|v| (v - lm).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let rp = lm + 3.0 * sl;
    eprintln!("ISO 9283 repeatability of the prototype plant: {rp:.3} mm (mean {lm:.3} mm)");
    assert!(rp > 0.6 && rp < 2.0, "{rp}");
}

/// Random setpoints inside the workspace (rate-limited moves, friction, backlash, missed steps):
/// the plant follows without a fault.
#[test]
fn random_moves_in_the_workspace_run_without_fault() {
    use rand::{Rng, SeedableRng};
    let mut plant = Plant::new(&RobotConfig::nominal(), &PlantConfig::prototype()).unwrap();
    let home = plant.home_steps();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let mut target = home;
    for k in 0..1500 {
        if k % 50 == 0 {
            target = std::array::from_fn(|i| home[i] + rng.random_range(-80..80));
        }
        plant.write(k as f64 * CYCLE, CYCLE, &cmd(target)).unwrap();
    }
    let st = plant.read(1500.0 * CYCLE, CYCLE).unwrap();
    assert!(!st.fault);
}

/// A setpoint without equilibrium: the drive reports the error and a fault and holds its
/// position (the cycle is rolled back); the next valid setpoint is followed again.
#[test]
fn a_setpoint_without_equilibrium_faults_and_holds() {
    let mut plant = ideal_with(|_| {});
    let home = plant.home_steps();
    let before = plant.true_state().clone();
    let e = plant
        .write(0.0, CYCLE, &cmd([home[0] + 1600, home[1], home[2]]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("leg 1") && e.contains("bending"), "{e}");
    let st = plant.read(CYCLE, CYCLE).unwrap();
    assert!(st.fault);
    assert_eq!(plant.true_state().counter, before.counter);
    assert_eq!(plant.true_state().eq.pose, before.eq.pose);
    plant
        .write(CYCLE, CYCLE, &cmd([home[0] + 5, home[1], home[2]]))
        .unwrap();
    let st = plant.read(2.0 * CYCLE, CYCLE).unwrap();
    assert!(!st.fault && st.steps[0] == home[0] + 5);
}

#[test]
fn an_early_command_takes_back_the_rest_of_the_cycle_and_the_plant_keeps_to_the_clock() {
    // Every tenth command comes 12 ms late and the next one on time, i.e. early against the
    // end of the late cycle. The plant takes back the rest of the late cycle each time (the
    // firmware's rule for a new target), so it never runs ahead of the clock, its measurements
    // stay in time order (those drained and made again are dropped, as `take_withdrawn` says),
    // and it ends where a punctual plant ends.
    let mut plant = ideal_with(|_| {});
    let mut punctual = ideal_with(|_| {});
    let home = plant.home_steps();
    let mut meas: Vec<pcr_plant::Measurement> = Vec::new();
    let mut rewinds = 0;
    for k in 0..100 {
        let t = k as f64 * CYCLE + if k % 10 == 3 { 0.012 } else { 0.0 };
        let c = cmd(wave(home, k as f64 * CYCLE, 60.0));
        plant.write(t, CYCLE, &c).unwrap();
        if let Some(t0) = plant.take_withdrawn() {
            rewinds += 1;
            meas.retain(|m| m.t_s <= t0 + 1e-12);
        }
        meas.extend(plant.drain_measurements());
        punctual.write(k as f64 * CYCLE, CYCLE, &c).unwrap();
        assert!(
            plant.time() <= t + CYCLE + 1e-9,
            "cycle {k}: the plant is at {} s, ahead of the command at {t} s",
            plant.time()
        );
    }
    assert_eq!(rewinds, 10, "each late command is followed by an early one");
    assert!(meas.windows(2).all(|w| w[0].t_s < w[1].t_s), "time order");
    // Settled at the last target, both plants are at the same pose.
    plant.idle_until(3.0).unwrap();
    punctual.idle_until(3.0).unwrap();
    let last = |p: &mut Plant| {
        p.drain_measurements()
            .into_iter()
            .rev()
            .find_map(|m| m.pose)
            .unwrap()
    };
    let (a, b) = (last(&mut plant), last(&mut punctual));
    for i in 0..3 {
        assert!((a[i] - b[i]).abs() < 1e-6, "{a:?} vs {b:?}");
    }
}
