//! End-to-end tests: the real firmware (built with avr-gcc) runs in simavr through the C
//! harness; the Rust serial backend talks to it over a pseudo-terminal, and the harness decodes
//! the coil patterns into step counts.
//!
//! Needs gcc-avr, avr-libc, simavr, libsimavr-dev, libelf-dev and pkg-config: without them the
//! tests FAIL and say to run `bash scripts/setup.sh`.
//!
//! Timing: the harness keeps AVR time from running ahead of wall-clock time, so the firmware
//! sees the host's real 20 ms cadence; assertions are on step counts and on AVR-cycle
//! timestamps, never on wall-clock durations, and waits use generous timeouts.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, OnceLock};
use std::time::{Duration, Instant};

use pcr_driver::protocol::{encode_frame, flags, ErrorCode, FwConfig, Message};
use pcr_driver::sim::{build_firmware, FirmwareBuild, SimFirmware, F_CPU};
use pcr_driver::{
    Driver, DriverError, DriverState, MotorCommand, PositionLimit, RateLimit, SerialConfig,
    SerialDriver,
};

const PERIOD: Duration = Duration::from_millis(20);
const PERIOD_S: f64 = 0.02;
/// AVR cycles per timer tick (100 us).
const TICK: u64 = F_CPU / 10_000;
/// AVR cycles per step at the default 600 steps/s.
const STEP_600: u64 = F_CPU / 600;

fn build() -> FirmwareBuild {
    static BUILD: OnceLock<Result<FirmwareBuild, String>> = OnceLock::new();
    BUILD
        .get_or_init(|| {
            let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("pcr-firmware");
            build_firmware(&dir)
        })
        .clone()
        .unwrap_or_else(|e| panic!("{e}"))
}

/// One emulator at a time: the machine has 2 cores shared with other builds.
fn serial_lock() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

fn link_path(name: &str) -> PathBuf {
    let dir =
        Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("pcr-sim-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

struct Rig {
    sim: SimFirmware,
    drv: SerialDriver,
    _guard: MutexGuard<'static, ()>,
}

/// Firmware configuration for streaming tests: a generous host watchdog so that a host thread
/// delayed by a busy machine does not trip it.
fn relaxed() -> FwConfig {
    FwConfig {
        watchdog_ms: 5000,
        ..FwConfig::default()
    }
}

fn rig(name: &str, fw: FwConfig) -> Rig {
    let guard = serial_lock();
    let b = build();
    let link = link_path(name);
    let sim = SimFirmware::spawn(&b, &link).unwrap_or_else(|e| panic!("{e}"));
    let mut cfg = SerialConfig::new(sim.port_path());
    // Generous: on a starved machine the emulator can stall for a second; a reply that never
    // comes still fails the test.
    cfg.reply_timeout = Duration::from_secs(3);
    cfg.firmware_config = Some(fw);
    let drv = SerialDriver::open(cfg).expect("open the emulated firmware");
    Rig {
        sim,
        drv,
        _guard: guard,
    }
}

fn cmd(steps: [i32; 3]) -> MotorCommand {
    MotorCommand {
        steps,
        enable: true,
    }
}

/// Streams `n` cycles at 20 ms (absolute schedule), returning the states read.
fn stream(
    d: &mut impl Driver,
    t0: &mut f64,
    n: usize,
    f: impl Fn(usize) -> [i32; 3],
) -> Vec<DriverState> {
    let start = Instant::now();
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        let due = start + PERIOD * k as u32;
        if let Some(w) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(w);
        }
        *t0 += PERIOD_S;
        d.write(*t0, PERIOD_S, &cmd(f(k))).unwrap();
        out.push(d.read(*t0, PERIOD_S).unwrap());
    }
    out
}

/// Keeps sending `target` until the drive reports it reached and idle.
fn settle(d: &mut impl Driver, t0: &mut f64, target: [i32; 3]) -> DriverState {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let s = stream(d, t0, 1, |_| target)[0];
        if s.steps == target && !s.moving {
            return s;
        }
        assert!(
            Instant::now() < deadline,
            "never settled at {target:?}: {s:?}"
        );
    }
}

