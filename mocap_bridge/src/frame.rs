//! Data frames: decoding the payload of a data packet (6DOF Euler bodies and labelled 3-D
//! markers, with or without residuals) and encoding one (for the simulator and the fixtures).
//!
//! A frame payload is `timestamp: u64` (microseconds since the capture started), `frame: u32`,
//! `components: u32`, then each component as `size: u32` (its header included), `type: u32`,
//! `count: u32`, `2D drop rate: u16`, `2D out-of-sync rate: u16` and `count` records of f32.
//! QTM marks an unseen marker or body with NaN coordinates: here that is `None`, never a
//! number.

/// Bytes of the frame header after the packet header (timestamp, frame number, count).
pub const FRAME_HEADER_LEN: usize = 16;
/// Bytes of a component header (size, type, count, drop rate, out-of-sync rate).
pub const COMPONENT_HEADER_LEN: usize = 16;

use crate::wire::{component, put_header, PacketType, HEADER_LEN};

/// A 6DOF body as measured (absent when QTM did not see it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Body {
    /// Position x, y, z, mm (capture frame).
    pub position_mm: [f64; 3],
    /// Euler angles 1, 2, 3, deg (QTM's Euler definition; by default rotations about the
    /// capture frame's x, y, z: roll, pitch, yaw).
    pub euler_deg: [f64; 3],
    /// Residual, mm (`None` without residuals or when not a number).
    pub residual_mm: Option<f64>,
}

/// A labelled marker as measured (absent when QTM did not see it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Marker {
    /// Position x, y, z, mm (capture frame).
    pub position_mm: [f64; 3],
    /// Residual, mm (`None` without residuals or when not a number).
    pub residual_mm: Option<f64>,
}

/// One frame: the bodies in the order of the 6DOF parameters, the markers in the order of
/// the 3-D labels.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Frame {
    /// QTM's timestamp, microseconds since the capture started.
    pub timestamp_us: u64,
    /// QTM's frame number.
    pub frame_number: u32,
    /// 6DOF bodies (`None` = not measured in this frame).
    pub bodies: Vec<Option<Body>>,
    /// Labelled markers (`None` = not measured in this frame).
    pub markers: Vec<Option<Marker>>,
    /// 2-D drop rate of the newest camera component, frames per thousand.
    pub drop_rate_2d: u16,
    /// 2-D out-of-sync rate of the newest camera component, frames per thousand.
    pub out_of_sync_2d: u16,
    /// Whether the frame carried a 6DOF component.
    pub has_bodies: bool,
    /// Whether the frame carried a 3-D marker component.
    pub has_markers: bool,
}

/// A malformed data frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// The payload is shorter than the frame header.
    #[error("data packet of {len} bytes is shorter than the 16-byte frame header")]
    ShortHeader {
        /// Payload bytes.
        len: usize,
    },
    /// A component header or size runs past the end of the packet.
    #[error("component {index} (at byte {at}) of size {size} overruns the {len}-byte frame")]
    ComponentOverrun {
        /// Index of the component.
        index: u32,
        /// Byte offset of the component in the payload.
        at: usize,
        /// Its size field.
        size: u32,
        /// Payload bytes.
        len: usize,
    },
    /// A component type the client did not ask for.
    #[error("component {index} has type {ty}, not one the client streams (6, 12, 1, 9)")]
    UnknownComponent {
        /// Index of the component.
        index: u32,
        /// Its type field.
        ty: u32,
    },
    /// The record count does not fit the component's size.
    #[error(
        "component {index} (type {ty}) declares {count} records of {record} bytes, which do not \
         fit its {size} bytes"
    )]
    CountOverrun {
        /// Index of the component.
        index: u32,
        /// Its type.
        ty: u32,
        /// The count field.
        count: u32,
        /// Bytes per record.
        record: usize,
        /// The component's size field.
        size: u32,
    },
    /// Bytes left over after the declared components.
    #[error("{extra} bytes after the {count} declared components")]
    TrailingBytes {
        /// Left-over bytes.
        extra: usize,
        /// Declared components.
        count: u32,
    },
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn f32_at(b: &[u8], at: usize) -> f64 {
    f64::from(f32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]))
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

