//! The native module `pcr._pcr` of the Python package `pcr`: thin bindings over the stack's
//! crates (no second implementation). Arrays in and out are numpy arrays; the Python layer
//! (`python/python/pcr/`) turns them into DataFrames and result objects. Errors are raised as
//! the exceptions of `pcr.errors` with the text the `pcr` tool prints; long calls release the
//! GIL.

use pyo3::prelude::*;

mod arrays;
mod calibration;
mod errors;
mod experiment;
mod planning;
mod plant;
mod recording;
mod residuals;
mod robot;

/// The native part of `pcr`.
#[pymodule]
fn _pcr(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("STATUSES", pcr_offline::kinematics_rows::STATUSES.to_vec())?;
    m.add_class::<robot::PyRobot>()?;
    m.add_class::<recording::PyRecording>()?;
    m.add_class::<calibration::PyCalibration>()?;
    m.add_class::<residuals::PyResiduals>()?;
    m.add_class::<plant::PyPlant>()?;
    m.add_function(wrap_pyfunction!(calibration::calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(residuals::residuals, m)?)?;
    m.add_function(wrap_pyfunction!(planning::plan, m)?)?;
    m.add_function(wrap_pyfunction!(planning::profile, m)?)?;
    m.add_function(wrap_pyfunction!(experiment::experiment_calibration, m)?)?;
    Ok(())
}
