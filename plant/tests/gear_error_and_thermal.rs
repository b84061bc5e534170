//! The two effects that exist for the residual analysis's validation sweep
//! (`scripts/validate_residuals.sh`): a periodic transmission error of a motor's gear (in the
//! residual library as `periodic`) and the lab's temperature cycle on the tendons (outside it).
//! Each is checked in its own signature on the time-stepped plant, against the formula of
//! `configs/plant.toml` written out here.

use pcr_driver::{Driver, MotorCommand};
use pcr_plant::config::PeriodicGearError;
use pcr_plant::{Plant, PlantConfig};
use pcr_robot::RobotConfig;
use std::f64::consts::TAU;

const CYCLE: f64 = 0.02;

fn cmd(steps: [i32; 3]) -> MotorCommand {
    MotorCommand {
        steps,
        enable: true,
    }
}

fn ideal_with(f: impl FnOnce(&mut PlantConfig)) -> Plant {
    let mut c = PlantConfig::ideal();
    f(&mut c);
    Plant::new(&RobotConfig::nominal(), &c).unwrap()
}

/// Motor 3's output lags it by 1.5 sin(2 pi q / 64 + 30 deg): the term of configs/plant.toml's
/// example with a larger amplitude.
fn periodic_term() -> PeriodicGearError {
    PeriodicGearError {
        motor: 3,
        period_steps: 64.0,
        amplitude_steps: 1.5,
        phase_deg: 30.0,
    }
}

fn lag(p: &PeriodicGearError, q: f64) -> f64 {
    p.amplitude_steps * (TAU * q / p.period_steps + p.phase_deg.to_radians()).sin()
}

#[test]
fn a_periodic_gear_error_lags_the_output_by_its_sine_of_the_rotor_position() {
    let term = periodic_term();
    let mut plant = ideal_with(|c| c.stepper.periodic = vec![term.clone()]);
    let home = plant.home_steps();
    // At rest at home the output is already where the gear puts it.
    let q0 = f64::from(home[2]);
    assert!((plant.true_state().output[2] - (q0 - lag(&term, q0))).abs() < 1e-12);
    let mut t = 0.0;
    let mut worst: f64 = 0.0;
    let mut seen = (f64::INFINITY, f64::NEG_INFINITY);
    // Two periods forth, one back, a step a cycle.
    let path: Vec<i32> = (1..=128).chain((64..128).rev()).collect();
    for d in path {
        let q = [home[0], home[1], home[2] + d];
        plant.write(t, CYCLE, &cmd(q)).unwrap();
        t += CYCLE;
        let s = plant.true_state();
        let m = f64::from(s.motor[2]);
        let err = s.output[2] - m;
        worst = worst.max((err + lag(&term, m)).abs());
        seen = (seen.0.min(err), seen.1.max(err));
        // The other motors' gears are exact.
        assert_eq!(s.output[0], f64::from(s.motor[0]));
        assert_eq!(s.output[1], f64::from(s.motor[1]));
    }
    assert!(worst < 1e-12, "{worst}");
    // The whole sine is seen: +-1.5 steps within the step grid (a 64-step period, whole steps).
    assert!(seen.0 < -1.49 && seen.1 > 1.49, "{seen:?}");
}

#[test]
fn the_play_lies_after_the_gear() {
    let term = periodic_term();
    let b = 4.0;
    let mut plant = ideal_with(|c| {
        c.stepper.periodic = vec![term.clone()];
        c.stepper.backlash = true;
        c.stepper.backlash_steps = [0.0, 0.0, b];
    });
    let home = plant.home_steps();
    let mut t = 0.0;
    let mut drive = |plant: &mut Plant, q3: i32| {
        plant.write(t, CYCLE, &cmd([home[0], home[1], q3])).unwrap();
        t += CYCLE;
        plant.true_state().clone()
    };
    // Forth: the roll trails the gear by half the play.
    for q in home[2] + 1..=home[2] + 40 {
        let s = drive(&mut plant, q);
        let g = f64::from(s.motor[2]) - lag(&term, f64::from(s.motor[2]));
        if q > home[2] + 8 {
            assert!((s.output[2] - (g - 0.5 * b)).abs() < 1e-12, "{q}");
        }
    }
    // Back: the roll stays until the gear has crossed the play, then leads it by half the play.
    let held = plant.true_state().output[2];
    let mut moved_at = None;
    for (k, q) in (home[2]..home[2] + 40).rev().enumerate() {
        let s = drive(&mut plant, q);
        let g = f64::from(s.motor[2]) - lag(&term, f64::from(s.motor[2]));
        if s.output[2] != held && moved_at.is_none() {
            moved_at = Some(k + 1);
        }
        if moved_at.is_some() {
            assert!((s.output[2] - (g + 0.5 * b)).abs() < 1e-12, "{q}");
        }
    }
    let k = moved_at.expect("the roll follows back");
    assert!((3..=6).contains(&k), "moved after {k} steps back");
}

