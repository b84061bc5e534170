//! The host ⇄ firmware wire protocol: framing, CRC, messages (see `driver/PROTOCOL.md`).
//!
//! One frame on the wire is `COBS(payload ‖ crc16_le) ‖ 0x00` where
//! `payload = type u8 ‖ seq u8 ‖ body`. All integers are little-endian. The CRC is
//! CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over the payload. The C side mirrors the
//! constants in `driver/firmware/protocol.h` (a unit test checks that they agree).
//!
//! This module is pure (no I/O) so that the serial backend, the tests and the bench share it.

use crate::interface::N_MOTORS;

/// Protocol version spoken by this host and the firmware (checked in the handshake).
pub const PROTOCOL_VERSION: u8 = 1;
/// Frame delimiter on the wire.
pub const DELIMITER: u8 = 0x00;
/// Largest payload (type + seq + body), before CRC and COBS.
pub const MAX_PAYLOAD: usize = 48;
/// Largest encoded frame (COBS of payload + CRC, plus the delimiter).
pub const MAX_FRAME: usize = MAX_PAYLOAD + 2 + 1 + 1;

/// Message type codes (requests; replies set bit 7).
pub mod msg_type {
    /// Handshake request.
    pub const HELLO: u8 = 0x01;
    /// Cycle setpoint.
    pub const SETPOINT: u8 = 0x02;
    /// Set the position counters (zeroing).
    pub const ZERO: u8 = 0x03;
    /// Energise or release the coils.
    pub const ENABLE: u8 = 0x04;
    /// Write the runtime configuration.
    pub const CONFIG: u8 = 0x05;
    /// Ask for positions, targets, flags and counters.
    pub const STATUS: u8 = 0x06;
    /// Clear a latched fault.
    pub const CLEAR_FAULT: u8 = 0x07;
    /// Handshake reply.
    pub const HELLO_REPLY: u8 = 0x81;
    /// Acknowledgement with positions and flags.
    pub const STATE: u8 = 0x82;
    /// Full status reply.
    pub const STATUS_REPLY: u8 = 0x86;
    /// Error reply.
    pub const ERROR: u8 = 0xFF;
}

/// Status flag bits in [`StateReport::flags`].
pub mod flags {
    /// The drive accepts motion (coils may still be released when idle).
    pub const ENABLED: u8 = 1 << 0;
    /// Motors are stepping towards the target.
    pub const MOVING: u8 = 1 << 1;
    /// The current target could not be reached within one cycle at the rate limit.
    pub const LIMITED: u8 = 1 << 2;
    /// The host went silent: motion stopped, fault latched.
    pub const WATCHDOG: u8 = 1 << 3;
    /// The coils are energised.
    pub const COILS_ON: u8 = 1 << 4;
    /// A fault is latched (setpoints are refused until CLEAR_FAULT).
    pub const FAULT: u8 = 1 << 5;
    /// The last reset was caused by the AVR hardware watchdog.
    pub const WDT_RESET: u8 = 1 << 6;
}

/// Error codes in [`Message::Error`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum ErrorCode {
    /// The frame's CRC did not match.
    Crc = 1,
    /// COBS decoding failed or the frame is too short/long.
    Framing = 2,
    /// Unknown message type.
    UnknownType = 3,
    /// Body length does not match the type.
    BadLength = 4,
    /// Setpoint sequence number not newer than the last accepted one.
    Sequence = 5,
    /// Setpoint outside the configured position range.
    Range = 6,
    /// Setpoint refused while a fault is latched.
    Fault = 7,
    /// Command refused while moving (e.g. ZERO).
    Busy = 8,
    /// Configuration values out of bounds.
    BadConfig = 9,
    /// Unsupported protocol version in HELLO.
    Version = 10,
    /// A code this host does not know.
    Other = 255,
}

