//! The serial backend: talks to the Arduino firmware (`driver/firmware/`) over `serialport`.
//!
//! One control cycle is `write` (sends a SETPOINT frame) then `read` (waits for its STATE
//! acknowledgement, matched by sequence number). Every anomaly (undecodable bytes, stale
//! replies, firmware error replies, timeouts) is counted in [`HostCounters`] and logged through
//! `tracing`; none of them moves a motor: the firmware only moves on a valid, in-range, newer
//! setpoint.
//!
//! When the port fails (unplugged Uno, emulator gone) the call returns
//! [`DriverError::Transport`], the port is dropped and later calls fail fast until
//! [`SerialDriver::reconnect`] succeeds.

use std::collections::VecDeque;
use std::io::{ErrorKind, Read, Write};
use std::time::{Duration, Instant};

use crate::interface::{Driver, DriverError, DriverState, MotorCommand, N_MOTORS};
use crate::protocol::{
    encode_frame, flags, DecodeError, ErrorCode, Frame, FrameDecoder, FwConfig, HelloReply,
    Message, StateReport, StatusReport, PROTOCOL_VERSION,
};

/// How to reach and set up the firmware.
#[derive(Debug, Clone)]
pub struct SerialConfig {
    /// Port path (`/dev/ttyACM0`, a PTY, a symlink).
    pub path: String,
    /// Baud rate (the firmware uses 115200).
    pub baud: u32,
    /// How long to wait for the reply to one request.
    pub reply_timeout: Duration,
    /// How long to keep retrying the handshake (a real Uno reboots when the port opens and its
    /// bootloader waits about 1.5 s before the firmware starts).
    pub handshake_timeout: Duration,
    /// Configuration written to the firmware after the handshake (`None`: keep its own).
    pub firmware_config: Option<FwConfig>,
}

impl SerialConfig {
    /// Defaults for a port path: 115200 baud, 50 ms reply timeout, 3 s handshake, firmware
    /// defaults.
    pub fn new(path: impl Into<String>) -> Self {
        Self {
            path: path.into(),
            baud: 115_200,
            reply_timeout: Duration::from_millis(50),
            handshake_timeout: Duration::from_secs(3),
            firmware_config: None,
        }
    }
}

/// Host-side counters (monotonic, never reset except by [`SerialDriver::reset_counters`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct HostCounters {
    /// Frames written.
    pub frames_sent: u64,
    /// Valid frames received.
    pub frames_received: u64,
    /// Received blocks that did not decode (garbage, CRC, truncated, too long).
    pub rx_decode_errors: u64,
    /// Valid replies whose sequence number matched no pending request (late or duplicate).
    pub stale_replies: u64,
    /// Requests without a reply in time.
    pub timeouts: u64,
    /// Firmware reports of a corrupted request (ERROR CRC / framing).
    pub fw_crc_reports: u64,
    /// Setpoints refused for their sequence number.
    pub fw_seq_rejects: u64,
    /// Setpoints refused for being out of range.
    pub fw_range_rejects: u64,
    /// Setpoints refused because a fault is latched.
    pub fw_fault_rejects: u64,
    /// Other error replies.
    pub fw_other_errors: u64,
    /// Acknowledgements with the LIMITED flag (rate limit hit in the firmware).
    pub limited_acks: u64,
    /// Transport failures (port closed, vanished, I/O error).
    pub transport_errors: u64,
    /// Successful reconnections.
    pub reconnects: u64,
}

/// The serial stepper driver.
pub struct SerialDriver {
    name: String,
    cfg: SerialConfig,
    port: Option<Box<dyn serialport::SerialPort>>,
    dec: FrameDecoder,
    inbox: VecDeque<Frame>,
    seq: u8,
    pending: Option<u8>,
    last: DriverState,
    last_flags: u8,
    last_err_count: u8,
    counters: HostCounters,
    hello: Option<HelloReply>,
}

impl std::fmt::Debug for SerialDriver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SerialDriver")
            .field("name", &self.name)
            .field("connected", &self.port.is_some())
            .field("counters", &self.counters)
            .finish()
    }
}

