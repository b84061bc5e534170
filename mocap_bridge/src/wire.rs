//! The QTM RT packet layer: packet types, the 8-byte header and the encoders of the packets the
//! project sends (commands from the client, replies and frames from the simulator).
//!
//! Every packet is `size: u32` (the whole packet, header included), `type: u32`, then
//! `size - 8` bytes of payload, little-endian on the little-endian port (the default
//! 22223). Strings (error, command, XML) are NUL-terminated on the wire.

use std::fmt;

/// Bytes of a packet header (size + type).
pub const HEADER_LEN: usize = 8;

/// The largest packet the client accepts, bytes (1 MiB). A frame of 1 body and 9 markers is
/// 204 bytes; the parameters XML of a large lab some tens of kB. A size field above this is a
/// protocol error (never an allocation).
pub const MAX_PACKET: usize = 1 << 20;

/// The default little-endian port of a QTM RT server.
pub const DEFAULT_PORT: u16 = 22223;

/// The welcome string a server sends on connection (as a command packet).
pub const WELCOME: &str = "QTM RT Interface connected";

/// Packet types (the header's `type` field).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum PacketType {
    /// The last command failed; the payload is the message.
    Error = 0,
    /// A command, or a successful command's reply.
    Command = 1,
    /// XML (parameters).
    Xml = 2,
    /// One frame of data.
    Data = 3,
    /// No measurement is running (header only).
    NoMoreData = 4,
    /// A C3D file.
    C3d = 5,
    /// An event (one byte).
    Event = 6,
    /// Auto-discover.
    Discover = 7,
    /// A QTM file.
    QtmFile = 8,
}

impl PacketType {
    /// From the wire value.
    pub fn from_u32(v: u32) -> Option<PacketType> {
        Some(match v {
            0 => PacketType::Error,
            1 => PacketType::Command,
            2 => PacketType::Xml,
            3 => PacketType::Data,
            4 => PacketType::NoMoreData,
            5 => PacketType::C3d,
            6 => PacketType::Event,
            7 => PacketType::Discover,
            8 => PacketType::QtmFile,
            _ => return None,
        })
    }
}

/// Data component types used by the project (the header's `type` field of a component).
pub mod component {
    /// Labelled 3-D markers: x, y, z (f32 mm).
    pub const MARKERS_3D: u32 = 1;
    /// 6DOF bodies, position and Euler angles (f32 mm, deg).
    pub const EULER_6D: u32 = 6;
    /// Labelled 3-D markers with residuals: x, y, z, residual (f32 mm).
    pub const MARKERS_3D_RES: u32 = 9;
    /// 6DOF bodies, position, Euler angles and residual (f32 mm, deg, mm).
    pub const EULER_6D_RES: u32 = 12;
}

/// QTM events (the byte of an event packet).
pub mod event {
    /// QTM connected to the cameras.
    pub const CONNECTED: u8 = 1;
    /// QTM disconnected from the cameras.
    pub const CONNECTION_CLOSED: u8 = 2;
    /// A capture started.
    pub const CAPTURE_STARTED: u8 = 3;
    /// A capture stopped.
    pub const CAPTURE_STOPPED: u8 = 4;
    /// Camera settings changed (the parameters may have changed).
    pub const CAMERA_SETTINGS_CHANGED: u8 = 11;
    /// QTM is shutting down.
    pub const QTM_SHUTTING_DOWN: u8 = 12;
}

/// A protocol version `major.minor` (`Version 1.25`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Version {
    /// Major number (1).
    pub major: u8,
    /// Minor number.
    pub minor: u8,
}

impl Version {
    /// `major.minor`.
    pub const fn new(major: u8, minor: u8) -> Version {
        Version { major, minor }
    }
    /// The newest version the client asks for.
    pub const NEWEST: Version = Version::new(1, 25);
    /// The oldest version the client accepts.
    pub const OLDEST: Version = Version::new(1, 19);

    /// Parses `1.25`.
    pub fn parse(s: &str) -> Option<Version> {
        let (a, b) = s.trim().split_once('.')?;
        Some(Version::new(a.parse().ok()?, b.parse().ok()?))
    }

    /// The next older minor version (`None` at `x.0`).
    pub fn older(self) -> Option<Version> {
        self.minor
            .checked_sub(1)
            .map(|m| Version::new(self.major, m))
    }
}

impl fmt::Display for Version {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{}", self.major, self.minor)
    }
}

/// Appends a packet header.
pub fn put_header(buf: &mut Vec<u8>, size: usize, ty: PacketType) {
    buf.extend_from_slice(&(size as u32).to_le_bytes());
    buf.extend_from_slice(&(ty as u32).to_le_bytes());
}

/// Appends a string packet (command, error or XML), NUL-terminated.
pub fn put_string(buf: &mut Vec<u8>, ty: PacketType, s: &str) {
    put_header(buf, HEADER_LEN + s.len() + 1, ty);
    buf.extend_from_slice(s.as_bytes());
    buf.push(0);
}

/// A string packet (command, error or XML) as a new buffer.
pub fn string_packet(ty: PacketType, s: &str) -> Vec<u8> {
    let mut b = Vec::with_capacity(HEADER_LEN + s.len() + 1);
    put_string(&mut b, ty, s);
    b
}

/// An event packet.
pub fn event_packet(ev: u8) -> Vec<u8> {
    let mut b = Vec::with_capacity(HEADER_LEN + 1);
    put_header(&mut b, HEADER_LEN + 1, PacketType::Event);
    b.push(ev);
    b
}

/// A no-more-data packet.
pub fn no_more_data_packet() -> Vec<u8> {
    let mut b = Vec::with_capacity(HEADER_LEN);
    put_header(&mut b, HEADER_LEN, PacketType::NoMoreData);
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn versions_print_and_parse_and_step_down() {
        assert_eq!(Version::NEWEST.to_string(), "1.25");
        assert_eq!(Version::new(1, 5).to_string(), "1.5");
        assert_eq!(Version::parse("1.19"), Some(Version::new(1, 19)));
        assert_eq!(Version::parse(" 1.05 "), Some(Version::new(1, 5)));
        assert_eq!(Version::parse("x"), None);
        assert_eq!(Version::NEWEST.older(), Some(Version::new(1, 24)));
        assert!(Version::new(1, 19) < Version::new(1, 25));
    }

    #[test]
    fn string_packets_carry_their_size_and_a_nul() {
        let p = string_packet(PacketType::Command, "Version 1.2");
        assert_eq!(&p[..4], &20u32.to_le_bytes());
        assert_eq!(&p[4..8], &1u32.to_le_bytes());
        assert_eq!(*p.last().unwrap(), 0);
        assert_eq!(event_packet(3), vec![9, 0, 0, 0, 6, 0, 0, 0, 3]);
        assert_eq!(no_more_data_packet(), vec![8, 0, 0, 0, 4, 0, 0, 0]);
    }
}
