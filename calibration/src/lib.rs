//! Calibration and evaluation of the 3-FbRR from recordings (`shared/spec/recording.md`), as in
//! the paper (`shared/spec/calibration.md`): the 13 tendon-map functions of Table I, the
//! two-step parameter calibration, ISO 9283 pose and path figures, the gear-backlash analysis,
//! and their reports. The crate reads recordings and robot configurations only: it knows
//! nothing of the simulated plant, so that it is never tested against its own assumptions.

pub mod data;
pub mod diagnosis;
pub mod joint;
pub mod lsq;
pub mod params;
pub mod step1;
pub mod step2;

pub use data::{DataError, SplitSource, StaticData, StaticPose};
pub mod backlash;
pub mod calibrate;
pub mod evaluate;
pub mod evaluation_report;
pub mod figures;
pub mod report;
pub mod segment;
pub mod stats;
