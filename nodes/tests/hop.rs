//! The hop listener the IK and the driver sleep on ([`pcr_nodes::hop`]): a sample notification
//! wakes it, its ticker delivers the period tick and the heartbeat at their rates, and SIGTERM
//! interrupts the wait and is reported (so a stopped chain process ends and its driver holds).
//! One test in its own binary: the termination flag is process-wide.

use pcr_messages::{services as s, PROTOCOL_VERSION};
use pcr_nodes::hop::{self, Ticker};
use pcr_nodes::ports::remove_leftovers;
use pcr_nodes::ChainNode;
use std::time::{Duration, Instant};

struct Cleanup(String);
impl Drop for Cleanup {
    fn drop(&mut self) {
        remove_leftovers(&self.0);
    }
}

#[test]
fn the_hop_listener_wakes_on_samples_ticks_heartbeats_and_sigterm() {
    let prefix = format!("pcrthop{}_", std::process::id());
    let _cleanup = Cleanup(prefix.clone());
    let cn = ChainNode::new("pcr-hop-test", &prefix, PROTOCOL_VERSION).unwrap();
    let listener = cn.hop_listener(s::JOINT_SETPOINT).unwrap();
    let notifier = cn.hop_notifier(s::JOINT_SETPOINT).unwrap();

    // A sample notification (pending before the wait) wakes it at once, and only as a sample.
    notifier.notify().unwrap();
    let w = hop::wait(&listener).unwrap();
    assert!(w.sample && !w.tick && !w.heartbeat && !w.terminate, "{w:?}");
    // Drained: nothing is pending any more.
    assert_eq!(hop::poll(&listener).unwrap(), hop::Wake::default());

    // The ticker: a 10 ms tick and a 50 ms heartbeat over 0.5 s.
    hop::catch_termination().unwrap();
    let ticker = Ticker::spawn(
        "pcr-hop-test-ticker",
        &prefix,
        PROTOCOL_VERSION,
        s::JOINT_SETPOINT,
        Some(Duration::from_millis(10)),
        Duration::from_millis(50),
    )
    .unwrap();
    let t0 = Instant::now();
    let (mut ticks, mut beats) = (0, 0);
    while t0.elapsed() < Duration::from_millis(500) {
        let w = hop::wait(&listener).unwrap();
        assert!(!w.sample && !w.terminate, "{w:?}");
        ticks += usize::from(w.tick);
        beats += usize::from(w.heartbeat);
    }
    // Coalesced wake-ups on a busy machine may merge ticks; the rates must still show.
    assert!(
        (25..=51).contains(&ticks),
        "{ticks} ticks of 10 ms in 0.5 s"
    );
    assert!(
        (5..=11).contains(&beats),
        "{beats} heartbeats of 50 ms in 0.5 s"
    );

    // SIGTERM to this (waiting) thread interrupts the wait and is reported.
    // SAFETY: pthread_self is always valid; the signal is caught by catch_termination.
    let me = unsafe { libc::pthread_self() } as usize;
    let killer = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(30));
        unsafe { libc::pthread_kill(me as libc::pthread_t, libc::SIGTERM) };
    });
    let t1 = Instant::now();
    let mut ended = false;
    while t1.elapsed() < Duration::from_secs(5) {
        if hop::wait(&listener).unwrap().terminate {
            ended = true;
            break;
        }
    }
    killer.join().unwrap();
    assert!(ended, "SIGTERM was not reported within 5 s");
    assert!(hop::termination_requested());
    // The ticker stops when dropped.
    let t2 = Instant::now();
    drop(ticker);
    assert!(t2.elapsed() < Duration::from_secs(1));
}
