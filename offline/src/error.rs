//! The error of an offline operation: what kind of input was wrong, and the text the `pcr`
//! tool prints for it (the chain of causes, each said once).

/// Which input an error is about (the Python package raises one exception class per kind).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    /// A robot, plant or program file (a bad key is named).
    Config,
    /// A recording (file, line and column are named).
    Recording,
    /// The calibration could not be done on the data.
    Calibration,
    /// The residual analysis could not be done on the data.
    Residuals,
    /// A plan was refused (the move and the time are named).
    Planning,
    /// The kinematic model has no answer (no home pose, no IK solution).
    Kinematics,
    /// The simulated plant failed.
    Plant,
    /// An argument is out of its range.
    Invalid,
}

/// An offline operation's error.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct OfflineError {
    /// What it is about.
    pub kind: ErrorKind,
    /// The text, causes included.
    pub message: String,
}

impl OfflineError {
    /// An error of `kind` with this text.
    pub fn new(kind: ErrorKind, message: impl Into<String>) -> OfflineError {
        OfflineError {
            kind,
            message: message.into(),
        }
    }

    /// An argument out of its range.
    pub fn invalid(message: impl Into<String>) -> OfflineError {
        OfflineError::new(ErrorKind::Invalid, message)
    }

    /// The error of `source`, of `kind`, its causes included.
    pub fn of(kind: ErrorKind, source: &(dyn std::error::Error + 'static)) -> OfflineError {
        OfflineError::new(kind, chain_text(source))
    }

    /// The same error with `context` said first (`context: message`).
    pub fn context(self, context: impl std::fmt::Display) -> OfflineError {
        OfflineError {
            kind: self.kind,
            message: format!("{context}: {}", self.message),
        }
    }
}

/// An error and its causes, each said once (an error often quotes its cause already), joined
/// by `: `, as `pcr` prints them.
pub fn chain_text(e: &(dyn std::error::Error + 'static)) -> String {
    let mut msg = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let t = c.to_string();
        if !msg.contains(&t) {
            msg.push_str(": ");
            msg.push_str(&t);
        }
        cause = c.source();
    }
    msg
}

macro_rules! kind_of {
    ($($t:ty => $k:ident),* $(,)?) => {
        $(impl From<$t> for OfflineError {
            fn from(e: $t) -> OfflineError {
                OfflineError::of(ErrorKind::$k, &e)
            }
        })*
    };
}

kind_of!(
    pcr_robot::ConfigError => Config,
    pcr_plant::PlantConfigError => Config,
    pcr_planner::program::ProgramError => Config,
    pcr_recording::RecordingError => Recording,
    pcr_recording::SettledError => Recording,
    pcr_calibration::calibrate::CalibError => Calibration,
    pcr_calibration::DataError => Calibration,
    pcr_calibration::report::ReportError => Calibration,
    pcr_residuals::report::ReportError => Residuals,
    pcr_residuals::series::SeriesError => Residuals,
    pcr_residuals::attribution::AttributionError => Residuals,
    pcr_kinematics::ModelError => Kinematics,
    pcr_kinematics::IkError => Kinematics,
    pcr_kinematics::FkError => Kinematics,
    pcr_kinematics::TendonMapError => Kinematics,
    pcr_plant::PlantError => Plant,
    pcr_plant::StaticsError => Plant,
    pcr_control::CommandError => Planning,
    pcr_experiments::RunnerError => Plant,
    pcr_experiments::DesignError => Planning,
);
