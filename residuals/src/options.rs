//! Settings of the attribution ([`crate::attribute`]).

use crate::effects;
use serde::Serialize;

/// Settings of the attribution.
#[derive(Debug, Clone, Serialize)]
pub struct Options {
    /// Family-wise significance level of one round (divided among the candidates).
    pub alpha: f64,
    /// Smallest RMS reduction of the held-out position error worth claiming, mm.
    pub min_effect_mm: f64,
    /// Largest number of effects added.
    pub max_rounds: usize,
    /// Candidates tried (names of [`crate::effects::ALL`]), in this order.
    pub candidates: Vec<String>,
    /// Largest distance of the extended model's geometry from the drawing, mm or degrees.
    pub max_geometry_change: f64,
    /// Solve every row on its own: no reuse of a row at rest's prediction, no warm-started
    /// loaded equilibrium, load responses computed at every row instead of interpolated between
    /// anchors. Slow; the reference the fast path is tested against.
    pub exact: bool,
    /// Where progress is reported (nowhere by default).
    #[serde(skip)]
    pub progress: crate::progress::ProgressSink,
    /// The static poses of the first calibration, to make it again from the drawing with the
    /// effects in the model ([`crate::recalibration`]); `None`: the calibration parameters are
    /// refined linearised only. The JSON says which (`from_drawing`).
    #[serde(rename = "from_drawing", serialize_with = "is_given")]
    pub recalibration: Option<std::sync::Arc<Recalibration>>,
}

/// Whether the static poses for the calibration from the drawing were given.
fn is_given<S: serde::Serializer>(
    r: &Option<std::sync::Arc<Recalibration>>,
    s: S,
) -> Result<S::Ok, S::Error> {
    s.serialize_bool(r.is_some())
}

impl Default for Options {
    fn default() -> Self {
        Options {
            alpha: 1e-2,
            min_effect_mm: 0.01,
            max_rounds: 6,
            candidates: effects::names().into_iter().map(String::from).collect(),
            max_geometry_change: 3.0,
            exact: false,
            progress: Default::default(),
            recalibration: None,
        }
    }
}

/// The static poses the analysis's first calibration was made from, so that it can be made
/// again with the effects in the model
/// ([`crate::recalibration`]).
#[derive(Debug, Clone)]
pub struct Recalibration {
    /// The static poses.
    pub data: pcr_calibration::StaticData,
    /// Index of their recording among the analysed series.
    pub series: usize,
    /// The first calibration's settings.
    pub options: pcr_calibration::calibrate::Options,
}