#[test]
fn a_periodic_gear_error_moves_the_platform_and_is_checked() {
    let mut plant = ideal_with(|c| c.stepper.periodic = vec![periodic_term()]);
    let mut exact = ideal_with(|_| {});
    let home = plant.home_steps();
    let mut largest: f64 = 0.0;
    for d in 1..=64 {
        let q = [home[0], home[1], home[2] + d];
        let t = d as f64 * CYCLE;
        plant.write(t, CYCLE, &cmd(q)).unwrap();
        exact.write(t, CYCLE, &cmd(q)).unwrap();
        let (a, b) = (plant.true_state().eq.pose, exact.true_state().eq.pose);
        largest = largest.max((a[0] - b[0]).hypot(a[1] - b[1]));
    }
    // 1.5 steps of leg 3 (0.023 mm of tendon, 0.19 deg of bending) move the platform by tenths
    // of a mm.
    assert!(largest > 0.05 && largest < 1.0, "{largest} mm");

    let mut c = PlantConfig::ideal();
    c.stepper.periodic = vec![PeriodicGearError {
        amplitude_steps: 11.0,
        ..periodic_term()
    }];
    let e = PlantConfig::from_toml_str(&c.to_toml_string(), "p.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("stepper.periodic[1].amplitude_steps"), "{e}");
    c.stepper.periodic[0].amplitude_steps = 1.0;
    c.stepper.periodic[0].motor = 4;
    let e = PlantConfig::from_toml_str(&c.to_toml_string(), "p.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("stepper.periodic[1].motor"), "{e}");
    // The inline form of configs/plant.toml's comment parses.
    let text = include_str!("../../configs/plant-ideal.toml").replace(
        "periodic = []",
        "periodic = [{ motor = 3, period_steps = 64.0, amplitude_steps = 1.0, phase_deg = 30.0 }]",
    );
    let c = PlantConfig::from_toml_str(&text, "p.toml").unwrap();
    assert_eq!(c.stepper.periodic.len(), 1);
    assert_eq!(c.stepper.periodic[0].period_steps, 64.0);
}

#[test]
fn the_temperature_cycle_lengthens_the_tendons_by_its_sine_of_time() {
    let (amp, period, phase) = ([0.02, -0.01, 0.0], 40.0, 30.0);
    let mut plant = ideal_with(|c| {
        c.thermal.enabled = true;
        c.thermal.amplitude_mm = amp;
        c.thermal.period_s = period;
        c.thermal.phase_deg = phase;
    });
    let home = plant.home_steps();
    plant.write(0.0, CYCLE, &cmd(home)).unwrap();
    let base = plant.true_state().clone();
    let mm_per_step = RobotConfig::nominal().legs[0].actuation.mm_per_step();
    let mut extremes = [(f64::INFINITY, f64::NEG_INFINITY); 3];
    let mut moved: f64 = 0.0;
    for k in 1..=80 {
        plant.idle_until(k as f64).unwrap();
        let s = plant.true_state();
        let t = s.t_s;
        assert_eq!(s.output, base.output, "the drives hold");
        let ph = phase.to_radians();
        let e = (TAU * t / period + ph).sin() - ph.sin();
        for i in 0..3 {
            let elongation = s.output[i] * mm_per_step - s.tendon_mm[i];
            assert!(
                (elongation - amp[i] * e).abs() < 1e-12,
                "t {t} leg {}: {elongation} vs {}",
                i + 1,
                amp[i] * e
            );
            extremes[i] = (extremes[i].0.min(elongation), extremes[i].1.max(elongation));
        }
        moved = moved.max((s.eq.pose[0] - base.eq.pose[0]).hypot(s.eq.pose[1] - base.eq.pose[1]));
    }
    // Bounded: two periods span twice the amplitude and no more (no growth, unlike drift).
    for i in 0..3 {
        let span = extremes[i].1 - extremes[i].0;
        assert!(
            (span - 2.0 * amp[i].abs()).abs() < 0.01 * amp[i].abs() + 1e-12,
            "leg {}: {span}",
            i + 1
        );
    }
    assert!(
        moved > 0.02,
        "the tendons' change moves the platform: {moved} mm"
    );
    // Off by default, and absent from a file is off.
    assert!(!PlantConfig::ideal().thermal.enabled);
    let text = include_str!("../../configs/plant-ideal.toml");
    let start = text.find("[thermal]").unwrap();
    let end = start + text[start..].find("[friction]").unwrap();
    let without = format!("{}{}", &text[..start], &text[end..]);
    assert_eq!(
        PlantConfig::from_toml_str(&without, "p.toml").unwrap(),
        PlantConfig::ideal()
    );
}
