//! [`FirmwareInTheLoop`]: serial driver -> firmware in simavr -> simulated plant.
//!
//! Clock: the plant runs on the emulated AVR time (seconds since the emulator started). The
//! harness keeps AVR time from running ahead of wall-clock time, so a caller pacing its cycles
//! at 20 ms of wall-clock time gives the firmware its real cadence. Each step the harness
//! decodes from the coil pins carries its AVR cycle; [`FirmwareInTheLoop::sync`] hands the
//! steps seen so far to [`Plant::advance_with_steps`], which applies each at the end of the
//! plant sub-step (10 ms with the default 2 sub-steps per 20 ms) that contains it.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use pcr_driver::interface::N_MOTORS;
use pcr_driver::protocol::FwConfig;
use pcr_driver::sim::{build_firmware, SimFirmware, F_CPU};
use pcr_driver::{Driver, DriverError, DriverState, MotorCommand, SerialConfig, SerialDriver};
use pcr_plant::sim::MotorStep;
use pcr_plant::{Measurement, Plant, PlantConfig, TrueState};
use pcr_robot::RobotConfig;

use crate::error::FilError;

/// How the FIL backend is started.
#[derive(Debug, Clone)]
pub struct FilOptions {
    /// Folder for the firmware build (`make` output, reused between runs) and the PTY link.
    pub work_dir: PathBuf,
    /// Firmware configuration sent at connection. `None`: the firmware defaults with
    /// `max_rate` set to the robot's `actuation.max_step_rate` (smallest over the legs).
    pub firmware: Option<FwConfig>,
    /// Serial reply timeout (generous: a busy machine can stall the emulator).
    pub reply_timeout: Duration,
    /// How long [`Driver::read`] waits for the coil log to reach the acknowledged positions.
    pub sync_timeout: Duration,
    /// When no step arrives, the plant's time still follows the emulator, this far behind the
    /// wall-clock time since the emulator started (s): the AVR never runs ahead of the wall
    /// clock, and this margin lets it fall behind by that much before a step would be late.
    pub idle_lag_s: f64,
}

impl Default for FilOptions {
    fn default() -> Self {
        Self {
            work_dir: std::env::temp_dir().join("pcr-fil"),
            firmware: None,
            reply_timeout: Duration::from_secs(2),
            sync_timeout: Duration::from_secs(2),
            idle_lag_s: 0.1,
        }
    }
}

impl FilOptions {
    /// The firmware defaults with `max_rate` set to the robot's `actuation.max_step_rate`
    /// (smallest over the legs): what [`FirmwareInTheLoop::start`] sends when
    /// [`FilOptions::firmware`] is `None`.
    pub fn firmware_for(robot: &RobotConfig) -> FwConfig {
        FwConfig {
            max_rate: robot
                .legs
                .iter()
                .map(|l| l.actuation.max_step_rate)
                .fold(f64::INFINITY, f64::min)
                .clamp(1.0, 1000.0) as u16,
            ..FwConfig::default()
        }
    }
}

/// Counters of the FIL coupling (see also the serial backend's).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FilCounters {
    /// Steps decoded from the coils and applied to the plant.
    pub steps_applied: u64,
    /// Steps that arrived dated before the plant's present time (applied at its next sub-step).
    pub late_steps: u64,
    /// Syncs after which the plant could not follow (no equilibrium; it held position).
    pub plant_faults: u64,
    /// Reads whose acknowledged positions the coil log did not reach within `sync_timeout`.
    pub sync_timeouts: u64,
    /// Illegal coil-pattern changes seen by the harness (lost steps on real hardware).
    pub illegal_patterns: u64,
}

/// The firmware-in-the-loop backend: a [`Driver`] whose `write` goes through the real serial
/// backend to the firmware in simavr, whose motor steps drive the plant.
pub struct FirmwareInTheLoop {
    // Field order = drop order: the port closes before the emulator is killed.
    serial: SerialDriver,
    sim: SimFirmware,
    plant: Plant,
    name: String,
    /// Firmware position minus the harness's coil count (the harness counts from 0).
    offset: [i64; N_MOTORS],
    next_event: usize,
    started: Instant,
    opts: FilOptions,
    enable: bool,
    plant_fault: bool,
    last_plant_error: Option<String>,
    counters: FilCounters,
}

impl std::fmt::Debug for FirmwareInTheLoop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FirmwareInTheLoop")
            .field("sim", &self.sim)
            .field("plant_time_s", &self.plant.time())
            .field("counters", &self.counters)
            .finish()
    }
}