fn transport(path: &str, what: &str, e: impl std::fmt::Display) -> DriverError {
    DriverError::Transport(format!("serial port {path}: {what}: {e}"))
}

impl SerialDriver {
    /// Opens the port, does the version handshake and writes the configuration.
    pub fn open(cfg: SerialConfig) -> Result<Self, DriverError> {
        let mut d = Self {
            name: format!("serial:{}", cfg.path),
            cfg,
            port: None,
            dec: FrameDecoder::new(),
            inbox: VecDeque::new(),
            seq: 0,
            pending: None,
            last: DriverState::default(),
            last_flags: 0,
            last_err_count: 0,
            counters: HostCounters::default(),
            hello: None,
        };
        d.connect()?;
        Ok(d)
    }

    fn connect(&mut self) -> Result<(), DriverError> {
        self.port = None;
        self.dec.reset();
        self.inbox.clear();
        self.pending = None;
        let port = serialport::new(self.cfg.path.as_str(), self.cfg.baud)
            .timeout(self.cfg.reply_timeout)
            .open()
            .map_err(|e| transport(&self.cfg.path, "cannot open", e))?;
        let _ = port.clear(serialport::ClearBuffer::All);
        self.port = Some(port);
        let hello = self.handshake()?;
        if let Some(fc) = self.cfg.firmware_config {
            self.configure(fc)?;
        }
        tracing::info!(
            port = %self.cfg.path,
            fw = ?hello.fw_version,
            reset_cause = hello.reset_cause,
            "stepper firmware connected"
        );
        Ok(())
    }

    fn handshake(&mut self) -> Result<HelloReply, DriverError> {
        let deadline = Instant::now() + self.cfg.handshake_timeout;
        loop {
            match self.request(Message::Hello {
                protocol: PROTOCOL_VERSION,
            }) {
                Ok(Message::HelloReply(h)) => {
                    if h.protocol != PROTOCOL_VERSION {
                        return Err(DriverError::Protocol(format!(
                            "firmware speaks protocol {} (host {PROTOCOL_VERSION})",
                            h.protocol
                        )));
                    }
                    if h.n_motors as usize != N_MOTORS {
                        return Err(DriverError::Protocol(format!(
                            "firmware drives {} motors, expected {N_MOTORS}",
                            h.n_motors
                        )));
                    }
                    self.hello = Some(h);
                    return Ok(h);
                }
                Ok(Message::Error {
                    code: ErrorCode::Version,
                    ..
                }) => {
                    return Err(DriverError::Protocol(format!(
                        "firmware refused protocol version {PROTOCOL_VERSION}"
                    )))
                }
                Ok(other) => {
                    tracing::warn!(?other, "unexpected handshake reply");
                    if Instant::now() >= deadline {
                        return Err(DriverError::Protocol(format!(
                            "unexpected handshake reply from the firmware: {other:?}"
                        )));
                    }
                    std::thread::sleep(Duration::from_millis(20));
                }
                Err(DriverError::Protocol(_)) if Instant::now() < deadline => {}
                Err(e @ DriverError::Protocol(_)) => {
                    return Err(DriverError::Protocol(format!(
                        "no handshake from the firmware within {:?}: {e}",
                        self.cfg.handshake_timeout
                    )))
                }
                Err(e) => return Err(e),
            }
        }
    }

    /// Drops the port and opens it again (same path), redoing the handshake and configuration.
    pub fn reconnect(&mut self) -> Result<HelloReply, DriverError> {
        self.close();
        self.connect()?;
        self.counters.reconnects += 1;
        Ok(self.hello.expect("handshake done"))
    }

    /// Closes the port; later calls fail with a transport error until [`Self::reconnect`].
    pub fn close(&mut self) {
        self.port = None;
        self.pending = None;
    }

    /// Whether the port is open.
    pub fn is_connected(&self) -> bool {
        self.port.is_some()
    }

    /// The firmware's handshake reply (version, reset cause, configuration).
    pub fn firmware(&self) -> Option<&HelloReply> {
        self.hello.as_ref()
    }

    /// Host-side counters.
    pub fn counters(&self) -> HostCounters {
        self.counters
    }

