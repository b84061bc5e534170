//! Closing the loop with measured data (`pcr residuals`): the calibrated model's residual on
//! every measured row of a recording, the features that can explain it, a library of candidate
//! effects (one module each under [`effects`], behind [`effects::Effect`]), an attribution that
//! fits on training blocks and scores on held-out ones, and the extended robot file whose
//! effects the running system compensates.
//!
//! Like the calibration, this crate reads recordings and robot files only: it knows nothing of
//! the simulated plant whose effects its tests try to find.

mod acceptance;
pub mod alignment;
pub mod attribution;
pub mod backward;
pub mod consistency;
pub mod context;
pub mod effects;
pub mod extension;
pub mod features;
pub mod fitted;
pub mod interpolation;
pub mod linear;
pub mod model;
pub mod nuisance;
pub mod options;
mod plausibility;
pub mod progress;
pub mod recalibration;
pub mod refine;
pub mod report;
pub mod scoring;
pub mod series;

pub use attribution::{attribute, Attribution, Verdict};
pub use fitted::Estimate;
pub use options::Options;
pub use progress::{Progress, ProgressSink};
pub use series::{Blocks, Series};
