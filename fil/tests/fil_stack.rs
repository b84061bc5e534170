//! End-to-end: serial driver -> real firmware in simavr -> simulated plant.
//!
//! Needs gcc-avr, avr-libc, simavr, libsimavr-dev, libelf-dev and pkg-config (installed by
//! `bash scripts/setup.sh`); without them the tests fail and say so.
//!
//! The emulator runs at real-time speed (its AVR time never runs ahead of the wall clock), so
//! the host paces its 20 ms cycles on the wall clock; assertions are on steps and poses, never
//! on wall-clock durations. One emulator at a time (2 shared cores).

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use pcr_driver::{Driver, DriverState, MotorCommand};
use pcr_fil::{FilOptions, FirmwareInTheLoop};
use pcr_kinematics::{Pose, Robot};
use pcr_plant::PlantConfig;
use pcr_robot::RobotConfig;

const PERIOD: Duration = Duration::from_millis(20);
const PERIOD_S: f64 = 0.02;

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path)
}

fn lock() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

fn robot() -> RobotConfig {
    RobotConfig::load(repo("configs/robot.toml")).unwrap()
}

fn start(plant: &str, opts: FilOptions) -> FirmwareInTheLoop {
    let cfg = PlantConfig::load(repo(plant)).unwrap();
    FirmwareInTheLoop::start(&robot(), &cfg, opts).unwrap_or_else(|e| panic!("{e}"))
}

/// Streaming tests: a generous firmware watchdog, so that a host thread delayed by a busy
/// machine does not trip it (the watchdog test uses the firmware's default 200 ms).
fn options() -> FilOptions {
    let mut fw = FilOptions::firmware_for(&robot());
    fw.watchdog_ms = 5000;
    FilOptions {
        firmware: Some(fw),
        ..strict_options()
    }
}

fn strict_options() -> FilOptions {
    FilOptions {
        work_dir: Path::new(env!("CARGO_TARGET_TMPDIR")).join("pcr-fil"),
        // A busy machine can stall the emulator for a second.
        reply_timeout: Duration::from_secs(3),
        sync_timeout: Duration::from_secs(5),
        ..FilOptions::default()
    }
}

/// Motor setpoints of a circle of radius `r` mm through the home pose, `n` cycles per turn,
/// from the CC IK, rounded to steps; starts and ends at home.
fn circle(r: f64, n: usize) -> Vec<[i32; 3]> {
    let kin = Robot::new(&robot()).unwrap();
    (0..=n)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            let pose = Pose {
                x: r * a.cos() - r,
                y: r * a.sin(),
                phi: 0.0,
            };
            let ik = kin.ik(&pose).unwrap();
            std::array::from_fn(|i| kin.kappa_to_steps(i, ik.kappa[i]).unwrap().round() as i32)
        })
        .collect()
}

fn cmd(steps: [i32; 3]) -> MotorCommand {
    MotorCommand {
        steps,
        enable: true,
    }
}

/// Host side of the loop: one setpoint per 20 ms of wall-clock time (absolute schedule).
struct Host {
    t: f64,
    next: Instant,
}

impl Host {
    fn new() -> Host {
        Host {
            t: 0.0,
            next: Instant::now(),
        }
    }
    fn cycle(&mut self, fil: &mut FirmwareInTheLoop, steps: [i32; 3]) -> DriverState {
        if let Some(w) = self.next.checked_duration_since(Instant::now()) {
            std::thread::sleep(w);
        }
        self.next += PERIOD;
        self.t += PERIOD_S;
        fil.write(self.t, PERIOD_S, &cmd(steps)).unwrap();
        let s = fil.read(self.t, PERIOD_S).unwrap();
        // Every read leaves the plant where the coils are: at or past the acknowledgement
        // (how far past depends on how late this thread ran; not asserted).
        let ts = fil.true_state();
        assert_eq!(ts.motor, ts.counter, "no missed steps in the FIL");
        s
    }
    /// Repeats `steps` until acknowledged there and idle (the segment completed).
    fn settle(&mut self, fil: &mut FirmwareInTheLoop, steps: [i32; 3]) -> DriverState {
        for _ in 0..500 {
            let s = self.cycle(fil, steps);
            assert!(!s.fault, "fault while settling at {steps:?}: {s:?}");
            if s.steps == steps && !s.moving {
                return s;
            }
        }
        panic!("never settled at {steps:?}");
    }
}

