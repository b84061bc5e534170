//! Robot configuration of the 3-FbRR planar parallel continuum robot.
//!
//! This crate is the one place where the robot's parameters live: geometry per leg
//! (`../shared/spec/geometry.md`), actuation, joint and bending limits, the working mode and the
//! robot-dependent tendon map (its coefficients; evaluation lives in `pcr-kinematics`).
//! Both the constant-curvature model (`pcr-kinematics`) and the physical truth model
//! (`pcr-plant`) read it, and share nothing else.
//!
//! Units follow geometry.md: millimetres and degrees in files, millimetres and radians in code.

pub mod config;
pub mod effects;
pub mod geometry;
pub mod tendon_map;

pub use config::{Actuation, ConfigError, LegConfig, Limits, RobotConfig, WorkingMode};
pub use effects::Effects;
pub use geometry::{rot, Vec2};
pub use tendon_map::{MapForm, MapReading, TendonMapKind, TendonMapSpec};
