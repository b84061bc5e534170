//! The stepper driver: one interface, several backends.
//!
//! [`Driver`] is the ros2_control-style hardware interface that the control chain calls every
//! cycle: `write` the new motor setpoint, `read` what the drive reports. The serial backend
//! ([`serial::SerialDriver`], Arduino firmware in `driver/firmware/`) and the simulated plant
//! (`pcr-plant`) both implement it, and safety limits ([`safety`]) wrap any implementation.
//!
//! * [`protocol`]: the wire protocol (COBS framing, CRC-16, messages), shared by the host, the
//!   tests and the bench; `driver/PROTOCOL.md` documents it and `firmware/protocol.h` mirrors it.
//! * [`sim`]: runs the real firmware in simavr (tests, bench).

pub mod interface;
pub mod protocol;
pub mod safety;
pub mod serial;
pub mod sim;

pub use interface::{Driver, DriverError, DriverState, MotorCommand};
pub use safety::{PositionLimit, RateLimit, Watchdog};
pub use serial::{HostCounters, SerialConfig, SerialDriver};
