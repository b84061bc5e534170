//! The stepper driver: one interface, several backends.
//!
//! [`Driver`] is the ros2_control-style hardware interface that the control chain calls every
//! cycle: `write` the new motor setpoint, `read` what the drive reports. The serial backend
//! (Arduino firmware) and the simulated plant (`pcr-plant`) both implement it, and safety limits
//! wrap any implementation.

pub mod interface;

pub use interface::{Driver, DriverError, DriverState, MotorCommand};