fn assert_no_illegal(sim: &SimFirmware) {
    let log = sim.log();
    assert!(
        log.illegal.is_empty(),
        "illegal coil patterns: {:?}",
        log.illegal
    );
}

#[test]
fn handshake_reports_version_and_config() {
    let mut r = rig("handshake", FwConfig::default());
    let h = *r.drv.firmware().unwrap();
    assert_eq!(h.protocol, pcr_driver::protocol::PROTOCOL_VERSION);
    assert_eq!(h.fw_version, [1, 0, 0]);
    assert_eq!(h.n_motors, 3);
    assert_eq!(h.config, FwConfig::default());
    let st = r.drv.status().unwrap();
    assert_eq!(st.steps, [0; 3]);
    assert_eq!(st.counters.crc_errors, 0);
    assert_eq!(st.flags & flags::FAULT, 0);
    assert_eq!(r.drv.name(), format!("serial:{}", r.sim.port_path()));
}

/// 20 ms setpoint streams: the steps decoded from the coils match the commands exactly, in
/// both directions, at different speeds per motor (one of them at the rate limit).
#[test]
fn setpoint_stream_steps_match_exactly() {
    let mut r = rig("stream", relaxed());
    let mut t = 0.0;
    // Phase A: +7, -3, +11 steps per cycle for 50 cycles.
    let a = |k: usize| {
        let k = k as i32 + 1;
        [7 * k, -3 * k, 11 * k]
    };
    let states = stream(&mut r.drv, &mut t, 50, a);
    // Acknowledged positions never run ahead of the commands and never go backwards.
    for w in states.windows(2) {
        for m in 0..3 {
            let (p0, p1) = (w[0].steps[m], w[1].steps[m]);
            assert!(p1.abs() >= p0.abs(), "motor {m} went back: {p0} -> {p1}");
        }
    }
    let end_a = a(49);
    settle(&mut r.drv, &mut t, end_a);
    let log_a = r.sim.log();
    assert_eq!(log_a.pos, end_a.map(i64::from));
    assert_eq!(log_a.step_counts(), [350, 150, 550]);
    // Phase B: back at -5, +12 (exactly the 600 steps/s limit), -1 per cycle.
    let b = |k: usize| {
        let k = k as i32 + 1;
        [end_a[0] - 5 * k, end_a[1] + 12 * k, end_a[2] - k]
    };
    stream(&mut r.drv, &mut t, 50, b);
    let end_b = b(49);
    settle(&mut r.drv, &mut t, end_b);
    let log = r.sim.log();
    assert_eq!(log.pos, end_b.map(i64::from));
    assert_eq!(log.step_counts(), [350 + 250, 150 + 600, 550 + 50]);
    // Monotonic within each phase: exactly the commanded steps, no back-and-forth.
    let n_a = log_a.steps.len();
    for (m, sign_a) in [(0usize, 1i64), (1, -1), (2, 1)] {
        let dirs: Vec<i64> = {
            let mut prev = 0i64;
            let mut v = Vec::new();
            for (i, e) in log.steps.iter().enumerate().filter(|(_, e)| e.motor == m) {
                v.push((e.pos - prev) * if i < n_a { sign_a } else { -sign_a });
                prev = e.pos;
            }
            v
        };
        assert!(
            dirs.iter().all(|&d| d == 1),
            "motor {m} reversed within a phase"
        );
    }
    // Rate limit: never faster than 600 steps/s (one 100 us tick of quantisation).
    for m in 0..3 {
        let min = log.min_step_interval(m).unwrap();
        assert!(
            min + TICK >= STEP_600,
            "motor {m}: {min} cycles between steps"
        );
    }
    assert_no_illegal(&r.sim);
    let st = r.drv.status().unwrap();
    assert_eq!(st.counters.crc_errors + st.counters.framing_errors, 0);
    assert_eq!(st.counters.seq_errors + st.counters.range_rejects, 0);
    assert_eq!(r.drv.counters().timeouts, 0);
    // The 10 kHz step interrupt plus the protocol leave the AVR mostly asleep.
    let Rig { sim, drv, _guard } = r;
    drop(drv);
    let (total, busy) = sim.stop().cpu.expect("harness reports its CPU load");
    let load = busy as f64 / total as f64;
    assert!(load < 0.5, "firmware CPU load {:.1} %", load * 100.0);
}

