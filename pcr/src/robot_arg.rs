//! The `--robot` argument of the offline tools: the file given, else `configs/robot.toml` of the
//! working directory when there is one, else the built-in nominal robot (geometry.md). Which
//! robot is used is said on stderr whenever it was not given.

use anyhow::Result;
use pcr_robot::RobotConfig;
use std::path::Path;

/// The robot file of the working directory used when `--robot` is not given.
pub const DEFAULT_FILE: &str = "configs/robot.toml";

/// The robot configuration of `--robot` (or the fallback) and the name to report it by.
pub fn load(arg: Option<&str>) -> Result<(RobotConfig, String)> {
    match arg {
        Some(p) => Ok((RobotConfig::load(p)?, p.to_string())),
        None if Path::new(DEFAULT_FILE).is_file() => {
            eprintln!("robot: {DEFAULT_FILE} (--robot to choose another)");
            Ok((RobotConfig::load(DEFAULT_FILE)?, DEFAULT_FILE.to_string()))
        }
        None => {
            eprintln!(
                "robot: the built-in nominal robot (geometry.md): no {DEFAULT_FILE} here; \
                 --robot to choose one"
            );
            Ok((RobotConfig::nominal(), "nominal (built-in)".to_string()))
        }
    }
}

/// The robot model of `--robot` (see [`load`]).
pub fn robot(arg: Option<&str>) -> Result<pcr_kinematics::Robot> {
    let (cfg, name) = load(arg)?;
    pcr_kinematics::Robot::new(&cfg).map_err(|e| anyhow::anyhow!("robot {name}: {e}"))
}
