//! The QTM RT client over TCP (blocking, one connection): welcome, version negotiation,
//! parameters, streaming; and [`QtmSource`], which keeps a stream alive: it detects a lost or
//! stalled connection by timeout and reconnects with exponential back-off.

use crate::clock::{monotonic_ns, ClockSync};
use crate::frame::{decode_frame, Components, Frame, FrameError};
use crate::params::{Parameters, ParamsError};
use crate::parser::{Packet, PacketParser, ProtocolError};
use crate::wire::{event, put_string, PacketType, Version, DEFAULT_PORT, MAX_PACKET, WELCOME};
use std::io::{ErrorKind, Read, Write};
use std::net::{TcpStream, ToSocketAddrs};
use std::time::{Duration, Instant};

/// How often the server sends frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StreamRate {
    /// Every frame QTM processes (`AllFrames`).
    AllFrames,
    /// About `n` frames per second (`Frequency:n`).
    Frequency(u32),
}

impl StreamRate {
    fn arg(&self) -> String {
        match self {
            StreamRate::AllFrames => "AllFrames".into(),
            StreamRate::Frequency(n) => format!("Frequency:{n}"),
        }
    }
}

/// Client settings.
#[derive(Debug, Clone, PartialEq)]
pub struct ClientConfig {
    /// Server host name or address.
    pub host: String,
    /// Server port (the little-endian port, 22223 by default).
    pub port: u16,
    /// TCP connect time-out.
    pub connect_timeout: Duration,
    /// Time-out of a command's reply.
    pub reply_timeout: Duration,
    /// No frame (nor no-more-data) for this long while streaming: the stream has stalled.
    pub stall_timeout: Duration,
    /// The version asked for first.
    pub newest: Version,
    /// The oldest version accepted when stepping down.
    pub oldest: Version,
    /// Stream rate.
    pub rate: StreamRate,
    /// Components streamed.
    pub components: Components,
    /// Largest packet accepted, bytes.
    pub max_packet: usize,
    /// First reconnection delay (doubles per failure).
    pub backoff_initial: Duration,
    /// Largest reconnection delay.
    pub backoff_max: Duration,
}

impl ClientConfig {
    /// Defaults for a server at `host:port`: versions 1.25 down to 1.19, all frames, 6DOF
    /// Euler and 3-D markers with residuals, 2 s connect and reply time-outs, 500 ms stall,
    /// back-off 100 ms doubling to 2 s.
    pub fn new(host: &str, port: u16) -> Self {
        Self {
            host: host.into(),
            port,
            connect_timeout: Duration::from_secs(2),
            reply_timeout: Duration::from_secs(2),
            stall_timeout: Duration::from_millis(500),
            newest: Version::NEWEST,
            oldest: Version::OLDEST,
            rate: StreamRate::AllFrames,
            components: Components::BRIDGE,
            max_packet: MAX_PACKET,
            backoff_initial: Duration::from_millis(100),
            backoff_max: Duration::from_secs(2),
        }
    }
}

impl Default for ClientConfig {
    fn default() -> Self {
        Self::new("127.0.0.1", DEFAULT_PORT)
    }
}