/// One setpoint from rest: all motors finish together at the end of the 20 ms segment, with
/// evenly spaced steps.
#[test]
fn segment_is_synchronised_and_evenly_spaced() {
    let mut r = rig("segment", relaxed());
    let mut t = 0.0;
    let target = [12, -6, 3];
    let s = stream(&mut r.drv, &mut t, 1, |_| target)[0];
    assert!(!s.limited);
    assert!(r
        .sim
        .wait_for(Duration::from_secs(10), |l| l.steps.len() == 21));
    let log = r.sim.log();
    let first_cycle = log.steps[0].cycle;
    let last: Vec<u64> = (0..3)
        .map(|m| log.steps_of(m).last().unwrap().cycle)
        .collect();
    // The three last steps happen in the same timer tick.
    let spread = last.iter().max().unwrap() - last.iter().min().unwrap();
    assert!(spread < TICK, "last steps {last:?}");
    // Steps are evenly spaced: n steps in 200 ticks -> intervals of floor/ceil(200/n) ticks.
    for (m, n) in [(0usize, 12u64), (1, 6), (2, 3)] {
        let c: Vec<u64> = log.steps_of(m).map(|e| e.cycle).collect();
        assert_eq!(c.len() as u64, n);
        for w in c.windows(2) {
            let ticks = (w[1] - w[0] + TICK / 2) / TICK;
            assert!(
                ticks == 200 / n || ticks == 200_u64.div_ceil(n),
                "motor {m}: {ticks} ticks between steps"
            );
        }
    }
    // The whole segment lasts 20 ms (first step of motor 0 at 200/12 ticks).
    let dur = *last.iter().max().unwrap() - first_cycle;
    let expect = 200 * TICK - 200 / 12 * TICK;
    assert!(
        dur.abs_diff(expect) <= 2 * TICK,
        "segment {dur} cycles, expected {expect}"
    );
    assert_no_illegal(&r.sim);
}

/// A target far beyond one cycle's reach is approached at the rate limit, never faster.
#[test]
fn rate_limit_spreads_a_far_target() {
    let fw = FwConfig {
        watchdog_ms: 0,
        ..FwConfig::default()
    };
    let mut r = rig("rate", fw);
    let mut t = 0.0;
    let target = [300, -300, 30];
    let s = stream(&mut r.drv, &mut t, 1, |_| target)[0];
    assert!(s.limited, "far setpoint must be flagged as limited");
    assert!(r
        .sim
        .wait_for(Duration::from_secs(20), |l| l.pos == [300, -300, 30]));
    let log = r.sim.log();
    for m in 0..2 {
        let min = log.min_step_interval(m).unwrap();
        assert!(min + TICK >= STEP_600, "motor {m}: {min} cycles");
        let c: Vec<u64> = log.steps_of(m).map(|e| e.cycle).collect();
        // 300 steps at 600 steps/s take at least 0.5 s of AVR time (minus one step).
        assert!(
            c[299] - c[0] >= 299 * STEP_600 - TICK,
            "too fast: {}",
            c[299] - c[0]
        );
        // No 20 ms window holds more than 12 steps (+1 for window alignment).
        for (i, &c0) in c.iter().enumerate() {
            let n = c[i..].iter().take_while(|&&x| x < c0 + F_CPU / 50).count();
            assert!(n <= 13, "motor {m}: {n} steps in 20 ms");
        }
    }
    let st = r.drv.status().unwrap();
    assert!(st.counters.rate_limited >= 24, "{:?}", st.counters);
    assert_eq!(st.steps, target);
    assert_eq!(st.flags & (flags::LIMITED | flags::MOVING), 0);
    assert_no_illegal(&r.sim);
}

