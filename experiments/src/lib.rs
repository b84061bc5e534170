//! The paper's experiments on the 3-FbRR: their designs, the row annotator that labels a
//! recording of them (in-process or live), and the in-process runner.
//!
//! - [`CalibrationSet`]: 21 points evenly spaced by arc length along each orientation's
//!   workspace boundary scaled by 0.75, 0.5 and 0.2, for phi = 0, +10, -10 deg (189 poses),
//!   with a seeded stratified train/test split (126 / 63), every pose checked for IK and
//!   singularity margin ([`calibration`], [`boundary`], [`split`]);
//! - [`Design`]: the calibration and repeatability visits ([`StaticDesign`]: from the origin,
//!   rest-to-rest line, settle and measurement dwell, back), the paper's circle and square
//!   ([`PathsDesign`]), the backlash blocks ([`BacklashDesign`]);
//! - [`Annotator`]: labels each row (`pose_id`, `rep`, `settled`, `set`, and the extra columns
//!   [`EXTRA_COLUMNS`]) from the row's own time, planned pose and commanded steps;
//! - with the `chain` feature (default): [`program_of`] turns a design into chain commands
//!   (at most 32 moves each) and [`run_in_process`] runs them on `pcr_control::SimChain`
//!   against the simulated plant, writing the recording.
//!
//! Without the `chain` feature the crate does not depend on the plant or the chain, so tools
//! that only read recordings can share the designs and the annotation rules. Units: mm,
//! degrees in files and options, radians in [`pcr_kinematics::Pose`], seconds, motor steps.
//! The protocols and every decision the paper leaves open: docs/experiments.md.

pub mod annotate;
pub mod boundary;
pub mod calibration;
pub mod design;
pub mod error;
pub mod figure;
#[cfg(feature = "chain")]
pub mod program;
#[cfg(feature = "chain")]
pub mod runner;
pub mod split;

pub use annotate::{Annotator, Label, Tolerances, EXTRA_COLUMNS};
pub use boundary::{workspace_boundary, Boundary, BoundaryCheck, BoundaryOptions};
pub use calibration::{check_pose, CalibrationOptions, CalibrationPose, CalibrationSet};
pub use design::{
    BacklashBlock, BacklashDesign, BacklashOptions, Design, ExperimentKind, PathShape, PathsDesign,
    StaticDesign, Visit, VisitTiming,
};
pub use error::{DesignError, InfeasiblePose};
pub use figure::{calibration_set_svg, FigureError};
#[cfg(feature = "chain")]
pub use program::{program_of, Program, ProgramCommand, ProgramError, LEAD_IN_S};
#[cfg(feature = "chain")]
pub use runner::{row_of_state, run_in_process, RunSetup, RunSummary, RunnerError};

/// Every column an experiment recording has: the format's 20 known columns, then
/// [`EXTRA_COLUMNS`].
pub fn columns() -> Vec<&'static str> {
    pcr_recording::KNOWN_COLUMNS
        .iter()
        .chain(EXTRA_COLUMNS.iter())
        .copied()
        .collect()
}
