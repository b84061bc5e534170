//! `pcr residuals` against the simulated plant with effects nobody declared to the model: each
//! test records static visits and the paper's paths on the in-process chain (the real planner,
//! IK and drive steps) with one effect on in the plant, analyses the recording, and checks the
//! name, the parameter and the held-out gain. The residual crate never sees the plant.

use pcr_experiments::{
    run_in_process, CalibrationOptions, Design, PathsDesign, RunSetup, StaticDesign, Tolerances,
    VisitTiming,
};
use pcr_kinematics::Robot;
use pcr_plant::PlantConfig;
use pcr_recording::Recording;
use pcr_residuals::{attribute, Attribution, Blocks, Options, Series, Verdict};
use pcr_robot::RobotConfig;

/// A plant with nominal geometry, the linear map, capture noise, and no other effect.
fn quiet_plant() -> PlantConfig {
    let mut p = PlantConfig::ideal();
    p.capture.noise = true;
    p
}

/// Records `design` with `model` driving `plant`.
fn record(model: &RobotConfig, plant: &PlantConfig, design: &Design) -> Recording {
    let setup = RunSetup {
        model: model.clone(),
        plant_robot: RobotConfig::nominal(),
        plant: plant.clone(),
        period_s: 0.02,
        seed: 1,
        metadata: vec![],
        tolerances: Tolerances::default(),
        capture_latency_s: None,
    };
    let mut out = Vec::new();
    run_in_process(design, &setup, &mut out, &mut |_| {}).unwrap();
    Recording::read(out.as_slice(), "plant run").unwrap()
}

/// Static visits (5 per scaled boundary: 45 poses) and the paper's paths twice.
fn designs() -> Vec<Design> {
    let robot = Robot::nominal();
    let cal = StaticDesign::calibration(
        &robot,
        &CalibrationOptions {
            points: 5,
            test_per_group: 2,
            ..CalibrationOptions::default()
        },
        VisitTiming {
            speed_mm_s: 30.0,
            settle_s: 0.6,
            measure_s: 0.4,
        },
    )
    .unwrap();
    vec![
        Design::Static(cal),
        Design::Paths(PathsDesign::default()),
        Design::Paths(PathsDesign::default()),
    ]
}

/// Analyses the recordings of `plant` driven by `model`, starting the analysis from `model`.
fn analyse(model: &RobotConfig, plant: &PlantConfig) -> Attribution {
    let series: Vec<Series> = designs()
        .iter()
        .enumerate()
        .map(|(k, d)| {
            Series::from_recording(&record(model, plant, d), &format!("run {k}")).unwrap()
        })
        .collect();
    let blocks = Blocks::in_time(&series, 2.0, 3);
    attribute(
        model,
        &RobotConfig::nominal(),
        &series,
        &blocks,
        &Options::default(),
    )
    .unwrap()
}

fn names(a: &Attribution) -> Vec<&str> {
    a.effects.iter().map(|e| e.name.as_str()).collect()
}

fn report(a: &Attribution) -> String {
    format!(
        "effects {:?}, verdict {:?}, before {:.3} after {:.3} mm, features {:?}",
        a.effects
            .iter()
            .map(|e| (&e.name, &e.params))
            .collect::<Vec<_>>(),
        a.verdict,
        a.before.position_rms_mm,
        a.after.position_rms_mm,
        a.correlated_features
            .iter()
            .map(|f| &f.feature)
            .collect::<Vec<_>>()
    )
}

#[test]
fn no_effect_beyond_the_model_gives_no_effect() {
    let a = analyse(&RobotConfig::nominal(), &quiet_plant());
    assert!(a.effects.is_empty(), "{}", report(&a));
    assert_eq!(a.verdict, Verdict::Explained, "{}", report(&a));
}

#[test]
fn finds_backlash_and_its_play() {
    let mut plant = quiet_plant();
    plant.stepper.backlash = true;
    plant.stepper.backlash_steps = [3.0, 4.0, 3.0];
    let a = analyse(&RobotConfig::nominal(), &plant);
    assert!(names(&a).contains(&"backlash"), "{}", report(&a));
    let b = a.robot.effects.backlash.as_ref().unwrap().steps;
    for (f, t) in b.iter().zip([3.0, 4.0, 3.0]) {
        assert!((f - t).abs() < 0.5, "{b:?}: {}", report(&a));
    }
    assert!(
        a.after.position_rms_mm < 0.6 * a.before.position_rms_mm,
        "{}",
        report(&a)
    );
}

