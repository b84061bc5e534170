//! Errors of the firmware-in-the-loop backend and of the backend selector.

use pcr_driver::DriverError;
use pcr_plant::{PlantConfigError, PlantError};

/// Why a backend could not be built or started.
#[derive(Debug, thiserror::Error)]
pub enum FilError {
    /// The firmware or the simavr harness could not be built (tools missing: the message
    /// names `scripts/setup.sh`).
    #[error("firmware build: {0}")]
    Build(String),
    /// The emulator could not be started.
    #[error("emulator: {0}")]
    Emulator(String),
    /// The serial link to the (emulated) firmware failed.
    #[error(transparent)]
    Driver(#[from] DriverError),
    /// The plant could not be built.
    #[error("plant: {0}")]
    Plant(#[from] PlantError),
    /// A plant configuration file could not be read.
    #[error(transparent)]
    PlantConfig(#[from] PlantConfigError),
    /// The backend selection (supervisor configuration) is malformed.
    #[error("driver backend configuration {origin}: {message}")]
    Config {
        /// File or text the configuration came from.
        origin: String,
        /// What is wrong.
        message: String,
    },
}