/// What went wrong with a connection.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The address does not resolve.
    #[error("cannot resolve {addr}: {source}")]
    Resolve {
        /// host:port.
        addr: String,
        /// Cause.
        source: std::io::Error,
    },
    /// The TCP connection cannot be made.
    #[error("cannot connect to {addr}: {source}")]
    Connect {
        /// host:port.
        addr: String,
        /// Cause.
        source: std::io::Error,
    },
    /// A socket read or write failed.
    #[error("{what}: {source}")]
    Io {
        /// What was being done.
        what: &'static str,
        /// Cause.
        source: std::io::Error,
    },
    /// The server closed the connection.
    #[error("the server closed the connection")]
    Closed,
    /// No reply in time.
    #[error("no reply to {waiting_for} within {ms} ms")]
    Timeout {
        /// The command or the welcome.
        waiting_for: String,
        /// The time-out, ms.
        ms: u128,
    },
    /// No frame in time while streaming.
    #[error("the stream stalled: no frame for {ms} ms")]
    Stalled {
        /// The time-out, ms.
        ms: u128,
    },
    /// The byte stream broke the protocol.
    #[error("protocol: {0}")]
    Protocol(#[from] ProtocolError),
    /// A malformed data frame.
    #[error("data frame: {0}")]
    Frame(#[from] FrameError),
    /// Unreadable parameters.
    #[error("{0}")]
    Params(#[from] ParamsError),
    /// The server answered with an error packet.
    #[error("the server refused {command:?}: {message}")]
    Refused {
        /// The command (or `connect`).
        command: String,
        /// The server's message.
        message: String,
    },
    /// The server's first packet was not the welcome.
    #[error("expected the welcome {WELCOME:?}, got {0:?}")]
    Welcome(String),
    /// No protocol version in range is accepted.
    #[error("the server accepts none of the protocol versions {newest} down to {oldest}")]
    NoVersion {
        /// Newest asked for.
        newest: Version,
        /// Oldest asked for.
        oldest: Version,
    },
    /// A reply that does not answer the command.
    #[error("unexpected reply to {command:?}: {reply:?}")]
    UnexpectedReply {
        /// The command.
        command: String,
        /// The reply.
        reply: String,
    },
}

/// What the stream delivered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Item {
    /// A frame (see [`QtmClient::frame`]).
    Frame,
    /// No measurement is running.
    NoMoreData,
    /// A QTM event.
    Event(u8),
}

enum Reply {
    Command(String),
    Xml(String),
    Error(String),
}

/// One connection to a QTM RT server.
#[derive(Debug)]
pub struct QtmClient {
    stream: TcpStream,
    parser: PacketParser,
    cfg: ClientConfig,
    version: Version,
    frame: Frame,
    rx_ns: u64,
    events: Vec<u8>,
    out: Vec<u8>,
}

impl QtmClient {
    /// Connects, reads the welcome and negotiates the protocol version: `Version` newest,
    /// then each older minor version down to the oldest accepted.
    pub fn connect(cfg: &ClientConfig) -> Result<QtmClient, ClientError> {
        let addr = format!("{}:{}", cfg.host, cfg.port);
        let sa = addr
            .to_socket_addrs()
            .map_err(|source| ClientError::Resolve {
                addr: addr.clone(),
                source,
            })?
            .next()
            .ok_or_else(|| ClientError::Resolve {
                addr: addr.clone(),
                source: std::io::Error::new(ErrorKind::NotFound, "no address"),
            })?;
        let stream = TcpStream::connect_timeout(&sa, cfg.connect_timeout)
            .map_err(|source| ClientError::Connect { addr, source })?;
        let _ = stream.set_nodelay(true);
        let mut c = QtmClient {
            stream,
            parser: PacketParser::new(cfg.max_packet),
            cfg: cfg.clone(),
            version: cfg.newest,
            frame: Frame::default(),
            rx_ns: 0,
            events: Vec::new(),
            out: Vec::with_capacity(256),
        };
        match c.wait_reply("the welcome")? {
            Reply::Command(s) if s.starts_with(WELCOME) => {}
            Reply::Error(message) => {
                return Err(ClientError::Refused {
                    command: "connect".into(),
                    message,
                })
            }
            Reply::Command(s) | Reply::Xml(s) => return Err(ClientError::Welcome(s)),
        }
        let mut v = cfg.newest;
        loop {
            let cmd = format!("Version {v}");
            c.send(&cmd)?;
            match c.wait_reply(&cmd)? {
                Reply::Command(s) if s.starts_with("Version set to") => {
                    c.version = v;
                    tracing::debug!(version = %v, "QTM RT protocol version negotiated");
                    return Ok(c);
                }
                Reply::Error(_) => match v.older() {
                    Some(o) if o >= cfg.oldest => v = o,
                    _ => {
                        return Err(ClientError::NoVersion {
                            newest: cfg.newest,
                            oldest: cfg.oldest,
                        })
                    }
                },
                Reply::Command(reply) | Reply::Xml(reply) => {
                    return Err(ClientError::UnexpectedReply {
                        command: cmd,
                        reply,
                    })
                }
            }
        }
    }

    /// The negotiated protocol version.
    pub fn version(&self) -> Version {
        self.version
    }

    /// Events received while waiting for replies (drained).
    pub fn take_events(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.events)
    }

    /// The newest frame (valid after [`Item::Frame`]).
    pub fn frame(&self) -> &Frame {
        &self.frame
    }

    /// CLOCK_MONOTONIC ns of the socket read that completed the newest packet.
    pub fn rx_ns(&self) -> u64 {
        self.rx_ns
    }

    /// Sends one command.
    pub fn send(&mut self, cmd: &str) -> Result<(), ClientError> {
        self.out.clear();
        put_string(&mut self.out, PacketType::Command, cmd);
        self.stream
            .write_all(&self.out)
            .map_err(|source| ClientError::Io {
                what: "sending a command",
                source,
            })
    }

    /// Reads what is available until `deadline`; `Ok(false)` on time-out.
    fn read_more(&mut self, deadline: Instant) -> Result<bool, ClientError> {
        let wait = deadline.saturating_duration_since(Instant::now());
        if wait.is_zero() {
            return Ok(false);
        }
        self.stream
            .set_read_timeout(Some(wait.max(Duration::from_micros(100))))
            .map_err(|source| ClientError::Io {
                what: "setting the read time-out",
                source,
            })?;
        let spare = self.parser.spare();
        if spare.is_empty() {
            // Cannot happen: the buffer holds a maximal packet plus a chunk and complete
            // packets are consumed before reading.
            return Err(ClientError::Protocol(ProtocolError::Poisoned));
        }
        match self.stream.read(spare) {
            Ok(0) => Err(ClientError::Closed),
            Ok(n) => {
                self.rx_ns = monotonic_ns();
                self.parser.advance(n);
                Ok(true)
            }
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => Ok(false),
            Err(e) if e.kind() == ErrorKind::Interrupted => Ok(true),
            Err(source) => Err(ClientError::Io {
                what: "reading from the server",
                source,
            }),
        }
    }

    /// Waits for the reply to a command (events are kept, stray frames skipped).
    fn wait_reply(&mut self, what: &str) -> Result<Reply, ClientError> {
        let deadline = Instant::now() + self.cfg.reply_timeout;
        loop {
            while let Some(p) = self.parser.next_packet()? {
                match p {
                    Packet::Command(s) => return Ok(Reply::Command(s.into())),
                    Packet::Xml(s) => return Ok(Reply::Xml(s.into())),
                    Packet::Error(s) => return Ok(Reply::Error(s.into())),
                    Packet::Event(e) => {
                        if self.events.len() < 64 {
                            self.events.push(e);
                        }
                    }
                    Packet::Data(_) | Packet::NoMoreData | Packet::Other(_) => {}
                }
            }
            if !self.read_more(deadline)? && Instant::now() >= deadline {
                return Err(ClientError::Timeout {
                    waiting_for: what.into(),
                    ms: self.cfg.reply_timeout.as_millis(),
                });
            }
        }
    }

    /// `GetParameters General 3D 6D`.
    pub fn parameters(&mut self) -> Result<Parameters, ClientError> {
        let cmd = "GetParameters General 3D 6D";
        self.send(cmd)?;
        match self.wait_reply(cmd)? {
            Reply::Xml(x) => Ok(Parameters::parse(&x)?),
            Reply::Error(message) => Err(ClientError::Refused {
                command: cmd.into(),
                message,
            }),
            Reply::Command(reply) => Err(ClientError::UnexpectedReply {
                command: cmd.into(),
                reply,
            }),
        }
    }

    /// `StreamFrames <rate> <components>` (the server does not reply on success: frames,
    /// or no-more-data, follow).
    pub fn start_streaming(&mut self) -> Result<(), ClientError> {
        let cmd = format!(
            "StreamFrames {} {}",
            self.cfg.rate.arg(),
            self.cfg.components.command_args()
        );
        self.send(&cmd)
    }

    /// `StreamFrames Stop`.
    pub fn stop_streaming(&mut self) -> Result<(), ClientError> {
        self.send("StreamFrames Stop")
    }

    /// The next frame, no-more-data or event; `Ok(None)` when `deadline` passes first.
    pub fn next(&mut self, deadline: Instant) -> Result<Option<Item>, ClientError> {
        loop {
            match self.parser.next_packet()? {
                Some(Packet::Data(d)) => {
                    decode_frame(d, &mut self.frame)?;
                    return Ok(Some(Item::Frame));
                }
                Some(Packet::NoMoreData) => return Ok(Some(Item::NoMoreData)),
                Some(Packet::Event(e)) => return Ok(Some(Item::Event(e))),
                Some(Packet::Error(s)) => {
                    return Err(ClientError::Refused {
                        command: "StreamFrames".into(),
                        message: s.into(),
                    })
                }
                Some(Packet::Command(s)) => {
                    tracing::debug!(reply = s, "QTM: unsolicited command reply")
                }
                Some(Packet::Xml(_) | Packet::Other(_)) => {}
                None => {
                    if !self.read_more(deadline)? && Instant::now() >= deadline {
                        return Ok(None);
                    }
                }
            }
        }
    }
}

