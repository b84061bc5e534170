//! The protocol-version handshake on the unversioned `pcr/protocol` service.

use crate::ports::ChainNode;
use anyhow::{Context, Result};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ipc;
use pcr_messages::{version_mismatch_message, NodeKind, ProtocolHello, PROTOCOL_SERVICE};
use std::cell::Cell;
use std::time::{Duration, Instant};

/// Announces this process's protocol version and checks everybody else's.
pub struct ProtocolGuard {
    publisher: Publisher<ipc::Service, ProtocolHello, ()>,
    subscriber: Subscriber<ipc::Service, ProtocolHello, ()>,
    me: ProtocolHello,
    supervisor_ok: Cell<bool>,
    pending: Cell<Option<ProtocolHello>>,
    handshake_done: Cell<bool>,
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
            supervisor_ok: Cell::new(false),
            pending: Cell::new(None),
            handshake_done: Cell::new(false),
        })
    }

    /// Announces this process (call every heartbeat).
    pub fn announce(&self) {
        let _ = crate::ports::publish(&self.publisher, self.me);
    }

    /// Drains the announcements heard so far. The supervisor's version is the reference: a
    /// supervisor of another version is an error at once; a peer process of another version is
    /// an error only if no supervisor of this version has been heard (a stray binary of another
    /// revision must not make the established chain refuse to run).
    pub fn check(&self) -> Result<(), Mismatch> {
        let mut peer_bad = None;
        while let Ok(Some(s)) = self.subscriber.receive() {
            let h = *s.payload();
            let is_sup = h.kind == NodeKind::Supervisor as u32;
            if h.version == self.me.version {
                if is_sup {
                    self.supervisor_ok.set(true);
                }
                continue;
            }
            if is_sup {
                return Err(self.mismatch(h));
            }
            peer_bad.get_or_insert(h);
        }
        if let Some(h) = peer_bad {
            self.pending.set(Some(h));
        }
        // Sticky during the handshake; reported once per peer announcement afterwards.
        let pending = if self.handshake_done.get() {
            self.pending.take()
        } else {
            self.pending.get()
        };
        match pending {
            Some(h) if !self.supervisor_ok.get() => Err(self.mismatch(h)),
            _ => Ok(()),
        }
    }

    fn mismatch(&self, peer: ProtocolHello) -> Mismatch {
        let who = format!(
            "the running {} (pid {})",
            NodeKind::from_u32(peer.kind).map_or("process", |k| k.name()),
            peer.pid
        );
        Mismatch {
            peer,
            message: version_mismatch_message(self.me.version, peer.version, &who),
        }
    }

    /// The start-up handshake: announces, then listens for `window` (peers announce every
    /// heartbeat); fails if the supervisor speaks another version, or if a peer does and no
    /// supervisor of this version was heard in the window.
    pub fn handshake(&self, window: Duration) -> Result<(), Mismatch> {
        let end = Instant::now() + window;
        loop {
            self.announce();
            let r = self.check();
            if let Err(m) = &r {
                if m.peer.kind == NodeKind::Supervisor as u32 {
                    return r;
                }
            }
            if Instant::now() >= end {
                self.handshake_done.set(true);
                self.pending.set(None);
                return r;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}