impl ErrorCode {
    /// Maps a wire byte to a code.
    pub fn from_u8(v: u8) -> Self {
        match v {
            1 => Self::Crc,
            2 => Self::Framing,
            3 => Self::UnknownType,
            4 => Self::BadLength,
            5 => Self::Sequence,
            6 => Self::Range,
            7 => Self::Fault,
            8 => Self::Busy,
            9 => Self::BadConfig,
            10 => Self::Version,
            _ => Self::Other,
        }
    }
}

/// Runtime configuration of the firmware (CONFIG request, HELLO reply).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FwConfig {
    /// Maximum step rate per motor, steps/s.
    pub max_rate: u16,
    /// Host silence after which motion stops and a fault latches, ms (0 = off).
    pub watchdog_ms: u16,
    /// Idle time after which the coils are released, ms (0 = keep energised).
    pub idle_off_ms: u16,
    /// Lowest accepted target, steps.
    pub pos_min: i32,
    /// Highest accepted target, steps.
    pub pos_max: i32,
    /// Segment (cycle) length, ms.
    pub cycle_ms: u8,
}

impl Default for FwConfig {
    fn default() -> Self {
        Self {
            max_rate: 600,
            watchdog_ms: 200,
            idle_off_ms: 0,
            pos_min: -20480,
            pos_max: 20480,
            cycle_ms: 20,
        }
    }
}

/// Body size of an encoded [`FwConfig`].
pub const CONFIG_LEN: usize = 15;

impl FwConfig {
    fn put(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.max_rate.to_le_bytes());
        out.extend_from_slice(&self.watchdog_ms.to_le_bytes());
        out.extend_from_slice(&self.idle_off_ms.to_le_bytes());
        out.extend_from_slice(&self.pos_min.to_le_bytes());
        out.extend_from_slice(&self.pos_max.to_le_bytes());
        out.push(self.cycle_ms);
    }
    fn get(r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        Ok(Self {
            max_rate: r.u16()?,
            watchdog_ms: r.u16()?,
            idle_off_ms: r.u16()?,
            pos_min: r.i32()?,
            pos_max: r.i32()?,
            cycle_ms: r.u8()?,
        })
    }
}

/// The handshake reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HelloReply {
    /// Protocol version of the firmware.
    pub protocol: u8,
    /// Firmware version (major, minor, patch).
    pub fw_version: [u8; 3],
    /// Number of motors driven.
    pub n_motors: u8,
    /// The AVR's MCUSR at boot (reset cause bits).
    pub reset_cause: u8,
    /// The configuration in force.
    pub config: FwConfig,
}

/// Acknowledgement sent for SETPOINT, ZERO, ENABLE, CONFIG and CLEAR_FAULT.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StateReport {
    /// Actual motor positions, steps.
    pub steps: [i32; N_MOTORS],
    /// [`flags`] bits.
    pub flags: u8,
    /// Count of bad frames received (CRC, framing, length, sequence, range), mod 256.
    pub err_count: u8,
}

/// Firmware counters (STATUS reply), all wrapping u16.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FwCounters {
    /// Valid frames received.
    pub rx_frames: u16,
    /// Frames with a bad CRC.
    pub crc_errors: u16,
    /// Frames that failed COBS decoding or were too short/long.
    pub framing_errors: u16,
    /// Setpoints with a stale or duplicate sequence number.
    pub seq_errors: u16,
    /// Setpoints refused because out of range.
    pub range_rejects: u16,
    /// Setpoint segments clamped by the rate limit.
    pub rate_limited: u16,
    /// Watchdog (host silence) trips.
    pub watchdog_trips: u16,
    /// Bytes lost because the RX ring buffer was full.
    pub rx_overflows: u16,
}

/// Full status reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StatusReport {
    /// Actual positions, steps.
    pub steps: [i32; N_MOTORS],
    /// Current targets, steps.
    pub targets: [i32; N_MOTORS],
    /// [`flags`] bits.
    pub flags: u8,
    /// Counters.
    pub counters: FwCounters,
}