/// What [`QtmSource::poll`] saw.
#[derive(Debug)]
pub enum SourceEvent {
    /// A frame: [`QtmSource::frame`], [`QtmSource::rx_ns`], [`QtmSource::frame_time_ns`].
    Frame,
    /// (Re)connected and streaming; [`QtmSource::parameters`] holds the server's parameters.
    Connected,
    /// The connection was lost or could not be made (a reconnection is scheduled).
    Lost(ClientError),
    /// The server has no measurement running.
    NoMoreData,
    /// A QTM event.
    Event(u8),
    /// Nothing before the poll's deadline.
    Idle,
}

/// Counters of a [`QtmSource`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SourceStats {
    /// Successful connections.
    pub connects: u64,
    /// Connections lost or refused.
    pub losses: u64,
    /// Frames received.
    pub frames: u64,
}

/// A stream that stays up: connects, negotiates, reads the parameters, streams, and on any
/// error, a close or a stall drops the connection and reconnects after a back-off delay
/// (doubling up to the maximum, reset by the first frame of a connection).
#[derive(Debug)]
pub struct QtmSource {
    cfg: ClientConfig,
    client: Option<QtmClient>,
    params: Option<Parameters>,
    backoff: Duration,
    next_attempt: Instant,
    last_data: Instant,
    got_frame: bool,
    clock: ClockSync,
    frame_time_ns: u64,
    /// Counters.
    pub stats: SourceStats,
}

