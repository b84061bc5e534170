//! Runs the real firmware in the simavr emulator (for the integration tests and the bench).
//!
//! [`build_firmware`] builds the firmware ELF and the C harness (`driver/firmware/sim/`) with
//! `make`; [`SimFirmware::spawn`] starts the harness, which attaches the AVR's UART0 to a
//! pseudo-terminal (reachable through a stable symlink) and reports every coil-pattern change
//! on stdout; a reader thread decodes those lines into per-motor step logs.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use crate::interface::N_MOTORS;

/// AVR clock, Hz.
pub const F_CPU: u64 = 16_000_000;

/// The built artefacts.
#[derive(Debug, Clone)]
pub struct FirmwareBuild {
    /// Firmware ELF.
    pub elf: PathBuf,
    /// Harness executable.
    pub harness: PathBuf,
}

/// The firmware source folder (`driver/firmware`).
pub fn firmware_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("firmware")
}

const SETUP_HINT: &str = "run `bash scripts/setup.sh` (installs gcc-avr avr-libc simavr \
                          libsimavr-dev libelf-dev pkg-config)";

fn have(cmd: &str, args: &[&str]) -> bool {
    Command::new(cmd)
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .map(|s| s.success())
        .unwrap_or(false)
}

/// Builds the firmware and the harness into `out_dir` with `make`.
///
/// Fails with a message naming `scripts/setup.sh` when avr-gcc or simavr are missing.
pub fn build_firmware(out_dir: &Path) -> Result<FirmwareBuild, String> {
    let mut missing = Vec::new();
    if !have("avr-gcc", &["--version"]) {
        missing.push("avr-gcc (gcc-avr, avr-libc)");
    }
    if !have("make", &["--version"]) {
        missing.push("make");
    }
    if !have("pkg-config", &["--exists", "simavr", "simavrparts"]) {
        missing.push("simavr development files (libsimavr-dev, pkg-config)");
    }
    if !missing.is_empty() {
        return Err(format!(
            "firmware tests need {}: {SETUP_HINT}",
            missing.join(", ")
        ));
    }
    let out = Command::new("make")
        .arg("-C")
        .arg(firmware_dir())
        .arg(format!("BUILD={}", out_dir.display()))
        .arg("all")
        .arg("sim")
        .output()
        .map_err(|e| format!("cannot run make: {e}; {SETUP_HINT}"))?;
    if !out.status.success() {
        return Err(format!(
            "firmware build failed ({SETUP_HINT} if a tool is missing):\n{}\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(FirmwareBuild {
        elf: out_dir.join("pcr_fw.elf"),
        harness: out_dir.join("pcr_sim"),
    })
}

/// One step seen on the coil pins.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StepEvent {
    /// Motor index.
    pub motor: usize,
    /// Position after the step.
    pub pos: i64,
    /// AVR cycle of the step.
    pub cycle: u64,
}

/// What the harness reported so far.
#[derive(Debug, Default, Clone)]
pub struct SimLog {
    /// Every step, in order.
    pub steps: Vec<StepEvent>,
    /// Current position per motor as decoded from the coils.
    pub pos: [i64; N_MOTORS],
    /// Coil release / energise events: (motor, on, cycle).
    pub coils: Vec<(usize, bool, u64)>,
    /// Illegal pattern changes (would lose steps on real hardware).
    pub illegal: Vec<String>,
    /// Whether the harness has exited.
    pub exited: bool,
    /// At a clean exit ([`SimFirmware::stop`]): (AVR cycles run, cycles not spent asleep).
    pub cpu: Option<(u64, u64)>,
}

impl SimLog {
    /// Steps of one motor.
    pub fn steps_of(&self, motor: usize) -> impl Iterator<Item = &StepEvent> {
        self.steps.iter().filter(move |e| e.motor == motor)
    }
    /// Number of steps (either direction) of each motor.
    pub fn step_counts(&self) -> [usize; N_MOTORS] {
        let mut c = [0; N_MOTORS];
        for e in &self.steps {
            c[e.motor] += 1;
        }
        c
    }
    /// Smallest interval between two consecutive steps of a motor, in AVR cycles.
    pub fn min_step_interval(&self, motor: usize) -> Option<u64> {
        let v: Vec<u64> = self.steps_of(motor).map(|e| e.cycle).collect();
        v.windows(2).map(|w| w[1] - w[0]).min()
    }
}

type Shared = Arc<(Mutex<SimLog>, Condvar)>;

/// A running emulated firmware.
pub struct SimFirmware {
    child: Child,
    link: PathBuf,
    pty: String,
    log: Shared,
}

impl std::fmt::Debug for SimFirmware {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimFirmware")
            .field("link", &self.link)
            .field("pty", &self.pty)
            .finish()
    }
}

