//! What fitting a candidate effect gives: its parameters with their uncertainties, the change
//! of every row's residual it predicts, and the change it makes to the robot file when it is
//! accepted.

use pcr_robot::RobotConfig;
use serde::Serialize;

/// A fitted parameter.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Estimate {
    /// Name.
    pub name: String,
    /// Value.
    pub value: f64,
    /// Standard error (`None` where it could not be estimated).
    pub std: Option<f64>,
    /// Unit.
    pub unit: String,
}

impl Estimate {
    /// A parameter `name` of `value` (in `unit`) with the standard error `std` (dropped when it
    /// is not finite).
    pub fn new(name: &str, value: f64, std: Option<f64>, unit: &str) -> Estimate {
        Estimate {
            name: name.into(),
            value,
            std: std.filter(|s| s.is_finite()),
            unit: unit.into(),
        }
    }
}

/// The change an accepted candidate makes to the robot file.
pub type Change = Box<dyn Fn(&mut RobotConfig) + Send + Sync>;

/// A candidate fitted to the training rows.
pub struct Fitted {
    /// Vocabulary name.
    pub name: &'static str,
    /// The effect's parameters (not the nuisance).
    pub params: Vec<Estimate>,
    /// Number of free parameters of the effect (information criterion).
    pub k: usize,
    /// Predicted change of the residual of every row (effect and nuisance; x, y mm and the
    /// weighted phi, mm).
    pub delta: Vec<[f64; 3]>,
    /// The effect's change alone, fitted without the nuisance (`None` for `geometry`): when it
    /// covers what a recalibration gains, the physical effect is preferred to the recalibration.
    pub alone: Option<Vec<[f64; 3]>>,
    /// Training SSE after the fit, mm^2.
    pub train_sse: f64,
    /// What it writes into the robot file.
    pub change: Change,
}