    /// Resets the host-side counters.
    pub fn reset_counters(&mut self) {
        self.counters = HostCounters::default();
    }

    /// Flags of the last acknowledgement ([`crate::protocol::flags`]).
    pub fn last_flags(&self) -> u8 {
        self.last_flags
    }

    fn next_seq(&mut self) -> u8 {
        self.seq = self.seq.wrapping_add(1);
        self.seq
    }

    fn drop_port(&mut self, err: DriverError) -> DriverError {
        self.counters.transport_errors += 1;
        tracing::error!(port = %self.cfg.path, error = %err, "serial transport failed; port dropped");
        self.port = None;
        self.pending = None;
        err
    }

    /// Writes raw bytes to the port (diagnostics and fault-injection tests).
    pub fn send_raw(&mut self, bytes: &[u8]) -> Result<(), DriverError> {
        let path = self.cfg.path.clone();
        let Some(port) = self.port.as_mut() else {
            self.counters.transport_errors += 1;
            return Err(DriverError::Transport(format!(
                "serial port {path} is closed (call reconnect())"
            )));
        };
        match port.write_all(bytes).and_then(|_| port.flush()) {
            Ok(()) => Ok(()),
            Err(e) => Err(self.drop_port(transport(&path, "write failed", e))),
        }
    }

    /// Every frame goes out as `0x00 ‖ frame ‖ 0x00`: the leading delimiter ends whatever
    /// partial frame (line noise, an interrupted write) the firmware may be holding.
    fn send(&mut self, msg: &Message) -> Result<u8, DriverError> {
        let seq = self.next_seq();
        let mut bytes = Vec::with_capacity(crate::protocol::MAX_FRAME + 1);
        bytes.push(crate::protocol::DELIMITER);
        bytes.extend(encode_frame(seq, msg));
        self.send_raw(&bytes)?;
        self.counters.frames_sent += 1;
        Ok(seq)
    }

    /// Reads from the port until a frame arrives or `deadline` passes.
    fn fill_inbox(&mut self, deadline: Instant) -> Result<bool, DriverError> {
        let path = self.cfg.path.clone();
        let mut buf = [0u8; 128];
        loop {
            if !self.inbox.is_empty() {
                return Ok(true);
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(false);
            }
            let Some(port) = self.port.as_mut() else {
                self.counters.transport_errors += 1;
                return Err(DriverError::Transport(format!(
                    "serial port {path} is closed (call reconnect())"
                )));
            };
            let wait = (deadline - now).max(Duration::from_millis(1));
            if let Err(e) = port.set_timeout(wait) {
                return Err(self.drop_port(transport(&path, "set timeout", e)));
            }
            match port.read(&mut buf) {
                Ok(0) => {
                    return Err(self.drop_port(transport(
                        &path,
                        "read",
                        "end of file (device gone)",
                    )))
                }
                Ok(n) => {
                    for &b in &buf[..n] {
                        match self.dec.push(b) {
                            None => {}
                            Some(Ok(f)) => {
                                self.counters.frames_received += 1;
                                self.inbox.push_back(f);
                            }
                            Some(Err(e)) => self.on_decode_error(e),
                        }
                    }
                }
                Err(e) if e.kind() == ErrorKind::TimedOut || e.kind() == ErrorKind::Interrupted => {
                }
                Err(e) => return Err(self.drop_port(transport(&path, "read failed", e))),
            }
        }
    }

    fn on_decode_error(&mut self, e: DecodeError) {
        self.counters.rx_decode_errors += 1;
        tracing::warn!(port = %self.cfg.path, error = %e, "undecodable bytes from the firmware");
    }

    fn note_unsolicited(&mut self, f: &Frame) {
        match f.msg {
            Message::Error {
                code: ErrorCode::Crc | ErrorCode::Framing,
                ..
            } => {
                self.counters.fw_crc_reports += 1;
                tracing::warn!(port = %self.cfg.path, "firmware received a corrupted frame");
            }
            _ => {
                self.counters.stale_replies += 1;
                tracing::warn!(port = %self.cfg.path, seq = f.seq, "stale reply dropped");
            }
        }
    }

