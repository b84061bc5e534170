//! The set-up of the paper's experiments on the in-process chain, as `pcr experiment` and
//! `pcr.experiment` do it: the robot model, the plant's robot and the plant of a supervisor
//! configuration (with replacements), and the run's metadata. The run itself is
//! [`pcr_experiments::run_in_process`].

use crate::error::{ErrorKind, OfflineError};
use pcr_experiments::{Design, RunSetup, Tolerances};
use pcr_kinematics::Robot;
use pcr_plant::PlantConfig;
use pcr_robot::RobotConfig;
use std::path::Path;

/// The robot model, the plant's robot and the plant of a run, with their names for the
/// metadata.
#[derive(Debug, Clone)]
pub struct Sources {
    /// The model that drives.
    pub model: RobotConfig,
    /// Its name.
    pub model_name: String,
    /// The plant's own robot (the configuration's `robot`).
    pub plant_robot: RobotConfig,
    /// Its name.
    pub plant_robot_name: String,
    /// The plant.
    pub plant: PlantConfig,
    /// Its name.
    pub plant_name: String,
    /// The configuration's `[capture] latency_ms`, s.
    pub capture_latency_s: Option<f64>,
}

fn config_error(message: String) -> OfflineError {
    OfflineError::new(ErrorKind::Config, message)
}

impl Sources {
    /// The sources of a supervisor configuration (only its `robot`, its `[capture]
    /// latency_ms` and the driver process's `backend` and `plant` are read, paths relative to
    /// the working directory, as the supervisor resolves them), with optional replacements of
    /// the model and the plant, and of the plant's seed.
    pub fn from_files(
        config: &Path,
        robot: Option<&Path>,
        plant: Option<&Path>,
        plant_seed: Option<u64>,
    ) -> Result<Sources, OfflineError> {
        let cfg_name = config.display().to_string();
        let text = std::fs::read_to_string(config)
            .map_err(|e| config_error(format!("--config {cfg_name}: cannot read the file: {e}")))?;
        let table: toml::Table = toml::from_str(&text).map_err(|e| {
            config_error(format!("--config {cfg_name}: not a valid TOML file: {e}"))
        })?;
        // The supervisor's default robot and its resolution: relative to the working directory.
        let robot_path = match table.get("robot") {
            None => "configs/robot.toml".to_string(),
            Some(toml::Value::String(s)) => s.clone(),
            Some(_) => {
                return Err(config_error(format!(
                    "--config {cfg_name}: key `robot` must be a file name"
                )))
            }
        };
        let plant_robot = RobotConfig::load(&robot_path).map_err(|e| {
            OfflineError::from(e).context(format!("--config {cfg_name}: robot = {robot_path:?}"))
        })?;
        let (model, model_name) = match robot {
            Some(p) => (
                RobotConfig::load(p).map_err(|e| {
                    OfflineError::from(e).context(format!("--robot {}", p.display()))
                })?,
                p.display().to_string(),
            ),
            None => (plant_robot.clone(), robot_path.clone()),
        };
        let (mut plant, plant_name) = match plant {
            Some(p) => (
                PlantConfig::load(p).map_err(|e| {
                    OfflineError::from(e).context(format!("--plant {}", p.display()))
                })?,
                p.display().to_string(),
            ),
            None => plant_of_config(&table, &cfg_name)?,
        };
        if let Some(s) = plant_seed {
            plant.seed = s;
        }
        let capture_latency_s = match table.get("capture").and_then(|c| c.get("latency_ms")) {
            None => None,
            Some(v) => match v.as_float().or_else(|| v.as_integer().map(|i| i as f64)) {
                Some(ms) if ms.is_finite() && (0.0..=1000.0).contains(&ms) => Some(ms * 1e-3),
                _ => {
                    return Err(config_error(format!(
                        "--config {cfg_name}: [capture] latency_ms = {v}: must be a number of \
                         milliseconds in 0..=1000"
                    )))
                }
            },
        };
        Ok(Sources {
            model,
            model_name,
            plant_robot,
            plant_robot_name: robot_path,
            plant,
            plant_name,
            capture_latency_s,
        })
    }

