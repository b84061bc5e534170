//! The driver backend a supervisor configuration selects: the real robot over a serial port,
//! the simulated plant alone, or the firmware in the loop.
//!
//! ```toml
//! [driver]
//! backend = "firmware_in_the_loop"     # or "serial", "plant"
//! plant = "configs/plant.toml"         # plant and firmware_in_the_loop
//! # port = "/dev/ttyACM0"              # serial
//! ```
//!
//! See `docs/fil.md` (`configs/fil.toml` is the full example).

use std::path::{Path, PathBuf};
use std::time::Duration;

use pcr_driver::{Driver, DriverError, DriverState, MotorCommand, SerialConfig, SerialDriver};
use pcr_plant::{Measurement, Plant, PlantConfig, TrueState};
use pcr_robot::RobotConfig;
use serde::{Deserialize, Serialize};

use crate::error::FilError;
use crate::firmware_in_the_loop::{FilOptions, FirmwareInTheLoop};

/// Which drive the control chain talks to (the `[driver]` table of a supervisor config).
/// Relative paths are taken relative to the process's working directory (the repository
/// root, like every `configs/...` path of the stack).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "backend", rename_all = "snake_case", deny_unknown_fields)]
pub enum DriverBackend {
    /// The real robot: Arduino Uno with the firmware on a serial port.
    Serial {
        /// Serial device, e.g. `/dev/ttyACM0`.
        port: String,
        /// Reply timeout, ms (default 50).
        #[serde(default)]
        reply_timeout_ms: Option<u64>,
    },
    /// The simulated plant alone, with its own stepper model (fast, deterministic, any speed).
    Plant {
        /// Plant configuration file (`configs/plant.toml`, `configs/plant-ideal.toml`).
        plant: PathBuf,
    },
    /// Serial driver -> real firmware in simavr -> simulated plant (real time).
    FirmwareInTheLoop {
        /// Plant configuration file.
        plant: PathBuf,
        /// Firmware build and PTY folder (default: `$TMPDIR/pcr-fil`).
        #[serde(default)]
        work_dir: Option<PathBuf>,
        /// Firmware host watchdog, ms (default: the firmware's 200; 0 = off). A longer one
        /// tolerates a starved emulator.
        #[serde(default)]
        watchdog_ms: Option<u16>,
    },
}

/// A supervisor configuration file may hold other tables; only `[driver]` is read here.
#[derive(Debug, Deserialize)]
struct Wrapper {
    driver: DriverBackend,
}

impl DriverBackend {
    /// Reads the `[driver]` table of a TOML text (other tables are ignored).
    pub fn from_toml_str(text: &str, origin: &str) -> Result<DriverBackend, FilError> {
        let value: toml::Table = toml::from_str(text).map_err(|e| FilError::Config {
            origin: origin.into(),
            message: e.to_string(),
        })?;
        let driver = value
            .get("driver")
            .cloned()
            .ok_or_else(|| FilError::Config {
                origin: origin.into(),
                message: "no [driver] table".into(),
            })?;
        let mut t = toml::Table::new();
        t.insert("driver".into(), driver);
        let w: Wrapper = t
            .try_into()
            .map_err(|e: toml::de::Error| FilError::Config {
                origin: origin.into(),
                message: format!("[driver]: {}", e.message()),
            })?;
        Ok(w.driver)
    }

    /// Reads the `[driver]` table of a TOML file (e.g. `configs/fil.toml`).
    pub fn load(path: impl AsRef<Path>) -> Result<DriverBackend, FilError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| FilError::Config {
            origin: path.display().to_string(),
            message: e.to_string(),
        })?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// Builds the backend: opens the port, builds the plant, or starts the FIL (builds the
    /// firmware, starts the emulator, connects).
    pub fn build_backend(&self, robot: &RobotConfig) -> Result<Backend, FilError> {
        Ok(match self {
            DriverBackend::Serial {
                port,
                reply_timeout_ms,
            } => {
                let mut cfg = SerialConfig::new(port.clone());
                if let Some(ms) = reply_timeout_ms {
                    cfg.reply_timeout = Duration::from_millis(*ms);
                }
                Backend::Serial(Box::new(SerialDriver::open(cfg)?))
            }
            DriverBackend::Plant { plant } => {
                let cfg = PlantConfig::load(plant)?;
                Backend::Plant(Box::new(Plant::new(robot, &cfg)?))
            }
            DriverBackend::FirmwareInTheLoop {
                plant,
                work_dir,
                watchdog_ms,
            } => {
                let cfg = PlantConfig::load(plant)?;
                let mut opts = FilOptions::default();
                if let Some(d) = work_dir {
                    opts.work_dir = d.clone();
                }
                if let Some(ms) = watchdog_ms {
                    let mut fw = FilOptions::firmware_for(robot);
                    fw.watchdog_ms = *ms;
                    opts.firmware = Some(fw);
                }
                Backend::FirmwareInTheLoop(Box::new(FirmwareInTheLoop::start(robot, &cfg, opts)?))
            }
        })
    }

    /// Builds the backend as a plain [`Driver`] (wrap it in the safety decorators as usual).
    pub fn build(&self, robot: &RobotConfig) -> Result<Box<dyn Driver>, FilError> {
        Ok(Box::new(self.build_backend(robot)?))
    }
}