/// Decodes a data packet's payload into `out` (its vectors are reused: no allocation once
/// they have grown to the frame's size; their length is bounded by the packet size). On error
/// `out` holds a partial frame that must not be used.
pub fn decode_frame(payload: &[u8], out: &mut Frame) -> Result<(), FrameError> {
    let len = payload.len();
    if len < FRAME_HEADER_LEN {
        return Err(FrameError::ShortHeader { len });
    }
    out.timestamp_us = u64::from_le_bytes(payload[0..8].try_into().unwrap_or([0; 8]));
    out.frame_number = u32_at(payload, 8);
    let count = u32_at(payload, 12);
    out.bodies.clear();
    out.markers.clear();
    out.has_bodies = false;
    out.has_markers = false;
    let mut at = FRAME_HEADER_LEN;
    for index in 0..count {
        if len - at < COMPONENT_HEADER_LEN {
            return Err(FrameError::ComponentOverrun {
                index,
                at,
                size: if len - at >= 4 {
                    u32_at(payload, at)
                } else {
                    0
                },
                len,
            });
        }
        let size = u32_at(payload, at);
        let ty = u32_at(payload, at + 4);
        if (size as usize) < COMPONENT_HEADER_LEN || size as usize > len - at {
            return Err(FrameError::ComponentOverrun {
                index,
                at,
                size,
                len,
            });
        }
        let n = u32_at(payload, at + 8);
        out.drop_rate_2d = u16::from_le_bytes([payload[at + 12], payload[at + 13]]);
        out.out_of_sync_2d = u16::from_le_bytes([payload[at + 14], payload[at + 15]]);
        let record = match ty {
            component::EULER_6D => 24,
            component::EULER_6D_RES => 28,
            component::MARKERS_3D => 12,
            component::MARKERS_3D_RES => 16,
            _ => return Err(FrameError::UnknownComponent { index, ty }),
        };
        let body_len = size as usize - COMPONENT_HEADER_LEN;
        if (n as usize).checked_mul(record) != Some(body_len) {
            return Err(FrameError::CountOverrun {
                index,
                ty,
                count: n,
                record,
                size,
            });
        }
        let data = &payload[at + COMPONENT_HEADER_LEN..at + size as usize];
        let res = record == 28 || record == 16;
        if matches!(ty, component::EULER_6D | component::EULER_6D_RES) {
            out.has_bodies = true;
            out.bodies.clear();
            for r in data.chunks_exact(record) {
                let v: [f64; 6] = std::array::from_fn(|k| f32_at(r, 4 * k));
                out.bodies
                    .push(v.iter().all(|x| x.is_finite()).then(|| Body {
                        position_mm: [v[0], v[1], v[2]],
                        euler_deg: [v[3], v[4], v[5]],
                        residual_mm: if res { finite(f32_at(r, 24)) } else { None },
                    }));
            }
        } else {
            out.has_markers = true;
            out.markers.clear();
            for r in data.chunks_exact(record) {
                let v: [f64; 3] = std::array::from_fn(|k| f32_at(r, 4 * k));
                out.markers
                    .push(v.iter().all(|x| x.is_finite()).then(|| Marker {
                        position_mm: v,
                        residual_mm: if res { finite(f32_at(r, 12)) } else { None },
                    }));
            }
        }
        at += size as usize;
    }
    if at != len {
        return Err(FrameError::TrailingBytes {
            extra: len - at,
            count,
        });
    }
    Ok(())
}

/// Which components an encoded frame carries (what a client asked for).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Components {
    /// 6DOF Euler (type 6).
    pub euler: bool,
    /// 6DOF Euler with residuals (type 12).
    pub euler_res: bool,
    /// 3-D markers (type 1).
    pub markers: bool,
    /// 3-D markers with residuals (type 9).
    pub markers_res: bool,
}

impl Components {
    /// 6DOF Euler with residuals and 3-D markers with residuals (what the bridge streams).
    pub const BRIDGE: Components = Components {
        euler: false,
        euler_res: true,
        markers: false,
        markers_res: true,
    };

    /// The command arguments (`6DEulerRes 3DRes`).
    pub fn command_args(&self) -> String {
        let mut v = Vec::new();
        if self.euler {
            v.push("6DEuler");
        }
        if self.euler_res {
            v.push("6DEulerRes");
        }
        if self.markers {
            v.push("3D");
        }
        if self.markers_res {
            v.push("3DRes");
        }
        v.join(" ")
    }
}

const NAN: f32 = f32::NAN;

