//! The protocol-version handshake on the unversioned `pcr/protocol` service.

use crate::ports::ChainNode;
use anyhow::{Context, Result};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ipc;
use pcr_messages::{version_mismatch_message, NodeKind, ProtocolHello, PROTOCOL_SERVICE};
use std::time::{Duration, Instant};

/// Announces this process's protocol version and checks everybody else's.
pub struct ProtocolGuard {
    publisher: Publisher<ipc::Service, ProtocolHello, ()>,
    subscriber: Subscriber<ipc::Service, ProtocolHello, ()>,
    me: ProtocolHello,
}

impl std::fmt::Debug for ProtocolGuard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ProtocolGuard({:?})", self.me)
    }
}

/// A peer that speaks another version.
#[derive(Debug, Clone)]
pub struct Mismatch {
    /// The peer's announcement.
    pub peer: ProtocolHello,
    /// The error text.
    pub message: String,
}

impl ProtocolGuard {
    /// Opens the handshake service for a process of `kind`.
    pub fn new(node: &ChainNode, kind: NodeKind) -> Result<Self> {
        let (publisher, subscriber) = node
            .unversioned::<ProtocolHello>(PROTOCOL_SERVICE)
            .context("protocol handshake service")?;
        Ok(Self {
            publisher,
            subscriber,
            me: ProtocolHello {
                version: node.version,
                kind: kind as u32,
                pid: std::process::id(),
                reserved: 0,
            },
        })
    }

    /// Announces this process (call every heartbeat).
    pub fn announce(&self) {
        let _ = self.publisher.send_copy(self.me);
    }

    /// Drains the announcements heard so far; the first one of another version is an error.
    pub fn check(&self) -> Result<(), Mismatch> {
        let mut bad = None;
        while let Ok(Some(s)) = self.subscriber.receive() {
            let h = *s.payload();
            if h.version != self.me.version && bad.is_none() {
                bad = Some(h);
            }
        }
        match bad {
            None => Ok(()),
            Some(peer) => {
                let who = format!(
                    "the running {} (pid {})",
                    NodeKind::from_u32(peer.kind).map_or("process", |k| k.name()),
                    peer.pid
                );
                Err(Mismatch {
                    peer,
                    message: version_mismatch_message(self.me.version, peer.version, &who),
                })
            }
        }
    }

    /// The start-up handshake: announces, then listens for `window` for peers of another
    /// version (peers announce every heartbeat).
    pub fn handshake(&self, window: Duration) -> Result<(), Mismatch> {
        let end = Instant::now() + window;
        loop {
            self.announce();
            self.check()?;
            if Instant::now() >= end {
                return Ok(());
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}