static INSTANCE: AtomicU64 = AtomicU64::new(0);

impl FirmwareInTheLoop {
    /// Builds the firmware and harness (incremental `make` into `opts.work_dir/firmware`),
    /// starts the emulator, connects the serial backend (handshake, configuration), builds the
    /// plant at rest at its home motor positions and sets the firmware's counters to them
    /// (ZERO), so that the firmware, the harness and the plant agree from the start.
    pub fn start(
        robot: &RobotConfig,
        plant_cfg: &PlantConfig,
        opts: FilOptions,
    ) -> Result<Self, FilError> {
        let plant = Plant::new(robot, plant_cfg)?;
        std::fs::create_dir_all(&opts.work_dir).map_err(|e| {
            FilError::Emulator(format!("cannot create {}: {e}", opts.work_dir.display()))
        })?;
        // Absolute: `make -C driver/firmware` would take a relative BUILD folder from there.
        let work_dir = std::path::absolute(&opts.work_dir).map_err(|e| {
            FilError::Emulator(format!("bad folder {}: {e}", opts.work_dir.display()))
        })?;
        let fw = build_firmware(&work_dir.join("firmware")).map_err(FilError::Build)?;
        let link = work_dir.join(format!(
            "uart-{}-{}",
            std::process::id(),
            INSTANCE.fetch_add(1, Ordering::Relaxed)
        ));
        let started = Instant::now();
        let sim = SimFirmware::spawn(&fw, &link).map_err(FilError::Emulator)?;
        let firmware = opts
            .firmware
            .unwrap_or_else(|| FilOptions::firmware_for(robot));
        let mut cfg = SerialConfig::new(sim.port_path());
        cfg.reply_timeout = opts.reply_timeout;
        cfg.firmware_config = Some(firmware);
        let mut serial = SerialDriver::open(cfg)?;
        let home = plant.home_steps();
        let st = serial.zero(0b111, home)?;
        let coils = sim.positions();
        let offset = std::array::from_fn(|i| i64::from(st.steps[i]) - coils[i]);
        tracing::info!(port = %sim.port_path(), ?home, "firmware-in-the-loop started");
        Ok(Self {
            name: format!("fil:{}", sim.port_path()),
            serial,
            sim,
            plant,
            offset,
            next_event: 0,
            started,
            opts,
            enable: true,
            plant_fault: false,
            last_plant_error: None,
            counters: FilCounters::default(),
        })
    }

    /// Emulated firmware time now, estimated from the wall clock (s since the emulator
    /// started, minus `idle_lag_s`); the plant never advances to a time before a seen step.
    fn avr_time_estimate(&self) -> f64 {
        self.started.elapsed().as_secs_f64() - self.opts.idle_lag_s
    }

    /// Hands the steps decoded from the coils so far to the plant and advances it to the
    /// latest of: its present time, the last step's time, the estimated emulator time. Called by
    /// [`Driver::read`]; call it to let the plant follow while the host sends nothing.
    /// Returns the plant's error if it could not follow (it then holds position and reports
    /// `fault`).
    pub fn sync(&mut self) -> Result<(), pcr_plant::PlantError> {
        let (events, next) = self.sim.steps_since(self.next_event);
        self.next_event = next;
        let now = self.plant.time();
        let steps: Vec<MotorStep> = events
            .iter()
            .map(|e| MotorStep {
                t_s: e.cycle as f64 / F_CPU as f64,
                motor: e.motor,
                pos: (e.pos + self.offset[e.motor]) as i32,
            })
            .collect();
        let late = steps.iter().filter(|s| s.t_s < now).count() as u64;
        if late > 0 {
            tracing::debug!(
                late,
                plant_time = now,
                "steps dated before the plant's time"
            );
        }
        self.counters.late_steps += late;
        self.counters.steps_applied += steps.len() as u64;
        self.counters.illegal_patterns = self.sim.illegal_count() as u64;
        let t_end = steps
            .last()
            .map_or(now, |s| s.t_s)
            .max(now)
            .max(self.avr_time_estimate());
        match self.plant.advance_with_steps(t_end, &steps, self.enable) {
            Ok(()) => {
                self.plant_fault = false;
                Ok(())
            }
            Err(e) => {
                tracing::warn!(error = %e, "plant cannot follow the firmware; it holds position");
                self.counters.plant_faults += 1;
                self.plant_fault = true;
                self.last_plant_error = Some(e.to_string());
                Err(e)
            }
        }
    }

