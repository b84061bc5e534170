//! The supervisor's configuration (`configs/sim.toml`, `configs/lab.toml`): which processes to
//! run with which backends, timing, restart policy, real-time settings. Every error names the
//! offending key (`process[2].backend`, `restart.max_failures`).

use serde::Deserialize;
use std::path::{Path, PathBuf};

/// A configuration error; the message names the key.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file cannot be read.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// Not valid TOML.
    #[error("{path}: not valid TOML: {message}")]
    Syntax {
        /// File.
        path: String,
        /// The parser's message (with line and column).
        message: String,
    },
    /// A key is unknown, missing or of the wrong type.
    #[error("{path}: key `{key}`: {message}")]
    Key {
        /// File.
        path: String,
        /// Dotted key path.
        key: String,
        /// What is wrong.
        message: String,
    },
}

/// The processes the supervisor knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ProcessName {
    /// `pcr-planner`.
    Planner,
    /// `pcr-ik`.
    Ik,
    /// `pcr-driver`.
    Driver,
    /// `pcr-mocap`.
    Mocap,
    /// `pcr-qtm` (the motion-capture bridge; needs a `[capture]` section).
    Qtm,
}

impl ProcessName {
    /// The short name.
    pub fn as_str(self) -> &'static str {
        match self {
            ProcessName::Planner => "planner",
            ProcessName::Ik => "ik",
            ProcessName::Driver => "driver",
            ProcessName::Mocap => "mocap",
            ProcessName::Qtm => "qtm",
        }
    }
    /// The binary's file name.
    pub fn binary(self) -> String {
        format!("pcr-{}", self.as_str())
    }
    /// The matching node kind.
    pub fn kind(self) -> pcr_messages::NodeKind {
        use pcr_messages::NodeKind as K;
        match self {
            ProcessName::Planner => K::Planner,
            ProcessName::Ik => K::Ik,
            ProcessName::Driver => K::Driver,
            ProcessName::Mocap => K::Mocap,
            ProcessName::Qtm => K::Qtm,
        }
    }
}

/// Driver backends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// Ideal drive with an FK pose sensor (fast, deterministic; tests).
    Sim,
    /// The simulated plant (`pcr-plant`): elastica statics and the error effects of its
    /// configuration, with its motion-capture view as the measured pose.
    Plant,
    /// The firmware over a serial port.
    Serial,
    /// Firmware in the loop: the serial driver -> the real firmware in simavr -> the plant.
    Fil,
}

fn d_prefix() -> String {
    "pcr_".into()
}
fn d_period() -> f64 {
    20.0
}
fn d_hb() -> f64 {
    100.0
}
fn d_hb_timeout() -> f64 {
    1000.0
}
fn d_startup() -> f64 {
    10_000.0
}
fn d_rec() -> String {
    "out/recordings".into()
}
fn d_robot() -> String {
    "configs/robot.toml".into()
}

/// Restart policy.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RestartConfig {
    /// Failures of one process within `window_s` after which the supervisor stops restarting
    /// and escalates to a safe stop.
    #[serde(default = "RestartConfig::d_max")]
    pub max_failures: u32,
    /// Window of the failure count, s.
    #[serde(default = "RestartConfig::d_window")]
    pub window_s: f64,
    /// First restart delay, ms (doubles per failure).
    #[serde(default = "RestartConfig::d_b0")]
    pub backoff_initial_ms: f64,
    /// Largest restart delay, ms.
    #[serde(default = "RestartConfig::d_b1")]
    pub backoff_max_ms: f64,
}

impl RestartConfig {
    fn d_max() -> u32 {
        3
    }
    fn d_window() -> f64 {
        60.0
    }
    fn d_b0() -> f64 {
        100.0
    }
    fn d_b1() -> f64 {
        2000.0
    }
}

