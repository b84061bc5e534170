//! The simulated QTM's frames (the plant's capture view) register back to the plant's capture
//! frame: with exact base points to within the capture noise, with the prototype's
//! manufacturing deviations to within those deviations (and a residual that shows them); a
//! marker QTM never sees is refused by name.

use pcr_control::capture_feed::{sim_parameters, CaptureFeed};
use pcr_driver::{Driver, MotorCommand};
use pcr_mocap_bridge::{Frame, MarkerLabels, Registration, RegistrationError};
use pcr_plant::{Plant, PlantConfig};
use pcr_robot::RobotConfig;

fn frames(cfg: &PlantConfig, n: usize) -> (Plant, Vec<Frame>) {
    let robot = RobotConfig::nominal();
    let mut plant = Plant::new(&robot, cfg).unwrap();
    let mut feed = CaptureFeed::new(&plant);
    let cmd = MotorCommand {
        steps: plant.home_steps(),
        enable: true,
    };
    let mut out = Vec::new();
    let mut t = 0.0;
    while out.len() < n {
        plant.write(t, 0.02, &cmd).unwrap();
        t += 0.02;
        plant.read(t, 0.02).unwrap();
        for m in plant.drain_measurements() {
            out.push(feed.frame_of(&m).clone());
        }
    }
    (plant, out)
}

fn register(cfg: &PlantConfig) -> Result<(Plant, Registration), RegistrationError> {
    let robot = RobotConfig::nominal();
    let base: [[f64; 2]; 3] = std::array::from_fn(|i| robot.legs[i].base_point());
    let (plant, f) = frames(cfg, 100);
    let reg = Registration::from_frames(
        &sim_parameters(cfg.capture.rate_hz),
        &f,
        &MarkerLabels::default(),
        &base,
        1.0,
    )?;
    Ok((plant, reg))
}

#[test]
fn registration_recovers_the_plants_capture_frame_within_the_noise() {
    let mut cfg = PlantConfig::prototype();
    cfg.geometry.enabled = false;
    let (_, reg) = register(&cfg).unwrap();
    let (dx, dy, dphi) = reg.planar_capture_frame();
    let c = &cfg.capture;
    // sigma 0.05 mm per coordinate, 100 frames averaged: ~0.005 mm per marker
    assert!((dx - c.frame_dx_mm).abs() < 0.02, "dx {dx}");
    assert!((dy - c.frame_dy_mm).abs() < 0.02, "dy {dy}");
    assert!(
        (dphi.to_degrees() - c.frame_dphi_deg).abs() < 0.005,
        "dphi {dphi}"
    );
    assert!(
        reg.residuals.iter().all(|r| r.residual_mm < 0.03),
        "{reg:?}"
    );
}

#[test]
fn manufacturing_deviations_of_the_base_show_in_the_residuals() {
    let cfg = PlantConfig::prototype();
    let (_, reg) = register(&cfg).unwrap();
    let (dx, dy, dphi) = reg.planar_capture_frame();
    let c = &cfg.capture;
    // the base points deviate by tenths of a mm and degrees from the configuration
    assert!((dx - c.frame_dx_mm).abs() < 1.0 && (dy - c.frame_dy_mm).abs() < 1.0);
    assert!((dphi.to_degrees() - c.frame_dphi_deg).abs() < 0.2);
    let worst = reg
        .residuals
        .iter()
        .map(|r| r.residual_mm)
        .fold(0.0, f64::max);
    assert!(worst > 0.1 && worst < 1.0, "{reg:?}");
    // a threshold below them refuses, naming the marker
    let e = reg.check(0.05).unwrap_err().to_string();
    assert!(e.contains("refused") && e.contains("B"), "{e}");
}

#[test]
fn a_base_marker_qtm_does_not_see_is_refused_by_name() {
    let mut cfg = PlantConfig::prototype();
    cfg.capture.dropout_probability = 0.9;
    let Err(e) = register(&cfg) else {
        panic!("registered without B1")
    };
    let e = e.to_string();
    assert!(e.contains("B1") && e.contains("missing"), "{e}");
}