    /// Waits for the reply with sequence number `seq`.
    fn wait_reply(&mut self, seq: u8) -> Result<Message, DriverError> {
        let deadline = Instant::now() + self.cfg.reply_timeout;
        loop {
            while let Some(f) = self.inbox.pop_front() {
                if f.seq == seq
                    && !matches!(
                        f.msg,
                        Message::Error {
                            code: ErrorCode::Crc | ErrorCode::Framing,
                            req_type: 0
                        }
                    )
                {
                    return Ok(f.msg);
                }
                self.note_unsolicited(&f);
            }
            if !self.fill_inbox(deadline)? {
                self.counters.timeouts += 1;
                tracing::warn!(port = %self.cfg.path, seq, "no reply from the firmware in time");
                return Err(DriverError::Protocol(format!(
                    "no reply to seq {seq} within {:?}",
                    self.cfg.reply_timeout
                )));
            }
        }
    }

    /// Sends one request and waits for its reply (any type, errors included).
    pub fn request(&mut self, msg: Message) -> Result<Message, DriverError> {
        self.pending = None;
        let seq = self.send(&msg)?;
        let reply = self.wait_reply(seq)?;
        if let Message::Error { code, req_type } = reply {
            self.count_fw_error(code, req_type);
        }
        Ok(reply)
    }

    fn count_fw_error(&mut self, code: ErrorCode, req_type: u8) {
        match code {
            ErrorCode::Sequence => self.counters.fw_seq_rejects += 1,
            ErrorCode::Range => self.counters.fw_range_rejects += 1,
            ErrorCode::Fault => self.counters.fw_fault_rejects += 1,
            ErrorCode::Crc | ErrorCode::Framing => self.counters.fw_crc_reports += 1,
            _ => self.counters.fw_other_errors += 1,
        }
        tracing::warn!(port = %self.cfg.path, ?code, req_type, "firmware error reply");
    }

    fn expect_state(&mut self, reply: Message, what: &str) -> Result<StateReport, DriverError> {
        match reply {
            Message::State(s) => {
                self.absorb(&s);
                Ok(s)
            }
            Message::Error { code, .. } => Err(match code {
                ErrorCode::Range => DriverError::Limit(format!("{what}: out of range")),
                c => DriverError::Protocol(format!("{what}: firmware error {c:?}")),
            }),
            other => Err(DriverError::Protocol(format!(
                "{what}: unexpected reply {other:?}"
            ))),
        }
    }

    fn absorb(&mut self, s: &StateReport) {
        self.last_flags = s.flags;
        if s.err_count != self.last_err_count {
            tracing::warn!(
                port = %self.cfg.path,
                count = s.err_count,
                "firmware bad-frame count changed"
            );
        }
        self.last_err_count = s.err_count;
        self.last.steps = s.steps;
        self.last.enabled = s.flags & flags::ENABLED != 0;
        self.last.moving = s.flags & flags::MOVING != 0;
        self.last.limited = s.flags & flags::LIMITED != 0;
        self.last.fault = s.flags & flags::FAULT != 0;
        if self.last.limited {
            self.counters.limited_acks += 1;
        }
    }

    /// Full status (positions, targets, flags, firmware counters).
    pub fn status(&mut self) -> Result<StatusReport, DriverError> {
        match self.request(Message::Status)? {
            Message::StatusReply(s) => {
                let err_count = self.last_err_count;
                self.absorb(&StateReport {
                    steps: s.steps,
                    flags: s.flags,
                    err_count,
                });
                Ok(s)
            }
            other => Err(DriverError::Protocol(format!(
                "status: unexpected reply {other:?}"
            ))),
        }
    }

    /// Sets the position counters of the motors in `mask` (zeroing). Refused while moving.
    pub fn zero(&mut self, mask: u8, steps: [i32; N_MOTORS]) -> Result<StateReport, DriverError> {
        let r = self.request(Message::Zero { mask, steps })?;
        self.expect_state(r, "zero")
    }

    /// Energises or releases the coils.
    pub fn set_enable(&mut self, enable: bool) -> Result<StateReport, DriverError> {
        let r = self.request(Message::Enable(enable))?;
        self.expect_state(r, "enable")
    }