impl Default for RestartConfig {
    fn default() -> Self {
        Self {
            max_failures: Self::d_max(),
            window_s: Self::d_window(),
            backoff_initial_ms: Self::d_b0(),
            backoff_max_ms: Self::d_b1(),
        }
    }
}

/// Real-time settings shared by all processes.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RealtimeConfig {
    /// Lock the processes' memory (mlockall).
    #[serde(default)]
    pub mlockall: bool,
    /// Hold the CPUs' tolerated wake-up latency at this many microseconds while the supervisor
    /// runs (`/dev/cpu_dma_latency`, usually 0: no deep idle states). Unset: leave it.
    #[serde(default)]
    pub cpu_dma_latency_us: Option<i32>,
}

/// Capture systems.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CaptureSystem {
    /// Qualisys QTM over its real-time protocol (`pcr-qtm`).
    Qtm,
}

/// The motion-capture system (`[capture]`): where the measured pose and the recording's
/// measured columns come from. Without it, `pcr-mocap` takes the driver backend's pose sensor.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaptureConfig {
    /// The system (`qtm`).
    pub system: CaptureSystem,
    /// QTM host.
    #[serde(default = "CaptureConfig::d_host")]
    pub host: String,
    /// QTM RT port (little-endian; 0 with `simulate`: any free port).
    #[serde(default = "CaptureConfig::d_port")]
    pub port: u16,
    /// The driver's plant backend serves a simulated QTM on `host:port` (simulation).
    #[serde(default)]
    pub simulate: bool,
    /// Registration file (`pcr qtm register`), or `auto` (register from the base markers at
    /// every connection).
    #[serde(default = "CaptureConfig::d_reg")]
    pub registration: String,
    /// The platform's 6DOF body (default: the first).
    pub body: Option<String>,
    /// A measurement older than this holds the correction, ms.
    #[serde(default = "CaptureConfig::d_stale")]
    pub stale_ms: f64,
    /// Ask QTM for about this many frames per second (default: all frames).
    pub frequency: Option<u32>,
    /// The capture system's latency from measurement to report, ms, as measured by the lab
    /// (e.g. QTM's real-time latency measurement): recorders that align the measured columns
    /// with the rows by capture time (`pcr experiment`) subtract it. Default: none declared.
    pub latency_ms: Option<f64>,
}

impl CaptureConfig {
    fn d_host() -> String {
        "127.0.0.1".into()
    }
    fn d_port() -> u16 {
        22223
    }
    fn d_reg() -> String {
        "auto".into()
    }
    fn d_stale() -> f64 {
        100.0
    }
}

/// One process to run.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProcessConfig {
    /// Which process (`planner`, `ik`, `driver`, `mocap`, `qtm`).
    pub name: ProcessName,
    /// Driver backend (`sim`, `serial`); driver only.
    pub backend: Option<Backend>,
    /// Serial port of the serial backend.
    pub port: Option<String>,
    /// Plant configuration of the plant backend (default: the built-in prototype plant).
    pub plant: Option<String>,
    /// SCHED_FIFO priority 1..99 (0 = normal scheduling).
    #[serde(default)]
    pub priority: i32,
    /// CPU affinity.
    pub cpu: Option<usize>,
    /// Extra command-line arguments.
    #[serde(default)]
    pub args: Vec<String>,
}

/// The live view (`[live]`): the run's channels served over the Foxglove WebSocket protocol
/// while the supervisor runs (open `ws://host:port` in Foxglove; `docs/foxglove-layout.json`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LiveConfig {
    /// Address to listen on (default 127.0.0.1: this machine only).
    #[serde(default = "LiveConfig::d_host")]
    pub host: String,
    /// TCP port (default 8765, Foxglove's; 0: any free port, printed at start and by `ctl
    /// status`).
    #[serde(default = "LiveConfig::d_port")]
    pub port: u16,
}

impl LiveConfig {
    fn d_host() -> String {
        "127.0.0.1".into()
    }
    fn d_port() -> u16 {
        8765
    }
}

