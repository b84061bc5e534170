//! The control steps of the chain as library types, and the in-process runtime.
//!
//! One implementation of each step, two runtimes (copper-rs style): the process binaries of
//! `pcr-nodes` wrap one step each with iceoryx2; [`InProcessChain`] wraps all of them on a
//! simulated clock for fast deterministic experiments and tests. Each `step` takes the cycle's
//! input and returns its output, is short and does not allocate.
//!
//! * [`InterpolatorStep`] around a [`SetpointSource`] ([`PlannerSource`]: the planner's
//!   jerk-limited paths; interim: [`InterimPathSource`]): the one 20 ms interpolator, with one
//!   pause/resume/stop behaviour, of the `pcr-planner` process, the in-process runtime and
//!   `pcr plan` ([`offline`]: the same step on a simulated clock, without IPC),
//! * [`IkStep`] (pcr-kinematics),
//! * [`DriverStep`] around any [`pcr_driver::Driver`] and a [`PoseSensor`] (interim plant:
//!   [`IdealDrive`] + [`FkPoseSensor`]; the simulated plant implements the same two traits),
//! * [`CorrectionStep`] (latency-compensated integral correction from the measured pose),
//! * [`Recorder`] (the recording format) and [`Accuracy`] (planned vs measured).

pub mod accuracy;
pub mod align;
pub mod capture_feed;
pub mod compensation;
pub mod correction;
pub mod drive;
pub mod driver_step;
pub mod ik;
pub mod interpolator;
pub mod offline;
pub mod planned;
pub mod plant_drive;
pub mod recorder;
pub mod runtime;
pub mod setpoint;

pub use accuracy::Accuracy;
pub use align::{AlignedSample, CaptureAligner};
pub use capture_feed::{sim_parameters, CaptureFeed};
pub use compensation::MotorCompensation;
pub use correction::{measured_of, CorrectionConfig, CorrectionConfigError, CorrectionStep};
pub use drive::{
    max_step_rate, safety_stack, FkPoseSensor, IdealDrive, NoPoseSensor, PoseSensor, SafeDriver,
};
pub use driver_step::{DriverStep, STALE_CYCLES};
pub use ik::IkStep;
pub use interpolator::{
    command_of_moves, moves_of, prepare_run, simple_command, CommandError, InterpolatorStep,
    PreparedRun,
};
pub use offline::{plan_moves, OfflinePlan, PlannedCycle, CYCLE_S};
pub use planned::{MotionLimits, PlannerSource};
pub use plant_drive::{plant_backend, PlantDrive, PlantSensor};
pub use recorder::{Measured, Recorder, RowMaker};
pub use runtime::{
    CycleOutput, IdealChain, InProcessChain, InterimChain, RunError, SimChain, SimChainError,
};
pub use setpoint::{
    circle_program, moves_of_program, paper_circle, paper_program, paper_square, square_program,
    Braking, InterimPathSource, Move, PlanError, SetpointSource,
};
