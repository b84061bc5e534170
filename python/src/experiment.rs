//! `pcr.experiment_calibration`: the paper's calibration set recorded on the in-process chain
//! against the simulated plant of a supervisor configuration, as `pcr experiment calibration`
//! records it (`pcr_offline::experiment_run` and `pcr_experiments::run_in_process`).

use crate::errors::err;
use crate::recording::PyRecording;
use pcr_experiments::{run_in_process, CalibrationOptions, Design, StaticDesign, VisitTiming};
use pcr_offline::experiment_run::{self, Sources};
use pcr_offline::OfflineError;
use pcr_recording::Recording;
use pyo3::prelude::*;
use std::path::PathBuf;

/// Records the calibration set on the simulated plant of the supervisor configuration
/// `config` (its robot and its driver's plant; `robot` replaces the model that drives,
/// `plant` the plant, `plant_seed` the plant's seed), as `pcr experiment calibration` does;
/// with `out` the recording is also written there. The GIL is released.
#[pyfunction]
#[pyo3(signature = (config, out = None, robot = None, plant = None, seed = 1, plant_seed = None, points = 21, scales = vec![0.75, 0.5, 0.2], phis_deg = vec![0.0, 10.0, -10.0], test_per_group = 7, singularity_margin = 2.0, speed_mm_s = 30.0, settle_s = 1.0, measure_s = 0.5))]
#[allow(clippy::too_many_arguments)]
pub fn experiment_calibration(
    py: Python<'_>,
    config: PathBuf,
    out: Option<PathBuf>,
    robot: Option<PathBuf>,
    plant: Option<PathBuf>,
    seed: u64,
    plant_seed: Option<u64>,
    points: usize,
    scales: Vec<f64>,
    phis_deg: Vec<f64>,
    test_per_group: usize,
    singularity_margin: f64,
    speed_mm_s: f64,
    settle_s: f64,
    measure_s: f64,
) -> PyResult<PyRecording> {
    let origin = out
        .as_ref()
        .map_or("<experiment calibration>".to_string(), |p| {
            p.display().to_string()
        });
    let rec = py
        .detach(|| -> Result<Recording, OfflineError> {
            if points == 0 {
                return Err(OfflineError::invalid("points must be >= 1"));
            }
            let src = Sources::from_files(&config, robot.as_deref(), plant.as_deref(), plant_seed)?;
            let options = CalibrationOptions {
                phis_deg,
                scales,
                points,
                test_per_group,
                seed,
                singularity_margin,
                ..CalibrationOptions::default()
            };
            let timing = VisitTiming {
                speed_mm_s,
                settle_s,
                measure_s,
            };
            let design = Design::Static(
                StaticDesign::calibration(&src.model_robot()?, &options, timing)
                    .map_err(|e| OfflineError::from(e).context("calibration design"))?,
            );
            let tool = concat!("pcr (Python) ", env!("CARGO_PKG_VERSION"));
            let setup = experiment_run::setup(&design, src, seed, tool)?;
            let mut buf = Vec::new();
            run_in_process(&design, &setup, &mut buf, &mut |_| {})
                .map_err(|e| OfflineError::from(e).context("calibration run"))?;
            if let Some(p) = &out {
                std::fs::write(p, &buf).map_err(|e| {
                    OfflineError::invalid(format!("{}: cannot write: {e}", p.display()))
                })?;
            }
            Ok(Recording::read(&buf[..], &origin)?)
        })
        .map_err(err)?;
    Ok(PyRecording { rec, origin })
}