/// A built backend: a [`Driver`], plus the simulated measurements when there is a plant.
pub enum Backend {
    /// The real robot.
    Serial(Box<SerialDriver>),
    /// The plant alone.
    Plant(Box<Plant>),
    /// Firmware in the loop.
    FirmwareInTheLoop(Box<FirmwareInTheLoop>),
}

impl std::fmt::Debug for Backend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Backend({})", self.name())
    }
}

impl Backend {
    /// Motion-capture samples reported since the last call (capture frame), when a plant is
    /// simulated; empty for the real robot (its capture comes from the mocap bridge).
    pub fn drain_measurements(&mut self) -> Vec<Measurement> {
        match self {
            Backend::Serial(_) => Vec::new(),
            Backend::Plant(p) => p.drain_measurements(),
            Backend::FirmwareInTheLoop(f) => f.drain_measurements(),
        }
    }

    /// The plant's true state, when a plant is simulated.
    pub fn true_state(&self) -> Option<&TrueState> {
        match self {
            Backend::Serial(_) => None,
            Backend::Plant(p) => Some(p.true_state()),
            Backend::FirmwareInTheLoop(f) => Some(f.true_state()),
        }
    }

    /// The plant, when one is simulated.
    pub fn plant(&self) -> Option<&Plant> {
        match self {
            Backend::Serial(_) => None,
            Backend::Plant(p) => Some(p),
            Backend::FirmwareInTheLoop(f) => Some(f.plant()),
        }
    }

    fn inner(&self) -> &dyn Driver {
        match self {
            Backend::Serial(d) => d.as_ref(),
            Backend::Plant(p) => p.as_ref(),
            Backend::FirmwareInTheLoop(f) => f.as_ref(),
        }
    }

    fn inner_mut(&mut self) -> &mut dyn Driver {
        match self {
            Backend::Serial(d) => d.as_mut(),
            Backend::Plant(p) => p.as_mut(),
            Backend::FirmwareInTheLoop(f) => f.as_mut(),
        }
    }
}

impl Driver for Backend {
    fn name(&self) -> &str {
        self.inner().name()
    }
    fn write(&mut self, time_s: f64, period_s: f64, cmd: &MotorCommand) -> Result<(), DriverError> {
        self.inner_mut().write(time_s, period_s, cmd)
    }
    fn read(&mut self, time_s: f64, period_s: f64) -> Result<DriverState, DriverError> {
        self.inner_mut().read(time_s, period_s)
    }
    fn diagnostics(&self) -> Vec<(String, u64)> {
        self.inner().diagnostics()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_each_backend_and_ignores_other_tables() {
        let fil = DriverBackend::from_toml_str(
            "[supervisor]\ncycle_ms = 20\n[driver]\nbackend = \"firmware_in_the_loop\"\nplant = \"configs/plant.toml\"\n",
            "test",
        )
        .unwrap();
        assert_eq!(
            fil,
            DriverBackend::FirmwareInTheLoop {
                plant: "configs/plant.toml".into(),
                work_dir: None,
                watchdog_ms: None
            }
        );
        let serial = DriverBackend::from_toml_str(
            "[driver]\nbackend = \"serial\"\nport = \"/dev/ttyACM0\"\n",
            "t",
        )
        .unwrap();
        assert_eq!(
            serial,
            DriverBackend::Serial {
                port: "/dev/ttyACM0".into(),
                reply_timeout_ms: None
            }
        );
        let plant = DriverBackend::from_toml_str(
            "[driver]\nbackend = \"plant\"\nplant = \"p.toml\"\n",
            "t",
        )
        .unwrap();
        assert_eq!(
            plant,
            DriverBackend::Plant {
                plant: "p.toml".into()
            }
        );
    }

    #[test]
    fn bad_selection_is_a_clear_error() {
        let e = DriverBackend::from_toml_str("[driver]\nbackend = \"usb\"\n", "sup.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("sup.toml") && e.contains("usb"), "{e}");
        let e = DriverBackend::from_toml_str("[driver]\nbackend = \"plant\"\n", "sup.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("plant"), "{e}");
        let e = DriverBackend::from_toml_str("x = 1\n", "sup.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("no [driver] table"), "{e}");
    }

    #[test]
    fn shipped_config_selects_the_fil() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/fil.toml");
        let b = DriverBackend::load(&path).unwrap();
        assert!(
            matches!(b, DriverBackend::FirmwareInTheLoop { .. }),
            "{b:?}"
        );
    }

    #[test]
    fn plant_backend_builds_and_drives() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/plant-ideal.toml");
        let b = DriverBackend::Plant { plant: path };
        let mut d = b.build_backend(&RobotConfig::nominal()).unwrap();
        let home = d.plant().unwrap().home_steps();
        let cmd = MotorCommand {
            steps: [home[0] + 5, home[1], home[2] - 5],
            enable: true,
        };
        d.write(0.02, 0.02, &cmd).unwrap();
        let s = d.read(0.02, 0.02).unwrap();
        assert_eq!(s.steps, cmd.steps);
        assert!(!d.drain_measurements().is_empty());
        assert_eq!(d.true_state().unwrap().counter, cmd.steps);
    }
}
