//! Planning for the 3-FbRR robot: the jerk-limited trajectory [`profiler`], task-space
//! [`path`]s with [`speed`] profiles along them, [`composite`] paths (lines and arcs traversed
//! without stopping at smooth junctions), synchronised [`joint`]-space moves of the motors,
//! the 20 ms [`interpolator`], and the TOML [`program`] files of composite programs.

pub mod composite;
pub mod interpolator;
pub mod joint;
pub mod path;
pub mod profiler;
pub mod program;
pub mod speed;
