//! Errors of the telemetry crate.

/// Why telemetry could not be written or served.
#[derive(Debug, thiserror::Error)]
pub enum TelemetryError {
    /// The MCAP file could not be created or written.
    #[error("MCAP file {path}: {source}")]
    Mcap {
        /// The file.
        path: String,
        /// The cause.
        source: foxglove::FoxgloveError,
    },
    /// A channel could not be created.
    #[error("channel {topic}: {source}")]
    Channel {
        /// The channel's topic.
        topic: String,
        /// The cause.
        source: foxglove::FoxgloveError,
    },
    /// The live server could not start.
    #[error("live server on {host}:{port}: {source}")]
    Live {
        /// The host it should listen on.
        host: String,
        /// The port it should listen on (0: any).
        port: u16,
        /// The cause.
        source: foxglove::FoxgloveError,
    },
    /// The recording to convert could not be read.
    #[error("{0}")]
    Recording(#[from] pcr_recording::RecordingError),
    /// The robot configuration could not be read or has no model.
    #[error("robot {path}: {message}")]
    Robot {
        /// The file.
        path: String,
        /// What is wrong.
        message: String,
    },
}
