//! Planning for the 3-FbRR robot: the jerk-limited trajectory [`profiler`], task-space
//! [`path`]s with [`speed`] profiles along them, [`composite`] paths (lines and arcs traversed
//! without stopping at smooth junctions), synchronised [`joint`]-space moves of the motors,
//! and the TOML [`program`] files of composite programs. The 20 ms interpolator that turns
//! programs into setpoints (with pause, resume and stop) is `pcr_control::InterpolatorStep`
//! over `pcr_control::PlannerSource`, which plans with this crate; it is the only one.

pub mod composite;
pub mod joint;
pub mod path;
pub mod profiler;
pub mod program;
pub mod speed;
