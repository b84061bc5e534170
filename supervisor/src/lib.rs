//! Supervisor of the process chain: starts the processes named in a configuration, watches them
//! (exit, heartbeat timeout), restarts them with backoff, escalates to a safe stop after repeated
//! failures, runs programs, records runs and reports path accuracy and deadline misses.

pub mod config;
pub mod ctl;
pub mod experiment;
pub mod figure;
pub mod supervisor;

pub use config::{ConfigError, SupervisorConfig};
