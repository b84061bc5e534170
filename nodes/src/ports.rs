//! The iceoryx2 node of a process and its ports. Service settings live here only, so that every
//! process (and the supervisor) opens each service with the same settings.

use crate::hop_service::{HopService, MAX_EVENT_ID, SAMPLE};
use anyhow::{anyhow, Context, Result};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::SendError;
use iceoryx2::prelude::*;
use pcr_messages::service_name_for;
use std::fmt::Debug;

/// Maximum publishers, subscribers, listeners and notifiers per service (restarts leave dead
/// ports behind until they are cleaned up).
const MAX_PORTS: usize = 16;
/// Maximum nodes per service.
const MAX_NODES: usize = 32;
/// Samples a subscriber can buffer (the supervisor drains every 20 ms).
const BUFFER: usize = 64;

/// A publisher and a subscriber of one service.
pub type PubSub<T> = (
    Publisher<ipc::Service, T, ()>,
    Subscriber<ipc::Service, T, ()>,
);

/// An iceoryx2 configuration whose files all start with `prefix`.
pub fn iox_config(prefix: &str) -> Result<Config> {
    let mut c = Config::default();
    c.global.prefix = FileName::new(prefix.as_bytes())
        .map_err(|e| anyhow!("invalid iceoryx2 prefix {prefix:?}: {e:?}"))?;
    Ok(c)
}

/// A process's iceoryx2 node, speaking one protocol version.
pub struct ChainNode {
    /// The node.
    pub node: Node<ipc::Service>,
    /// The protocol version of the service names.
    pub version: u32,
    /// The node of the hop events ([`HopService`]), made on first use.
    hop: std::cell::OnceCell<Node<HopService>>,
    name: NodeName,
    config: Config,
}

impl Debug for ChainNode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ChainNode(v{})", self.version)
    }
}

impl ChainNode {
    /// Creates the node `name` under `prefix`.
    pub fn new(name: &str, prefix: &str, version: u32) -> Result<Self> {
        let config = iox_config(prefix)?;
        let node_name: NodeName = name
            .try_into()
            .map_err(|e| anyhow!("invalid node name {name:?}: {e:?}"))?;
        let node = NodeBuilder::new()
            .name(&node_name)
            .config(&config)
            .create::<ipc::Service>()
            .map_err(|e| anyhow!("cannot create iceoryx2 node {name:?}: {e:?}"))?;
        Ok(Self {
            node,
            version,
            hop: std::cell::OnceCell::new(),
            name: node_name,
            config,
        })
    }

    /// The node of the hop events: a second node of the same name and configuration, made on
    /// first use (only the IK, the driver and the planner need it).
    fn hop_node(&self) -> Result<&Node<HopService>> {
        if let Some(n) = self.hop.get() {
            return Ok(n);
        }
        let n = NodeBuilder::new()
            .name(&self.name)
            .config(&self.config)
            .create::<HopService>()
            .map_err(|e| anyhow!("cannot create iceoryx2 hop node: {e:?}"))?;
        Ok(self.hop.get_or_init(|| n))
    }

    fn sname(&self, base: &str) -> Result<ServiceName> {
        let n = service_name_for(self.version, base);
        n.as_str()
            .try_into()
            .map_err(|e| anyhow!("invalid service name {n:?}: {e:?}"))
    }