    /// Clears a latched fault (watchdog); the motors stay where they are.
    pub fn clear_fault(&mut self) -> Result<StateReport, DriverError> {
        let r = self.request(Message::ClearFault)?;
        self.expect_state(r, "clear fault")
    }

    /// Writes the firmware configuration (refused while moving).
    pub fn configure(&mut self, c: FwConfig) -> Result<StateReport, DriverError> {
        let r = self.request(Message::Config(c))?;
        let s = self.expect_state(r, "config")?;
        self.cfg.firmware_config = Some(c);
        if let Some(h) = self.hello.as_mut() {
            h.config = c;
        }
        Ok(s)
    }

    /// Sends a setpoint with an explicit sequence number (tests of out-of-order handling);
    /// returns the firmware's reply.
    pub fn setpoint_with_seq(
        &mut self,
        seq: u8,
        cmd: &MotorCommand,
    ) -> Result<Message, DriverError> {
        self.pending = None;
        let msg = Message::Setpoint {
            enable: cmd.enable,
            steps: cmd.steps,
        };
        self.send_raw(&encode_frame(seq, &msg))?;
        self.counters.frames_sent += 1;
        let r = self.wait_reply(seq)?;
        match r {
            Message::Error { code, req_type } => self.count_fw_error(code, req_type),
            Message::State(s) => {
                // Accepted: continue the sequence from there.
                self.seq = seq;
                self.absorb(&s);
            }
            _ => {}
        }
        Ok(r)
    }
}

impl Driver for SerialDriver {
    fn name(&self) -> &str {
        &self.name
    }

    fn write(
        &mut self,
        _time_s: f64,
        _period_s: f64,
        cmd: &MotorCommand,
    ) -> Result<(), DriverError> {
        if let Some(old) = self.pending.take() {
            // The previous setpoint was never read: its ack will arrive as a stale reply.
            tracing::debug!(seq = old, "previous setpoint not read");
        }
        let seq = self.send(&Message::Setpoint {
            enable: cmd.enable,
            steps: cmd.steps,
        })?;
        self.pending = Some(seq);
        Ok(())
    }

    fn diagnostics(&self) -> Vec<(String, u64)> {
        let c = &self.counters;
        [
            ("frames_sent", c.frames_sent),
            ("frames_received", c.frames_received),
            ("rx_decode_errors", c.rx_decode_errors),
            ("stale_replies", c.stale_replies),
            ("timeouts", c.timeouts),
            ("fw_crc_reports", c.fw_crc_reports),
            ("fw_seq_rejects", c.fw_seq_rejects),
            ("fw_range_rejects", c.fw_range_rejects),
            ("fw_fault_rejects", c.fw_fault_rejects),
            ("fw_other_errors", c.fw_other_errors),
            ("limited_acks", c.limited_acks),
            ("transport_errors", c.transport_errors),
            ("reconnects", c.reconnects),
            ("fw_bad_frames_mod256", u64::from(self.last_err_count)),
        ]
        .into_iter()
        .map(|(k, v)| (format!("serial.{k}"), v))
        .collect()
    }

    fn read(&mut self, time_s: f64, _period_s: f64) -> Result<DriverState, DriverError> {
        match self.pending.take() {
            Some(seq) => match self.wait_reply(seq)? {
                Message::State(s) => self.absorb(&s),
                Message::Error { code, req_type } => {
                    self.count_fw_error(code, req_type);
                    match code {
                        ErrorCode::Fault => {
                            // Holding position in a latched fault: report it as state.
                            self.last.fault = true;
                            self.last.moving = false;
                        }
                        ErrorCode::Range => {
                            return Err(DriverError::Limit(
                                "setpoint out of the firmware's position range (refused)".into(),
                            ))
                        }
                        c => {
                            return Err(DriverError::Protocol(format!(
                                "setpoint refused by the firmware: {c:?}"
                            )))
                        }
                    }
                }
                other => {
                    return Err(DriverError::Protocol(format!(
                        "unexpected reply to setpoint: {other:?}"
                    )))
                }
            },
            None => {
                self.status()?;
            }
        }
        self.last.time_s = time_s;
        Ok(self.last)
    }
}
