//! The client against the crate's own server (the simulator): negotiation with an older
//! server, streaming at a reduced rate, and the reconnecting source across a server restart
//! and a stalled stream.

use pcr_mocap_bridge::client::Item;
use pcr_mocap_bridge::{
    Body, ClientConfig, Frame, Marker, Parameters, QtmClient, QtmServer, QtmSource, ServerConfig,
    SourceEvent, StreamRate, Version,
};
use std::time::{Duration, Instant};

fn params() -> Parameters {
    Parameters {
        version: None,
        frequency_hz: Some(100.0),
        labels: vec!["B1".into(), "B2".into(), "B3".into()],
        bodies: vec!["platform".into()],
    }
}

fn frame(k: u32) -> Frame {
    Frame {
        timestamp_us: u64::from(k) * 10_000,
        frame_number: k,
        bodies: vec![Some(Body {
            position_mm: [f64::from(k), 2.0, 0.0],
            euler_deg: [0.0, 0.0, 1.5],
            residual_mm: Some(0.25),
        })],
        markers: vec![
            Some(Marker {
                position_mm: [1.0, 2.0, 3.0],
                residual_mm: Some(0.5),
            }),
            None,
            Some(Marker {
                position_mm: [4.0, 5.0, 6.0],
                residual_mm: Some(0.5),
            }),
        ],
        has_bodies: true,
        has_markers: true,
        ..Default::default()
    }
}

fn server(newest: Version) -> QtmServer {
    let mut c = ServerConfig::new("127.0.0.1:0", params());
    c.newest = newest;
    QtmServer::bind(c).unwrap()
}

fn wait_for(mut cond: impl FnMut() -> bool) {
    let end = Instant::now() + Duration::from_secs(10);
    while !cond() {
        assert!(Instant::now() < end, "condition not met within 10 s");
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn an_older_server_is_spoken_to_in_its_version_and_frames_arrive_at_the_asked_rate() {
    let s = server(Version::new(1, 21));
    let mut cfg = ClientConfig::new("127.0.0.1", s.local_addr().port());
    cfg.rate = StreamRate::Frequency(50);
    let mut c = QtmClient::connect(&cfg).unwrap();
    assert_eq!(c.version(), Version::new(1, 21));
    let p = c.parameters().unwrap();
    assert_eq!(p.version, Some(Version::new(1, 21)));
    assert_eq!((p.labels.len(), p.bodies[0].as_str()), (3, "platform"));
    c.start_streaming().unwrap();
    wait_for(|| s.streaming_clients() == 1);
    for k in 1..=10 {
        s.push(&frame(k));
    }
    // 100 Hz capture, 50 Hz asked: every second frame
    let mut got = Vec::new();
    while got.len() < 5 {
        match c.next(Instant::now() + Duration::from_secs(5)).unwrap() {
            Some(Item::Frame) => {
                assert_eq!(c.frame(), &frame(c.frame().frame_number));
                got.push(c.frame().frame_number)
            }
            other => panic!("{other:?}"),
        }
    }
    assert_eq!(got, [2, 4, 6, 8, 10]);
}

#[test]
fn the_source_reconnects_after_a_server_restart_and_after_a_stall() {
    let s = server(Version::NEWEST);
    let mut cfg = ClientConfig::new("127.0.0.1", s.local_addr().port());
    cfg.stall_timeout = Duration::from_millis(300);
    cfg.backoff_initial = Duration::from_millis(20);
    let mut src = QtmSource::new(cfg);
    let poll = |src: &mut QtmSource| src.poll(Instant::now() + Duration::from_millis(20));
    assert!(matches!(poll(&mut src), SourceEvent::Connected));
    assert_eq!(src.version(), Some(Version::NEWEST));
    wait_for(|| s.streaming_clients() == 1);
    let mut k = 0;
    let mut frames = 0;
    while frames < 3 {
        k += 1;
        s.push(&frame(k));
        if let SourceEvent::Frame = poll(&mut src) {
            frames += 1;
            assert!(src.frame_time_ns() <= src.rx_ns());
        }
    }
    // QTM restarts: connection closed, refused for 200 ms, then back
    s.simulate_restart(Duration::from_millis(200));
    let mut lost = false;
    let end = Instant::now() + Duration::from_secs(10);
    loop {
        assert!(Instant::now() < end, "no reconnection");
        match poll(&mut src) {
            SourceEvent::Lost(e) => {
                lost = true;
                tracing_free_log(&e.to_string());
            }
            SourceEvent::Connected if lost => break,
            _ => {}
        }
        k += 1;
        s.push(&frame(k));
    }
    assert!(
        src.stats.losses >= 1 && src.stats.connects == 2,
        "{:?}",
        src.stats
    );
    // frames flow again
    wait_for(|| s.streaming_clients() == 1);
    loop {
        k += 1;
        s.push(&frame(k));
        if let SourceEvent::Frame = poll(&mut src) {
            break;
        }
    }
    // the server stops sending (no frame, no no-more-data): a stall, then a reconnection
    let end = Instant::now() + Duration::from_secs(10);
    loop {
        assert!(Instant::now() < end, "stall not detected");
        if let SourceEvent::Lost(e) = poll(&mut src) {
            assert!(e.to_string().contains("stalled"), "{e}");
            break;
        }
    }
    let end = Instant::now() + Duration::from_secs(10);
    while !matches!(poll(&mut src), SourceEvent::Connected) {
        assert!(Instant::now() < end, "no reconnection after the stall");
    }
}

fn tracing_free_log(_: &str) {}

#[test]
fn the_eleventh_client_is_refused() {
    let s = server(Version::NEWEST);
    let cfg = ClientConfig::new("127.0.0.1", s.local_addr().port());
    let clients: Vec<QtmClient> = (0..10).map(|_| QtmClient::connect(&cfg).unwrap()).collect();
    let e = QtmClient::connect(&cfg).unwrap_err();
    assert!(e.to_string().contains("Max number of clients"), "{e}");
    drop(clients);
}
