//! Jerk-limited trajectory profiler, paths and interpolator (work in progress).
