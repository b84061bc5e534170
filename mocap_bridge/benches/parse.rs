//! Parsing one frame of 1 body and 9 markers (6DOF Euler + 3-D, both with residuals): the
//! packet parser and the frame decoder, from bytes to a decoded frame.

use criterion::{criterion_group, criterion_main, Criterion};
use pcr_mocap_bridge::frame::{decode_frame, put_frame};
use pcr_mocap_bridge::parser::{Packet, PacketParser};
use pcr_mocap_bridge::{Body, Components, Frame, Marker};
use std::hint::black_box;

fn frame() -> Frame {
    Frame {
        timestamp_us: 123_456_789,
        frame_number: 4242,
        bodies: vec![Some(Body {
            position_mm: [12.5, -7.25, 0.5],
            euler_deg: [0.1, -0.2, 33.0],
            residual_mm: Some(0.3),
        })],
        markers: (0..9)
            .map(|i| {
                (i != 4).then(|| Marker {
                    position_mm: [i as f64 * 10.0, -5.0, 0.25],
                    residual_mm: Some(0.2),
                })
            })
            .collect(),
        has_bodies: true,
        has_markers: true,
        ..Default::default()
    }
}

fn bench(c: &mut Criterion) {
    let mut bytes = Vec::new();
    put_frame(&mut bytes, &frame(), Components::BRIDGE);
    let mut parser = PacketParser::default();
    let mut out = Frame::default();
    c.bench_function("parse_frame_1_body_9_markers", |b| {
        b.iter(|| {
            parser.push(black_box(&bytes));
            if let Ok(Some(Packet::Data(d))) = parser.next_packet() {
                decode_frame(d, &mut out).ok();
            }
            black_box(&out);
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
