//! Firmware-in-the-loop (FIL) simulation of the 3-FbRR drive chain.
//!
//! The whole stack runs as on the real robot down to the coil pins: the real serial backend
//! ([`pcr_driver::SerialDriver`]) talks over a pseudo-terminal to the real firmware running in
//! the simavr AVR emulator ([`pcr_driver::sim`]); the steps the firmware emits on its coil pins,
//! with their emulated times, drive the motors of the simulated plant ([`pcr_plant::Plant`]),
//! whose own stepper model (rate limit, missed steps) is bypassed while backlash, creep,
//! friction, the statics and the motion capture stay the plant's.
//!
//! - [`FirmwareInTheLoop`] (`firmware_in_the_loop.rs`): the FIL backend, a [`pcr_driver::Driver`].
//! - [`DriverBackend`], [`Backend`] (`backend.rs`): the selector a supervisor configuration
//!   uses (serial port, plant alone, or FIL) and what it builds.
//! - [`FilError`] (`error.rs`).
//!
//! Documentation: `docs/fil.md`.

pub mod backend;
pub mod error;
pub mod firmware_in_the_loop;

pub use backend::{Backend, DriverBackend};
pub use error::FilError;
pub use firmware_in_the_loop::{FilCounters, FilOptions, FirmwareInTheLoop};