impl SimFirmware {
    /// Starts the harness; the UART is reachable at `link` (a symlink to the PTY).
    pub fn spawn(build: &FirmwareBuild, link: &Path) -> Result<Self, String> {
        let mut child = Command::new(&build.harness)
            .arg(&build.elf)
            .arg("--link")
            .arg(link)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .map_err(|e| format!("cannot start {}: {e}", build.harness.display()))?;
        let stdout = child.stdout.take().expect("piped stdout");
        let log: Shared = Arc::new((Mutex::new(SimLog::default()), Condvar::new()));
        let (tx, rx) = std::sync::mpsc::channel::<String>();
        let log2 = log.clone();
        std::thread::spawn(move || {
            let mut tx = Some(tx);
            for line in BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                let w: Vec<&str> = line.split_whitespace().collect();
                let (lock, cv) = &*log2;
                let mut g = lock.lock().unwrap();
                match w.as_slice() {
                    ["PTY", name] => {
                        if let Some(t) = tx.take() {
                            let _ = t.send(name.to_string());
                        }
                    }
                    ["S", m, p, c] => {
                        if let (Ok(m), Ok(p), Ok(c)) = (m.parse(), p.parse(), c.parse()) {
                            if m < N_MOTORS {
                                g.pos[m] = p;
                                g.steps.push(StepEvent {
                                    motor: m,
                                    pos: p,
                                    cycle: c,
                                });
                            }
                        }
                    }
                    ["C", m, on, c] => {
                        if let (Ok(m), Ok(c)) = (m.parse(), c.parse()) {
                            g.coils.push((m, *on == "1", c));
                        }
                    }
                    ["X", ..] => g.illegal.push(line.clone()),
                    ["T", total, busy] => {
                        if let (Ok(t), Ok(b)) = (total.parse(), busy.parse()) {
                            g.cpu = Some((t, b));
                        }
                    }
                    _ => {}
                }
                cv.notify_all();
            }
            let (lock, cv) = &*log2;
            lock.lock().unwrap().exited = true;
            cv.notify_all();
        });
        let pty = match rx.recv_timeout(Duration::from_secs(20)) {
            Ok(p) => p,
            Err(_) => {
                let _ = child.kill();
                let _ = child.wait();
                return Err("the simavr harness did not print its PTY".into());
            }
        };
        Ok(Self {
            child,
            link: link.to_path_buf(),
            pty,
            log,
        })
    }

    /// Path to open with the serial backend (stable across restarts).
    pub fn port_path(&self) -> String {
        self.link.display().to_string()
    }

    /// The PTY slave the harness created.
    pub fn pty(&self) -> &str {
        &self.pty
    }

    /// A copy of the log.
    pub fn log(&self) -> SimLog {
        self.log.0.lock().unwrap().clone()
    }

    /// The steps from index `from` of the step log on (for streaming it incrementally without
    /// copying the whole log), and the index to pass next time.
    pub fn steps_since(&self, from: usize) -> (Vec<StepEvent>, usize) {
        let g = self.log.0.lock().unwrap();
        let from = from.min(g.steps.len());
        (g.steps[from..].to_vec(), g.steps.len())
    }

    /// Number of illegal coil-pattern changes seen so far (lost steps on real hardware).
    pub fn illegal_count(&self) -> usize {
        self.log.0.lock().unwrap().illegal.len()
    }

    /// Whether the harness has exited.
    pub fn exited(&self) -> bool {
        self.log.0.lock().unwrap().exited
    }

    /// Positions decoded from the coil patterns.
    pub fn positions(&self) -> [i64; N_MOTORS] {
        self.log.0.lock().unwrap().pos
    }

    /// Waits until `pred` holds on the log or `timeout` passes; returns whether it held.
    pub fn wait_for(&self, timeout: Duration, pred: impl Fn(&SimLog) -> bool) -> bool {
        let deadline = Instant::now() + timeout;
        let (lock, cv) = &*self.log;
        let mut g = lock.lock().unwrap();
        loop {
            if pred(&g) {
                return true;
            }
            let now = Instant::now();
            if now >= deadline || g.exited {
                return pred(&g);
            }
            g = cv.wait_timeout(g, deadline - now).unwrap().0;
        }
    }

    /// Stops the emulator cleanly (closes its stdin) and returns the final log, with the
    /// firmware's CPU load in [`SimLog::cpu`].
    pub fn stop(mut self) -> SimLog {
        drop(self.child.stdin.take());
        let _ = self.wait_for(Duration::from_secs(10), |l| l.exited);
        self.kill();
        self.log()
    }

    /// Kills the emulator (the port vanishes).
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for SimFirmware {
    fn drop(&mut self) {
        self.kill();
    }
}