/// When the host goes silent the firmware stops the motors and latches a fault; setpoints are
/// refused until CLEAR_FAULT.
#[test]
fn watchdog_stops_motors_when_host_goes_silent() {
    let mut r = rig("watchdog", FwConfig::default()); // 200 ms watchdog
    let mut t = 0.0;
    let s = stream(&mut r.drv, &mut t, 1, |_| [5000, 0, -5000])[0];
    assert!(s.moving && s.limited);
    // Silence: poll the status (which does not feed the watchdog) until the fault shows.
    let deadline = Instant::now() + Duration::from_secs(15);
    let st = loop {
        let st = r.drv.status().unwrap();
        if st.flags & flags::WATCHDOG != 0 {
            break st;
        }
        assert!(Instant::now() < deadline, "watchdog never tripped");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(st.flags & flags::FAULT != 0);
    assert_eq!(st.flags & flags::MOVING, 0);
    assert_eq!(st.targets, st.steps, "target reset to the stop position");
    assert_eq!(st.counters.watchdog_trips, 1);
    // 200 ms at 600 steps/s is 120 steps, plus at most one 20 ms segment.
    assert!(st.steps[0] > 0 && st.steps[0] <= 120 + 12, "{:?}", st.steps);
    // The motors really stopped: nothing moves on the coils afterwards.
    let n = r.sim.log().steps.len();
    std::thread::sleep(Duration::from_millis(200));
    assert_eq!(r.sim.log().steps.len(), n);
    assert_eq!(r.sim.positions(), st.steps.map(i64::from));
    // Setpoints are refused while the fault is latched (reported as a fault state).
    let s = stream(&mut r.drv, &mut t, 1, |_| [5000, 0, -5000])[0];
    assert!(s.fault);
    assert_eq!(r.drv.counters().fw_fault_rejects, 1);
    assert_eq!(r.sim.log().steps.len(), n);
    // Recovery.
    let c = r.drv.clear_fault().unwrap();
    assert_eq!(c.flags & flags::FAULT, 0);
    let here = st.steps;
    let next = [here[0] + 4, here[1], here[2] - 4];
    let s = settle(&mut r.drv, &mut t, next);
    assert!(!s.fault);
    assert_eq!(r.sim.positions(), next.map(i64::from));
    assert_no_illegal(&r.sim);
}

/// Garbage, truncated frames, bad CRCs, out-of-order sequence numbers, impossible setpoints:
/// each is detected and counted, and no motor moves.
#[test]
fn bad_input_is_counted_and_never_moves_a_motor() {
    let fw = FwConfig {
        watchdog_ms: 0,
        ..FwConfig::default()
    };
    let mut r = rig("bad_input", fw);
    let mut t = 0.0;
    let home = [10, -10, 5];
    settle(&mut r.drv, &mut t, home);
    let steps_before = r.sim.log().steps.len();
    let away = [20, -20, 15];

    // 1. Seeded random garbage (with a few zeros), then a valid request still works.
    let mut x: u64 = 0xC0FF_EE00_2026;
    let garbage: Vec<u8> = (0..600)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            match x % 40 {
                0 => 0,
                _ => (x >> 24) as u8,
            }
        })
        .collect();
    // Paced at the line rate (64 bytes = 5.6 ms at 115200 baud) like a real UART: simavr 1.6's
    // uart_pty loses the link when more than its 512-byte FIFO is pending (its PTY thread and
    // the AVR thread feed the UART without a lock), which a real serial line cannot do.
    for chunk in garbage.chunks(64) {
        r.drv.send_raw(chunk).unwrap();
        std::thread::sleep(Duration::from_millis(6));
    }
    let st = r.drv.status().unwrap();
    assert!(
        st.counters.framing_errors + st.counters.crc_errors > 0,
        "{:?}",
        st.counters
    );
    assert_eq!(st.steps, home);

    // 2. Wrong CRC on a setpoint that would move.
    let mut f = encode_frame(
        200,
        &Message::Setpoint {
            enable: true,
            steps: away,
        },
    );
    let n = f.len();
    f[n - 2] ^= 0x5A; // last CRC byte (non-zero either way for this frame)
    assert_ne!(f[n - 2], 0);
    let c0 = r.drv.status().unwrap().counters;
    r.drv.send_raw(&[0]).unwrap();
    r.drv.send_raw(&f).unwrap();
    // 3. Truncated setpoint frame.
    let f = encode_frame(
        201,
        &Message::Setpoint {
            enable: true,
            steps: away,
        },
    );
    r.drv.send_raw(&f[..f.len() / 2]).unwrap();
    r.drv.send_raw(&[0]).unwrap();
    let st = r.drv.status().unwrap();
    assert!(st.counters.crc_errors > c0.crc_errors);
    assert_eq!(
        st.counters.crc_errors + st.counters.framing_errors,
        c0.crc_errors + c0.framing_errors + 2
    );
    assert!(r.drv.counters().fw_crc_reports >= 1);

    // 4. Sequence numbers: newer accepted, stale and duplicate refused.
    let here = MotorCommand {
        steps: home,
        enable: true,
    };
    let go = MotorCommand {
        steps: away,
        enable: true,
    };
    assert!(matches!(
        r.drv.setpoint_with_seq(100, &here).unwrap(),
        Message::State(_)
    ));
    for seq in [99u8, 100, 50, 228] {
        let rep = r.drv.setpoint_with_seq(seq, &go).unwrap();
        assert_eq!(
            rep,
            Message::Error {
                code: ErrorCode::Sequence,
                req_type: 2
            },
            "seq {seq}"
        );
    }
    // 5. Impossible setpoints: out of the position range (refused), through the Driver API.
    for bad in [[30_000, 0, 0], [0, -20_481, 0], [0, 0, i32::MAX]] {
        t += PERIOD_S;
        r.drv.write(t, PERIOD_S, &cmd(bad)).unwrap();
        match r.drv.read(t, PERIOD_S) {
            Err(DriverError::Limit(msg)) => assert!(msg.contains("range"), "{msg}"),
            other => panic!("expected a range refusal, got {other:?}"),
        }
    }
    // 6. Unknown type and wrong body length.
    let mut raw = vec![0x42, 7, 1, 2];
    let crc = pcr_driver::protocol::crc16_ccitt(&raw);
    raw.extend_from_slice(&crc.to_le_bytes());
    let mut enc = Vec::new();
    pcr_driver::protocol::cobs_encode(&raw, &mut enc);
    enc.push(0);
    r.drv.send_raw(&enc).unwrap();
    let mut raw = vec![0x02, 8, 1, 2, 3]; // SETPOINT with a 3-byte body
    let crc = pcr_driver::protocol::crc16_ccitt(&raw);
    raw.extend_from_slice(&crc.to_le_bytes());
    let mut enc = Vec::new();
    pcr_driver::protocol::cobs_encode(&raw, &mut enc);
    enc.push(0);
    r.drv.send_raw(&enc).unwrap();

    let st = r.drv.status().unwrap();
    assert_eq!(st.counters.seq_errors, 4);
    assert_eq!(st.counters.range_rejects, 3);
    assert_eq!(st.steps, home, "a bad input moved a motor");
    assert_eq!(st.targets, home);
    let hc = r.drv.counters();
    assert_eq!(hc.fw_seq_rejects, 4);
    assert_eq!(hc.fw_range_rejects, 3);
    assert!(
        hc.stale_replies >= 2,
        "error replies to the hand-made frames: {hc:?}"
    );
    // Nothing moved on the coils during all of this.
    std::thread::sleep(Duration::from_millis(100));
    assert_eq!(r.sim.log().steps.len(), steps_before);
    assert_eq!(r.sim.positions(), home.map(i64::from));

    // 7. And the link still works.
    let s = settle(&mut r.drv, &mut t, away);
    assert_eq!(s.steps, away);
    assert_eq!(r.sim.positions(), away.map(i64::from));
    assert_no_illegal(&r.sim);
}

