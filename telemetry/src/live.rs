//! [`LiveServer`]: the channels of a [`Telemetry`] served over the Foxglove WebSocket protocol.

use foxglove::{WebSocketServer, WebSocketServerHandle};

use crate::{Telemetry, TelemetryError};

/// A Foxglove WebSocket server on a telemetry's context. Every client has a queue of
/// [`LiveServer::BACKLOG`] messages in the SDK; when a client does not keep up, its oldest
/// messages are dropped, so logging never waits for a client.
pub struct LiveServer {
    handle: Option<WebSocketServerHandle>,
    host: String,
    port: u16,
}

impl std::fmt::Debug for LiveServer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveServer")
            .field("host", &self.host)
            .field("port", &self.port)
            .finish()
    }
}

impl LiveServer {
    /// Messages queued per client before the oldest are dropped (about 2 s of the chain's
    /// channels at 50 Hz).
    pub const BACKLOG: usize = 1024;

    /// Starts serving on `host:port` (port 0: any free port; see [`Self::port`]). The server
    /// runs on the SDK's own tokio threads.
    pub fn start(
        telemetry: &Telemetry,
        name: &str,
        host: &str,
        port: u16,
    ) -> Result<Self, TelemetryError> {
        let handle = WebSocketServer::new()
            .context(telemetry.context())
            .name(name)
            .bind(host, port)
            .message_backlog_size(Self::BACKLOG)
            .start_blocking()
            .map_err(|source| TelemetryError::Live {
                host: host.into(),
                port,
                source,
            })?;
        let port = handle.port();
        Ok(Self {
            handle: Some(handle),
            host: host.into(),
            port,
        })
    }

    /// The port the server listens on.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// The address to give Foxglove: `ws://host:port`.
    pub fn url(&self) -> String {
        format!("ws://{}:{}", self.host, self.port)
    }

    /// Clients connected now.
    pub fn clients(&self) -> usize {
        self.handle.as_ref().map_or(0, |h| h.client_count())
    }

    /// Stops the server (clients are disconnected).
    pub fn stop(mut self) {
        if let Some(h) = self.handle.take() {
            h.stop().detach_all();
        }
    }
}