/// Streams the circle; every 20 cycles and at the end it holds the setpoint until the
/// segment completed and calls `check` with the commanded steps.
fn run_circle(
    fil: &mut FirmwareInTheLoop,
    setpoints: &[[i32; 3]],
    mut check: impl FnMut(&FirmwareInTheLoop, [i32; 3]),
) -> usize {
    let mut host = Host::new();
    let mut checks = 0;
    for (k, &q) in setpoints.iter().enumerate() {
        host.cycle(fil, q);
        if k % 20 == 19 || k + 1 == setpoints.len() {
            host.settle(fil, q);
            check(fil, q);
            checks += 1;
        }
    }
    checks
}

/// (a) The plant's motors make exactly the steps the firmware emits on its coils: after each
/// completed segment the plant's motor counters, rotors and (without play) gear outputs equal
/// the commanded positions, and the plant took as many steps as the coils show.
#[test]
fn plant_motors_follow_the_firmware_steps_exactly() {
    let _g = lock();
    let setpoints = circle(5.0, 100);
    assert_eq!(setpoints[0], [176, 176, 176]);
    let moves: Vec<i32> = setpoints
        .windows(2)
        .flat_map(|w| (0..3).map(move |i| (w[1][i] - w[0][i]).abs()))
        .collect();
    let biggest = *moves.iter().max().unwrap();
    assert!(biggest > 0 && biggest <= 12, "{biggest} steps per cycle");

    // Prototype plant: backlash, creep, friction, capture noise all on.
    let mut fil = start("configs/plant.toml", options());
    let backlash = fil.plant().config().stepper.backlash_steps;
    let checks = run_circle(&mut fil, &setpoints, |fil, q| {
        let ts = fil.true_state();
        assert_eq!(ts.counter, q);
        assert_eq!(ts.motor, q);
        assert_eq!(fil.coil_positions(), q.map(i64::from));
        for i in 0..3 {
            assert!(
                (ts.output[i] - f64::from(q[i])).abs() <= 0.5 * backlash[i] + 1e-12,
                "leg {i}: output {} motor {}",
                ts.output[i],
                q[i]
            );
        }
    });
    assert_eq!(checks, 6);
    let c = fil.counters();
    let coil_steps = fil.emulator().log().steps.len() as u64;
    assert_eq!(c.steps_applied, coil_steps);
    assert_eq!(c.illegal_patterns, 0);
    assert_eq!(c.plant_faults, 0);
    assert!(coil_steps > 100, "{coil_steps}");
    // The capture kept reporting on the emulated clock (100 Hz).
    let n_meas = fil.drain_measurements().len() as f64;
    let t = fil.plant().time();
    assert!(n_meas >= 0.9 * t * 100.0, "{n_meas} samples in {t} s");

    // Same run, ideal plant (no play): the gear outputs equal the commands too.
    drop(fil);
    let mut fil = start("configs/plant-ideal.toml", options());
    run_circle(&mut fil, &setpoints, |fil, q| {
        assert_eq!(fil.true_state().output, q.map(f64::from));
    });
}

/// (b) With every plant effect off the platform pose equals the constant-curvature FK of the
/// commanded steps to 1e-6 mm.
#[test]
fn ideal_plant_pose_equals_cc_fk_of_the_commanded_steps() {
    let _g = lock();
    let kin = Robot::new(&robot()).unwrap();
    let setpoints = circle(8.0, 80);
    let mut fil = start("configs/plant-ideal.toml", options());
    let mut worst: f64 = 0.0;
    let checks = run_circle(&mut fil, &setpoints, |fil, q| {
        let fk = kin.fk_steps(&q.map(f64::from)).unwrap();
        let p = fil.true_state().eq.pose;
        let d = (p[0] - fk.x).hypot(p[1] - fk.y);
        assert!(d < 1e-6, "at {q:?}: plant {p:?} vs CC FK {fk:?}: {d} mm");
        assert!(
            (p[2] - fk.phi).abs() < 1e-8,
            "at {q:?}: phi {} vs {}",
            p[2],
            fk.phi
        );
        worst = worst.max(d);
    });
    assert_eq!(checks, 5);
    eprintln!("largest plant - CC FK distance: {worst:e} mm");
}

