//! The fast path of `pcr residuals` (rows at rest reusing their prediction, warm-started loaded
//! equilibria, load responses interpolated between anchor rows, rows and candidates in
//! parallel) against the exact path (`Options::exact`: every row solved on its own), on plant
//! recordings with a compliance effect (joint springs; a load with backlash): the same effects in
//! the same order, the same parameters within 0.15 of their standard error, the same verdict.

use pcr_integration_tests::plant_recordings::{quiet_plant, record, visits_and_paths};
use pcr_plant::PlantConfig;
use pcr_recording::Recording;
use pcr_residuals::progress::Progress;
use pcr_residuals::{attribute, Attribution, Blocks, Options, ProgressSink, Series};
use pcr_robot::RobotConfig;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// Records static visits (`points` per scaled boundary) and the paper's paths twice on the
/// in-process chain, the nominal model driving `plant`.
fn recordings(plant: &PlantConfig, points: usize) -> Vec<Recording> {
    visits_and_paths(points, 2)
        .iter()
        .map(|d| record(&RobotConfig::nominal(), plant, d))
        .collect()
}

/// Counts what the attribution reports.
#[derive(Default)]
struct Counter {
    stages: Mutex<Vec<(usize, String, usize)>>,
    steps: AtomicUsize,
}

impl Progress for Counter {
    fn stage(&self, round: usize, what: &str, rows: usize, _steps: usize) {
        self.stages
            .lock()
            .unwrap()
            .push((round, what.to_string(), rows));
    }

    fn step(&self) {
        self.steps.fetch_add(1, Ordering::Relaxed);
    }
}

fn analyse(recs: &[Recording], exact: bool, progress: ProgressSink) -> Attribution {
    let series: Vec<Series> = recs
        .iter()
        .enumerate()
        .map(|(k, r)| Series::from_recording(r, &format!("run {k}")).unwrap())
        .collect();
    let blocks = Blocks::in_time(&series, 2.0, 3);
    let opts = Options {
        exact,
        progress,
        ..Options::default()
    };
    attribute(
        &RobotConfig::nominal(),
        &RobotConfig::nominal(),
        &series,
        &blocks,
        &opts,
    )
    .unwrap()
}

fn summary(a: &Attribution) -> String {
    format!(
        "{:?} {:?}",
        a.effects
            .iter()
            .map(|e| (&e.name, &e.params))
            .collect::<Vec<_>>(),
        a.verdict
    )
}

/// The fast and the exact path agree on `plant`'s recordings; returns the fast result.
fn assert_fast_is_exact(plant: &PlantConfig, points: usize) -> Attribution {
    let recs = recordings(plant, points);
    let counter = Arc::new(Counter::default());
    let fast = analyse(&recs, false, ProgressSink::new(counter.clone()));
    let exact = analyse(&recs, true, ProgressSink::default());
    let names = |a: &Attribution| a.effects.iter().map(|e| e.name.clone()).collect::<Vec<_>>();
    assert_eq!(
        names(&fast),
        names(&exact),
        "fast {} vs exact {}",
        summary(&fast),
        summary(&exact)
    );
    for (x, y) in fast.effects.iter().zip(&exact.effects) {
        for (p, q) in x.params.iter().zip(&y.params) {
            assert_eq!(p.name, q.name);
            let std = p.std.unwrap_or(0.0).max(q.std.unwrap_or(0.0));
            // The fast path interpolates the loaded kinematics and their load responses
            // between solved rows (to 1e-3 mm and 0.5 %); an estimate the data barely
            // determine (a couple of 0 +- 0.39 N mm) then stops at a slightly different point
            // of the acceptance's iteration (0.12 of its error; forces within 0.01).
            let tol = 0.15 * std + 1e-6 * (1.0 + p.value.abs());
            assert!(
                (p.value - q.value).abs() <= tol,
                "{} {}: fast {} vs exact {} (std {std})",
                x.name,
                p.name,
                p.value,
                q.value
            );
        }
    }
    assert_eq!(fast.verdict, exact.verdict);
    let rms = (fast.after.position_rms_mm - exact.after.position_rms_mm).abs();
    assert!(rms < 1e-3, "held-out RMS differs by {rms} mm");
    // The progress went through the options: every round's candidates, then what remains.
    let stages = counter.stages.lock().unwrap();
    assert!(
        stages
            .iter()
            .any(|(r, w, rows)| *r == 1 && w == "fitting candidates" && *rows > 1000),
        "{stages:?}"
    );
    assert_eq!(stages.last().map(|s| s.1.as_str()), Some("what remains"));
    assert!(counter.steps.load(Ordering::Relaxed) >= Options::default().candidates.len());
    fast
}

#[test]
fn fast_path_finds_what_the_exact_path_finds_with_joint_springs() {
    let mut plant = quiet_plant();
    plant.mechanics.k_m_n_mm_per_rad = 300.0;
    plant.mechanics.k_p_n_mm_per_rad = 200.0;
    let a = assert_fast_is_exact(&plant, 5);
    assert!(
        a.effects.iter().any(|e| e.name == "joint_springs"),
        "{}",
        summary(&a)
    );
}

#[test]
fn fast_path_finds_what_the_exact_path_finds_with_backlash_and_a_load() {
    let mut plant = quiet_plant();
    plant.stepper.backlash = true;
    plant.stepper.backlash_steps = [3.0, 4.0, 3.0];
    plant.external_wrench.fx_n = 0.4;
    plant.external_wrench.fy_n = -0.3;
    let a = assert_fast_is_exact(&plant, 5);
    assert!(
        a.effects.iter().any(|e| e.name == "backlash"),
        "{}",
        summary(&a)
    );
}
