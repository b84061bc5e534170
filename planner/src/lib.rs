//! Jerk-limited trajectory profiler (see [`profiler`]); task-space paths and the 20 ms
//! interpolator are future work.

pub mod profiler;
