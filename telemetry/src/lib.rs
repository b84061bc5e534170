//! Telemetry of the chain: what a run shows, on channels with Foxglove schemas where one fits and
//! JSON schemas otherwise, written to an MCAP file beside the run's CSV and served live over the
//! Foxglove WebSocket protocol (both through the Foxglove SDK, `foxglove`).
//!
//! - [`Telemetry`] holds the channels of one Foxglove context (see [`topics`] for what each
//!   carries and in which units) and turns the chain's messages and the recording's rows into
//!   messages on them, stamped with the chain's clock (CLOCK_MONOTONIC, ns);
//! - [`McapFile`] writes every message logged on a [`Telemetry`] to an MCAP file, flushing a
//!   chunk at least every [`McapFile::FLUSH_EVERY`] so that a killed writer leaves a file the
//!   MCAP readers recover up to that;
//! - [`LiveServer`] serves the same channels to Foxglove (or any client of the protocol); a slow
//!   client only loses messages (the SDK's per-client queue drops the oldest);
//! - [`convert`] turns any recording of the format (`shared/spec/recording.md`) into the same
//!   MCAP (`pcr convert`).
//!
//! Lengths on the Foxglove schemas (poses, scene, transforms) are in metres, as Foxglove expects;
//! the JSON channels keep the recording's units (mm, degrees, steps, s).

pub mod channels;
pub mod convert;
pub mod error;
pub mod live;
pub mod mcap_file;
pub mod row;
pub mod scene;
pub mod schemas;
pub mod topics;

pub use channels::{CycleStats, LogLevel, LogLines, RunEvent, RunEventKind, Telemetry};
pub use convert::{convert, ConvertSummary};
pub use error::TelemetryError;
pub use live::LiveServer;
pub use mcap_file::McapFile;
pub use row::RowSample;
pub use scene::RobotScene;