#[test]
fn finds_latency_and_two_effects_at_once() {
    // Capture latency 40 ms and backlash together.
    let mut plant = quiet_plant();
    plant.capture.latency_s = 0.04;
    plant.stepper.backlash = true;
    plant.stepper.backlash_steps = [3.0, 4.0, 3.0];
    let a = analyse(&RobotConfig::nominal(), &plant);
    let n = names(&a);
    assert!(
        n.contains(&"latency") && n.contains(&"backlash"),
        "{}",
        report(&a)
    );
    let l = a.robot.effects.latency.as_ref().unwrap().latency_s;
    assert!((l - 0.04).abs() < 0.005, "latency {l}: {}", report(&a));
    assert!(
        a.after.position_rms_mm < 0.3 * a.before.position_rms_mm,
        "{}",
        report(&a)
    );
}

#[test]
fn finds_joint_springs_and_their_stiffness() {
    let mut plant = quiet_plant();
    plant.mechanics.k_m_n_mm_per_rad = 300.0;
    plant.mechanics.k_p_n_mm_per_rad = 200.0;
    let a = analyse(&RobotConfig::nominal(), &plant);
    assert!(names(&a).contains(&"joint_springs"), "{}", report(&a));
    let c = a.robot.effects.compliance.as_ref().unwrap();
    assert!((c.k_m_n_mm_per_rad - 300.0).abs() < 45.0, "{}", report(&a));
    assert!((c.k_p_n_mm_per_rad - 200.0).abs() < 30.0, "{}", report(&a));
    assert!(
        a.after.position_rms_mm < 0.5 * a.before.position_rms_mm,
        "{}",
        report(&a)
    );
}

#[test]
fn finds_an_external_load_and_its_force() {
    let mut plant = quiet_plant();
    plant.external_wrench.fx_n = 0.4;
    plant.external_wrench.fy_n = -0.3;
    let a = analyse(&RobotConfig::nominal(), &plant);
    assert!(names(&a).contains(&"external_load"), "{}", report(&a));
    let c = a.robot.effects.compliance.as_ref().unwrap();
    assert!(
        (c.force_n[0] - 0.4).abs() < 0.06 && (c.force_n[1] + 0.3).abs() < 0.06,
        "{}",
        report(&a)
    );
    assert!(
        a.after.position_rms_mm < 0.5 * a.before.position_rms_mm,
        "{}",
        report(&a)
    );
}

#[test]
fn finds_a_misregistered_capture_frame() {
    let mut plant = quiet_plant();
    plant.capture.registration_error_dx_mm = 0.8;
    plant.capture.registration_error_dphi_deg = 0.3;
    let a = analyse(&RobotConfig::nominal(), &plant);
    assert!(names(&a).contains(&"frame"), "{}", report(&a));
    let f = a.robot.effects.frame.as_ref().unwrap();
    // The correction undoes the error: its rotation is the error's, its offset the error's
    // seen through the rotation (both small here).
    assert!((f.dphi_deg.abs() - 0.3).abs() < 0.05, "{}", report(&a));
    assert!((f.dx_mm.hypot(f.dy_mm) - 0.8).abs() < 0.2, "{}", report(&a));
    assert!(
        a.after.position_rms_mm < 0.5 * a.before.position_rms_mm,
        "{}",
        report(&a)
    );
}

#[test]
fn finds_tendon_creep() {
    let mut plant = quiet_plant();
    plant.creep.enabled = true;
    plant.creep.compliance_mm_per_n = 2.0e-3;
    plant.creep.time_constant_s = 20.0;
    let a = analyse(&RobotConfig::nominal(), &plant);
    assert!(names(&a).contains(&"creep"), "{}", report(&a));
    let c = a.robot.effects.creep.as_ref().unwrap();
    // tension = EI theta / (l_C a) with theta = dl / a: gain = compliance EI / (l_C a^2) = 0.021
    for g in c.gain {
        assert!((g - 0.021).abs() < 0.008, "{}", report(&a));
    }
    assert!(
        a.after.position_rms_mm < 0.6 * a.before.position_rms_mm,
        "{}",
        report(&a)
    );
}

#[test]
fn an_effect_outside_the_library_is_unexplained_and_named_by_its_feature() {
    // Leg 1's tendon runs over leg 3's roll: leg 1 bends with leg 3's displacement too.
    let mut plant = quiet_plant();
    plant.tendon_map.cross_coupling = 0.15;
    let a = analyse(&RobotConfig::nominal(), &plant);
    assert_eq!(a.verdict, Verdict::Unexplained, "{}", report(&a));
    // The remainder follows the coupled leg (1) and the leg whose displacement drives it (3).
    let named: Vec<&str> = a
        .correlated_features
        .iter()
        .map(|f| f.feature.as_str())
        .collect();
    assert!(
        named
            .iter()
            .any(|f| *f == "q3_steps" || *f == "bending3_deg"),
        "leg 3's displacement drives the coupling: {}",
        report(&a)
    );
    assert!(
        named
            .iter()
            .take(3)
            .any(|f| f.ends_with('1') || f.ends_with("1_deg") || f.ends_with("1_steps")),
        "leg 1 is the coupled one: {}",
        report(&a)
    );
}
