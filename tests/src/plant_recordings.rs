//! Recordings of the simulated plant for the tests that check an analysis against effects they
//! chose: the plants, the experiment designs, the run on the in-process chain (the real planner,
//! IK and drive steps), and the empty recording that a test fills with the plant's static truth.

use pcr_experiments::{
    run_in_process, CalibrationOptions, Design, PathsDesign, RunSetup, StaticDesign, Tolerances,
    VisitTiming,
};
use pcr_kinematics::Robot;
use pcr_plant::PlantConfig;
use pcr_recording::Recording;
use pcr_robot::RobotConfig;

/// A plant with nominal geometry, the linear map, capture noise, and no other effect.
pub fn quiet_plant() -> PlantConfig {
    let mut p = PlantConfig::ideal();
    p.capture.noise = true;
    p
}

/// The plant with the prototype's geometry deviations scaled by `scale` and its tendon map;
/// every other effect off; capture noise (0.05 mm, 0.05 deg per coordinate) on or off.
pub fn geometry_and_map_plant(scale: f64, noise: bool) -> PlantConfig {
    let proto = PlantConfig::prototype();
    let mut p = PlantConfig::ideal();
    p.geometry = proto.geometry;
    let g = &mut p.geometry;
    for d in [
        &mut g.d_r_base_mm,
        &mut g.d_beta_deg,
        &mut g.d_psi_deg,
        &mut g.d_l_c_mm,
        &mut g.d_l_ce_mm,
        &mut g.d_l_st_mm,
        &mut g.d_r_p_mm,
        &mut g.d_theta_p_deg,
    ] {
        d.iter_mut().for_each(|v| *v *= scale);
    }
    p.tendon_map = proto.tendon_map;
    p.capture.noise = noise;
    p
}

/// The paper's calibration visits on the nominal robot: `points` per scaled boundary (nine
/// boundaries), `test_per_group` of each group held out, each visited with `timing`.
pub fn calibration_visits(points: usize, test_per_group: usize, timing: VisitTiming) -> Design {
    let cal = StaticDesign::calibration(
        &Robot::nominal(),
        &CalibrationOptions {
            points,
            test_per_group,
            ..CalibrationOptions::default()
        },
        timing,
    )
    .unwrap();
    Design::Static(cal)
}

/// Static visits (`points` per scaled boundary, nine boundaries, two per group held out, at
/// 30 mm/s with 0.6 s settling and 0.4 s measuring) and the paper's paths `paths` times.
pub fn visits_and_paths(points: usize, paths: usize) -> Vec<Design> {
    let timing = VisitTiming {
        speed_mm_s: 30.0,
        settle_s: 0.6,
        measure_s: 0.4,
    };
    std::iter::once(calibration_visits(points, 2, timing))
        .chain((0..paths).map(|_| Design::Paths(PathsDesign::default())))
        .collect()
}

/// Records `design` on the in-process chain with `model` driving `plant` (the plant's own robot
/// nominal, a 20 ms period, seed 1), read back as the file `plant run`.
pub fn record(model: &RobotConfig, plant: &PlantConfig, design: &Design) -> Recording {
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

/// A recording with no rows and the columns of static visits: time, motors, the measured
/// platform pose and passive joints M_i, pose id, settled and the train/test set.
pub fn empty_static_recording() -> Recording {
    Recording {
        columns: [
            "t_s", "q1", "q2", "q3", "x_mm", "y_mm", "phi_deg", "m1x_mm", "m1y_mm", "m2x_mm",
            "m2y_mm", "m3x_mm", "m3y_mm", "pose_id", "settled", "set",
        ]
        .map(String::from)
        .to_vec(),
        ..Recording::default()
    }
}
