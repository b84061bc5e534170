//! The in-process runtime on the real parts: the planner's jerk-limited paths and the simulated
//! plant (elastica statics, stepper, backlash, friction, capture noise).

use pcr_control::{simple_command, CorrectionConfig, CorrectionStep, SimChain};
use pcr_messages::{command_kind, program_id};
use pcr_plant::PlantConfig;
use pcr_robot::RobotConfig;

const ROBOT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/robot.toml");
const IDEAL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/plant-ideal.toml");
const PROTO: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/plant.toml");

fn run(plant: &str, program: u32) -> pcr_control::Accuracy {
    let robot = RobotConfig::load(ROBOT).unwrap();
    let cfg = PlantConfig::load(plant).unwrap();
    let mut c = SimChain::simulated(&robot, &cfg, 0.02).unwrap();
    c.run(
        &simple_command(command_kind::RUN, program, 1),
        120.0,
        |_| {},
    )
    .unwrap()
}

#[test]
fn the_ideal_plant_follows_the_papers_program_to_step_quantisation() {
    let acc = run(IDEAL, program_id::PAPER);
    println!("ideal plant: {acc}");
    assert!(acc.n > 600, "{acc}");
    assert!(acc.max_pos_mm < 0.5 && acc.rms_pos_mm() < 0.2, "{acc}");
}

#[test]
fn the_prototype_plant_shows_the_model_error_the_calibration_must_remove() {
    let acc = run(PROTO, program_id::CIRCLE);
    println!("prototype plant: {acc}");
    // Uncalibrated: geometry deviations, the true tendon map, backlash and friction give errors
    // of millimetres, far above the ideal plant's step quantisation, but the run completes.
    assert!(acc.n > 300, "{acc}");
    assert!(acc.rms_pos_mm() > 0.3 && acc.max_pos_mm < 20.0, "{acc}");
}

fn run_corrected(plant: &str, program: u32, gain: f64) -> pcr_control::Accuracy {
    let robot = RobotConfig::load(ROBOT).unwrap();
    let cfg = PlantConfig::load(plant).unwrap();
    let c = SimChain::simulated(&robot, &cfg, 0.02).unwrap();
    let mut c = c.with_correction(CorrectionStep::new(CorrectionConfig {
        gain,
        limit_mm: 5.0,
        latency_s: cfg.capture.latency_s,
    }));
    c.run(
        &simple_command(command_kind::RUN, program, 1),
        120.0,
        |_| {},
    )
    .unwrap()
}

#[test]
fn the_capture_correction_removes_most_of_the_prototypes_model_error() {
    let open = run(PROTO, program_id::CIRCLE);
    let closed = run_corrected(PROTO, program_id::CIRCLE, 0.3);
    println!("open loop {open}\ncorrected (gain 0.3) {closed}");
    // The slowly varying model error goes; step quantisation, backlash reversals and capture
    // noise stay.
    assert!(closed.n > 300, "{closed}");
    assert!(
        closed.mean_pos_mm() < open.mean_pos_mm() / 3.0,
        "{open}\n{closed}"
    );
    assert!(
        closed.max_pos_mm < open.max_pos_mm / 2.0,
        "{open}\n{closed}"
    );
    assert!(
        closed.rms_phi_deg() < open.rms_phi_deg() / 3.0,
        "{open}\n{closed}"
    );
    // gain 0 reports the error and changes nothing
    let zero = run_corrected(PROTO, program_id::CIRCLE, 0.0);
    assert_eq!(zero.mean_pos_mm(), open.mean_pos_mm());
}

#[test]
fn the_plant_drive_reports_the_captured_joints_with_the_pose() {
    let robot = RobotConfig::load(ROBOT).unwrap();
    let cfg = PlantConfig::load(IDEAL).unwrap();
    let mut c = SimChain::simulated(&robot, &cfg, 0.02).unwrap();
    let model = pcr_kinematics::Robot::new(&robot).unwrap();
    for _ in 0..5 {
        c.cycle().unwrap();
    }
    // On the ideal plant at home the captured M_i are the model's M_i of the home steps.
    let joints = c.plant_drive().joints();
    let home = c.plant_drive().home_steps();
    for i in 0..3 {
        let m = joints[i].expect("captured at 100 Hz, no dropouts");
        let want = model.joint_m(i, model.steps_to_kappa(i, home[i] as f64));
        assert!(
            (m[0] - want[0]).hypot(m[1] - want[1]) < 1e-3,
            "leg {}: {m:?} vs {want:?}",
            i + 1
        );
    }
}

#[test]
fn a_changed_model_drives_the_same_plant() {
    // The truth is built on the plant's own robot; the driving model may differ (a calibrated
    // robot): the plant starts at the same home either way.
    let robot = RobotConfig::load(ROBOT).unwrap();
    let mut model = robot.clone();
    model.legs[0].l_c_mm += 2.0;
    let cfg = PlantConfig::load(IDEAL).unwrap();
    let a = SimChain::simulated(&robot, &cfg, 0.02).unwrap();
    let b = SimChain::simulated_on(&model, &robot, &cfg, 0.02).unwrap();
    assert_eq!(a.plant_drive().home_steps(), b.plant_drive().home_steps());
    assert_eq!(
        b.ik.robot().config().legs[0].l_c_mm,
        robot.legs[0].l_c_mm + 2.0
    );
}

/// The friction of the joints and their supports, declared in the robot file, is fed forward
/// by the IK: on a plant whose only effect is that friction (three times the prototype's),
/// the circle's error falls to a tenth of the uncompensated one (1.2 -> 0.11 mm RMS).
#[test]
fn declared_friction_is_fed_forward() {
    let robot = RobotConfig::load(ROBOT).unwrap();
    let mut cfg = PlantConfig::load(IDEAL).unwrap();
    cfg.friction.joints = true;
    cfg.friction.joint_torque_n_mm = 6.0;
    cfg.friction.supports = true;
    cfg.friction.support_force_n = 0.12;
    let run_with = |model: &RobotConfig| {
        let mut c = SimChain::simulated_on(model, &robot, &cfg, 0.02).unwrap();
        c.run(
            &simple_command(command_kind::RUN, program_id::CIRCLE, 1),
            120.0,
            |_| {},
        )
        .unwrap()
    };
    let open = run_with(&robot);
    let mut declared = robot.clone();
    declared.effects.friction = Some(pcr_robot::effects::Friction {
        joint_torque_n_mm: 6.0,
        support_force_n: 0.12,
        joint_presliding_rad: pcr_robot::effects::Friction::default_joint_presliding(),
        support_presliding_mm: pcr_robot::effects::Friction::default_support_presliding(),
        ei_n_mm2: pcr_robot::effects::Friction::default_ei(),
    });
    let fed = run_with(&declared);
    println!("friction not compensated {open}\nfed forward {fed}");
    assert!(open.rms_pos_mm() > 0.3, "{open}");
    assert!(fed.rms_pos_mm() < 0.15 * open.rms_pos_mm(), "{open}\n{fed}");
    assert!(
        fed.rms_phi_deg() < 0.4 * open.rms_phi_deg(),
        "{open}\n{fed}"
    );
}
