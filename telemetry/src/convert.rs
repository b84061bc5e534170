//! `pcr convert`: a recording of the format (`shared/spec/recording.md`, any program's) to the
//! MCAP the supervisor writes beside its CSV.

use std::path::Path;

use pcr_recording::Recording;

use crate::{McapFile, RobotScene, RowSample, Telemetry, TelemetryError};

/// What a conversion wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConvertSummary {
    /// Rows converted (one message per row on the row channel).
    pub rows: usize,
    /// Rows with a planned pose.
    pub planned: usize,
    /// Rows with a measured pose.
    pub measured: usize,
    /// Whether the robot was drawn (a robot was given).
    pub scene: bool,
}

/// The robot's scene of a robot configuration file.
pub fn robot_scene(path: &Path) -> Result<RobotScene, TelemetryError> {
    let err = |message: String| TelemetryError::Robot {
        path: path.display().to_string(),
        message,
    };
    let cfg = pcr_robot::RobotConfig::load(path).map_err(|e| err(e.to_string()))?;
    let robot = pcr_kinematics::Robot::new(&cfg).map_err(|e| err(e.to_string()))?;
    Ok(RobotScene::new(robot))
}

/// Converts the recording `csv` into the MCAP `mcap` (truncated if it exists); the robot is drawn
/// when `robot` is given. Message times are the rows' `t_s` (the CSV has no other clock).
pub fn convert(
    csv: &Path,
    mcap: &Path,
    robot: Option<&Path>,
) -> Result<ConvertSummary, TelemetryError> {
    let rec = Recording::read_path(csv)?;
    let scene = robot.map(robot_scene).transpose()?;
    let drawn = scene.is_some();
    let mut tel = Telemetry::new(scene)?;
    let mut meta = rec.metadata.clone();
    meta.push(("converted_from".into(), csv.display().to_string()));
    let file = McapFile::create(&tel, mcap, &meta)?;
    let mut summary = ConvertSummary {
        rows: 0,
        planned: 0,
        measured: 0,
        scene: drawn,
    };
    for row in &rec.rows {
        let extra: Vec<Option<&str>> = row.extra.iter().map(|c| c.as_deref()).collect();
        tel.row(
            &RowSample {
                chain_t_s: row.t_s,
                row,
                extra: &extra,
                state: None,
            },
            &rec.extra_columns,
        );
        summary.rows += 1;
        summary.planned += crate::scene::planned_pose(row).is_some() as usize;
        summary.measured += row.measured_pose().is_some() as usize;
    }
    file.finish()?;
    Ok(summary)
}
