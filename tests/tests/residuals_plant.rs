//! `pcr residuals` against the simulated plant with effects nobody declared to the model: each
//! test records static visits and the paper's paths on the in-process chain (the real planner,
//! IK and drive steps) with one effect on in the plant, analyses the recording, and checks the
//! name, the parameter and the held-out gain. The residual crate never sees the plant.

use pcr_experiments::Design;
use pcr_integration_tests::plant_recordings::{quiet_plant, record, visits_and_paths};
use pcr_plant::PlantConfig;
use pcr_recording::{Recording, COMMAND_DELAY_KEY};
use pcr_residuals::alignment::TimingFinding;
use pcr_residuals::{attribute, Attribution, Blocks, Options, Series, Verdict};
use pcr_robot::RobotConfig;

/// Static visits (5 per scaled boundary: 45 poses) and the paper's paths twice.
fn designs() -> Vec<Design> {
    visits_and_paths(5, 2)
}

/// The same recording as another recorder would write it: each row's q is the motor position
/// its pose answers (the command of the row before, in this chain), and the file declares no
/// command delay (`shared/spec/recording.md`, "Timing": D = 0). `declare` writes a
/// `command_delay_s` line anyway (a wrong declaration). Written and read back as text.
fn as_position_reached(rec: &Recording, declare: Option<f64>) -> Recording {
    let mut r = rec.clone();
    for k in (1..r.rows.len()).rev() {
        r.rows[k].q = rec.rows[k - 1].q;
    }
    r.metadata.retain(|(k, _)| k != COMMAND_DELAY_KEY);
    if let Some(d) = declare {
        r.metadata.push((COMMAND_DELAY_KEY.into(), d.to_string()));
    }
    let mut text = Vec::new();
    r.write(&mut text).unwrap();
    Recording::read(text.as_slice(), "position-reached recording").unwrap()
}

/// The same experiment as a logger of another lab writes it: the position reached in each row
/// (D = 0, undeclared), every second row (40 ms), no metadata at all, its own column order,
/// CRLF line ends and a column the format does not know.
fn as_another_logger(rec: &Recording) -> Recording {
    let reached = as_position_reached(rec, None);
    let mut text = Vec::new();
    reached.write(&mut text).unwrap();
    let text = String::from_utf8(text).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let order: Vec<usize> = (0..header.len()).rev().collect();
    let row = |cells: Vec<&str>, extra: &str| {
        let mut out: Vec<&str> = order.iter().map(|&i| cells[i]).collect();
        out.insert(2, extra);
        out.join(",")
    };
    let mut out = vec![
        "# written by another lab's logger".to_string(),
        row(header.clone(), "temperature_c"),
    ];
    out.extend(
        lines
            .step_by(2)
            .map(|l| row(l.split(',').collect(), "21.5")),
    );
    let text = out.join("\r\n") + "\r\n";
    Recording::read(text.as_bytes(), "another lab's recording").unwrap()
}

