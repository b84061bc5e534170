//! `pcr-mocap-bridge`: the Qualisys real-time (QTM RT) protocol, as the lab's motion-capture
//! data source.
//!
//! * [`parser`]: the sans-IO packet parser (bytes in, split or coalesced anywhere, packets out;
//!   bounded memory, never panics on input);
//! * [`frame`], [`params`]: data frames (6DOF Euler bodies, labelled 3-D markers, with
//!   residuals) and the parameters XML;
//! * [`client`]: the TCP client (welcome, version negotiation 1.25 down to 1.19, parameters,
//!   streaming) and [`client::QtmSource`], which reconnects with back-off after a loss or a
//!   stall;
//! * [`server`]: a QTM RT server for simulation and tests, fed with frames by its host;
//! * [`registration`], [`sample`]: the capture-to-robot transform fitted to the base markers
//!   and frames mapped into the robot frame.
//!
//! Units: millimetres and degrees on the wire (QTM's), radians for the robot-frame
//! orientation, microseconds for QTM timestamps, nanoseconds of CLOCK_MONOTONIC for local
//! times. A value QTM did not measure (NaN on the wire) is `None`.
//!
//! The bridge knows nothing of the robot's simulation: whoever hosts a [`server::QtmServer`]
//! pushes [`frame::Frame`]s into it.

pub mod client;
pub mod clock;
pub mod frame;
pub mod params;
pub mod parser;
pub mod registration;
pub mod sample;
pub mod server;
pub mod wire;

pub use client::{ClientConfig, ClientError, QtmClient, QtmSource, SourceEvent, StreamRate};
pub use frame::{Body, Components, Frame, Marker};
pub use params::Parameters;
pub use registration::{MarkerLabels, Registration, RegistrationError};
pub use sample::{Mapper, RobotSample};
pub use server::{QtmServer, ServerConfig};
pub use wire::Version;