/// A closed or vanished port gives a clear transport error; reconnecting to a restarted
/// firmware works.
#[test]
fn vanished_port_gives_clear_error_and_reconnects() {
    let mut r = rig("vanish", relaxed());
    let mut t = 0.0;
    settle(&mut r.drv, &mut t, [8, 8, 8]);

    // Closed by the host.
    r.drv.close();
    let e = r.drv.write(t, PERIOD_S, &cmd([9, 9, 9])).unwrap_err();
    assert!(
        matches!(&e, DriverError::Transport(m) if m.contains("closed")),
        "{e}"
    );
    r.drv.reconnect().unwrap();
    settle(&mut r.drv, &mut t, [9, 9, 9]);

    // The device vanishes (emulator killed, like an unplugged Uno).
    r.sim.kill();
    let err = (0..3)
        .find_map(|_| {
            t += PERIOD_S;
            match r.drv.write(t, PERIOD_S, &cmd([10, 10, 10])) {
                Err(e) => Some(e),
                Ok(()) => r.drv.read(t, PERIOD_S).err(),
            }
        })
        .expect("no error on a vanished port");
    assert!(matches!(&err, DriverError::Transport(_)), "{err}");
    assert!(err.to_string().contains(&r.sim.port_path()), "{err}");
    assert!(!r.drv.is_connected());
    let e = r.drv.read(t, PERIOD_S).unwrap_err();
    assert!(
        matches!(&e, DriverError::Transport(m) if m.contains("reconnect")),
        "{e}"
    );
    // Nothing to reconnect to yet.
    std::fs::remove_file(r.sim.port_path()).ok();
    let e = r.drv.reconnect().unwrap_err();
    assert!(
        matches!(&e, DriverError::Transport(m) if m.contains("cannot open")),
        "{e}"
    );

    // The firmware comes back (fresh boot) at the same path.
    let link = PathBuf::from(r.sim.port_path());
    r.sim = SimFirmware::spawn(&build(), &link).unwrap();
    let h = r.drv.reconnect().unwrap();
    assert_eq!(h.config.watchdog_ms, 5000, "configuration re-applied");
    let st = r.drv.status().unwrap();
    assert_eq!(st.steps, [0; 3], "a rebooted firmware starts from zero");
    r.drv.zero(0b111, [9, 9, 9]).unwrap();
    settle(&mut r.drv, &mut t, [12, 6, 9]);
    assert_eq!(r.sim.positions(), [3, -3, 0]);
    assert_eq!(r.drv.counters().reconnects, 2);
    assert!(r.drv.counters().transport_errors >= 2);
}