/// Analyses recordings, starting the analysis from `model`.
fn attribute_on(model: &RobotConfig, recs: &[Recording]) -> Attribution {
    let series: Vec<Series> = recs
        .iter()
        .enumerate()
        .map(|(k, r)| Series::from_recording(r, &format!("run {k}")).unwrap())
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

/// The two readings of one experiment agree: the same effects in the same order, with the same
/// parameters (within a tenth of their standard error).
fn assert_same_findings(a: &Attribution, b: &Attribution, what: &str) {
    assert_eq!(names(a), names(b), "{what}: {} vs {}", report(a), report(b));
    for (x, y) in a.effects.iter().zip(&b.effects) {
        for (p, q) in x.params.iter().zip(&y.params) {
            let tol = 0.1 * p.std.unwrap_or(0.0) + 1e-6 * (1.0 + p.value.abs());
            assert!(
                (p.value - q.value).abs() <= tol,
                "{what}: {} {}: {} vs {}",
                x.name,
                p.name,
                p.value,
                q.value
            );
        }
    }
    assert_eq!(a.verdict, b.verdict, "{what}");
}

/// Analyses the recordings of `plant` driven by `model`, starting the analysis from `model`, in
/// both readings of the timing contract: as this chain records (each row's command executed
/// over the next cycle, `command_delay_s` = one period declared) and as a recorder of the
/// position reached writes the same rows (q one row later, no declaration). Both must name the
/// same effects with the same parameters, and the data must agree with each declaration.
fn analyse(model: &RobotConfig, plant: &PlantConfig) -> Attribution {
    analyse_designs(model, plant, &designs())
}

/// [`analyse`] on other designs.
fn analyse_designs(model: &RobotConfig, plant: &PlantConfig, designs: &[Design]) -> Attribution {
    let recs: Vec<Recording> = designs.iter().map(|d| record(model, plant, d)).collect();
    for r in &recs {
        assert_eq!(
            r.command_delay_s().unwrap(),
            0.02,
            "the chain declares its D"
        );
    }
    let chain = attribute_on(model, &recs);
    let reached: Vec<Recording> = recs.iter().map(|r| as_position_reached(r, None)).collect();
    let other = attribute_on(model, &reached);
    assert_same_findings(&chain, &other, "chain vs position-reached reading");
    for a in [&chain, &other] {
        assert!(a.timing_finding.is_none(), "{:?}", a.timing);
        assert!(
            a.timing
                .iter()
                .all(|t| t.finding != TimingFinding::DeclarationError),
            "{:?}",
            a.timing
        );
    }
    chain
}

fn names(a: &Attribution) -> Vec<&str> {
    a.effects.iter().map(|e| e.name.as_str()).collect()
}

fn report(a: &Attribution) -> String {
    if std::env::var_os("PCR_TEST_SCORES").is_some() {
        for c in &a.candidates {
            eprintln!(
                "round {} {}: gain {:.4} total {:.4} p {:.1e} dBIC {:.1} {} {:?}",
                c.round,
                c.name,
                c.effect_mm,
                c.total_gain_mm,
                c.p_value,
                c.delta_bic,
                c.note,
                c.params
                    .iter()
                    .map(|p| (p.name.as_str(), p.value))
                    .collect::<Vec<_>>()
            );
        }
    }
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

/// Friction in the supports alone (the joints turn freely), at three times the prototype's: the
/// fit from no friction holds the joints' limit at zero when its first step takes it below, and
/// fits the supports on their own column, a play's columns beside them
/// (`effects::friction::step_at`; on the joints' column, as it once did, the analysis named a
/// backlash and a latency, plays of 5.1-5.2 steps). Found alone, with the supports' force, no
/// play beside it, and its halves agreeing (the joints held at zero in one half, 0.08 +- 0.05
/// N mm in the other, is no disagreement: docs/residuals.md, "Friction").
#[test]
fn finds_friction_in_the_supports_alone() {
    let mut plant = quiet_plant();
    plant.friction = PlantConfig::prototype().friction;
    plant.friction.joint_torque_n_mm = 0.0;
    plant.friction.support_force_n *= 3.0;
    let a = analyse(&RobotConfig::nominal(), &plant);
    assert_eq!(names(&a), ["friction"], "{}", report(&a));
    let f = a.robot.effects.friction.as_ref().unwrap();
    assert!(
        f.joint_torque_n_mm < 0.5 && (f.support_force_n - 0.12).abs() < 0.012,
        "{f:?}: {}",
        report(&a)
    );
    assert_eq!(a.verdict, Verdict::Explained, "{}", report(&a));
}

/// The prototype's friction at three times its value beside its gear play: the two
/// hysteresis sources are told apart (a play acts on the motors, before the structure; the
/// friction on the pose through the structure's compliance, stuck elements holding), each with
/// its parameters, in both readings of the timing.
#[test]
fn finds_friction_beside_backlash_and_tells_them_apart() {
    let mut plant = quiet_plant();
    plant.stepper.backlash = true;
    plant.stepper.backlash_steps = [3.0, 4.0, 3.0];
    plant.friction = PlantConfig::prototype().friction;
    plant.friction.joint_torque_n_mm *= 3.0;
    plant.friction.support_force_n *= 3.0;
    let a = analyse(&RobotConfig::nominal(), &plant);
    let n = names(&a);
    assert!(
        n.contains(&"friction") && n.contains(&"backlash"),
        "{}",
        report(&a)
    );
    let b = a.robot.effects.backlash.as_ref().unwrap().steps;
    for (f, t) in b.iter().zip([3.0, 4.0, 3.0]) {
        assert!((f - t).abs() < 0.3, "{b:?}: {}", report(&a));
    }
    let f = a.robot.effects.friction.as_ref().unwrap();
    assert!(
        (f.joint_torque_n_mm - 6.0).abs() < 0.9 && (f.support_force_n - 0.12).abs() < 0.012,
        "{f:?}: {}",
        report(&a)
    );
    assert_eq!(a.verdict, Verdict::Explained, "{}", report(&a));
    assert!(
        a.after.position_rms_mm < 0.2 * a.before.position_rms_mm,
        "{}",
        report(&a)
    );
}

#[test]
fn another_labs_logger_at_half_the_rate_gives_the_same_backlash() {
    let mut plant = quiet_plant();
    plant.stepper.backlash = true;
    plant.stepper.backlash_steps = [3.0, 4.0, 3.0];
    let model = RobotConfig::nominal();
    let recs: Vec<Recording> = designs()
        .iter()
        .map(|d| record(&model, &plant, d))
        .collect();
    let other: Vec<Recording> = recs.iter().map(as_another_logger).collect();
    assert!(other[0].command_delay_s().unwrap() == 0.0 && other[0].metadata.is_empty());
    assert!(other[0].rows.len() < recs[0].rows.len() / 2 + 1);
    let (a, b) = (attribute_on(&model, &recs), attribute_on(&model, &other));
    assert_eq!(names(&a), names(&b), "{} vs {}", report(&a), report(&b));
    assert_eq!(a.verdict, b.verdict, "{} vs {}", report(&a), report(&b));
    assert!(b.timing_finding.is_none(), "{:?}", b.timing);
    assert!(names(&a).contains(&"backlash"), "{}", report(&a));
    // Half the rows: the parameters agree within two standard errors of the coarser file.
    let params = |x: &Attribution| -> Vec<pcr_residuals::Estimate> {
        x.effects.iter().flat_map(|e| e.params.clone()).collect()
    };
    for (x, y) in params(&a).iter().zip(&params(&b)) {
        let tol = 2.0 * y.std.unwrap_or(0.05);
        assert!(
            (x.value - y.value).abs() <= tol,
            "{}: {} vs {} (+- {tol})",
            x.name,
            x.value,
            y.value
        );
    }
}

/// The same rows with each row's q the command of the row after (so each pose answers the
/// command two rows before its own) and no declaration: 40 ms of delay the file does not
/// declare, written as text.
fn answering_two_rows_earlier(rec: &Recording) -> Recording {
    let mut r = rec.clone();
    for k in 0..r.rows.len() - 1 {
        r.rows[k].q = rec.rows[k + 1].q;
    }
    r.rows.pop();
    r.metadata.retain(|(k, _)| k != COMMAND_DELAY_KEY);
    let mut text = Vec::new();
    r.write(&mut text).unwrap();
    Recording::read(text.as_slice(), "undeclared-delay recording").unwrap()
}

#[test]
fn an_undeclared_delay_with_backlash_and_friction_is_explained() {
    // The prototype's lag sources: a 10 ms capture latency, plays, support and joint friction.
    let mut plant = quiet_plant();
    plant.capture.latency_s = 0.01;
    plant.stepper.backlash = true;
    plant.stepper.backlash_steps = [3.0, 4.0, 3.0];
    plant.friction = PlantConfig::prototype().friction;
    let model = RobotConfig::nominal();
    let recs: Vec<Recording> = designs()
        .iter()
        .map(|d| record(&model, &plant, d))
        .collect();
    let late: Vec<Recording> = recs.iter().map(answering_two_rows_earlier).collect();
    let (a, b) = (attribute_on(&model, &recs), attribute_on(&model, &late));
    // 40 ms beyond the declaration is latency: both readings name the same effects, the
    // undeclared file's latency 40 ms longer, the same plays, and both are explained.
    let mut sorted = [names(&a), names(&b)];
    sorted.iter_mut().for_each(|n| n.sort());
    assert_eq!(sorted[0], sorted[1], "{} vs {}", report(&a), report(&b));
    assert!(names(&b).contains(&"latency"), "{}", report(&b));
    assert!(names(&b).contains(&"friction"), "{}", report(&b));
    let latency = |x: &Attribution| {
        x.robot
            .effects
            .latency
            .as_ref()
            .map_or(0.0, |l| l.latency_s)
    };
    let extra = latency(&b) - latency(&a);
    assert!(
        (extra - 0.04).abs() < 0.003,
        "{extra}: {} vs {}",
        report(&a),
        report(&b)
    );
    let plays = |x: &Attribution| x.robot.effects.backlash.as_ref().unwrap().steps;
    for (p, q) in plays(&a).iter().zip(plays(&b)) {
        assert!((p - q).abs() < 0.1, "{:?} vs {:?}", plays(&a), plays(&b));
    }
    assert_eq!(a.verdict, Verdict::Explained, "{}", report(&a));
    assert_eq!(b.verdict, Verdict::Explained, "{}", report(&b));
    assert!(
        b.after.position_rms_mm < 1.05 * a.after.position_rms_mm,
        "{} vs {}",
        report(&b),
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

#[test]
fn finds_a_steady_drift_of_one_tendon() {
    // Leg 2's tendon lengthens by 0.3 um/s (about 0.1 mm over the records).
    let mut plant = quiet_plant();
    plant.drift.enabled = true;
    plant.drift.rate_mm_per_s = [0.0, 3.0e-4, 0.0];
    let a = analyse(&RobotConfig::nominal(), &plant);
    assert_eq!(names(&a).first(), Some(&"drift"), "{}", report(&a));
    assert!(!names(&a).contains(&"creep"), "{}", report(&a));
    let r = a.robot.effects.drift.as_ref().unwrap().rate_mm_per_s;
    assert!((r[1] - 3.0e-4).abs() < 0.5e-4, "{}", report(&a));
    assert!(r[0].abs() < 0.5e-4 && r[2].abs() < 0.5e-4, "{}", report(&a));
    assert!(
        a.after.position_rms_mm < 0.5 * a.before.position_rms_mm,
        "{}",
        report(&a)
    );
}

#[test]
fn finds_backlash_and_a_load_together() {
    let mut plant = quiet_plant();
    plant.stepper.backlash = true;
    plant.stepper.backlash_steps = [3.0, 6.0, 3.0];
    plant.external_wrench.fx_n = 1.0;
    // The load is a smooth function of the pose that the calibration parameters mimic in part:
    // more visits and four runs of the paths give the held-out blocks to tell it apart.
    let a = analyse_designs(&RobotConfig::nominal(), &plant, &visits_and_paths(9, 4));
    let n = names(&a);
    assert!(
        n.contains(&"backlash") && n.contains(&"external_load"),
        "{}",
        report(&a)
    );
    let b = a.robot.effects.backlash.as_ref().unwrap().steps;
    for (f, t) in b.iter().zip([3.0, 6.0, 3.0]) {
        assert!((f - t).abs() < 0.6, "{b:?}: {}", report(&a));
    }
    let c = a.robot.effects.compliance.as_ref().unwrap();
    assert!(
        (c.force_n[0] - 1.0).abs() < 0.15 && c.force_n[1].abs() < 0.15,
        "{}",
        report(&a)
    );
}

#[test]
fn a_recording_that_declares_a_longer_delay_than_it_has_gets_a_timing_finding() {
    // A load in the data: the finding must be made, and the load found as in a correctly
    // declared file. (With backlash on rest-to-rest moves a delay and a play look alike, and a
    // wrong declaration can go unnoticed: docs/residuals.md, "Limits".)
    let mut plant = quiet_plant();
    plant.external_wrench.fx_n = 0.4;
    plant.external_wrench.fy_n = -0.3;
    let model = RobotConfig::nominal();
    let recs: Vec<Recording> = designs()
        .iter()
        .map(|d| record(&model, &plant, d))
        .collect();
    let right = attribute_on(&model, &recs);
    let wrong: Vec<Recording> = recs
        .iter()
        .map(|r| as_position_reached(r, Some(0.02)))
        .collect();
    let a = attribute_on(&model, &wrong);
    let finding = a.timing_finding.as_deref().unwrap_or_default();
    assert!(
        finding.contains("Timing declaration error") && finding.contains("0.02 s"),
        "{finding:?} {:?}",
        a.timing
    );
    for t in a.timing.iter().filter(|t| t.moving_rows > 500) {
        assert_eq!(t.finding, TimingFinding::DeclarationError, "{t:?}");
        let d = t.estimated_s.unwrap();
        assert!(
            d < 0.015,
            "the data show less than the declared 0.02 s: {t:?}"
        );
        assert_eq!(t.delay_used_s, 0.0, "{t:?}");
    }
    // The finding is never the reason to name another effect: the same effects as the file with
    // a right declaration.
    assert_same_findings(&right, &a, "right vs wrong declaration");
}

#[test]
fn clean_data_with_the_prototype_geometry_and_map_give_no_effect_at_the_noise_floor() {
    // The prototype's geometry deviations and true tanh tendon map, capture noise, nothing else:
    // calibrated first (as `pcr residuals` does), the analysis must name nothing and leave the
    // held-out error within twice the floor (the noise-free plant against the noisy
    // measurement, on the same rows).
    let proto = PlantConfig::prototype();
    let mut plant = quiet_plant();
    plant.geometry = proto.geometry.clone();
    plant.tendon_map = proto.tendon_map.clone();
    let model = RobotConfig::nominal();
    let designs = designs();
    let recs: Vec<Recording> = designs.iter().map(|d| record(&model, &plant, d)).collect();
    let mut silent = plant.clone();
    silent.capture.noise = false;
    let truth: Vec<Recording> = designs.iter().map(|d| record(&model, &silent, d)).collect();
    let sd = pcr_calibration::StaticData::from_recording(&recs[0], "run 0", 1, 1.0 / 3.0).unwrap();
    let cal = pcr_calibration::calibrate::calibrate_data(
        &model,
        &sd,
        &pcr_calibration::calibrate::Options::default(),
    )
    .unwrap();
    for (label, data) in [
        ("chain", recs.clone()),
        (
            "position reached",
            recs.iter().map(|r| as_position_reached(r, None)).collect(),
        ),
    ] {
        let series: Vec<Series> = data
            .iter()
            .enumerate()
            .map(|(k, r)| Series::from_recording(r, &format!("run {k}")).unwrap())
            .collect();
        let blocks = Blocks::in_time(&series, 2.0, 3);
        let a = attribute(&cal.robot, &model, &series, &blocks, &Options::default()).unwrap();
        assert!(a.effects.is_empty(), "{label}: {}", report(&a));
        assert_eq!(a.verdict, Verdict::Explained, "{label}: {}", report(&a));
        // The floor on the held-out rows: measured minus the noise-free plant.
        let (mut s2, mut n) = (0.0, 0usize);
        for (si, (r, t)) in recs.iter().zip(&truth).enumerate() {
            for (k, (x, y)) in r.rows.iter().zip(&t.rows).enumerate() {
                if !blocks.held_out[blocks.block[si][k]] {
                    continue;
                }
                if let (Some(m), Some(p)) = (x.measured_pose(), y.measured_pose()) {
                    s2 += (m[0] - p[0]).powi(2) + (m[1] - p[1]).powi(2);
                    n += 1;
                }
            }
        }
        let floor = (s2 / n as f64).sqrt();
        assert!(
            (0.05..0.1).contains(&floor),
            "the capture noise of 0.05 mm per axis: {floor}"
        );
        assert!(
            a.after.position_rms_mm < 2.0 * floor,
            "{label}: held-out RMS {:.4} mm against the floor {floor:.4}: {}",
            a.after.position_rms_mm,
            report(&a)
        );
    }
}
