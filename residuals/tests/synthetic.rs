//! The attribution machinery on data the extended model itself generates (known effects, white
//! noise): the effects it must find, the parameters it must recover, and no false discovery.
//! The tests against the independent plant are in tests/tests/residuals_plant.rs.

use pcr_kinematics::Robot;
use pcr_recording::{Recording, Row};
use pcr_residuals::model::ExtendedModel;
use pcr_residuals::{attribute, Blocks, Options, Series, Verdict};
use pcr_robot::effects::{Backlash, Latency};
use pcr_robot::RobotConfig;
use rand::{Rng, SeedableRng};

fn normal(rng: &mut impl Rng) -> f64 {
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A recording of `truth` (robot file with effects) driven through a sequence of targets with
/// rest-to-rest moves and dwells; the measured pose is the truth's prediction plus noise.
fn record(truth: &RobotConfig, seconds: f64, noise_mm: f64, seed: u64) -> Recording {
    let nominal = Robot::new(&RobotConfig::nominal()).unwrap();
    let home: [f64; 3] =
        std::array::from_fn(|i| nominal.kappa_to_steps(i, nominal.home_kappa[i]).unwrap());
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    // Motor targets: a random walk of joint moves, each 1.2 s of smooth motion then 0.8 s rest.
    let mut rows = Vec::new();
    let (dt, mut t) = (0.02, 0.0);
    let mut from = home;
    while t < seconds {
        let to: [f64; 3] =
            std::array::from_fn(|i| home[i] + 70.0 * (2.0 * rng.random::<f64>() - 1.0));
        for k in 0..100 {
            let s = (k as f64 / 60.0).min(1.0);
            let w = 0.5 - 0.5 * (std::f64::consts::PI * s).cos();
            let q: [i32; 3] =
                std::array::from_fn(|i| (from[i] + w * (to[i] - from[i])).round() as i32);
            let mut r = Row::new(t, q);
            r.settled = Some(k >= 75);
            r.pose_id = (k >= 75).then_some(rows.len() as u64 / 100);
            rows.push(r);
            t += dt;
        }
        from = to;
    }
    let mut rec = Recording {
        columns: [
            "t_s", "q1", "q2", "q3", "x_mm", "y_mm", "phi_deg", "pose_id", "settled",
        ]
        .map(String::from)
        .to_vec(),
        rows,
        ..Recording::default()
    };
    let s = Series::from_recording(&rec_with_dummy_pose(&rec), "truth").unwrap();
    let preds = ExtendedModel::new(truth, pcr_residuals::effects::chain())
        .unwrap()
        .predict(&s);
    for (r, p) in rec.rows.iter_mut().zip(preds) {
        let p = p
            .pose
            .expect("the truth reaches every commanded configuration");
        r.pose = [
            Some(p[0] + noise_mm * normal(&mut rng)),
            Some(p[1] + noise_mm * normal(&mut rng)),
            Some(p[2].to_degrees() + noise_mm * normal(&mut rng)),
        ];
    }
    rec
}

/// The same rows with a zero pose (a series needs measured rows to exist).
fn rec_with_dummy_pose(rec: &Recording) -> Recording {
    let mut r = rec.clone();
    for row in &mut r.rows {
        row.pose = [Some(0.0); 3];
    }
    r
}

fn analyse(truth: &RobotConfig, model: &RobotConfig, seconds: f64) -> pcr_residuals::Attribution {
    let rec = record(truth, seconds, 0.05, 7);
    let s = vec![Series::from_recording(&rec, "synthetic").unwrap()];
    let b = Blocks::in_time(&s, 2.0, 3);
    attribute(model, model, &s, &b, &Options::default()).unwrap()
}

#[test]
fn finds_latency_and_backlash_with_their_values() {
    let model = RobotConfig::nominal();
    let mut truth = model.clone();
    truth.effects.latency = Some(Latency { latency_s: 0.05 });
    truth.effects.backlash = Some(Backlash {
        steps: [3.0, 5.0, 2.0],
    });
    let a = analyse(&truth, &model, 240.0);
    let names: Vec<&str> = a.effects.iter().map(|e| e.name.as_str()).collect();
    assert!(
        names.contains(&"latency") && names.contains(&"backlash"),
        "{names:?}"
    );
    let l = a.robot.effects.latency.as_ref().unwrap().latency_s;
    assert!((l - 0.05).abs() < 0.003, "latency {l}");
    let b = a.robot.effects.backlash.as_ref().unwrap().steps;
    for (f, t) in b.iter().zip([3.0, 5.0, 2.0]) {
        assert!((f - t).abs() < 0.3, "backlash {b:?}");
    }
    assert!(a.after.position_rms_mm < 0.5 * a.before.position_rms_mm);
    assert_eq!(a.verdict, Verdict::Explained, "{:?}", a.correlated_features);
    // Every candidate was tried in the first round, with a score.
    assert!(a.candidates.iter().filter(|c| c.round == 1).count() >= 8);
}

#[test]
fn no_effect_gives_no_effect() {
    let model = RobotConfig::nominal();
    let a = analyse(&model, &model, 120.0);
    assert!(
        a.effects.is_empty(),
        "{:?}",
        a.effects.iter().map(|e| &e.name).collect::<Vec<_>>()
    );
    assert_eq!(a.verdict, Verdict::Explained);
    assert!((a.after.position_rms_mm - a.before.position_rms_mm).abs() < 1e-12);
}