    fn pubsub<T: Debug + ZeroCopySend + 'static>(
        &self,
        name: ServiceName,
    ) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>>
    {
        self.node
            .service_builder(&name)
            .publish_subscribe::<T>()
            .max_publishers(MAX_PORTS)
            .max_subscribers(MAX_PORTS)
            .max_nodes(MAX_NODES)
            .subscriber_max_buffer_size(BUFFER)
            .history_size(0)
            .open_or_create()
            .map_err(|e| anyhow!("cannot open service {name:?}: {e:?}"))
    }

    /// A publisher on the versioned service `base`.
    pub fn publisher<T: Debug + ZeroCopySend + 'static>(
        &self,
        base: &str,
    ) -> Result<Publisher<ipc::Service, T, ()>> {
        self.pubsub::<T>(self.sname(base)?)?
            .publisher_builder()
            .create()
            .map_err(|e| anyhow!("cannot create publisher on {base}: {e:?}"))
    }

    /// A subscriber on the versioned service `base`.
    pub fn subscriber<T: Debug + ZeroCopySend + 'static>(
        &self,
        base: &str,
    ) -> Result<Subscriber<ipc::Service, T, ()>> {
        self.pubsub::<T>(self.sname(base)?)?
            .subscriber_builder()
            .create()
            .map_err(|e| anyhow!("cannot create subscriber on {base}: {e:?}"))
    }

    /// A publisher and a subscriber on the unversioned service `name` (protocol handshake).
    pub fn unversioned<T: Debug + ZeroCopySend + 'static>(&self, name: &str) -> Result<PubSub<T>> {
        let sn: ServiceName = name
            .try_into()
            .map_err(|e| anyhow!("invalid service name {name:?}: {e:?}"))?;
        let f = self.pubsub::<T>(sn)?;
        let p = f
            .publisher_builder()
            .create()
            .map_err(|e| anyhow!("cannot create publisher on {name}: {e:?}"))?;
        let s = f
            .subscriber_builder()
            .create()
            .map_err(|e| anyhow!("cannot create subscriber on {name}: {e:?}"))?;
        Ok((p, s))
    }

    fn event(
        &self,
        base: &str,
    ) -> Result<iceoryx2::service::port_factory::event::PortFactory<ipc::Service>> {
        let name = self.sname(base)?;
        self.node
            .service_builder(&name)
            .event()
            .max_notifiers(MAX_PORTS)
            .max_listeners(MAX_PORTS)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(|e| anyhow!("cannot open event service {base}: {e:?}"))
    }

    /// A notifier on the versioned event service `base`.
    pub fn notifier(&self, base: &str) -> Result<Notifier<ipc::Service>> {
        self.event(base)?
            .notifier_builder()
            .create()
            .map_err(|e| anyhow!("cannot create notifier on {base}: {e:?}"))
    }

    /// A listener on the versioned event service `base`.
    pub fn listener(&self, base: &str) -> Result<Listener<ipc::Service>> {
        self.event(base)?
            .listener_builder()
            .create()
            .map_err(|e| anyhow!("cannot create listener on {base}: {e:?}"))
    }

    fn hop_event(
        &self,
        base: &str,
    ) -> Result<iceoryx2::service::port_factory::event::PortFactory<HopService>> {
        let name = self.sname(base)?;
        self.hop_node()?
            .service_builder(&name)
            .event()
            .max_notifiers(MAX_PORTS)
            .max_listeners(MAX_PORTS)
            .max_nodes(MAX_NODES)
            .event_id_max_value(MAX_EVENT_ID)
            .open_or_create()
            .map_err(|e| anyhow!("cannot open hop event service {base}: {e:?}"))
    }

    /// A notifier on the hop event service `base` (the chain's hot path: see [`crate::hop`]).
    pub fn hop_notifier(&self, base: &str) -> Result<Notifier<HopService>> {
        self.hop_event(base)?
            .notifier_builder()
            .default_event_id(SAMPLE)
            .create()
            .map_err(|e| anyhow!("cannot create notifier on {base}: {e:?}"))
    }

    /// A listener on the hop event service `base`, woken by [`crate::hop::wait`].
    pub fn hop_listener(&self, base: &str) -> Result<Listener<HopService>> {
        self.hop_event(base)?
            .listener_builder()
            .create()
            .map_err(|e| anyhow!("cannot create listener on {base}: {e:?}"))
    }
}

/// Publishes `value` without a copy through an intermediate buffer: loans a sample in the
/// service's shared-memory data segment, writes the value into it in place and sends it (the
/// subscribers receive the offset of that very sample). The error is `Publisher::send_copy`'s,
/// so call sites keep their error handling.
#[inline]
pub fn publish<T: Debug + ZeroCopySend + 'static>(
    publisher: &Publisher<ipc::Service, T, ()>,
    value: T,
) -> Result<usize, SendError> {
    let sample = publisher.loan_uninit()?;
    sample.write_payload(value).send()
}

/// Drains a subscriber, keeping the newest sample (copied out).
pub fn latest<T: Debug + ZeroCopySend + Copy + 'static>(
    sub: &Subscriber<ipc::Service, T, ()>,
) -> Result<Option<T>> {
    let mut last = None;
    while let Some(s) = sub.receive().context("receive")? {
        last = Some(*s.payload());
    }
    Ok(last)
}

/// Removes the iceoryx2 files left under `prefix` once no node of the prefix is alive (the
/// global management segment is not removed by iceoryx2 itself). Returns how many were removed.
pub fn remove_leftovers(prefix: &str) -> usize {
    let Ok(cfg) = iox_config(prefix) else {
        return 0;
    };
    let mut alive = 0;
    let _ = Node::<ipc::Service>::list(&cfg, |s| {
        match s {
            NodeState::Alive(_) => alive += 1,
            NodeState::Dead(d) => {
                let _ = d.try_remove_stale_resources();
            }
            _ => {}
        }
        CallbackProgression::Continue
    });
    if alive > 0 {
        return 0;
    }
    let mut n = 0;
    for dir in ["/dev/shm", "/tmp/iceoryx2"] {
        let Ok(rd) = std::fs::read_dir(dir) else {
            continue;
        };
        for e in rd.flatten() {
            if e.file_name().to_string_lossy().starts_with(prefix) {
                let p = e.path();
                let ok = if p.is_dir() {
                    std::fs::remove_dir_all(&p).is_ok()
                } else {
                    std::fs::remove_file(&p).is_ok()
                };
                n += usize::from(ok);
            }
        }
    }
    n
}
