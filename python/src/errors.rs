//! Library errors as the exceptions of `pcr.errors` (defined in Python so that an invalid
//! argument is both a `pcr.PcrError` and a `ValueError`).

use pcr_offline::error::{ErrorKind, OfflineError};
use pyo3::prelude::*;
use pyo3::types::PyType;

/// The exception class name of an error kind.
fn class_name(kind: ErrorKind) -> &'static str {
    match kind {
        ErrorKind::Config => "ConfigError",
        ErrorKind::Recording => "RecordingError",
        ErrorKind::Calibration => "CalibrationError",
        ErrorKind::Residuals => "ResidualsError",
        ErrorKind::Planning => "PlanningError",
        ErrorKind::Kinematics => "KinematicsError",
        ErrorKind::Plant => "PlantError",
        ErrorKind::Invalid => "InvalidArgument",
    }
}

/// The Python exception of an offline error.
pub fn to_py(e: OfflineError) -> PyErr {
    Python::attach(|py| {
        let class = py
            .import("pcr.errors")
            .and_then(|m| m.getattr(class_name(e.kind)))
            .and_then(|c| c.cast_into::<PyType>().map_err(PyErr::from));
        match class {
            Ok(c) => PyErr::from_type(c, e.message),
            Err(import_error) => import_error,
        }
    })
}

/// Any library error as its Python exception.
pub fn err<E: Into<OfflineError>>(e: E) -> PyErr {
    to_py(e.into())
}

/// An invalid argument (`pcr.InvalidArgument`, a `ValueError`).
pub fn invalid(message: impl Into<String>) -> PyErr {
    to_py(OfflineError::invalid(message))
}
