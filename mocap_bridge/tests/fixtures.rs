//! Byte-level fixtures of the QTM RT protocol (laid out by hand from the protocol
//! documentation, independent of the crate's encoders) played by a scripted server against
//! the client: welcome, version negotiation down to an older server, parameters XML, frames
//! with several components, events interleaved with replies, a header split across reads, a
//! truncated packet, an oversized size field, garbage after the welcome, error and
//! no-more-data packets.

use pcr_mocap_bridge::client::Item;
use pcr_mocap_bridge::parser::ProtocolError;
use pcr_mocap_bridge::{ClientConfig, ClientError, QtmClient, Version};
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// One step of a scripted server.
enum Step {
    /// Send these bytes in one write.
    Send(Vec<u8>),
    /// Send these bytes in pieces cut at the given offsets, pausing between pieces.
    SendSplit(Vec<u8>, Vec<usize>),
    /// Read one command packet and check its text.
    Expect(&'static str),
    /// Close the connection.
    Close,
}

/// A string packet as the documentation lays it out: size (LE u32, header included), type,
/// text, NUL.
fn pkt(ty: u32, text: &str) -> Vec<u8> {
    let mut b = Vec::new();
    b.extend_from_slice(&((8 + text.len() + 1) as u32).to_le_bytes());
    b.extend_from_slice(&ty.to_le_bytes());
    b.extend_from_slice(text.as_bytes());
    b.push(0);
    b
}

fn welcome() -> Vec<u8> {
    // 35 bytes: 8 header + 26 characters + NUL
    let w = pkt(1, "QTM RT Interface connected");
    assert_eq!(&w[..8], &[35, 0, 0, 0, 1, 0, 0, 0]);
    w
}

fn event(e: u8) -> Vec<u8> {
    vec![9, 0, 0, 0, 6, 0, 0, 0, e]
}

const PARAMS: &str = "<QTM_Parameters_Ver_1.25>\
<General><Frequency>100</Frequency><Capture_Time>10.0</Capture_Time></General>\
<The_3D><AxisUpwards>+Z</AxisUpwards><Labels>3</Labels>\
<Label><Name>B1</Name><RGBColor>255</RGBColor></Label>\
<Label><Name>B2</Name><RGBColor>255</RGBColor></Label>\
<Label><Name>M1</Name><RGBColor>255</RGBColor></Label></The_3D>\
<The_6D><Body><Name>platform</Name><Enabled>true</Enabled><Points>\
<Point X=\"1\" Y=\"2\" Z=\"3\" Virtual=\"0\" PhysicalId=\"0\" Name=\"p1\"/></Points></Body>\
<Body><Name>wand</Name></Body></The_6D></QTM_Parameters_Ver_1.25>";

/// A data packet: timestamp 1 000 000 us, frame 7, two components: 6DOF Euler with
/// residuals (2 bodies: `platform` at (10, 20, 30) mm, angles (0, 0, 45) deg, residual 0.5;
/// `wand` not seen: NaN) and 3-D with residuals (3 markers: B1 (1, 2, 3) res 0.25, B2 not
/// seen, M1 (-4, 5.5, 0) res 0.125).
fn frame_packet() -> Vec<u8> {
    let f = |v: f32| v.to_le_bytes();
    let nan = f32::NAN.to_le_bytes();
    let mut six = Vec::new();
    six.extend_from_slice(&(16u32 + 2 * 28).to_le_bytes()); // component size
    six.extend_from_slice(&12u32.to_le_bytes()); // 6DOF Euler residual
    six.extend_from_slice(&2u32.to_le_bytes()); // body count
    six.extend_from_slice(&[0, 0, 0, 0]); // 2D drop rate, out-of-sync rate
    for v in [10.0, 20.0, 30.0, 0.0, 0.0, 45.0, 0.5] {
        six.extend_from_slice(&f(v));
    }
    for _ in 0..7 {
        six.extend_from_slice(&nan);
    }
    let mut three = Vec::new();
    three.extend_from_slice(&(16u32 + 3 * 16).to_le_bytes());
    three.extend_from_slice(&9u32.to_le_bytes()); // 3D residual
    three.extend_from_slice(&3u32.to_le_bytes());
    three.extend_from_slice(&[0, 0, 0, 0]);
    for v in [1.0, 2.0, 3.0, 0.25] {
        three.extend_from_slice(&f(v));
    }
    for _ in 0..4 {
        three.extend_from_slice(&[0xff, 0xff, 0xff, 0xff]); // QTM's "all bits set" NaN
    }
    for v in [-4.0, 5.5, 0.0, 0.125] {
        three.extend_from_slice(&f(v));
    }
    let mut b = Vec::new();
    let size = 8 + 16 + six.len() + three.len();
    b.extend_from_slice(&(size as u32).to_le_bytes());
    b.extend_from_slice(&3u32.to_le_bytes());
    b.extend_from_slice(&1_000_000u64.to_le_bytes());
    b.extend_from_slice(&7u32.to_le_bytes());
    b.extend_from_slice(&2u32.to_le_bytes());
    b.extend(six);
    b.extend(three);
    b
}

fn read_command(s: &mut TcpStream) -> String {
    let mut h = [0u8; 8];
    s.read_exact(&mut h).unwrap();
    let size = u32::from_le_bytes(h[..4].try_into().unwrap()) as usize;
    assert_eq!(
        u32::from_le_bytes(h[4..].try_into().unwrap()),
        1,
        "a command packet"
    );
    let mut body = vec![0; size - 8];
    s.read_exact(&mut body).unwrap();
    String::from_utf8(body)
        .unwrap()
        .trim_end_matches('\0')
        .into()
}

/// Plays `script` to the first client; returns its port and the thread (which fails the test
/// if the client sends something else).
fn scripted(script: Vec<Step>) -> (u16, JoinHandle<()>) {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = l.local_addr().unwrap().port();
    let t = std::thread::spawn(move || {
        let (mut s, _) = l.accept().unwrap();
        s.set_nodelay(true).unwrap();
        for step in script {
            match step {
                Step::Send(b) => s.write_all(&b).unwrap(),
                Step::SendSplit(b, cuts) => {
                    let mut from = 0;
                    for c in cuts.into_iter().chain([b.len()]) {
                        s.write_all(&b[from..c]).unwrap();
                        s.flush().unwrap();
                        std::thread::sleep(Duration::from_millis(20));
                        from = c;
                    }
                }
                Step::Expect(cmd) => assert_eq!(read_command(&mut s), cmd),
                Step::Close => return,
            }
        }
        // keep the connection open until the client goes
        let mut sink = [0u8; 256];
        let _ = s.set_read_timeout(Some(Duration::from_secs(5)));
        while matches!(s.read(&mut sink), Ok(n) if n > 0) {}
    });
    (port, t)
}

fn cfg(port: u16) -> ClientConfig {
    let mut c = ClientConfig::new("127.0.0.1", port);
    c.reply_timeout = Duration::from_secs(5);
    c
}

fn next(c: &mut QtmClient) -> Result<Option<Item>, ClientError> {
    c.next(Instant::now() + Duration::from_secs(5))
}

#[test]
fn welcome_negotiation_parameters_and_a_frame_of_two_components() {
    let frame = frame_packet();
    let (port, t) = scripted(vec![
        // the welcome, its header split across two reads
        Step::SendSplit(welcome(), vec![3]),
        Step::Expect("Version 1.25"),
        // an event interleaved before the reply
        Step::Send([event(3), pkt(1, "Version set to 1.25")].concat()),
        Step::Expect("GetParameters General 3D 6D"),
        Step::SendSplit([event(11), pkt(2, PARAMS)].concat(), vec![9, 12, 100]),
        Step::Expect("StreamFrames AllFrames 6DEulerRes 3DRes"),
        // no more data first, then the frame cut in the middle of a component header and
        // coalesced with an event and a second copy of the frame
        Step::Send(vec![8, 0, 0, 0, 4, 0, 0, 0]),
        Step::SendSplit(
            [frame.clone(), event(4), frame.clone()].concat(),
            vec![30, frame.len() + 4],
        ),
    ]);
    let mut c = QtmClient::connect(&cfg(port)).unwrap();
    assert_eq!(c.version(), Version::new(1, 25));
    let p = c.parameters().unwrap();
    assert_eq!(p.frequency_hz, Some(100.0));
    assert_eq!(p.labels, ["B1", "B2", "M1"]);
    assert_eq!(p.bodies, ["platform", "wand"]);
    assert_eq!(c.take_events(), vec![3, 11]);
    c.start_streaming().unwrap();
    assert_eq!(next(&mut c).unwrap(), Some(Item::NoMoreData));
    assert_eq!(next(&mut c).unwrap(), Some(Item::Frame));
    let f = c.frame().clone();
    assert_eq!((f.timestamp_us, f.frame_number), (1_000_000, 7));
    let b = f.bodies[0].unwrap();
    assert_eq!(b.position_mm, [10.0, 20.0, 30.0]);
    assert_eq!(b.euler_deg, [0.0, 0.0, 45.0]);
    assert_eq!(b.residual_mm, Some(0.5));
    assert_eq!(f.bodies[1], None, "NaN body = not measured");
    assert_eq!(f.markers[0].unwrap().position_mm, [1.0, 2.0, 3.0]);
    assert_eq!(f.markers[1], None, "NaN marker = not measured");
    assert_eq!(f.markers[2].unwrap().residual_mm, Some(0.125));
    assert_eq!(next(&mut c).unwrap(), Some(Item::Event(4)));
    assert_eq!(next(&mut c).unwrap(), Some(Item::Frame));
    assert_eq!(c.frame(), &f);
    drop(c);
    t.join().unwrap();
}

#[test]
fn negotiation_steps_down_to_an_older_server() {
    let mut script = vec![Step::Send(welcome())];
    for v in ["1.25", "1.24", "1.23", "1.22", "1.21"] {
        script.push(Step::Expect(match v {
            "1.25" => "Version 1.25",
            "1.24" => "Version 1.24",
            "1.23" => "Version 1.23",
            "1.22" => "Version 1.22",
            _ => "Version 1.21",
        }));
        script.push(Step::Send(pkt(0, "Version NOT supported")));
    }
    script.push(Step::Expect("Version 1.20"));
    script.push(Step::Send(pkt(1, "Version set to 1.20")));
    let (port, t) = scripted(script);
    let c = QtmClient::connect(&cfg(port)).unwrap();
    assert_eq!(c.version(), Version::new(1, 20));
    drop(c);
    t.join().unwrap();
}

#[test]
fn a_server_older_than_1_19_is_refused() {
    let mut script = vec![Step::Send(welcome())];
    for _ in 19..=25 {
        script.push(Step::Send(pkt(0, "Version NOT supported")));
    }
    let (port, _t) = scripted(script);
    let e = QtmClient::connect(&cfg(port)).unwrap_err();
    assert!(matches!(e, ClientError::NoVersion { .. }), "{e}");
    assert!(e.to_string().contains("1.25 down to 1.19"), "{e}");
}

fn streaming_client(after_stream: Vec<u8>) -> Result<Vec<Item>, ClientError> {
    let (port, _t) = scripted(vec![
        Step::Send(welcome()),
        Step::Expect("Version 1.25"),
        Step::Send(pkt(1, "Version set to 1.25")),
        Step::Expect("StreamFrames AllFrames 6DEulerRes 3DRes"),
        Step::Send(after_stream),
        Step::Close,
    ]);
    let mut c = QtmClient::connect(&cfg(port))?;
    c.start_streaming()?;
    let mut items = Vec::new();
    loop {
        match next(&mut c)? {
            Some(i) => items.push(i),
            None => return Ok(items),
        }
    }
}

#[test]
fn a_truncated_packet_is_a_closed_connection_not_a_frame() {
    let f = frame_packet();
    let e = streaming_client(f[..f.len() - 5].to_vec()).unwrap_err();
    assert!(matches!(e, ClientError::Closed), "{e}");
}

#[test]
fn an_oversized_size_field_is_a_protocol_error_without_allocation() {
    let e = streaming_client(vec![0xff, 0xff, 0xff, 0xff, 3, 0, 0, 0, 1, 2, 3]).unwrap_err();
    assert!(
        matches!(
            e,
            ClientError::Protocol(ProtocolError::SizeTooLarge { size: u32::MAX, .. })
        ),
        "{e}"
    );
}

#[test]
fn an_error_packet_while_streaming_is_reported() {
    let e = streaming_client(pkt(0, "Parse error")).unwrap_err();
    assert!(e.to_string().contains("Parse error"), "{e}");
}

#[test]
fn garbage_after_the_welcome_is_a_protocol_error() {
    let (port, _t) = scripted(vec![
        Step::Send(welcome()),
        Step::Expect("Version 1.25"),
        Step::Send(b"HTTP/1.1 400 Bad Request\r\n\r\n".to_vec()),
    ]);
    let e = QtmClient::connect(&cfg(port)).unwrap_err();
    assert!(matches!(e, ClientError::Protocol(_)), "{e}");
}

#[test]
fn a_full_server_refuses_with_an_error_packet() {
    let (port, _t) = scripted(vec![Step::Send(pkt(
        0,
        "Connection refused. Max number of clients reached.",
    ))]);
    let e = QtmClient::connect(&cfg(port)).unwrap_err();
    assert!(e.to_string().contains("Max number of clients"), "{e}");
}