/// (c) When the host goes silent the firmware's watchdog stops the motors and latches a fault;
/// the plant holds the position the motors stopped at, also while time goes on.
#[test]
fn firmware_watchdog_stop_leaves_the_plant_holding() {
    let _g = lock();
    let mut fil = start("configs/plant.toml", strict_options());
    let home = fil.plant().home_steps();
    // 240 steps away on leg 1 = 20 segments at 12 steps: far more than the 200 ms watchdog.
    let target = [home[0] + 240, home[1] - 120, home[2] - 120];
    let mut host = Host::new();
    for _ in 0..3 {
        let s = host.cycle(&mut fil, target);
        assert!(s.limited && !s.fault, "{s:?}");
    }
    // Host silent: the watchdog (200 ms) trips.
    std::thread::sleep(Duration::from_millis(700));
    let t = host.t + 0.7;
    let s = fil.read(t, PERIOD_S).unwrap(); // no setpoint pending: STATUS
    assert!(s.fault, "{s:?}");
    assert!(!s.moving, "{s:?}");
    assert_ne!(s.steps, target, "the watchdog stopped the motion midway");
    assert!(s.steps[0] > home[0] + 12, "it moved first: {:?}", s.steps);
    let stopped = s.steps;
    let ts = fil.true_state().clone();
    assert_eq!(ts.counter, stopped);
    assert_eq!(ts.motor, stopped);
    assert_eq!(fil.coil_positions(), stopped.map(i64::from));

    // Time goes on, nothing moves (creep is slow: the pose stays within a micrometre).
    std::thread::sleep(Duration::from_millis(400));
    let s2 = fil.read(t + 0.4, PERIOD_S).unwrap();
    assert!(s2.fault);
    assert_eq!(s2.steps, stopped);
    let later = fil.true_state();
    assert!(later.t_s > ts.t_s + 0.2, "{} -> {}", ts.t_s, later.t_s);
    assert_eq!(later.counter, stopped);
    assert_eq!(later.output, ts.output);
    let d = (later.eq.pose[0] - ts.eq.pose[0]).hypot(later.eq.pose[1] - ts.eq.pose[1]);
    assert!(d < 1e-3, "pose drifted {d} mm");

    // Setpoints are refused while the fault is latched; the plant still holds.
    let s3 = host.cycle(&mut fil, target);
    assert!(s3.fault);
    assert_eq!(fil.true_state().counter, stopped);
    // CLEAR_FAULT, then it follows again.
    fil.serial_mut().clear_fault().unwrap();
    // A relaxed watchdog from here on: a starved host must not trip it again.
    fil.serial_mut()
        .configure(options().firmware.unwrap())
        .unwrap();
    let back = [stopped[0] - 6, stopped[1] + 6, stopped[2]];
    let mut host = Host::new();
    let s4 = host.settle(&mut fil, back);
    assert!(!s4.fault);
    assert_eq!(fil.true_state().counter, back);
}

/// The supervisor's path: a `[driver]` table selects the FIL, `build_backend` starts it, the
/// usual safety decorators wrap it, and the plant's capture and true state stay reachable.
#[test]
fn selector_builds_the_fil_behind_the_safety_wrappers() {
    let _g = lock();
    let text = format!(
        "[supervisor]\ncycle_ms = 20\n\n[driver]\nbackend = \"firmware_in_the_loop\"\nplant = {:?}\nwork_dir = {:?}\nwatchdog_ms = 5000\n",
        repo("configs/plant.toml"),
        Path::new(env!("CARGO_TARGET_TMPDIR")).join("pcr-fil")
    );
    let sel = pcr_fil::DriverBackend::from_toml_str(&text, "test").unwrap();
    let backend = sel
        .build_backend(&robot())
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(backend.name().starts_with("fil:"), "{}", backend.name());
    let home = backend.plant().unwrap().home_steps();
    let mut drv = pcr_driver::Watchdog::new(
        pcr_driver::PositionLimit::new(
            pcr_driver::RateLimit::new(backend, 600.0),
            [0; 3],
            [400; 3],
        ),
        1.0,
    );
    let target = [home[0] + 30, home[1] - 20, home[2] + 10];
    let mut t = 0.0;
    let mut next = Instant::now();
    let mut done = false;
    for _ in 0..300 {
        if let Some(w) = next.checked_duration_since(Instant::now()) {
            std::thread::sleep(w);
        }
        next += PERIOD;
        t += PERIOD_S;
        drv.write(t, PERIOD_S, &cmd(target)).unwrap();
        let s = drv.read(t, PERIOD_S).unwrap();
        assert!(!s.fault, "{s:?}");
        if s.steps == target && !s.moving {
            done = true;
            break;
        }
    }
    assert!(done, "never reached {target:?}");
    let backend = drv.inner_mut().inner_mut().inner_mut();
    assert_eq!(backend.true_state().unwrap().counter, target);
    assert!(!backend.drain_measurements().is_empty());
    let diag = drv.diagnostics();
    assert!(
        diag.iter().any(|(k, _)| k == "fil.steps_applied"),
        "{diag:?}"
    );
    assert!(diag.iter().any(|(k, _)| k == "serial.timeouts"), "{diag:?}");
}
