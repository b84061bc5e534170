//! Constant-curvature kinematic model of the 3-FbRR planar parallel continuum robot.
//!
//! Conventions are those of `../shared/spec/geometry.md`: millimetres, radians inside the code,
//! curvatures in 1/mm, motor steps as signed numbers. The model has two layers:
//! - the robot-dependent model ([`tendon`]): tendon displacement to curvature, and
//! - the robot-independent model: leg forward kinematics ([`leg`]), loop closure, IK ([`ik`]),
//!   FK ([`fk`]), Jacobians and singularities ([`jacobian`]) and the workspace ([`workspace`]).

pub mod check;
pub mod fk;
pub mod friction;
pub mod ik;
mod inverse;
pub mod jacobian;
pub mod leg;
pub mod lu3;
pub mod model;
pub mod pose;
pub mod statics;
pub mod tendon;
pub mod workspace;

pub use check::{CheckOptions, MotionRejected, Violation};
pub use fk::FkError;
pub use ik::{IkError, IkSolution, LegRoot, LegRoots};
pub use jacobian::Conditioning;
pub use leg::Leg;
pub use model::{ModelError, Robot};
pub use pose::Pose;
pub use tendon::{TendonMap, TendonMapError};