impl QtmSource {
    /// A source that connects at the first poll.
    pub fn new(cfg: ClientConfig) -> Self {
        let now = Instant::now();
        Self {
            backoff: cfg.backoff_initial,
            cfg,
            client: None,
            params: None,
            next_attempt: now,
            last_data: now,
            got_frame: false,
            clock: ClockSync::new(),
            frame_time_ns: 0,
            stats: SourceStats::default(),
        }
    }

    /// The configuration.
    pub fn config(&self) -> &ClientConfig {
        &self.cfg
    }

    /// Connected and streaming.
    pub fn is_connected(&self) -> bool {
        self.client.is_some()
    }

    /// The parameters of the current (or last) connection.
    pub fn parameters(&self) -> Option<&Parameters> {
        self.params.as_ref()
    }

    /// The negotiated version of the current connection.
    pub fn version(&self) -> Option<Version> {
        self.client.as_ref().map(QtmClient::version)
    }

    /// The newest frame.
    pub fn frame(&self) -> Option<&Frame> {
        self.client.as_ref().map(QtmClient::frame)
    }

    /// CLOCK_MONOTONIC ns of the read that delivered the newest frame.
    pub fn rx_ns(&self) -> u64 {
        self.client.as_ref().map_or(0, QtmClient::rx_ns)
    }

    /// The newest frame's QTM timestamp on the local CLOCK_MONOTONIC, ns (see
    /// [`ClockSync`]): frames delivered together keep their own capture times.
    pub fn frame_time_ns(&self) -> u64 {
        self.frame_time_ns
    }

    fn drop_connection(&mut self, why: ClientError) -> SourceEvent {
        self.client = None;
        self.stats.losses += 1;
        self.next_attempt = Instant::now() + self.backoff;
        self.backoff = (self.backoff * 2).min(self.cfg.backoff_max);
        SourceEvent::Lost(why)
    }

    fn open(&mut self) -> Result<(), ClientError> {
        let mut c = QtmClient::connect(&self.cfg)?;
        let p = c.parameters()?;
        c.start_streaming()?;
        self.params = Some(p);
        self.client = Some(c);
        self.clock.reset();
        self.got_frame = false;
        self.last_data = Instant::now();
        self.stats.connects += 1;
        Ok(())
    }

    /// Waits until `until` at most for the next thing to report.
    pub fn poll(&mut self, until: Instant) -> SourceEvent {
        if self.client.is_none() {
            let now = Instant::now();
            if now < self.next_attempt {
                std::thread::sleep(self.next_attempt.min(until) - now);
                if Instant::now() < self.next_attempt {
                    return SourceEvent::Idle;
                }
            }
            return match self.open() {
                Ok(()) => SourceEvent::Connected,
                Err(e) => self.drop_connection(e),
            };
        }
        let stall_at = self.last_data + self.cfg.stall_timeout;
        let deadline = until.min(stall_at);
        let Some(c) = self.client.as_mut() else {
            return SourceEvent::Idle;
        };
        match c.next(deadline) {
            Ok(Some(Item::Frame)) => {
                self.last_data = Instant::now();
                self.stats.frames += 1;
                if !self.got_frame {
                    self.got_frame = true;
                    self.backoff = self.cfg.backoff_initial;
                }
                let ts = c.frame().timestamp_us;
                self.frame_time_ns = self.clock.update(ts, c.rx_ns());
                SourceEvent::Frame
            }
            Ok(Some(Item::NoMoreData)) => {
                self.last_data = Instant::now();
                SourceEvent::NoMoreData
            }
            Ok(Some(Item::Event(e))) => {
                if e == event::CAMERA_SETTINGS_CHANGED {
                    // The labels or bodies may have changed: read them again.
                    self.backoff = self.cfg.backoff_initial;
                    let _ = self.drop_connection(ClientError::Closed);
                    self.next_attempt = Instant::now();
                }
                SourceEvent::Event(e)
            }
            Ok(None) => {
                if Instant::now() >= stall_at {
                    let ms = self.cfg.stall_timeout.as_millis();
                    self.drop_connection(ClientError::Stalled { ms })
                } else {
                    SourceEvent::Idle
                }
            }
            Err(e) => self.drop_connection(e),
        }
    }
}