    /// Waits (up to `sync_timeout`) until the coil log has passed through `steps` (each motor's
    /// position since the last sync took that value; the motors may have moved on since), then
    /// [`Self::sync`]s. A STATE acknowledgement leaves the firmware after the steps before it
    /// were made, but the harness reports the steps on another channel (its stdout).
    fn sync_to(&mut self, steps: [i32; N_MOTORS]) {
        let off = self.offset;
        let from = self.next_event;
        let start = self.plant.true_state().counter;
        let reached = self.sim.wait_for(self.opts.sync_timeout, |l| {
            (0..N_MOTORS).all(|i| {
                let want = i64::from(steps[i]) - off[i];
                i64::from(start[i]) - off[i] == want
                    || l.steps[from.min(l.steps.len())..]
                        .iter()
                        .any(|e| e.motor == i && e.pos == want)
            })
        });
        if !reached {
            self.counters.sync_timeouts += 1;
            tracing::warn!(
                ?steps,
                coils = ?self.coil_positions(),
                "coil log did not reach the acknowledged positions"
            );
        }
        let _ = self.sync();
    }

    /// Motor positions decoded from the coil pins (in the firmware's counting), steps.
    pub fn coil_positions(&self) -> [i64; N_MOTORS] {
        let p = self.sim.positions();
        std::array::from_fn(|i| p[i] + self.offset[i])
    }

    /// The plant (true state, capture model, configuration...).
    pub fn plant(&self) -> &Plant {
        &self.plant
    }

    /// The plant's true state now (its time is the emulated firmware time, s).
    pub fn true_state(&self) -> &TrueState {
        self.plant.true_state()
    }

    /// Motion-capture samples reported since the last call (capture frame), oldest first;
    /// their times are emulated firmware time.
    pub fn drain_measurements(&mut self) -> Vec<Measurement> {
        self.plant.drain_measurements()
    }

    /// The latest motion-capture sample (capture frame), without consuming it.
    pub fn latest_measurement(&self) -> Option<Measurement> {
        self.plant.latest_measurement()
    }

    /// The serial backend (status, clear_fault, configure, counters...).
    pub fn serial_mut(&mut self) -> &mut SerialDriver {
        &mut self.serial
    }

    /// The running emulator (its step log, with AVR-cycle timestamps).
    pub fn emulator(&self) -> &SimFirmware {
        &self.sim
    }

    /// Coupling counters.
    pub fn counters(&self) -> FilCounters {
        self.counters
    }

    /// The last error of the plant (no equilibrium), if it could not follow at the last sync.
    pub fn plant_error(&self) -> Option<&str> {
        self.plant_fault
            .then_some(self.last_plant_error.as_deref())
            .flatten()
    }
}

impl Driver for FirmwareInTheLoop {
    fn name(&self) -> &str {
        &self.name
    }

    /// Sends the setpoint to the emulated firmware (one SETPOINT frame).
    fn write(&mut self, time_s: f64, period_s: f64, cmd: &MotorCommand) -> Result<(), DriverError> {
        self.enable = cmd.enable;
        self.serial.write(time_s, period_s, cmd)
    }

    /// The firmware's acknowledged state (positions when the setpoint was accepted); before
    /// returning, the plant has taken every step up to those positions (and any made since
    /// that the harness already reported). `fault` is also set
    /// when the plant could not follow (no equilibrium; it holds position).
    fn read(&mut self, time_s: f64, period_s: f64) -> Result<DriverState, DriverError> {
        let mut st = self.serial.read(time_s, period_s)?;
        if st.fault {
            // A refused setpoint (latched fault) reports the last known positions, not the
            // present ones: nothing to wait for (the firmware holds).
            let _ = self.sync();
        } else {
            self.sync_to(st.steps);
        }
        st.fault |= self.plant_fault;
        Ok(st)
    }

    fn diagnostics(&self) -> Vec<(String, u64)> {
        let c = self.counters;
        let mut d = self.serial.diagnostics();
        d.extend(
            [
                ("steps_applied", c.steps_applied),
                ("late_steps", c.late_steps),
                ("plant_faults", c.plant_faults),
                ("sync_timeouts", c.sync_timeouts),
                ("illegal_patterns", c.illegal_patterns),
            ]
            .into_iter()
            .map(|(k, v)| (format!("fil.{k}"), v)),
        );
        d
    }
}