/// The host-side safety wrappers in front of the serial backend: a jumpy command stream
/// reaches the firmware rate- and range-limited, so the firmware never has to refuse or clamp.
#[test]
fn safety_wrappers_in_front_of_the_serial_backend() {
    let r = rig("safety", relaxed());
    let Rig { sim, drv, _guard } = r;
    let mut d = PositionLimit::new(RateLimit::new(drv, 500.0), [-50; 3], [50; 3]);
    let mut t = 0.0;
    let states = stream(&mut d, &mut t, 20, |k| {
        if k % 2 == 0 {
            [1000, -1000, 0]
        } else {
            [1000, -1000, 7]
        }
    });
    assert!(states.iter().all(|s| s.limited));
    settle(&mut d, &mut t, [50, -50, 7]);
    assert_eq!(sim.positions(), [50, -50, 7]);
    let st = d.inner_mut().inner_mut().status().unwrap();
    let diag = d.diagnostics();
    let get = |k: &str| diag.iter().find(|(n, _)| n == k).map(|x| x.1);
    assert_eq!(get("position_limit.interventions"), Some(20));
    assert_eq!(get("serial.timeouts"), Some(0));
    assert_eq!(get("rate_limit.interventions"), Some(4)); // 0 -> 50 at 10 steps per cycle
    assert_eq!(st.counters.range_rejects, 0);
    let log = sim.log();
    for m in 0..2 {
        // The host limits the average rate (500 steps/s: 10 steps per cycle); the firmware
        // bounds the instantaneous one (600 steps/s) when it folds a late segment's rest.
        let min = log.min_step_interval(m).unwrap();
        assert!(min + TICK >= STEP_600, "motor {m}: {min}");
        let c: Vec<u64> = log.steps_of(m).map(|e| e.cycle).collect();
        assert!(
            c[49] - c[0] >= 49 * (F_CPU / 600) - TICK,
            "motor {m} too fast"
        );
    }
    assert!(log.illegal.is_empty());
}