/// Every message of the protocol (both directions).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Message {
    /// Handshake with the host's protocol version.
    Hello {
        /// Host protocol version.
        protocol: u8,
    },
    /// Cycle setpoint: absolute targets to reach by the end of the segment.
    Setpoint {
        /// Energise the coils.
        enable: bool,
        /// Absolute targets, steps.
        steps: [i32; N_MOTORS],
    },
    /// Sets the position counters of the motors in `mask` (bit i = motor i).
    Zero {
        /// Motors to set.
        mask: u8,
        /// New positions, steps.
        steps: [i32; N_MOTORS],
    },
    /// Energises (true) or releases the coils.
    Enable(bool),
    /// Writes the configuration.
    Config(FwConfig),
    /// Status request.
    Status,
    /// Clears a latched fault.
    ClearFault,
    /// Handshake reply.
    HelloReply(HelloReply),
    /// Acknowledgement.
    State(StateReport),
    /// Status reply.
    StatusReply(StatusReport),
    /// Error reply.
    Error {
        /// Why.
        code: ErrorCode,
        /// Type of the offending request (0 if unknown).
        req_type: u8,
    },
}

impl Message {
    /// The type byte.
    pub fn type_code(&self) -> u8 {
        use msg_type::*;
        match self {
            Message::Hello { .. } => HELLO,
            Message::Setpoint { .. } => SETPOINT,
            Message::Zero { .. } => ZERO,
            Message::Enable(_) => ENABLE,
            Message::Config(_) => CONFIG,
            Message::Status => STATUS,
            Message::ClearFault => CLEAR_FAULT,
            Message::HelloReply(_) => HELLO_REPLY,
            Message::State(_) => STATE,
            Message::StatusReply(_) => STATUS_REPLY,
            Message::Error { .. } => ERROR,
        }
    }

