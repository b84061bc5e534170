//! The sans-IO packet parser: bytes in (split or coalesced at any byte), packets out.
//!
//! The parser owns one buffer of fixed capacity (`max_packet` plus one read chunk) allocated at
//! construction; it never grows. A size field outside `8..=max_packet` is an error before any
//! byte of the body is buffered, so a hostile size (4 GB) costs nothing. After an error the
//! parser is poisoned: the stream is out of sync and the connection must be dropped.

use crate::wire::{PacketType, HEADER_LEN, MAX_PACKET};

/// Bytes the parser accepts beyond one maximal packet (one socket read).
pub const READ_CHUNK: usize = 64 * 1024;

/// A protocol violation found in the byte stream.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ProtocolError {
    /// The size field is smaller than a header.
    #[error("packet size {size} at stream offset {offset} is smaller than the 8-byte header")]
    SizeTooSmall {
        /// The size field.
        size: u32,
        /// Offset of the packet in the stream, bytes.
        offset: u64,
    },
    /// The size field exceeds the bound.
    #[error("packet size {size} at stream offset {offset} exceeds the maximum of {max} bytes")]
    SizeTooLarge {
        /// The size field.
        size: u32,
        /// The bound.
        max: usize,
        /// Offset of the packet in the stream, bytes.
        offset: u64,
    },
    /// A string packet (error, command, XML) is not UTF-8.
    #[error("{kind} packet at stream offset {offset} is not UTF-8 text")]
    NotText {
        /// Which packet type.
        kind: &'static str,
        /// Offset of the packet in the stream, bytes.
        offset: u64,
    },
    /// An event packet without exactly one event byte.
    #[error("event packet at stream offset {offset} has {len} payload bytes (expected 1)")]
    BadEvent {
        /// Payload bytes.
        len: usize,
        /// Offset of the packet in the stream, bytes.
        offset: u64,
    },
    /// A type field the protocol does not define.
    #[error("unknown packet type {ty} at stream offset {offset}")]
    UnknownType {
        /// The type field.
        ty: u32,
        /// Offset of the packet in the stream, bytes.
        offset: u64,
    },
    /// The parser already failed; the stream is out of sync.
    #[error("the packet stream is out of sync after an earlier error")]
    Poisoned,
}

