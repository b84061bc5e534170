//! Host-side tests of the serial backend against a fake peer on a pseudo-terminal pair
//! (no emulator): a silent port, a firmware speaking another protocol version, a missing port.

use std::io::{Read, Write};
use std::time::Duration;

use pcr_driver::protocol::{encode_frame, FrameDecoder, FwConfig, HelloReply, Message};
use pcr_driver::{DriverError, SerialConfig, SerialDriver};
use serialport::{SerialPort, TTYPort};

fn pair() -> (TTYPort, String) {
    let (master, slave) = TTYPort::pair().expect("pty pair");
    let name = slave.name().expect("slave name");
    drop(slave);
    (master, name)
}

fn cfg(path: &str) -> SerialConfig {
    let mut c = SerialConfig::new(path);
    c.handshake_timeout = Duration::from_millis(300);
    c
}

#[test]
fn silent_port_fails_the_handshake_clearly() {
    let (_master, name) = pair();
    let e = SerialDriver::open(cfg(&name)).unwrap_err();
    assert!(
        matches!(&e, DriverError::Protocol(m) if m.contains("no handshake")),
        "{e}"
    );
}

#[test]
fn missing_port_is_a_transport_error() {
    let e = SerialDriver::open(cfg("/nonexistent/ttyPCR")).unwrap_err();
    assert!(
        matches!(&e, DriverError::Transport(m) if m.contains("cannot open") && m.contains("/nonexistent/ttyPCR")),
        "{e}"
    );
}

#[test]
fn other_protocol_version_is_refused() {
    let (mut master, name) = pair();
    master.set_timeout(Duration::from_millis(50)).unwrap();
    let peer = std::thread::spawn(move || {
        let mut dec = FrameDecoder::new();
        let mut buf = [0u8; 64];
        let deadline = std::time::Instant::now() + Duration::from_secs(5);
        while std::time::Instant::now() < deadline {
            let n = match master.read(&mut buf) {
                Ok(n) => n,
                Err(_) => {
                    // EIO until the host opens the slave side, or a read timeout
                    std::thread::sleep(Duration::from_millis(5));
                    continue;
                }
            };
            for f in dec.push_all(&buf[..n]).into_iter().flatten() {
                if let Message::Hello { .. } = f.msg {
                    let reply = Message::HelloReply(HelloReply {
                        protocol: 2,
                        fw_version: [9, 9, 9],
                        n_motors: 3,
                        reset_cause: 0,
                        config: FwConfig::default(),
                    });
                    master.write_all(&encode_frame(f.seq, &reply)).unwrap();
                    return master; // kept open until the host has read the reply
                }
            }
        }
        master
    });
    let e = SerialDriver::open(cfg(&name)).unwrap_err();
    assert!(
        matches!(&e, DriverError::Protocol(m) if m.contains("protocol 2")),
        "{e}"
    );
    drop(peer.join().unwrap());
}