    /// The model that drives.
    pub fn model_robot(&self) -> Result<Robot, OfflineError> {
        Robot::new(&self.model)
            .map_err(|e| OfflineError::from(e).context(format!("robot model {}", self.model_name)))
    }

    /// The same plant driven by another model.
    pub fn with_model(&self, model: RobotConfig, name: String) -> Sources {
        Sources {
            model,
            model_name: name,
            ..self.clone()
        }
    }
}

/// The plant of the supervisor configuration's driver process.
fn plant_of_config(table: &toml::Table, cfg: &str) -> Result<(PlantConfig, String), OfflineError> {
    let procs = match table.get("process") {
        Some(toml::Value::Array(a)) => a.as_slice(),
        None => &[],
        Some(_) => {
            return Err(config_error(format!(
                "--config {cfg}: `process` must be an array of tables ([[process]])"
            )))
        }
    };
    let driver = procs.iter().enumerate().find(|(_, p)| {
        p.get("name")
            .and_then(toml::Value::as_str)
            .is_some_and(|n| n == "driver")
    });
    let Some((i, driver)) = driver else {
        return Err(config_error(format!(
            "--config {cfg}: no driver process, so no plant: give --plant P"
        )));
    };
    let backend = driver
        .get("backend")
        .and_then(toml::Value::as_str)
        .unwrap_or("sim");
    match backend {
        "plant" | "fil" => match driver.get("plant") {
            None => Ok((
                PlantConfig::prototype(),
                "prototype (built-in; the config's driver names no plant)".into(),
            )),
            Some(toml::Value::String(p)) => Ok((
                PlantConfig::load(p).map_err(|e| {
                    OfflineError::from(e).context(format!("--config {cfg}: process[{i}].plant"))
                })?,
                p.clone(),
            )),
            Some(_) => Err(config_error(format!(
                "--config {cfg}: process[{i}].plant must be a file name"
            ))),
        },
        "sim" => Ok((
            PlantConfig::ideal(),
            "ideal (built-in; the config's driver uses the ideal sim backend)".into(),
        )),
        "serial" => Err(config_error(format!(
            "--config {cfg}: the driver uses the serial backend (the real robot); the \
             in-process runner needs a simulated plant: give --plant P"
        ))),
        other => Err(config_error(format!(
            "--config {cfg}: process[{i}].backend = {other:?} is not a known backend"
        ))),
    }
}

/// `created`: `SOURCE_DATE_EPOCH` (seconds) when set, so that runs can be byte-identical, else
/// now.
pub fn created() -> Result<String, OfflineError> {
    match std::env::var("SOURCE_DATE_EPOCH") {
        Ok(s) => {
            let secs: i64 = s.trim().parse().map_err(|_| {
                OfflineError::invalid(format!(
                    "SOURCE_DATE_EPOCH = {s:?} is not a number of seconds"
                ))
            })?;
            Ok(crate::clock::utc_of(secs))
        }
        Err(_) => Ok(crate::clock::utc_now()),
    }
}

/// The run set-up of `design` on the sources' plant: 20 ms period, the split's `seed`, and the
/// metadata naming the model, the plant, their robot and `tool` (e.g. `pcr 0.1.0`).
pub fn setup(
    design: &Design,
    src: Sources,
    seed: u64,
    tool: &str,
) -> Result<RunSetup, OfflineError> {
    let kind = design.kind();
    Ok(RunSetup {
        model: src.model,
        plant_robot: src.plant_robot,
        plant: src.plant,
        period_s: 0.02,
        seed,
        metadata: vec![
            ("robot".into(), src.model_name),
            ("plant".into(), src.plant_name),
            ("plant_robot".into(), src.plant_robot_name),
            (
                "source".into(),
                format!("pcr experiment {kind} (in-process chain on the simulated plant, {tool})"),
            ),
            ("created".into(), created()?),
        ],
        tolerances: Tolerances::default(),
        capture_latency_s: src.capture_latency_s,
    })
}
