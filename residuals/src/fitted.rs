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

/// A number with four significant digits (scientific notation for the very small and large):
/// how parameters of very different scales (a play in steps, a drift rate in mm/s, a map
/// coefficient) are printed.
pub fn significant(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let exponent = v.abs().log10().floor() as i32;
    if !(-3..6).contains(&exponent) {
        return format!("{v:.3e}");
    }
    let digits = (3 - exponent).max(0) as usize;
    format!("{v:.digits$}")
}

impl Estimate {
    /// `name = value +- std unit` with four significant digits (`+-` written as `pm`).
    pub fn text(&self, pm: &str) -> String {
        match self.std {
            Some(s) => format!(
                "{} = {} {pm} {} {}",
                self.name,
                significant(self.value),
                significant(s),
                self.unit
            ),
            None => format!("{} = {} {}", self.name, significant(self.value), self.unit),
        }
    }

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

/// The change an accepted candidate makes to the robot file (shared: a search that goes back
/// to a round takes that round's fits again).
pub type Change = std::sync::Arc<dyn Fn(&mut RobotConfig) + Send + Sync>;

/// A candidate fitted to the training rows.
#[derive(Clone)]
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameters_print_with_four_significant_digits() {
        assert_eq!(significant(3.00623), "3.006");
        assert_eq!(significant(-0.0020001), "-0.002000");
        assert_eq!(significant(65000.0), "65000");
        assert_eq!(significant(3.9e-7), "3.900e-7");
        assert_eq!(
            Estimate::new("rate", -0.002, Some(3.9e-7), "mm/s").text("+-"),
            "rate = -0.002000 +- 3.900e-7 mm/s"
        );
    }
}
