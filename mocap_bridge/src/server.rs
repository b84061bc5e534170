//! A QTM RT server for simulation and tests: the subset of the protocol the bridge and the
//! official SDK use (welcome, `Version`, `QTMVersion`, `ByteOrder`, `GetState`,
//! `GetParameters`, `GetCurrentFrame`, `StreamFrames` with `AllFrames`, `Frequency:n`,
//! `FrequencyDivisor:n` and the components 6DEuler, 6DEulerRes, 3D, 3DRes, `TakeControl`,
//! `ReleaseControl`), up to ten clients, each in its own negotiated version.
//!
//! The host pushes frames ([`QtmServer::push`]); the server sends each streaming client the
//! components it asked for. It knows nothing of where the frames come from.
//! [`QtmServer::simulate_restart`] closes every connection and the listening socket for a
//! while, as a restarting QTM would (connections are refused meanwhile).

use crate::frame::{put_frame, Components, Frame};
use crate::params::Parameters;
use crate::parser::{Packet, PacketParser};
use crate::wire::{
    event, event_packet, no_more_data_packet, string_packet, PacketType, Version, WELCOME,
};
use std::io::{ErrorKind, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// Server settings.
#[derive(Debug, Clone, PartialEq)]
pub struct ServerConfig {
    /// Address to listen on (`127.0.0.1:22223`; port 0 picks a free one).
    pub bind: String,
    /// The newest protocol version accepted.
    pub newest: Version,
    /// The oldest protocol version accepted.
    pub oldest: Version,
    /// What `GetParameters` declares (frequency, labels, bodies).
    pub parameters: Parameters,
    /// Simultaneous clients (QTM: 10).
    pub max_clients: usize,
}

impl ServerConfig {
    /// Versions 1.1 to 1.25, ten clients.
    pub fn new(bind: &str, parameters: Parameters) -> Self {
        Self {
            bind: bind.into(),
            newest: Version::NEWEST,
            oldest: Version::new(1, 1),
            parameters,
            max_clients: 10,
        }
    }
}

#[derive(Debug, Default)]
struct StreamSpec {
    components: Components,
    divisor: u32,
    counter: u32,
}

#[derive(Debug)]
struct Conn {
    writer: Mutex<TcpStream>,
    version: Mutex<Version>,
    stream: Mutex<Option<StreamSpec>>,
    closed: AtomicBool,
}

#[derive(Debug)]
struct Inner {
    cfg: ServerConfig,
    clients: Mutex<Vec<Arc<Conn>>>,
    capturing: AtomicBool,
    latest: Mutex<Option<Frame>>,
    down_until: Mutex<Option<Instant>>,
    stop: AtomicBool,
    frames_sent: AtomicU64,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// The simulator's server.
#[derive(Debug)]
pub struct QtmServer {
    inner: Arc<Inner>,
    addr: SocketAddr,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl QtmServer {
    /// Binds and starts accepting (a thread per client). Capturing starts on (frames pushed
    /// are streamed); see [`QtmServer::set_capturing`].
    pub fn bind(cfg: ServerConfig) -> std::io::Result<QtmServer> {
        let listener = TcpListener::bind(&cfg.bind)?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let inner = Arc::new(Inner {
            cfg,
            clients: Mutex::new(Vec::new()),
            capturing: AtomicBool::new(true),
            latest: Mutex::new(None),
            down_until: Mutex::new(None),
            stop: AtomicBool::new(false),
            frames_sent: AtomicU64::new(0),
        });
        let i2 = inner.clone();
        let thread = std::thread::Builder::new()
            .name("qtm-accept".into())
            .spawn(move || accept_loop(i2, listener, addr))?;
        Ok(QtmServer {
            inner,
            addr,
            thread: Some(thread),
        })
    }

    /// The bound address.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Connected clients.
    pub fn clients(&self) -> usize {
        lock(&self.inner.clients).len()
    }

    /// Clients currently streaming.
    pub fn streaming_clients(&self) -> usize {
        lock(&self.inner.clients)
            .iter()
            .filter(|c| lock(&c.stream).is_some())
            .count()
    }

    /// Frames written to clients so far.
    pub fn frames_sent(&self) -> u64 {
        self.inner.frames_sent.load(Ordering::Relaxed)
    }

    /// Starts or stops the capture: events to every client, no-more-data to streaming ones
    /// when it stops.
    pub fn set_capturing(&self, on: bool) {
        if self.inner.capturing.swap(on, Ordering::SeqCst) == on {
            return;
        }
        let ev = event_packet(if on {
            event::CAPTURE_STARTED
        } else {
            event::CAPTURE_STOPPED
        });
        for c in lock(&self.inner.clients).iter() {
            write_to(c, &ev);
            if !on && lock(&c.stream).is_some() {
                write_to(c, &no_more_data_packet());
            }
        }
    }

    /// Sends an event to every client.
    pub fn send_event(&self, ev: u8) {
        let p = event_packet(ev);
        for c in lock(&self.inner.clients).iter() {
            write_to(c, &p);
        }
    }

    /// Streams one frame to every streaming client (with the components each asked for, at
    /// its rate). Writes are bounded by a short time-out; a client that cannot keep up is
    /// dropped.
    pub fn push(&self, frame: &Frame) {
        if !self.inner.capturing.load(Ordering::Relaxed) {
            return;
        }
        *lock(&self.inner.latest) = Some(frame.clone());
        let mut buf = Vec::with_capacity(512);
        let clients: Vec<Arc<Conn>> = lock(&self.inner.clients).clone();
        for c in clients {
            let comps = {
                let mut s = lock(&c.stream);
                match s.as_mut() {
                    Some(spec) => {
                        spec.counter = spec.counter.wrapping_add(1);
                        (spec.counter % spec.divisor.max(1) == 0).then_some(spec.components)
                    }
                    None => None,
                }
            };
            if let Some(comps) = comps {
                buf.clear();
                put_frame(&mut buf, frame, comps);
                write_to(&c, &buf);
                self.inner.frames_sent.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Closes every connection and stops listening for `downtime` (connections are refused),
    /// then listens again: a QTM restart.
    pub fn simulate_restart(&self, downtime: Duration) {
        *lock(&self.inner.down_until) = Some(Instant::now() + downtime);
        close_all(&self.inner);
    }
}

impl Drop for QtmServer {
    fn drop(&mut self) {
        self.inner.stop.store(true, Ordering::SeqCst);
        close_all(&self.inner);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn close_all(inner: &Inner) {
    let clients: Vec<Arc<Conn>> = lock(&inner.clients).drain(..).collect();
    for c in clients {
        c.closed.store(true, Ordering::SeqCst);
        let _ = lock(&c.writer).shutdown(Shutdown::Both);
    }
}

fn write_to(c: &Conn, bytes: &[u8]) {
    if c.closed.load(Ordering::Relaxed) {
        return;
    }
    let mut w = lock(&c.writer);
    if w.write_all(bytes).is_err() {
        c.closed.store(true, Ordering::SeqCst);
        let _ = w.shutdown(Shutdown::Both);
    }
}

fn accept_loop(inner: Arc<Inner>, listener: TcpListener, addr: SocketAddr) {
    let mut listener = Some(listener);
    while !inner.stop.load(Ordering::Relaxed) {
        let down = *lock(&inner.down_until);
        match (down, &listener) {
            (Some(t), _) if Instant::now() < t => {
                listener = None;
                std::thread::sleep(Duration::from_millis(10));
                continue;
            }
            (Some(_), None) | (None, None) => match TcpListener::bind(addr) {
                Ok(l) => {
                    let _ = l.set_nonblocking(true);
                    listener = Some(l);
                    *lock(&inner.down_until) = None;
                    tracing::info!(%addr, "QTM simulator listening again");
                }
                Err(_) => {
                    std::thread::sleep(Duration::from_millis(50));
                    continue;
                }
            },
            _ => {}
        }
        let Some(l) = &listener else { continue };
        match l.accept() {
            Ok((s, peer)) => {
                let _ = s.set_nonblocking(false);
                let _ = s.set_nodelay(true);
                let _ = s.set_write_timeout(Some(Duration::from_millis(200)));
                let full = {
                    let mut clients = lock(&inner.clients);
                    clients.retain(|c| !c.closed.load(Ordering::Relaxed));
                    clients.len() >= inner.cfg.max_clients
                };
                let mut s = s;
                if full {
                    let _ = s.write_all(&string_packet(
                        PacketType::Error,
                        "Connection refused. Max number of clients reached.",
                    ));
                    continue;
                }
                let Ok(reader) = s.try_clone() else { continue };
                let conn = Arc::new(Conn {
                    writer: Mutex::new(s),
                    version: Mutex::new(Version::new(1, 1)),
                    stream: Mutex::new(None),
                    closed: AtomicBool::new(false),
                });
                write_to(&conn, &string_packet(PacketType::Command, WELCOME));
                lock(&inner.clients).push(conn.clone());
                let i2 = inner.clone();
                let r = std::thread::Builder::new()
                    .name("qtm-client".into())
                    .spawn(move || client_loop(i2, conn, reader));
                if r.is_err() {
                    tracing::warn!(%peer, "QTM simulator: cannot start a client thread");
                }
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(10));
            }
            Err(_) => std::thread::sleep(Duration::from_millis(10)),
        }
    }
}

fn client_loop(inner: Arc<Inner>, conn: Arc<Conn>, mut reader: TcpStream) {
    let _ = reader.set_read_timeout(Some(Duration::from_millis(200)));
    let mut parser = PacketParser::new(64 * 1024);
    'outer: while !conn.closed.load(Ordering::Relaxed) && !inner.stop.load(Ordering::Relaxed) {
        let spare = parser.spare();
        match reader.read(spare) {
            Ok(0) => break,
            Ok(n) => parser.advance(n),
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => continue,
            Err(e) if e.kind() == ErrorKind::Interrupted => continue,
            Err(_) => break,
        }
        loop {
            let cmd = match parser.next_packet() {
                Ok(Some(Packet::Command(c))) => c.to_string(),
                Ok(Some(Packet::Xml(_))) => {
                    write_to(
                        &conn,
                        &string_packet(PacketType::Error, "Setting parameters failed"),
                    );
                    continue;
                }
                Ok(Some(_)) => {
                    write_to(
                        &conn,
                        &string_packet(PacketType::Error, "Command not supported."),
                    );
                    continue;
                }
                Ok(None) => break,
                Err(_) => break 'outer,
            };
            handle(&inner, &conn, &cmd);
        }
    }
    conn.closed.store(true, Ordering::SeqCst);
    let _ = lock(&conn.writer).shutdown(Shutdown::Both);
    lock(&inner.clients).retain(|c| !Arc::ptr_eq(c, &conn));
}

fn parse_components(args: &[&str]) -> Result<Components, String> {
    let mut c = Components::default();
    for a in args {
        match a.to_ascii_lowercase().as_str() {
            "6deuler" => c.euler = true,
            "6deulerres" => c.euler_res = true,
            "3d" => c.markers = true,
            "3dres" => c.markers_res = true,
            "all" => c = Components::BRIDGE,
            other => return Err(format!("Component {other} not supported by the simulator")),
        }
    }
    if c == Components::default() {
        return Err("Parse error".into());
    }
    Ok(c)
}

fn handle(inner: &Inner, conn: &Conn, cmd: &str) {
    let words: Vec<&str> = cmd.split_whitespace().collect();
    let reply = |s: &str| write_to(conn, &string_packet(PacketType::Command, s));
    let error = |s: &str| write_to(conn, &string_packet(PacketType::Error, s));
    let capturing = inner.capturing.load(Ordering::Relaxed);
    let Some(first) = words.first() else {
        return error("Parse error");
    };
    match first.to_ascii_lowercase().as_str() {
        "version" => match words.get(1) {
            None => reply(&format!("Version is {}", lock(&conn.version))),
            Some(v) => match Version::parse(v) {
                Some(v) if v >= inner.cfg.oldest && v <= inner.cfg.newest => {
                    *lock(&conn.version) = v;
                    reply(&format!("Version set to {v}"));
                }
                _ => error("Version NOT supported"),
            },
        },
        "qtmversion" => reply("QTM Version is pcr-mocap-bridge simulator"),
        "byteorder" => reply("Byte order is little endian"),
        "getstate" => write_to(
            conn,
            &event_packet(if capturing {
                event::CAPTURE_STARTED
            } else {
                event::CONNECTED
            }),
        ),
        "takecontrol" => reply("You are now master"),
        "releasecontrol" => reply("You are now a regular client"),
        "getparameters" => {
            let (mut g, mut d3, mut d6) = (false, false, false);
            for w in &words[1..] {
                match w.to_ascii_lowercase().as_str() {
                    "all" => (g, d3, d6) = (true, true, true),
                    "general" => g = true,
                    "3d" => d3 = true,
                    "6d" => d6 = true,
                    _ => {}
                }
            }
            if !(g || d3 || d6) {
                return error("Parse error");
            }
            let v = *lock(&conn.version);
            let x = inner.cfg.parameters.to_xml(v, g, d3, d6);
            write_to(conn, &string_packet(PacketType::Xml, &x));
        }
        "getcurrentframe" => match parse_components(&words[1..]) {
            Ok(c) => match (capturing, lock(&inner.latest).as_ref()) {
                (true, Some(f)) => {
                    let mut b = Vec::new();
                    put_frame(&mut b, f, c);
                    write_to(conn, &b);
                }
                _ => write_to(conn, &no_more_data_packet()),
            },
            Err(e) => error(&e),
        },
        "streamframes" => {
            let Some(rate) = words.get(1) else {
                return error("Parse error");
            };
            let rate = rate.to_ascii_lowercase();
            if rate == "stop" {
                *lock(&conn.stream) = None;
                return;
            }
            let hz = inner.cfg.parameters.frequency_hz.unwrap_or(100.0);
            let divisor = if rate == "allframes" {
                1
            } else if let Some(n) = rate.strip_prefix("frequency:") {
                match n.parse::<f64>() {
                    Ok(n) if n > 0.0 => (hz / n).round().max(1.0) as u32,
                    _ => return error("Parse error"),
                }
            } else if let Some(n) = rate.strip_prefix("frequencydivisor:") {
                match n.parse::<u32>() {
                    Ok(n) if n > 0 => n,
                    _ => return error("Parse error"),
                }
            } else {
                return error("Parse error");
            };
            match parse_components(&words[2..]) {
                Ok(components) => {
                    *lock(&conn.stream) = Some(StreamSpec {
                        components,
                        divisor,
                        counter: 0,
                    });
                    if !capturing {
                        write_to(conn, &no_more_data_packet());
                    }
                }
                Err(e) => error(&e),
            }
        }
        _ => error("Command not supported."),
    }
}