/// With `idle_off_ms` set, the coils are released once the motors have been idle that long and
/// re-energised on the same phase before the next move; ENABLE(false) releases them at once.
#[test]
fn coils_released_when_idle_if_configured() {
    let fw = FwConfig {
        idle_off_ms: 100,
        watchdog_ms: 0,
        ..FwConfig::default()
    };
    let mut r = rig("idle", fw);
    let mut t = 0.0;
    settle(&mut r.drv, &mut t, [5, -3, 2]);
    let released = |l: &pcr_driver::sim::SimLog| {
        (0..3).all(|m| {
            l.coils
                .iter()
                .rev()
                .find(|c| c.0 == m)
                .is_some_and(|c| !c.1)
        })
    };
    assert!(r.sim.wait_for(Duration::from_secs(10), released));
    let st = r.drv.status().unwrap();
    assert_eq!(st.flags & flags::COILS_ON, 0);
    assert!(st.flags & flags::ENABLED != 0);
    // Moving again energises the coils on the phase they were released at (else the harness
    // would report an illegal pattern), and the steps still count exactly.
    settle(&mut r.drv, &mut t, [9, -9, 0]);
    assert_eq!(r.sim.positions(), [9, -9, 0]);
    let st = r.drv.set_enable(false).unwrap();
    assert_eq!(st.flags & (flags::COILS_ON | flags::ENABLED), 0);
    assert!(r.sim.wait_for(Duration::from_secs(5), released));
    // A setpoint re-enables.
    settle(&mut r.drv, &mut t, [10, -10, 1]);
    assert_eq!(r.sim.positions(), [10, -10, 1]);
    assert_no_illegal(&r.sim);
}

/// Commands the firmware must refuse: unsupported protocol version, out-of-bounds
/// configuration, zeroing or reconfiguring while moving.
#[test]
fn firmware_refuses_bad_commands() {
    let fw = FwConfig {
        watchdog_ms: 0,
        ..FwConfig::default()
    };
    let mut r = rig("refusals", fw);
    let rep = r.drv.request(Message::Hello { protocol: 2 }).unwrap();
    assert_eq!(
        rep,
        Message::Error {
            code: ErrorCode::Version,
            req_type: 1
        }
    );
    for bad in [
        FwConfig { max_rate: 0, ..fw },
        FwConfig {
            max_rate: 5000,
            ..fw
        },
        FwConfig { cycle_ms: 2, ..fw },
        FwConfig {
            pos_min: 10,
            pos_max: 10,
            ..fw
        },
        FwConfig {
            watchdog_ms: 5,
            ..fw
        },
    ] {
        let e = r.drv.configure(bad).unwrap_err();
        assert!(e.to_string().contains("BadConfig"), "{bad:?}: {e}");
    }
    // Busy while moving.
    let mut t = 0.0;
    let s = stream(&mut r.drv, &mut t, 1, |_| [500, 0, 0])[0];
    assert!(s.moving);
    let e = r.drv.zero(0b001, [0, 0, 0]).unwrap_err();
    assert!(e.to_string().contains("Busy"), "{e}");
    let e = r.drv.configure(FwConfig::default()).unwrap_err();
    assert!(e.to_string().contains("Busy"), "{e}");
    // Stop (ENABLE false stops and releases), then zeroing works.
    r.drv.set_enable(false).unwrap();
    let st = r.drv.zero(0b001, [0, 0, 0]).unwrap();
    assert_eq!(st.steps, [0, 0, 0]);
    let st = r.drv.status().unwrap();
    assert_eq!(st.targets, [0, 0, 0]);
    assert_eq!(r.drv.counters().fw_other_errors, 1 + 5 + 2);
    assert_no_illegal(&r.sim);
}
