//! `pcr.calibrate`: the paper's calibration of `pcr calibrate` (two steps refined jointly, or
//! the two steps alone), with its options; the result is the library's (its JSON is the
//! CLI's `--json`, its robot file the CLI's `--out`).

use crate::errors::{err, invalid};
use crate::recording::PyRecording;
use crate::robot::PyRobot;
use pcr_calibration::calibrate::{self as cal_lib, Calibration, Method, Options, ParameterSet};
use pcr_calibration::StaticData;
use pcr_offline::clock::utc_now;
use pcr_robot::{RobotConfig, TendonMapKind};
use pyo3::prelude::*;
use std::path::PathBuf;

/// A calibration's result (native part of `pcr.Calibration`).
#[pyclass(name = "Calibration", module = "pcr._pcr", frozen)]
pub struct PyCalibration {
    cal: Calibration,
    data: StaticData,
    start: RobotConfig,
}

/// The calibration options of the CLI's `--params`, `--method`, `--function`, `--phi-weight`
/// and `--seed`.
fn options(
    params: &str,
    method: &str,
    function: Option<u8>,
    phi_weight: Option<f64>,
    seed: u64,
) -> PyResult<Options> {
    let parameters = match params {
        "paper" => ParameterSet::Paper,
        "extended" => ParameterSet::Extended,
        other => {
            return Err(invalid(format!(
                "params = {other:?}: must be \"paper\" or \"extended\""
            )))
        }
    };
    let method = match method {
        "joint" => Method::Joint,
        "paper" => Method::Paper,
        other => {
            return Err(invalid(format!(
                "method = {other:?}: must be \"joint\" or \"paper\""
            )))
        }
    };
    let function =
        match function {
            None => None,
            Some(f) => Some(TendonMapKind::from_table_index(f as usize).ok_or_else(|| {
                invalid(format!("function = {f}: must be a Table I function 1..13"))
            })?),
        };
    if let Some(w) = phi_weight {
        if !(w.is_finite() && w >= 0.0) {
            return Err(invalid(format!(
                "phi_weight_mm_per_deg = {w}: must be a number of mm per degree >= 0"
            )));
        }
    }
    Ok(Options {
        parameters,
        method,
        function,
        phi_weight_mm_per_deg: phi_weight,
        seed,
        ..Options::default()
    })
}

/// Calibrates a robot from a recording with static poses, as `pcr calibrate` does (the GIL is
/// released). `robot`: the robot the recording was made with (default: the built-in nominal
/// robot); `report`: a folder for the Markdown report and its figures.
#[pyfunction]
#[pyo3(signature = (data, robot = None, params = "paper", method = "joint", function = None, phi_weight_mm_per_deg = None, seed = 1, report = None))]
#[allow(clippy::too_many_arguments)]
pub fn calibrate(
    py: Python<'_>,
    data: PyRef<'_, PyRecording>,
    robot: Option<PyRef<'_, PyRobot>>,
    params: &str,
    method: &str,
    function: Option<u8>,
    phi_weight_mm_per_deg: Option<f64>,
    seed: u64,
    report: Option<PathBuf>,
) -> PyResult<PyCalibration> {
    let opts = options(params, method, function, phi_weight_mm_per_deg, seed)?;
    let start = robot.map_or_else(RobotConfig::nominal, |r| r.config().clone());
    let (rec, origin) = (&data.rec, data.origin.as_str());
    let (cal, static_data) = py
        .detach(|| -> Result<_, pcr_offline::OfflineError> {
            let sd = StaticData::from_recording(rec, origin, opts.seed, opts.test_fraction)?;
            let cal = cal_lib::calibrate_data(&start, &sd, &opts)?;
            if let Some(dir) = &report {
                pcr_calibration::report::write_report(dir, &cal, &sd, &start)?;
            }
            Ok((cal, sd))
        })
        .map_err(err)?;
    Ok(PyCalibration {
        cal,
        data: static_data,
        start,
    })
}

#[pymethods]
impl PyCalibration {
    /// Everything as the JSON of `pcr calibrate --json`.
    fn json(&self) -> PyResult<String> {
        serde_json::to_string_pretty(&self.cal).map_err(|e| invalid(e.to_string()))
    }

    /// The calibrated robot file (`pcr calibrate --out`), stamped `created` (default: now).
    #[pyo3(signature = (created = None))]
    fn to_toml(&self, created: Option<String>) -> String {
        cal_lib::robot_file(&self.cal, &created.unwrap_or_else(utc_now))
    }

    /// The calibrated robot.
    #[getter]
    fn robot(&self) -> PyResult<PyRobot> {
        PyRobot::of_config(
            &self.cal.robot,
            format!("calibrated on {}", self.cal.data.file),
        )
    }

    /// The robot of the paper's two steps.
    #[getter]
    fn paper_robot(&self) -> PyResult<PyRobot> {
        PyRobot::of_config(
            &self.cal.paper_robot,
            format!("paper's two steps on {}", self.cal.data.file),
        )
    }

    /// Writes the Markdown report and its figures into `dir` (`pcr calibrate --report`);
    /// returns the report's path.
    fn write_report(&self, py: Python<'_>, dir: PathBuf) -> PyResult<PathBuf> {
        py.detach(|| {
            pcr_calibration::report::write_report(&dir, &self.cal, &self.data, &self.start)
        })
        .map_err(err)
    }
}
