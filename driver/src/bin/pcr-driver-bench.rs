//! Serial round-trip bench against the emulated firmware (simavr).
//!
//!     cargo run --release -p pcr-driver --bin pcr-driver-bench -- [--cycles N] [--port PATH]
//!
//! Without `--port` it builds the firmware and the simavr harness (needs `bash scripts/setup.sh`)
//! and runs the firmware in the emulator; with `--port` it talks to a real Uno. It streams N
//! setpoints at 20 ms (a slow sine on each motor) and measures, per cycle, the time from the
//! start of `write` to the end of `read` (setpoint out, acknowledgement back), then prints
//! percentiles next to the budget computed from the frame sizes at 115200 baud.

use std::time::{Duration, Instant};

use pcr_driver::protocol::{wire_len, FwConfig, Message, StateReport, StatusReport};
use pcr_driver::sim::{build_firmware, SimFirmware};
use pcr_driver::{Driver, MotorCommand, SerialConfig, SerialDriver};

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((p / 100.0) * (sorted.len() - 1) as f64).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

fn report(name: &str, mut v: Vec<f64>) {
    v.sort_by(|a, b| a.total_cmp(b));
    let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
    println!(
        "{name:<28} n={:<5} mean={mean:6.3} p50={:6.3} p90={:6.3} p99={:6.3} p99.9={:6.3} max={:6.3} ms",
        v.len(),
        percentile(&v, 50.0),
        percentile(&v, 90.0),
        percentile(&v, 99.0),
        percentile(&v, 99.9),
        v.last().copied().unwrap_or(f64::NAN),
    );
}

fn main() {
    let mut cycles = 500usize;
    let mut port: Option<String> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--cycles" => {
                cycles = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .expect("--cycles N")
            }
            "--port" => port = args.next(),
            _ => {
                eprintln!("usage: pcr-driver-bench [--cycles N] [--port PATH]");
                std::process::exit(2);
            }
        }
    }

    let mut sim_handle = None;
    let path = match port {
        Some(p) => p,
        None => {
            let dir = std::env::temp_dir().join(format!("pcr-driver-bench-{}", std::process::id()));
            std::fs::create_dir_all(&dir).unwrap();
            let b = build_firmware(&dir).unwrap_or_else(|e| {
                eprintln!("{e}");
                std::process::exit(1)
            });
            let sim = SimFirmware::spawn(&b, &dir.join("port")).unwrap_or_else(|e| {
                eprintln!("{e}");
                std::process::exit(1)
            });
            let p = sim.port_path();
            sim_handle = Some((sim, dir));
            p
        }
    };

    let mut cfg = SerialConfig::new(path.clone());
    cfg.reply_timeout = Duration::from_millis(200);
    cfg.firmware_config = Some(FwConfig {
        watchdog_ms: 1000,
        ..FwConfig::default()
    });
    let mut d = SerialDriver::open(cfg).expect("open");

    // Budget from the frame sizes (each frame is preceded by one delimiter byte).
    let sp = wire_len(&Message::Setpoint {
        enable: true,
        steps: [0; 3],
    }) + 1;
    let ack = wire_len(&Message::State(StateReport::default()));
    let st = wire_len(&Message::StatusReply(StatusReport::default()));
    let byte_ms = 10.0 / 115_200.0 * 1000.0;
    println!("port {path}");
    println!(
        "frames on the wire: setpoint {sp} B, ack {ack} B, status reply {st} B; \
         {byte_ms:.4} ms per byte at 115200 8N1"
    );
    let wire_ms = (sp + ack) as f64 * byte_ms;
    println!(
        "cycle exchange on the wire: {} B = {wire_ms:.3} ms = {:.1} % of the 20 ms cycle",
        sp + ack,
        wire_ms / 20.0 * 100.0
    );

    let period = Duration::from_millis(20);
    let start = Instant::now();
    let mut rtt = Vec::with_capacity(cycles);
    let mut late = 0usize;
    let mut failed = 0usize;
    for k in 0..cycles {
        let due = start + period * k as u32;
        match due.checked_duration_since(Instant::now()) {
            Some(w) => std::thread::sleep(w),
            None => late += 1,
        }
        let t = k as f64 * 0.02;
        let ph = 2.0 * std::f64::consts::PI * t / 4.0;
        let cmd = MotorCommand {
            steps: [
                (300.0 * ph.sin()) as i32,
                (300.0 * (ph + 2.1).sin()) as i32,
                (300.0 * (ph + 4.2).sin()) as i32,
            ],
            enable: true,
        };
        let t0 = Instant::now();
        d.write(t, 0.02, &cmd).expect("write");
        match d.read(t, 0.02) {
            Ok(_) => rtt.push(t0.elapsed().as_secs_f64() * 1e3),
            Err(e) => {
                failed += 1;
                eprintln!("cycle {k}: {e}");
            }
        }
    }
    let mut status = Vec::with_capacity(100);
    for _ in 0..100 {
        let t0 = Instant::now();
        d.status().expect("status");
        status.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    let mean = rtt.iter().sum::<f64>() / rtt.len() as f64;
    report("setpoint -> ack round trip", rtt.clone());
    report("status request round trip", status);
    println!(
        "mean round trip uses {:.1} % of the 20 ms cycle (wire time alone {:.1} %); {late} cycles started late",
        mean / 20.0 * 100.0,
        wire_ms / 20.0 * 100.0
    );
    let fw = d.status().expect("status");
    println!(
        "{failed} cycles failed; firmware counters: {:?}",
        fw.counters
    );
    let c = d.counters();
    println!("host counters: {c:?}");
    drop(d);
    if let Some((sim, dir)) = sim_handle {
        let log = sim.stop();
        let _ = std::fs::remove_dir_all(&dir);
        if let Some((total, busy)) = log.cpu {
            println!(
                "firmware CPU load (emulated ATmega328P, whole run): {:.1} % ({busy} of {total} cycles awake)",
                busy as f64 / total as f64 * 100.0,
            );
        }
        println!(
            "steps decoded from the coils: {:?}; illegal patterns: {}",
            log.step_counts(),
            log.illegal.len()
        );
    }
}
