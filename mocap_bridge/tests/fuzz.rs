//! Property-based fuzzing of the packet parser, the frame decoder and the parameters parser
//! (proptest; a smoke run in CI: `PROPTEST_CASES` raises the case count, see docs/mocap.md).
//! Properties: no panic on any input; the parser's buffer never grows past its fixed bound;
//! valid streams survive arbitrary splitting; single-byte corruptions of valid frames give a
//! frame or an error, never a panic.

use pcr_mocap_bridge::frame::{decode_frame, frame_payload, put_frame};
use pcr_mocap_bridge::parser::{Packet, PacketParser};
use pcr_mocap_bridge::{Body, Components, Frame, Marker, Parameters, Version};
use proptest::prelude::*;

const MAX: usize = 4096;

fn config() -> ProptestConfig {
    ProptestConfig {
        cases: std::env::var("PROPTEST_CASES")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(512),
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

fn drain(p: &mut PacketParser, frame: &mut Frame) -> bool {
    loop {
        match p.next_packet() {
            Ok(Some(Packet::Data(d))) => {
                let _ = decode_frame(d, frame);
            }
            Ok(Some(_)) => {}
            Ok(None) => return true,
            Err(_) => return false,
        }
    }
}

fn arb_frame() -> impl Strategy<Value = Frame> {
    let f = prop_oneof![Just(f64::NAN), -1e4f64..1e4];
    let body = proptest::array::uniform7(f.clone()).prop_map(|v| {
        v[..6].iter().all(|x| x.is_finite()).then(|| Body {
            position_mm: [v[0], v[1], v[2]],
            euler_deg: [v[3], v[4], v[5]],
            residual_mm: v[6].is_finite().then_some(v[6]),
        })
    });
    let marker = proptest::array::uniform4(f).prop_map(|v| {
        v[..3].iter().all(|x| x.is_finite()).then(|| Marker {
            position_mm: [v[0], v[1], v[2]],
            residual_mm: v[3].is_finite().then_some(v[3]),
        })
    });
    (
        any::<u64>(),
        any::<u32>(),
        proptest::collection::vec(body, 0..4),
        proptest::collection::vec(marker, 0..12),
    )
        .prop_map(|(ts, n, bodies, markers)| Frame {
            timestamp_us: ts,
            frame_number: n,
            bodies,
            markers,
            has_bodies: true,
            has_markers: true,
            ..Default::default()
        })
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn random_bytes_never_panic_nor_grow_the_buffer(chunks in proptest::collection::vec(
        proptest::collection::vec(any::<u8>(), 0..600), 0..12)) {
        let mut p = PacketParser::new(MAX);
        let mut f = Frame::default();
        'feed: for c in &chunks {
            let mut rest = &c[..];
            while !rest.is_empty() {
                let n = p.push(rest);
                rest = &rest[n..];
                prop_assert!(p.buffered() <= MAX + pcr_mocap_bridge::parser::READ_CHUNK);
                if !drain(&mut p, &mut f) {
                    break 'feed;
                }
            }
        }
    }

    #[test]
    fn plausible_packets_with_lying_sizes_and_counts_never_panic(packets in proptest::collection::vec(
        (0u32..10, -3i32..4, 0u32..6, proptest::collection::vec(
            (prop_oneof![Just(1u32), Just(6), Just(9), Just(12), 0u32..20], 0u32..8, -20i32..20,
             proptest::collection::vec(any::<u8>(), 0..64)), 0..4)), 1..8)) {
        // headers that are nearly right: real types, sizes off by a few bytes, data packets
        // of components with real or unknown types, counts and sizes that may lie
        let mut stream = Vec::new();
        for (ty, size_err, n_comp, comps) in &packets {
            let mut body = Vec::new();
            if *ty == 3 {
                body.extend_from_slice(&7u64.to_le_bytes());
                body.extend_from_slice(&1u32.to_le_bytes());
                body.extend_from_slice(&n_comp.to_le_bytes());
                for (cty, count, cerr, data) in comps {
                    let size = (16 + data.len()) as i64 + i64::from(*cerr);
                    body.extend_from_slice(&(size.max(0) as u32).to_le_bytes());
                    body.extend_from_slice(&cty.to_le_bytes());
                    body.extend_from_slice(&count.to_le_bytes());
                    body.extend_from_slice(&[0, 0, 0, 0]);
                    body.extend_from_slice(data);
                }
            } else if let Some((_, _, _, data)) = comps.first() {
                body.extend_from_slice(data);
            }
            let size = (8 + body.len()) as i64 + i64::from(*size_err);
            stream.extend_from_slice(&(size.max(0) as u32).to_le_bytes());
            stream.extend_from_slice(&ty.to_le_bytes());
            stream.extend_from_slice(&body);
        }
        let mut p = PacketParser::new(MAX);
        let mut f = Frame::default();
        p.push(&stream);
        drain(&mut p, &mut f);
    }

    #[test]
    fn random_payloads_never_panic_the_frame_decoder(
        payload in proptest::collection::vec(any::<u8>(), 0..400)) {
        let mut f = Frame::default();
        let _ = decode_frame(&payload, &mut f);
        prop_assert!(f.bodies.len() + f.markers.len() <= payload.len() / 12 + 1);
    }

    #[test]
    fn valid_frames_survive_any_split_and_corruption_is_contained(
        frames in proptest::collection::vec(arb_frame(), 1..4),
        cuts in proptest::collection::vec(any::<prop::sample::Index>(), 0..6),
        flip in any::<prop::sample::Index>(), byte in any::<u8>()) {
        let mut stream = Vec::new();
        for fr in &frames {
            put_frame(&mut stream, fr, Components::BRIDGE);
        }
        let mut at: Vec<usize> = cuts.iter().map(|i| i.index(stream.len())).collect();
        at.sort_unstable();
        at.push(stream.len());
        let mut p = PacketParser::new(MAX);
        let mut got = Vec::new();
        let mut from = 0;
        for c in at {
            p.push(&stream[from..c]);
            from = c;
            while let Some(pk) = p.next_packet().unwrap() {
                let Packet::Data(d) = pk else { panic!("{pk:?}") };
                let mut f = Frame::default();
                decode_frame(d, &mut f).unwrap();
                got.push(f);
            }
        }
        prop_assert_eq!(got.len(), frames.len());
        for (g, f) in got.iter().zip(&frames) {
            prop_assert_eq!(g.frame_number, f.frame_number);
            prop_assert_eq!(g.bodies.iter().filter(|b| b.is_some()).count(),
                            f.bodies.iter().filter(|b| b.is_some()).count());
        }
        // one corrupted byte in a payload: a frame or an error, never a panic
        let mut payload = frame_payload(&frames[0], Components::BRIDGE);
        let i = flip.index(payload.len());
        payload[i] = byte;
        let mut f = Frame::default();
        let _ = decode_frame(&payload, &mut f);
    }

    #[test]
    fn random_and_mutated_xml_never_panics(text in ".{0,300}", cut in any::<prop::sample::Index>(),
                                           junk in "[<>/&a-zA-Z_0-9\" =.]{0,20}") {
        let _ = Parameters::parse(&text);
        let p = Parameters {
            version: None,
            frequency_hz: Some(100.0),
            labels: vec!["B1".into(), "M1".into()],
            bodies: vec!["platform".into()],
        };
        let mut x = p.to_xml(Version::NEWEST, true, true, true);
        let mut i = cut.index(x.len());
        while !x.is_char_boundary(i) {
            i -= 1;
        }
        x.insert_str(i, &junk);
        if let Ok(q) = Parameters::parse(&x) {
            prop_assert!(q.labels.len() <= 10 && q.bodies.len() <= 10);
        }
    }
}