/// The supervisor configuration.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SupervisorConfig {
    /// Robot configuration file (relative to the working directory).
    #[serde(default = "d_robot")]
    pub robot: String,
    /// Prefix of every iceoryx2 file of the chain.
    #[serde(default = "d_prefix")]
    pub iceoryx2_prefix: String,
    /// Control period, ms.
    #[serde(default = "d_period")]
    pub period_ms: f64,
    /// Heartbeat period, ms.
    #[serde(default = "d_hb")]
    pub heartbeat_ms: f64,
    /// A process without heartbeat for this long is hung, ms.
    #[serde(default = "d_hb_timeout")]
    pub heartbeat_timeout_ms: f64,
    /// Time a started process has to send its first heartbeat, ms.
    #[serde(default = "d_startup")]
    pub startup_timeout_ms: f64,
    /// Where recordings go.
    #[serde(default = "d_rec")]
    pub recording_dir: String,
    /// Control socket (default `/tmp/pcr-supervisor-<prefix>.sock`).
    pub control_socket: Option<String>,
    /// Directory of the process binaries (default: the supervisor's own).
    pub bin_dir: Option<String>,
    /// Restart policy.
    #[serde(default)]
    pub restart: RestartConfig,
    /// Real-time settings.
    #[serde(default)]
    pub realtime: RealtimeConfig,
    /// The motion-capture system, if any.
    #[serde(default)]
    pub capture: Option<CaptureConfig>,
    /// The live view over the Foxglove WebSocket protocol, if any.
    #[serde(default)]
    pub live: Option<LiveConfig>,
    /// The processes.
    #[serde(default)]
    pub process: Vec<ProcessConfig>,
}