    fn put_body(&self, out: &mut Vec<u8>) {
        fn steps(out: &mut Vec<u8>, s: &[i32; N_MOTORS]) {
            for v in s {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        match self {
            Message::Hello { protocol } => out.push(*protocol),
            Message::Setpoint { enable, steps: s } => {
                out.push(u8::from(*enable));
                steps(out, s);
            }
            Message::Zero { mask, steps: s } => {
                out.push(*mask);
                steps(out, s);
            }
            Message::Enable(e) => out.push(u8::from(*e)),
            Message::Config(c) => c.put(out),
            Message::Status | Message::ClearFault => {}
            Message::HelloReply(h) => {
                out.push(h.protocol);
                out.extend_from_slice(&h.fw_version);
                out.push(h.n_motors);
                out.push(h.reset_cause);
                h.config.put(out);
            }
            Message::State(s) => {
                steps(out, &s.steps);
                out.push(s.flags);
                out.push(s.err_count);
            }
            Message::StatusReply(s) => {
                steps(out, &s.steps);
                steps(out, &s.targets);
                out.push(s.flags);
                let c = &s.counters;
                for v in [
                    c.rx_frames,
                    c.crc_errors,
                    c.framing_errors,
                    c.seq_errors,
                    c.range_rejects,
                    c.rate_limited,
                    c.watchdog_trips,
                    c.rx_overflows,
                ] {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
            Message::Error { code, req_type } => {
                out.push(*code as u8);
                out.push(*req_type);
            }
        }
    }

    /// Expected body length for a type code, `None` for unknown types.
    pub fn body_len(type_code: u8) -> Option<usize> {
        use msg_type::*;
        Some(match type_code {
            HELLO => 1,
            SETPOINT | ZERO => 13,
            ENABLE => 1,
            CONFIG => CONFIG_LEN,
            STATUS | CLEAR_FAULT => 0,
            HELLO_REPLY => 6 + CONFIG_LEN,
            STATE => 14,
            STATUS_REPLY => 41,
            ERROR => 2,
            _ => return None,
        })
    }

    fn get_body(type_code: u8, body: &[u8]) -> Result<Self, DecodeError> {
        use msg_type::*;
        let want = Self::body_len(type_code).ok_or(DecodeError::UnknownType(type_code))?;
        if body.len() != want {
            return Err(DecodeError::BadLength {
                type_code,
                len: body.len(),
            });
        }
        let mut r = Reader { b: body, i: 0 };
        let m = match type_code {
            HELLO => Message::Hello { protocol: r.u8()? },
            SETPOINT => Message::Setpoint {
                enable: r.u8()? & 1 != 0,
                steps: r.steps()?,
            },
            ZERO => Message::Zero {
                mask: r.u8()?,
                steps: r.steps()?,
            },
            ENABLE => Message::Enable(r.u8()? & 1 != 0),
            CONFIG => Message::Config(FwConfig::get(&mut r)?),
            STATUS => Message::Status,
            CLEAR_FAULT => Message::ClearFault,
            HELLO_REPLY => Message::HelloReply(HelloReply {
                protocol: r.u8()?,
                fw_version: [r.u8()?, r.u8()?, r.u8()?],
                n_motors: r.u8()?,
                reset_cause: r.u8()?,
                config: FwConfig::get(&mut r)?,
            }),
            STATE => Message::State(StateReport {
                steps: r.steps()?,
                flags: r.u8()?,
                err_count: r.u8()?,
            }),
            STATUS_REPLY => Message::StatusReply(StatusReport {
                steps: r.steps()?,
                targets: r.steps()?,
                flags: r.u8()?,
                counters: FwCounters {
                    rx_frames: r.u16()?,
                    crc_errors: r.u16()?,
                    framing_errors: r.u16()?,
                    seq_errors: r.u16()?,
                    range_rejects: r.u16()?,
                    rate_limited: r.u16()?,
                    watchdog_trips: r.u16()?,
                    rx_overflows: r.u16()?,
                },
            }),
            ERROR => Message::Error {
                code: ErrorCode::from_u8(r.u8()?),
                req_type: r.u8()?,
            },
            _ => return Err(DecodeError::UnknownType(type_code)),
        };
        Ok(m)
    }
}

struct Reader<'a> {
    b: &'a [u8],
    i: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        let s = self
            .b
            .get(self.i..self.i + N)
            .ok_or(DecodeError::Truncated)?;
        self.i += N;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Ok(a)
    }
    fn u8(&mut self) -> Result<u8, DecodeError> {
        Ok(self.take::<1>()?[0])
    }
    fn u16(&mut self) -> Result<u16, DecodeError> {
        Ok(u16::from_le_bytes(self.take()?))
    }
    fn i32(&mut self) -> Result<i32, DecodeError> {
        Ok(i32::from_le_bytes(self.take()?))
    }
    fn steps(&mut self) -> Result<[i32; N_MOTORS], DecodeError> {
        Ok([self.i32()?, self.i32()?, self.i32()?])
    }
}

/// A decoded frame: sequence number and message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame {
    /// Sequence number (requests: chosen by the host; replies: echo of the request's).
    pub seq: u8,
    /// The message.
    pub msg: Message,
}

/// Why a frame could not be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// COBS structure is invalid (a code byte points past the end, or an embedded zero).
    #[error("COBS framing error")]
    Cobs,
    /// Frame too short to hold type, seq and CRC, or a field is missing.
    #[error("frame truncated")]
    Truncated,
    /// Frame longer than [`MAX_FRAME`] (bytes were dropped until the next delimiter).
    #[error("frame too long")]
    TooLong,
    /// CRC mismatch.
    #[error("CRC mismatch (got {got:#06x}, computed {computed:#06x})")]
    Crc {
        /// CRC found in the frame.
        got: u16,
        /// CRC computed over the payload.
        computed: u16,
    },
    /// Unknown message type.
    #[error("unknown message type {0:#04x}")]
    UnknownType(u8),
    /// Body length does not match the type.
    #[error("bad body length {len} for type {type_code:#04x}")]
    BadLength {
        /// The type.
        type_code: u8,
        /// The body length found.
        len: usize,
    },
}

/// CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no final xor.
pub fn crc16_ccitt(data: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in data {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// COBS-encodes `data` (which may contain zeros) into `out`, without the delimiter.
pub fn cobs_encode(data: &[u8], out: &mut Vec<u8>) {
    let mut code_idx = out.len();
    out.push(0);
    let mut code: u8 = 1;
    for &b in data {
        if b == 0 {
            out[code_idx] = code;
            code_idx = out.len();
            out.push(0);
            code = 1;
        } else {
            out.push(b);
            code += 1;
            if code == 0xFF {
                out[code_idx] = code;
                code_idx = out.len();
                out.push(0);
                code = 1;
            }
        }
    }
    out[code_idx] = code;
}

/// Decodes one COBS block (without the delimiter).
pub fn cobs_decode(data: &[u8]) -> Result<Vec<u8>, DecodeError> {
    let mut out = Vec::with_capacity(data.len());
    let mut i = 0;
    while i < data.len() {
        let code = data[i];
        if code == 0 {
            return Err(DecodeError::Cobs);
        }
        let end = i + code as usize;
        if end > data.len() {
            return Err(DecodeError::Cobs);
        }
        let block = &data[i + 1..end];
        if block.contains(&0) {
            return Err(DecodeError::Cobs);
        }
        out.extend_from_slice(block);
        i = end;
        if code != 0xFF && i < data.len() {
            out.push(0);
        }
    }
    Ok(out)
}

/// Encodes a frame (COBS, CRC, trailing delimiter) ready to write to the port.
pub fn encode_frame(seq: u8, msg: &Message) -> Vec<u8> {
    let mut payload = Vec::with_capacity(MAX_PAYLOAD + 2);
    payload.push(msg.type_code());
    payload.push(seq);
    msg.put_body(&mut payload);
    let crc = crc16_ccitt(&payload);
    payload.extend_from_slice(&crc.to_le_bytes());
    let mut out = Vec::with_capacity(payload.len() + 2);
    cobs_encode(&payload, &mut out);
    out.push(DELIMITER);
    out
}

/// Decodes one frame given the bytes between two delimiters (COBS-encoded).
pub fn decode_frame(encoded: &[u8]) -> Result<Frame, DecodeError> {
    if encoded.len() > MAX_FRAME - 1 {
        return Err(DecodeError::TooLong);
    }
    let raw = cobs_decode(encoded)?;
    if raw.len() < 4 {
        return Err(DecodeError::Truncated);
    }
    let (payload, crc_bytes) = raw.split_at(raw.len() - 2);
    let got = u16::from_le_bytes([crc_bytes[0], crc_bytes[1]]);
    let computed = crc16_ccitt(payload);
    if got != computed {
        return Err(DecodeError::Crc { got, computed });
    }
    let msg = Message::get_body(payload[0], &payload[2..])?;
    Ok(Frame {
        seq: payload[1],
        msg,
    })
}

/// Encoded size on the wire (bytes, delimiter included) of a message.
pub fn wire_len(msg: &Message) -> usize {
    encode_frame(0, msg).len()
}

/// Streaming decoder: feed bytes as they arrive, get frames (or errors) at each delimiter.
///
/// Resynchronisation is automatic: whatever garbage arrives, the next `0x00` ends it and the
/// following frame decodes normally. Empty blocks (two delimiters in a row) are ignored, so a
/// sender may prefix a frame with a delimiter to flush a partial frame on the other side.
#[derive(Debug, Default)]
pub struct FrameDecoder {
    buf: Vec<u8>,
    overflow: bool,
}

impl FrameDecoder {
    /// A new decoder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Drops any partial frame.
    pub fn reset(&mut self) {
        self.buf.clear();
        self.overflow = false;
    }

    /// Feeds one byte; returns a result when a delimiter closes a non-empty block.
    pub fn push(&mut self, b: u8) -> Option<Result<Frame, DecodeError>> {
        if b != DELIMITER {
            if self.buf.len() < MAX_FRAME {
                self.buf.push(b);
            } else {
                self.overflow = true;
            }
            return None;
        }
        if self.buf.is_empty() && !self.overflow {
            return None;
        }
        let r = if self.overflow {
            Err(DecodeError::TooLong)
        } else {
            decode_frame(&self.buf)
        };
        self.reset();
        Some(r)
    }

    /// Feeds many bytes, collecting every result.
    pub fn push_all(&mut self, bytes: &[u8]) -> Vec<Result<Frame, DecodeError>> {
        bytes.iter().filter_map(|&b| self.push(b)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all_messages() -> Vec<Message> {
        vec![
            Message::Hello { protocol: 1 },
            Message::Setpoint {
                enable: true,
                steps: [1, -2, i32::MAX],
            },
            Message::Zero {
                mask: 0b101,
                steps: [0, 0, i32::MIN],
            },
            Message::Enable(false),
            Message::Config(FwConfig::default()),
            Message::Status,
            Message::ClearFault,
            Message::HelloReply(HelloReply {
                protocol: 1,
                fw_version: [1, 2, 3],
                n_motors: 3,
                reset_cause: 8,
                config: FwConfig::default(),
            }),
            Message::State(StateReport {
                steps: [0, 256, -65536],
                flags: 0x3F,
                err_count: 7,
            }),
            Message::StatusReply(StatusReport {
                steps: [1, 2, 3],
                targets: [4, 5, 6],
                flags: 1,
                counters: FwCounters {
                    rx_frames: 1,
                    crc_errors: 2,
                    framing_errors: 3,
                    seq_errors: 4,
                    range_rejects: 5,
                    rate_limited: 6,
                    watchdog_trips: 7,
                    rx_overflows: 0xFFFF,
                },
            }),
            Message::Error {
                code: ErrorCode::Range,
                req_type: msg_type::SETPOINT,
            },
        ]
    }

    /// Deterministic generator for the fuzz-style tests (splitmix64).
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        fn below(&mut self, n: u64) -> u64 {
            self.next() % n
        }
    }

    #[test]
    fn crc_check_value() {
        assert_eq!(crc16_ccitt(b"123456789"), 0x29B1);
    }

    #[test]
    fn cobs_known_vectors() {
        let cases: &[(&[u8], &[u8])] = &[
            (&[], &[0x01]),
            (&[0x00], &[0x01, 0x01]),
            (&[0x00, 0x00], &[0x01, 0x01, 0x01]),
            (&[0x11, 0x22, 0x00, 0x33], &[0x03, 0x11, 0x22, 0x02, 0x33]),
            (&[0x11, 0x00, 0x00, 0x00], &[0x02, 0x11, 0x01, 0x01, 0x01]),
        ];
        for (raw, enc) in cases {
            let mut out = Vec::new();
            cobs_encode(raw, &mut out);
            assert_eq!(&out[..], *enc, "encode {raw:?}");
            assert_eq!(cobs_decode(enc).unwrap(), raw.to_vec(), "decode {enc:?}");
        }
        // 254 non-zero bytes: one full block.
        let raw: Vec<u8> = (1..=254).collect();
        let mut out = Vec::new();
        cobs_encode(&raw, &mut out);
        assert_eq!(out[0], 0xFF);
        assert_eq!(cobs_decode(&out).unwrap(), raw);
    }

    #[test]
    fn round_trip_every_message() {
        for (i, m) in all_messages().into_iter().enumerate() {
            let seq = (i * 37) as u8;
            let wire = encode_frame(seq, &m);
            assert_eq!(*wire.last().unwrap(), 0);
            assert!(!wire[..wire.len() - 1].contains(&0));
            assert!(wire.len() <= MAX_FRAME, "{m:?} is {} bytes", wire.len());
            let f = decode_frame(&wire[..wire.len() - 1]).unwrap();
            assert_eq!(f, Frame { seq, msg: m });
        }
    }

    /// The example frame of PROTOCOL.md.
    #[test]
    fn golden_setpoint_frame() {
        let f = encode_frame(
            1,
            &Message::Setpoint {
                enable: true,
                steps: [12, -6, 3],
            },
        );
        let want = [
            0x05, 0x02, 0x01, 0x01, 0x0c, 0x01, 0x01, 0x06, 0xfa, 0xff, 0xff, 0xff, 0x03, 0x01,
            0x01, 0x03, 0x28, 0xc7, 0x00,
        ];
        assert_eq!(f, want);
    }

    #[test]
    fn cycle_frame_sizes() {
        let sp = Message::Setpoint {
            enable: true,
            steps: [-1, -1, -1],
        };
        assert_eq!(wire_len(&sp), 19);
        assert_eq!(wire_len(&Message::State(StateReport::default())), 20);
    }

    #[test]
    fn detects_crc_and_truncation() {
        let m = Message::Setpoint {
            enable: true,
            steps: [10, 20, 30],
        };
        let wire = encode_frame(5, &m);
        let body = &wire[..wire.len() - 1];
        // Any single flipped bit is caught (COBS, CRC or length).
        for i in 0..body.len() {
            for bit in 0..8 {
                let mut bad = body.to_vec();
                bad[i] ^= 1 << bit;
                if bad[i] == 0 {
                    continue; // would be a delimiter: a different frame split
                }
                assert!(decode_frame(&bad).is_err(), "byte {i} bit {bit}");
            }
        }
        for n in 0..body.len() {
            assert!(decode_frame(&body[..n]).is_err(), "truncated to {n}");
        }
    }

    #[test]
    fn decoder_resynchronises_after_garbage() {
        let mut dec = FrameDecoder::new();
        let m = Message::Status;
        let mut stream = vec![0x55, 0x13, 0xFF, 0x01];
        stream.push(0);
        stream.extend(encode_frame(9, &m));
        stream.extend(std::iter::repeat_n(0xAA, 200)); // too long
        stream.push(0);
        stream.extend(encode_frame(10, &m));
        let r = dec.push_all(&stream);
        assert_eq!(r.len(), 4);
        assert!(r[0].is_err());
        assert_eq!(r[1], Ok(Frame { seq: 9, msg: m }));
        assert_eq!(r[2], Err(DecodeError::TooLong));
        assert_eq!(r[3], Ok(Frame { seq: 10, msg: m }));
    }

    /// Property test: random garbage interleaved with valid frames never yields a wrong frame,
    /// and every valid frame that is preceded by a delimiter is recovered.
    #[test]
    fn fuzz_garbage_never_forges_frames() {
        let msgs = all_messages();
        let mut rng = Rng(0x5EED_2026_1122);
        let mut false_frames = 0usize;
        for _ in 0..2000 {
            let mut dec = FrameDecoder::new();
            let mut expected = Vec::new();
            let mut stream = Vec::new();
            for k in 0..4 {
                let n = rng.below(60) as usize;
                for _ in 0..n {
                    stream.push(rng.next() as u8);
                }
                stream.push(0); // sender-side flush delimiter
                let m = msgs[rng.below(msgs.len() as u64) as usize];
                let seq = k as u8;
                stream.extend(encode_frame(seq, &m));
                expected.push(Frame { seq, msg: m });
            }
            let got: Vec<Frame> = dec.push_all(&stream).into_iter().flatten().collect();
            // Garbage can only decode to a valid frame by passing a 16-bit CRC and the length
            // check; the expected frames must all be there, in order.
            let mut it = got.iter();
            for e in &expected {
                loop {
                    let g = it.next().expect("expected frame lost");
                    if g == e {
                        break;
                    }
                    false_frames += 1;
                }
            }
        }
        // 8000 garbage runs: a forged frame needs a CRC collision (p ~ 1/65536 each).
        assert!(false_frames <= 2, "{false_frames} forged frames");
    }

    /// Random bytes fed to the decoder never panic, and the decoder stays usable.
    #[test]
    fn fuzz_random_bytes_no_panic() {
        let mut rng = Rng(42);
        let mut dec = FrameDecoder::new();
        for _ in 0..200_000 {
            let b = if rng.below(20) == 0 {
                0
            } else {
                rng.next() as u8
            };
            let _ = dec.push(b);
        }
        dec.push(0);
        let r = dec.push_all(&encode_frame(1, &Message::Status));
        assert_eq!(
            r,
            vec![Ok(Frame {
                seq: 1,
                msg: Message::Status
            })]
        );
    }

    /// The firmware header mirrors these constants.
    #[test]
    fn c_header_matches() {
        let h = include_str!("../firmware/protocol.h");
        let get = |name: &str| -> i64 {
            let line = h
                .lines()
                .find(|l| {
                    let mut w = l.split_whitespace();
                    w.next() == Some("#define") && w.next() == Some(name)
                })
                .unwrap_or_else(|| panic!("{name} missing from protocol.h"));
            let v = line.split_whitespace().nth(2).unwrap();
            let v = v.trim_end_matches('u').trim_end_matches('U');
            if let Some(hex) = v.strip_prefix("0x") {
                i64::from_str_radix(hex, 16).unwrap()
            } else {
                v.parse().unwrap()
            }
        };
        use msg_type::*;
        assert_eq!(get("PROTO_VERSION"), PROTOCOL_VERSION as i64);
        assert_eq!(get("PROTO_MAX_PAYLOAD"), MAX_PAYLOAD as i64);
        for (n, v) in [
            ("MSG_HELLO", HELLO),
            ("MSG_SETPOINT", SETPOINT),
            ("MSG_ZERO", ZERO),
            ("MSG_ENABLE", ENABLE),
            ("MSG_CONFIG", CONFIG),
            ("MSG_STATUS", STATUS),
            ("MSG_CLEAR_FAULT", CLEAR_FAULT),
            ("MSG_HELLO_REPLY", HELLO_REPLY),
            ("MSG_STATE", STATE),
            ("MSG_STATUS_REPLY", STATUS_REPLY),
            ("MSG_ERROR", ERROR),
        ] {
            assert_eq!(get(n), v as i64, "{n}");
        }
        for (n, v) in [
            ("FLAG_ENABLED", flags::ENABLED),
            ("FLAG_MOVING", flags::MOVING),
            ("FLAG_LIMITED", flags::LIMITED),
            ("FLAG_WATCHDOG", flags::WATCHDOG),
            ("FLAG_COILS_ON", flags::COILS_ON),
            ("FLAG_FAULT", flags::FAULT),
            ("FLAG_WDT_RESET", flags::WDT_RESET),
        ] {
            assert_eq!(get(n), v as i64, "{n}");
        }
        for (n, v) in [
            ("ERR_CRC", ErrorCode::Crc),
            ("ERR_FRAMING", ErrorCode::Framing),
            ("ERR_UNKNOWN_TYPE", ErrorCode::UnknownType),
            ("ERR_BAD_LENGTH", ErrorCode::BadLength),
            ("ERR_SEQUENCE", ErrorCode::Sequence),
            ("ERR_RANGE", ErrorCode::Range),
            ("ERR_FAULT", ErrorCode::Fault),
            ("ERR_BUSY", ErrorCode::Busy),
            ("ERR_BAD_CONFIG", ErrorCode::BadConfig),
            ("ERR_VERSION", ErrorCode::Version),
        ] {
            assert_eq!(get(n), v as i64, "{n}");
        }
        let d = FwConfig::default();
        assert_eq!(get("DEFAULT_MAX_RATE"), d.max_rate as i64);
        assert_eq!(get("DEFAULT_WATCHDOG_MS"), d.watchdog_ms as i64);
        assert_eq!(get("DEFAULT_IDLE_OFF_MS"), d.idle_off_ms as i64);
        assert_eq!(get("DEFAULT_POS_MIN"), d.pos_min as i64);
        assert_eq!(get("DEFAULT_POS_MAX"), d.pos_max as i64);
        assert_eq!(get("DEFAULT_CYCLE_MS"), d.cycle_ms as i64);
    }
}
