//! Planning for the 3-FbRR robot: the jerk-limited trajectory [`profiler`], task-space
//! [`path`]s with [`speed`] profiles along them, and the 20 ms [`interpolator`].

pub mod interpolator;
pub mod path;
pub mod profiler;
pub mod speed;
