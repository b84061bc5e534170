//! `pcr.residuals`: the residual analysis of `pcr residuals` with its options (calibration
//! first, held-out blocks or holdout recordings, the candidate library); the result is the
//! library's (its JSON is the CLI's `--json`, its robot file the CLI's `--out`).

use crate::errors::{err, invalid};
use crate::recording::PyRecording;
use crate::robot::PyRobot;
use pcr_offline::clock::utc_now;
use pcr_offline::residuals_run;
use pcr_residuals::{attribute, Attribution, Options};
use pcr_robot::RobotConfig;
use pyo3::prelude::*;
use std::path::PathBuf;

/// A residual analysis's result (native part of `pcr.Residuals`).
#[pyclass(name = "Residuals", module = "pcr._pcr", frozen)]
pub struct PyResiduals {
    res: Attribution,
    calibration: Option<String>,
    messages: Vec<String>,
}

/// Analyses what the calibrated model lacks, as `pcr residuals` does (the GIL is released):
/// calibrates `robot` (default: the built-in nominal robot) on the static poses of the first
/// `data` recording that has some (not with `no_calibrate`), holds out every third block of
/// about `block_s` (or the `holdout` recordings whole), attributes the residual to the
/// candidate effects, and with `report` writes the report folder (`residuals_before.csv`,
/// report.md, figures).
#[pyfunction]
#[pyo3(signature = (data, holdout = Vec::new(), robot = None, no_calibrate = false, exact = false, block_s = 4.0, alpha = 1e-2, min_effect_mm = 0.01, candidates = None, report = None))]
#[allow(clippy::too_many_arguments)]
pub fn residuals(
    py: Python<'_>,
    data: Vec<PyRef<'_, PyRecording>>,
    holdout: Vec<PyRef<'_, PyRecording>>,
    robot: Option<PyRef<'_, PyRobot>>,
    no_calibrate: bool,
    exact: bool,
    block_s: f64,
    alpha: f64,
    min_effect_mm: f64,
    candidates: Option<Vec<String>>,
    report: Option<PathBuf>,
) -> PyResult<PyResiduals> {
    if data.is_empty() {
        return Err(invalid("data: at least one recording is needed"));
    }
    let candidates = candidates.unwrap_or_default();
    residuals_run::check_options(block_s, alpha, &candidates).map_err(err)?;
    let start: RobotConfig = robot.map_or_else(RobotConfig::nominal, |r| r.config().clone());
    let named = |v: &[PyRef<'_, PyRecording>]| -> Vec<residuals_run::Named> {
        v.iter()
            .map(|r| (r.rec.clone(), r.origin.clone()))
            .collect()
    };
    let (data_n, holdout_n) = (named(&data), named(&holdout));
    let inputs = data_n
        .iter()
        .map(|(_, o)| format!("`{o}`"))
        .chain(holdout_n.iter().map(|(_, o)| format!("`{o}` (holdout)")))
        .collect::<Vec<_>>()
        .join(", ");
    let opts = Options {
        alpha,
        min_effect_mm,
        candidates: if candidates.is_empty() {
            Options::default().candidates
        } else {
            candidates
        },
        exact,
        ..Options::default()
    };
    let (res, calibration, messages) = py
        .detach(|| -> Result<_, pcr_offline::OfflineError> {
            let said = std::sync::Mutex::new(Vec::new());
            let prepared = residuals_run::prepare(
                &start,
                &data_n,
                &holdout_n,
                no_calibrate,
                block_s,
                &|line| said.lock().expect("not poisoned").push(line.to_string()),
            )?;
            if let Some(dir) = &report {
                std::fs::create_dir_all(dir).map_err(|e| {
                    pcr_offline::OfflineError::invalid(format!(
                        "cannot create {}: {e}",
                        dir.display()
                    ))
                })?;
                let p = dir.join("residuals_before.csv");
                let f = std::fs::File::create(&p).map_err(|e| {
                    pcr_offline::OfflineError::invalid(format!("cannot write {}: {e}", p.display()))
                })?;
                let mut w = std::io::BufWriter::new(f);
                pcr_residuals::attribution::residual_table(
                    &prepared.robot,
                    &prepared.series,
                    &prepared.blocks,
                    &mut w,
                )?;
            }
            let opts = Options {
                recalibration: prepared.recalibration.clone(),
                ..opts.clone()
            };
            let res = attribute(
                &prepared.robot,
                &start,
                &prepared.series,
                &prepared.blocks,
                &opts,
            )?;
            if let Some(dir) = &report {
                pcr_residuals::report::write_report(dir, &res, &inputs)?;
            }
            let cal = match &prepared.calibration {
                Some((_, c)) => Some(
                    serde_json::to_string_pretty(c)
                        .map_err(|e| pcr_offline::OfflineError::invalid(e.to_string()))?,
                ),
                None => None,
            };
            Ok((res, cal, said.into_inner().expect("not poisoned")))
        })
        .map_err(err)?;
    Ok(PyResiduals {
        res,
        calibration,
        messages,
    })
}

#[pymethods]
impl PyResiduals {
    /// Everything as the JSON of `pcr residuals --json`.
    fn json(&self) -> PyResult<String> {
        serde_json::to_string_pretty(&self.res).map_err(|e| invalid(e.to_string()))
    }

    /// The calibration done first, as the JSON of `pcr calibrate --json` (None with
    /// `no_calibrate` or without static poses).
    fn calibration_json(&self) -> Option<String> {
        self.calibration.clone()
    }

    /// What the set-up said (the calibration's summary line).
    #[getter]
    fn messages(&self) -> Vec<String> {
        self.messages.clone()
    }

    /// The extended robot file (`pcr residuals --out`), stamped `created` (default: now).
    #[pyo3(signature = (created = None))]
    fn to_toml(&self, created: Option<String>) -> String {
        residuals_run::extended_file(&self.res, &created.unwrap_or_else(utc_now))
    }

    /// The extended robot.
    #[getter]
    fn robot(&self) -> PyResult<PyRobot> {
        PyRobot::of_config(&self.res.robot, "extended by the residual analysis".into())
    }
}
