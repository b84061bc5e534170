//! Closing the loop with measured data (`pcr residuals`): the calibrated model's residual on
//! every measured row of a recording, the features that can explain it, a library of candidate
//! effects, an attribution that fits on training blocks and scores on held-out ones, and the
//! extended robot file whose effects the running system compensates.
//!
//! Like the calibration, this crate reads recordings and robot files only: it knows nothing of
//! the simulated plant whose effects its tests try to find.

mod acceptance;
pub mod alignment;
pub mod attribution;
pub mod candidates;
pub mod context;
pub mod features;
pub mod linear;
pub mod model;
mod plausibility;
pub mod progress;
pub mod refine;
pub mod report;
pub mod scoring;
pub mod series;

pub use attribution::{attribute, Attribution, Options, Verdict};
pub use progress::{Progress, ProgressSink};
pub use series::{Blocks, Series};