/// Appends a whole data packet (header included) of `frame` with the given components.
pub fn put_frame(buf: &mut Vec<u8>, frame: &Frame, c: Components) {
    let start = buf.len();
    put_header(buf, 0, PacketType::Data);
    buf.extend_from_slice(&frame.timestamp_us.to_le_bytes());
    buf.extend_from_slice(&frame.frame_number.to_le_bytes());
    let n = [c.euler, c.euler_res, c.markers, c.markers_res]
        .iter()
        .filter(|&&b| b)
        .count() as u32;
    buf.extend_from_slice(&n.to_le_bytes());
    let f = |buf: &mut Vec<u8>, v: f64| buf.extend_from_slice(&(v as f32).to_le_bytes());
    let comp_header = |buf: &mut Vec<u8>, ty: u32, count: usize, record: usize| {
        let size = COMPONENT_HEADER_LEN + count * record;
        buf.extend_from_slice(&(size as u32).to_le_bytes());
        buf.extend_from_slice(&ty.to_le_bytes());
        buf.extend_from_slice(&(count as u32).to_le_bytes());
        buf.extend_from_slice(&frame.drop_rate_2d.to_le_bytes());
        buf.extend_from_slice(&frame.out_of_sync_2d.to_le_bytes());
    };
    for (on, res) in [(c.euler, false), (c.euler_res, true)] {
        if !on {
            continue;
        }
        let (ty, rec) = if res {
            (component::EULER_6D_RES, 28)
        } else {
            (component::EULER_6D, 24)
        };
        comp_header(buf, ty, frame.bodies.len(), rec);
        for b in &frame.bodies {
            match b {
                Some(b) => {
                    for v in b.position_mm.iter().chain(&b.euler_deg) {
                        f(buf, *v);
                    }
                    if res {
                        f(buf, b.residual_mm.unwrap_or(f64::NAN));
                    }
                }
                None => {
                    for _ in 0..rec / 4 {
                        buf.extend_from_slice(&NAN.to_le_bytes());
                    }
                }
            }
        }
    }
    for (on, res) in [(c.markers, false), (c.markers_res, true)] {
        if !on {
            continue;
        }
        let (ty, rec) = if res {
            (component::MARKERS_3D_RES, 16)
        } else {
            (component::MARKERS_3D, 12)
        };
        comp_header(buf, ty, frame.markers.len(), rec);
        for m in &frame.markers {
            match m {
                Some(m) => {
                    for v in m.position_mm {
                        f(buf, v);
                    }
                    if res {
                        f(buf, m.residual_mm.unwrap_or(f64::NAN));
                    }
                }
                None => {
                    for _ in 0..rec / 4 {
                        buf.extend_from_slice(&NAN.to_le_bytes());
                    }
                }
            }
        }
    }
    let size = (buf.len() - start) as u32;
    buf[start..start + 4].copy_from_slice(&size.to_le_bytes());
}

/// The payload of a data packet (without its 8-byte header), for tests and benchmarks.
pub fn frame_payload(frame: &Frame, c: Components) -> Vec<u8> {
    let mut b = Vec::new();
    put_frame(&mut b, frame, c);
    b.split_off(HEADER_LEN)
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn sample() -> Frame {
        Frame {
            timestamp_us: 1_234_567,
            frame_number: 42,
            bodies: vec![
                Some(Body {
                    position_mm: [10.5, -3.25, 0.0],
                    euler_deg: [0.0, 0.0, 12.5],
                    residual_mm: Some(0.25),
                }),
                None,
            ],
            markers: vec![
                Some(Marker {
                    position_mm: [-246.75, -142.5, 0.0],
                    residual_mm: Some(0.5),
                }),
                None,
                Some(Marker {
                    position_mm: [1.0, 2.0, 3.0],
                    residual_mm: None,
                }),
            ],
            drop_rate_2d: 0,
            out_of_sync_2d: 0,
            has_bodies: true,
            has_markers: true,
        }
    }

    #[test]
    fn a_frame_round_trips_with_not_measured_as_none() {
        let f = sample();
        let mut out = Frame::default();
        decode_frame(&frame_payload(&f, Components::BRIDGE), &mut out).unwrap();
        assert_eq!(out, f);
        // without residuals the residuals are gone, the rest is the same
        let c = Components {
            euler: true,
            markers: true,
            ..Default::default()
        };
        decode_frame(&frame_payload(&f, c), &mut out).unwrap();
        assert_eq!(out.bodies[0].unwrap().residual_mm, None);
        assert_eq!(out.bodies[1], None);
        assert_eq!(out.markers[0].unwrap().position_mm, [-246.75, -142.5, 0.0]);
    }

    #[test]
    fn counts_overrunning_the_component_are_errors() {
        let f = sample();
        let mut p = frame_payload(&f, Components::BRIDGE);
        // body count of the first component (offset 16 + 8) raised to 1000
        p[24..28].copy_from_slice(&1000u32.to_le_bytes());
        let mut out = Frame::default();
        assert!(matches!(
            decode_frame(&p, &mut out),
            Err(FrameError::CountOverrun { count: 1000, .. })
        ));
        let mut p = frame_payload(&f, Components::BRIDGE);
        p[12..16].copy_from_slice(&3u32.to_le_bytes());
        assert!(matches!(
            decode_frame(&p, &mut out),
            Err(FrameError::ComponentOverrun { index: 2, .. })
        ));
        let mut p = frame_payload(&f, Components::BRIDGE);
        p[20..24].copy_from_slice(&77u32.to_le_bytes());
        assert_eq!(
            decode_frame(&p, &mut out),
            Err(FrameError::UnknownComponent { index: 0, ty: 77 })
        );
    }
}