/// One packet, borrowing the parser's buffer until the next call.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Packet<'a> {
    /// An error message (a command failed).
    Error(&'a str),
    /// A command reply (or the welcome).
    Command(&'a str),
    /// XML text.
    Xml(&'a str),
    /// A data frame's payload (decode with [`crate::frame::decode_frame`]).
    Data(&'a [u8]),
    /// No measurement running.
    NoMoreData,
    /// An event number.
    Event(u8),
    /// A packet type the client does not use (C3D, QTM file, discover), skipped.
    Other(PacketType),
}

/// The packet parser.
#[derive(Debug)]
pub struct PacketParser {
    buf: Box<[u8]>,
    start: usize,
    end: usize,
    /// Bytes of the packet returned last, released at the next call.
    pending: usize,
    max_packet: usize,
    /// Stream offset of `buf[start]`.
    offset: u64,
    poisoned: bool,
}

impl Default for PacketParser {
    fn default() -> Self {
        Self::new(MAX_PACKET)
    }
}

impl PacketParser {
    /// A parser accepting packets of at most `max_packet` bytes (at least a header).
    pub fn new(max_packet: usize) -> Self {
        let max_packet = max_packet.max(HEADER_LEN);
        Self {
            buf: vec![0; max_packet + READ_CHUNK].into_boxed_slice(),
            start: 0,
            end: 0,
            pending: 0,
            max_packet,
            offset: 0,
            poisoned: false,
        }
    }

    /// Bytes buffered and not yet returned as packets.
    pub fn buffered(&self) -> usize {
        self.end - self.start - self.pending
    }

    /// Total stream bytes consumed as packets.
    pub fn stream_offset(&self) -> u64 {
        self.offset
    }

    fn release(&mut self) {
        self.start += self.pending;
        self.offset += self.pending as u64;
        self.pending = 0;
        if self.start == self.end {
            self.start = 0;
            self.end = 0;
        }
    }

    fn compact(&mut self) {
        if self.start > 0 {
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
        }
    }

    /// The free space to read into (after releasing the last packet and compacting). Call
    /// [`PacketParser::advance`] with the number of bytes written.
    pub fn spare(&mut self) -> &mut [u8] {
        self.release();
        self.compact();
        &mut self.buf[self.end..]
    }

    /// Marks `n` bytes of [`PacketParser::spare`] as filled.
    pub fn advance(&mut self, n: usize) {
        self.end = (self.end + n).min(self.buf.len());
    }

    /// Copies as many of `bytes` as fit into the buffer; returns how many. Call
    /// [`PacketParser::next_packet`] until it returns `Ok(None)` before pushing the rest.
    pub fn push(&mut self, bytes: &[u8]) -> usize {
        let spare = self.spare();
        let n = bytes.len().min(spare.len());
        spare[..n].copy_from_slice(&bytes[..n]);
        self.advance(n);
        n
    }

    /// The next complete packet, `Ok(None)` if more bytes are needed.
    pub fn next_packet(&mut self) -> Result<Option<Packet<'_>>, ProtocolError> {
        if self.poisoned {
            return Err(ProtocolError::Poisoned);
        }
        self.release();
        let avail = self.end - self.start;
        if avail < HEADER_LEN {
            return Ok(None);
        }
        let h = &self.buf[self.start..self.start + HEADER_LEN];
        let size = u32::from_le_bytes([h[0], h[1], h[2], h[3]]);
        let ty = u32::from_le_bytes([h[4], h[5], h[6], h[7]]);
        let offset = self.offset;
        if (size as usize) < HEADER_LEN {
            self.poisoned = true;
            return Err(ProtocolError::SizeTooSmall { size, offset });
        }
        if size as usize > self.max_packet {
            self.poisoned = true;
            return Err(ProtocolError::SizeTooLarge {
                size,
                max: self.max_packet,
                offset,
            });
        }
        let size = size as usize;
        if avail < size {
            return Ok(None);
        }
        let Some(kind) = PacketType::from_u32(ty) else {
            self.poisoned = true;
            return Err(ProtocolError::UnknownType { ty, offset });
        };
        self.pending = size;
        let body = &self.buf[self.start + HEADER_LEN..self.start + size];
        let text = |name: &'static str| -> Result<&str, ProtocolError> {
            let end = body.iter().position(|&b| b == 0).unwrap_or(body.len());
            std::str::from_utf8(&body[..end])
                .map_err(|_| ProtocolError::NotText { kind: name, offset })
        };
        let p = match kind {
            PacketType::Error => text("error").map(Packet::Error),
            PacketType::Command => text("command").map(Packet::Command),
            PacketType::Xml => text("XML").map(Packet::Xml),
            PacketType::Data => Ok(Packet::Data(body)),
            PacketType::NoMoreData => Ok(Packet::NoMoreData),
            PacketType::Event => match body {
                [e] => Ok(Packet::Event(*e)),
                _ => Err(ProtocolError::BadEvent {
                    len: body.len(),
                    offset,
                }),
            },
            other => Ok(Packet::Other(other)),
        };
        match p {
            Ok(p) => Ok(Some(p)),
            Err(e) => {
                self.poisoned = true;
                Err(e)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{event_packet, string_packet};

    #[test]
    fn packets_split_at_every_byte_and_coalesced_come_out_whole() {
        let mut stream = string_packet(PacketType::Command, "QTM RT Interface connected");
        stream.extend(event_packet(3));
        stream.extend(string_packet(PacketType::Xml, "<a/>"));
        for cut in 0..stream.len() {
            let mut p = PacketParser::new(1024);
            let mut got = Vec::new();
            for part in [&stream[..cut], &stream[cut..]] {
                assert_eq!(p.push(part), part.len());
                while let Some(pk) = p.next_packet().unwrap() {
                    got.push(format!("{pk:?}"));
                }
            }
            assert_eq!(
                got,
                [
                    "Command(\"QTM RT Interface connected\")",
                    "Event(3)",
                    "Xml(\"<a/>\")"
                ],
                "cut at {cut}"
            );
            assert_eq!(p.buffered(), 0);
        }
    }

    #[test]
    fn hostile_sizes_are_errors_and_poison_the_stream() {
        let mut p = PacketParser::new(1024);
        p.push(&[0xff, 0xff, 0xff, 0xff, 3, 0, 0, 0]);
        assert!(matches!(
            p.next_packet(),
            Err(ProtocolError::SizeTooLarge { size: u32::MAX, .. })
        ));
        assert_eq!(p.next_packet(), Err(ProtocolError::Poisoned));
        let mut p = PacketParser::new(1024);
        p.push(&[4, 0, 0, 0, 1, 0, 0, 0]);
        assert!(matches!(
            p.next_packet(),
            Err(ProtocolError::SizeTooSmall { size: 4, .. })
        ));
        let mut p = PacketParser::new(1024);
        p.push(&[10, 0, 0, 0, 6, 0, 0, 0, 1, 2]);
        assert!(matches!(
            p.next_packet(),
            Err(ProtocolError::BadEvent { len: 2, .. })
        ));
        let mut p = PacketParser::new(1024);
        p.push(&[8, 0, 0, 0, 99, 0, 0, 0]);
        assert!(matches!(
            p.next_packet(),
            Err(ProtocolError::UnknownType { ty: 99, .. })
        ));
    }
}