impl SupervisorConfig {
    /// Loads and validates a file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, ConfigError> {
        let p = path.as_ref();
        let text = std::fs::read_to_string(p).map_err(|source| ConfigError::Read {
            path: p.display().to_string(),
            source,
        })?;
        Self::from_toml_str(&text, &p.display().to_string())
    }

    /// Parses and validates a TOML text (`origin` names it in errors).
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let value: toml::Value = toml::from_str(text).map_err(|e| ConfigError::Syntax {
            path: origin.into(),
            message: e.to_string().trim().replace('\n', " | "),
        })?;
        let cfg: SupervisorConfig = serde_path_to_error::deserialize(value).map_err(|e| {
            let key = e.path().to_string();
            ConfigError::Key {
                path: origin.into(),
                key: if key == "." {
                    "(top level)".into()
                } else {
                    key
                },
                message: e.into_inner().to_string(),
            }
        })?;
        cfg.validate(origin)?;
        Ok(cfg)
    }

    fn validate(&self, origin: &str) -> Result<(), ConfigError> {
        let bad = |key: String, message: String| ConfigError::Key {
            path: origin.into(),
            key,
            message,
        };
        for (k, v) in [
            ("period_ms", self.period_ms),
            ("heartbeat_ms", self.heartbeat_ms),
            ("heartbeat_timeout_ms", self.heartbeat_timeout_ms),
            ("startup_timeout_ms", self.startup_timeout_ms),
            ("restart.window_s", self.restart.window_s),
            (
                "restart.backoff_initial_ms",
                self.restart.backoff_initial_ms,
            ),
            ("restart.backoff_max_ms", self.restart.backoff_max_ms),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(k.into(), format!("must be a positive number, got {v}")));
            }
        }
        if let Some(l) = &self.live {
            if l.host.trim().is_empty() {
                return Err(bad(
                    "live.host".into(),
                    "must name an address to listen on (e.g. \"127.0.0.1\")".into(),
                ));
            }
        }
        if let Some(us) = self.realtime.cpu_dma_latency_us {
            if us < 0 {
                return Err(bad(
                    "realtime.cpu_dma_latency_us".into(),
                    format!("must be >= 0 microseconds, got {us}"),
                ));
            }
        }
        if self.heartbeat_timeout_ms <= 2.0 * self.heartbeat_ms {
            return Err(bad(
                "heartbeat_timeout_ms".into(),
                format!(
                    "must exceed twice heartbeat_ms ({} ms), got {}",
                    self.heartbeat_ms, self.heartbeat_timeout_ms
                ),
            ));
        }
        if self.iceoryx2_prefix.is_empty()
            || !self
                .iceoryx2_prefix
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            return Err(bad(
                "iceoryx2_prefix".into(),
                format!(
                    "must be non-empty ASCII letters, digits, '_' or '-', got {:?}",
                    self.iceoryx2_prefix
                ),
            ));
        }
        let mut seen = Vec::new();
        for (i, p) in self.process.iter().enumerate() {
            let key = |k: &str| format!("process[{i}].{k}");
            if seen.contains(&p.name) {
                return Err(bad(
                    key("name"),
                    format!("{} listed twice", p.name.as_str()),
                ));
            }
            seen.push(p.name);
            if !(0..=99).contains(&p.priority) {
                return Err(bad(
                    key("priority"),
                    format!("must be 0..=99, got {}", p.priority),
                ));
            }
            match (p.name, p.backend) {
                (ProcessName::Driver, None) => {
                    return Err(bad(
                        key("backend"),
                        "missing (sim, plant, fil or serial)".into(),
                    ))
                }
                (ProcessName::Driver, Some(Backend::Serial)) if p.port.is_none() => {
                    return Err(bad(key("port"), "the serial backend needs a port".into()))
                }
                (ProcessName::Driver, _) => {}
                (n, Some(_)) => {
                    return Err(bad(
                        key("backend"),
                        format!("only the driver has a backend, not {}", n.as_str()),
                    ))
                }
                _ => {}
            }
            if p.plant.is_some() && !matches!(p.backend, Some(Backend::Plant | Backend::Fil)) {
                return Err(bad(
                    key("plant"),
                    "only the plant and fil backends take a plant configuration".into(),
                ));
            }
            if p.port.is_some() && p.name != ProcessName::Driver {
                return Err(bad(key("port"), "only the driver has a port".into()));
            }
        }
        let has_qtm = seen.contains(&ProcessName::Qtm);
        match &self.capture {
            Some(c) => {
                if !has_qtm {
                    return Err(bad(
                        "capture".into(),
                        "a capture system needs a [[process]] named qtm (the bridge)".into(),
                    ));
                }
                if !(c.stale_ms.is_finite() && c.stale_ms > 0.0) {
                    return Err(bad(
                        "capture.stale_ms".into(),
                        format!("must be a positive number, got {}", c.stale_ms),
                    ));
                }
                let plant = self
                    .process
                    .iter()
                    .any(|p| p.name == ProcessName::Driver && p.backend == Some(Backend::Plant));
                if c.simulate && !plant {
                    return Err(bad(
                        "capture.simulate".into(),
                        "only the driver's plant backend can simulate a QTM".into(),
                    ));
                }
                if c.port == 0 && !c.simulate {
                    return Err(bad(
                        "capture.port".into(),
                        "port 0 (any free port) only with simulate = true".into(),
                    ));
                }
            }
            None if has_qtm => {
                return Err(bad(
                    "process".into(),
                    "the qtm process needs a [capture] section (system = \"qtm\", host, port)"
                        .into(),
                ))
            }
            None => {}
        }
        for needed in [ProcessName::Planner, ProcessName::Ik, ProcessName::Driver] {
            if !seen.contains(&needed) {
                return Err(bad(
                    "process".into(),
                    format!("the chain needs a [[process]] named {}", needed.as_str()),
                ));
            }
        }
        Ok(())
    }

    /// The control socket path.
    pub fn socket_path(&self) -> PathBuf {
        match &self.control_socket {
            Some(p) => PathBuf::from(p),
            None => {
                std::env::temp_dir().join(format!("pcr-supervisor-{}.sock", self.iceoryx2_prefix))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const OK: &str = r#"
robot = "configs/robot.toml"
[[process]]
name = "planner"
[[process]]
name = "ik"
[[process]]
name = "driver"
backend = "sim"
"#;

    fn err(text: &str) -> String {
        SupervisorConfig::from_toml_str(text, "t.toml")
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn minimal_config_loads_with_defaults() {
        let c = SupervisorConfig::from_toml_str(OK, "t").unwrap();
        assert_eq!(c.period_ms, 20.0);
        assert_eq!(c.process.len(), 3);
        assert_eq!(c.restart.max_failures, 3);
    }

    #[test]
    fn errors_name_the_key() {
        let e = err(&OK.replace("backend = \"sim\"", "backend = \"warp\""));
        assert!(e.contains("process[2].backend"), "{e}");
        let e = err(&format!("{OK}\n[restart]\nmax_failures = \"three\"\n"));
        assert!(e.contains("restart.max_failures"), "{e}");
        let e = err(&format!("period_ms = -1.0\n{OK}"));
        assert!(e.contains("period_ms"), "{e}");
        let e = err(&format!("{OK}\n[realtime]\ncpu_dma_latency_us = -5\n"));
        assert!(e.contains("realtime.cpu_dma_latency_us"), "{e}");
        let e = err(&format!("colour = 1\n{OK}"));
        assert!(e.contains("colour"), "{e}");
        let e = err(&OK.replace("backend = \"sim\"", "backend = \"serial\""));
        assert!(e.contains("process[2].port"), "{e}");
        let e = err("[[process]]\nname = \"ik\"\n");
        assert!(e.contains("planner"), "{e}");
        let e = err("period_ms = ");
        assert!(e.contains("not valid TOML"), "{e}");
        let e = err(&format!("{OK}\n[[process]]\nname = \"qtm\"\n"));
        assert!(e.contains("[capture]"), "{e}");
        let e = err(&format!("{OK}\n[capture]\nsystem = \"qtm\"\n"));
        assert!(e.contains("`capture`") && e.contains("qtm"), "{e}");
        let e = err(&format!(
            "{OK}\n[[process]]\nname = \"qtm\"\n[capture]\nsystem = \"qtm\"\nsimulate = true\n"
        ));
        assert!(e.contains("capture.simulate"), "{e}");
        let e = err(&format!("{OK}\n[capture]\nsystem = \"vicon\"\n"));
        assert!(e.contains("capture.system"), "{e}");
        let e = err(&format!("{OK}\n[live]\nport = 70000\n"));
        assert!(e.contains("live.port"), "{e}");
        let e = err(&format!("{OK}\n[live]\nport = -1\n"));
        assert!(e.contains("live.port"), "{e}");
        let e = err(&format!("{OK}\n[live]\nhost = \"\"\n"));
        assert!(e.contains("live.host"), "{e}");
        let e = err(&format!("{OK}\n[live]\nprot = 1\n"));
        assert!(e.contains("live") && e.contains("prot"), "{e}");
    }

    #[test]
    fn live_defaults_to_foxglove_s_port_on_this_machine() {
        let c = SupervisorConfig::from_toml_str(&format!("{OK}\n[live]\n"), "t").unwrap();
        let l = c.live.unwrap();
        assert_eq!((l.host.as_str(), l.port), ("127.0.0.1", 8765));
        assert!(SupervisorConfig::from_toml_str(OK, "t")
            .unwrap()
            .live
            .is_none());
    }

    #[test]
    fn shipped_configs_load() {
        let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/");
        for f in ["sim.toml", "sim-corrected.toml", "sim-fil.toml", "lab.toml"] {
            SupervisorConfig::load(format!("{root}{f}")).unwrap();
        }
    }
}
