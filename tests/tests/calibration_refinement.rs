//! The joint refinement reaches the optimum of its own objective: on another program's
//! recording of a robot we did not build (`../shared/data/foreign-f0/calib.csv`), started from
//! the two steps' solution and from that solution perturbed far off in every parameter, it
//! ends at the same parameters (to a small fraction of their standard errors) and the same
//! cost, below the two steps'.

use pcr_calibration::calibrate::{
    calibrate, leg_observations, pose_observations, Calibration, Options,
};
use pcr_calibration::joint::{refine, JointFit, JointObservations, JointParams};
use pcr_calibration::step1::{FreeGeometry, LegObservation};
use pcr_calibration::step2::{PoseObservation, Step2Params};
use pcr_calibration::StaticData;
use pcr_recording::{Recording, Split};
use pcr_robot::RobotConfig;
use std::path::Path;

fn foreign_calib() -> Recording {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/foreign-f0/calib.csv");
    assert!(
        p.exists(),
        "{}: the shared recordings of another program are missing",
        p.display()
    );
    Recording::read_path(&p).unwrap()
}

/// The training observations of the calibration's split.
fn observations(
    start: &RobotConfig,
    rec: &Recording,
    opts: &Options,
) -> ([Vec<LegObservation>; 3], Vec<PoseObservation>) {
    let data = StaticData::from_recording(rec, "f0", opts.seed, opts.test_fraction).unwrap();
    (
        std::array::from_fn(|i| leg_observations(start, &data, i, Split::Train)),
        pose_observations(&data, Split::Train),
    )
}

fn refine_from(
    start: &RobotConfig,
    cal: &Calibration,
    from: &RobotConfig,
    obs: JointObservations<'_>,
) -> JointFit {
    let free = JointParams {
        legs: FreeGeometry::PAPER,
        platform: Step2Params::PAPER,
        forms: std::array::from_fn(|i| cal.paper_robot.legs[i].tendon_map.form()),
        frame: false,
    };
    refine(start, from, free, obs, cal.step2.phi_weight_mm_per_deg).unwrap()
}

#[test]
fn the_joint_refinement_returns_to_its_optimum_from_a_perturbed_start() {
    let rec = foreign_calib();
    let start = RobotConfig::nominal();
    let opts = Options::default();
    let cal = calibrate(&start, &rec, "f0", &opts).unwrap();
    let (legs, poses) = observations(&start, &rec, &opts);
    let obs = JointObservations {
        legs: &legs,
        poses: &poses,
    };
    let from_two_steps = refine_from(&start, &cal, &cal.paper_robot, obs);
    // The two steps' solution off by tenths of a millimetre and degree in every geometric
    // parameter and 2 % in every map slope: about 25 times the optimum's training RMS.
    let mut far = cal.paper_robot.clone();
    for (i, l) in far.legs.iter_mut().enumerate() {
        l.psi_deg += 0.3 * (i as f64 - 1.0);
        l.l_c_mm += 0.5;
        l.r_p_mm -= 0.3;
        l.theta_p_deg += 0.3;
        l.tendon_map.coeffs[1] *= 1.02;
        if let Some(k) = l.tendon_map.coeffs_neg.first_mut() {
            *k *= 0.98;
        }
    }
    let from_far = refine_from(&start, &cal, &far, obs);
    println!(
        "two steps {:.5} mm -> {:.5} mm ({} evaluations); perturbed {:.4} mm -> {:.5} mm ({} evaluations)",
        from_two_steps.start_rms_mm,
        from_two_steps.rms_mm,
        from_two_steps.evaluations,
        from_far.start_rms_mm,
        from_far.rms_mm,
        from_far.evaluations
    );
    assert!(from_two_steps.converged && from_far.converged);
    assert!(from_far.start_rms_mm > 20.0 * from_far.rms_mm);
    // The refinement improves on the two steps' cost.
    assert!(from_two_steps.rms_mm < from_two_steps.start_rms_mm);
    // The same optimum from both starts: the cost to 1e-6 relative, every parameter to 1 % of
    // its standard error.
    assert!((from_far.rms_mm / from_two_steps.rms_mm - 1.0).abs() < 1e-6);
    for (a, b) in from_two_steps.params.iter().zip(&from_far.params) {
        assert_eq!(a.name, b.name);
        let se = a.std.unwrap();
        assert!(
            (a.value - b.value).abs() < 0.01 * se,
            "{}: {} against {} (standard error {se})",
            a.name,
            a.value,
            b.value
        );
    }
}
