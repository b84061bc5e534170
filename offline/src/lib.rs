//! The offline tools' operations as library calls: options in, results out.
//!
//! The `pcr` binary (files and options) and the Python package `pcr` (arrays and keyword
//! arguments) both call these functions, so that the same inputs give the same results through
//! either: the IK and FK row of `pcr ik` / `pcr fk` ([`kinematics_rows`]), the chain's plan of
//! a shape, program file or joint move ([`plan_request`]), a setpoint series through the
//! simulated plant ([`plant_run`]), and the residual analysis's set-up: its checks, the
//! calibration first, the held-out blocks ([`residuals_run`]). Errors are typed
//! ([`OfflineError`]); their text is what the tools print.

pub mod clock;
pub mod error;
pub mod experiment_run;
pub mod kinematics_rows;
pub mod plan_request;
pub mod plant_run;
pub mod residuals_run;

pub use error::OfflineError;
