//! Specification of the robot-dependent model: the map from tendon displacement to curvature.
//!
//! Only the *specification* (which function, which coefficients) lives here; evaluation,
//! derivatives and inversion are in `pcr-kinematics::tendon`. The thirteen candidate functions
//! follow the regression families of the paper's Table I (Nuelle et al.): polynomials, root
//! series and logarithmic forms. Each non-constant basis function `b(dl)` is extended to negative
//! displacements as an odd function, `b(-dl) = -b(dl)`; the constant `k0` stays an offset.

use serde::{Deserialize, Serialize};

/// The regression families. `dl` is the signed tendon displacement in mm, kappa in 1/mm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TendonMapKind {
    /// kappa = k1 dl (paper eq. 1 when k1 = 1/(a l_C)).
    Linear,
    /// kappa = k0 + k1 dl
    Affine,
    /// kappa = k0 + k1 dl + k2 dl|dl|
    Poly2,
    /// kappa = k0 + k1 dl + k2 dl|dl| + k3 dl^3
    Poly3,
    /// kappa = k0 + k1 dl + k2 sgn(dl)|dl|^(1/2)
    Root2,
    /// root series up to |dl|^(1/3)
    Root3,
    /// root series up to |dl|^(1/4)
    Root4,
    /// root series up to |dl|^(1/5)
    Root5,
    /// root series up to |dl|^(1/6)
    Root6,
    /// kappa = k1 sgn(dl) ln(1 + |dl|)
    Log,
    /// kappa = k0 + k1 sgn(dl) ln(1 + |dl|)
    LogAffine,
    /// kappa = k0 + k1 dl + k2 sgn(dl) ln(1 + |dl|)
    LinLog,
    /// kappa = k0 + k1 sgn(dl) ln(1 + |dl|) + k2 sgn(dl) ln(1 + |dl|)^2
    Log2,
}

impl TendonMapKind {
    /// Every family, in Table I order.
    pub const ALL: [TendonMapKind; 13] = [
        TendonMapKind::Linear,
        TendonMapKind::Affine,
        TendonMapKind::Poly2,
        TendonMapKind::Poly3,
        TendonMapKind::Root2,
        TendonMapKind::Root3,
        TendonMapKind::Root4,
        TendonMapKind::Root5,
        TendonMapKind::Root6,
        TendonMapKind::Log,
        TendonMapKind::LogAffine,
        TendonMapKind::LinLog,
        TendonMapKind::Log2,
    ];

    /// Number of coefficients k0, k1, ... the family takes (Linear and Log have no k0).
    pub fn n_coeffs(self) -> usize {
        match self {
            TendonMapKind::Linear | TendonMapKind::Log => 1,
            TendonMapKind::Affine | TendonMapKind::LogAffine => 2,
            TendonMapKind::Poly2 | TendonMapKind::LinLog | TendonMapKind::Log2 => 3,
            TendonMapKind::Poly3 => 4,
            TendonMapKind::Root2 => 3,
            TendonMapKind::Root3 => 4,
            TendonMapKind::Root4 => 5,
            TendonMapKind::Root5 => 6,
            TendonMapKind::Root6 => 7,
        }
    }

    /// Whether the first coefficient is the constant offset k0.
    pub fn has_offset(self) -> bool {
        !matches!(self, TendonMapKind::Linear | TendonMapKind::Log)
    }

    /// The name used in configuration files.
    pub fn name(self) -> &'static str {
        match self {
            TendonMapKind::Linear => "linear",
            TendonMapKind::Affine => "affine",
            TendonMapKind::Poly2 => "poly2",
            TendonMapKind::Poly3 => "poly3",
            TendonMapKind::Root2 => "root2",
            TendonMapKind::Root3 => "root3",
            TendonMapKind::Root4 => "root4",
            TendonMapKind::Root5 => "root5",
            TendonMapKind::Root6 => "root6",
            TendonMapKind::Log => "log",
            TendonMapKind::LogAffine => "log_affine",
            TendonMapKind::LinLog => "lin_log",
            TendonMapKind::Log2 => "log2",
        }
    }
}

impl std::fmt::Display for TendonMapKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A tendon map of one leg as written in the robot configuration.
///
/// `coeffs` are k0, k1, ... for families with an offset and k1, ... otherwise (kappa in 1/mm,
/// dl in mm). An empty `coeffs` with `model = "linear"` means the nominal map
/// kappa = dl / (a l_C) of geometry.md.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TendonMapSpec {
    /// Which regression family.
    pub model: TendonMapKind,
    /// Its coefficients (see the family for their order).
    #[serde(default)]
    pub coeffs: Vec<f64>,
}

impl Default for TendonMapSpec {
    fn default() -> Self {
        TendonMapSpec {
            model: TendonMapKind::Linear,
            coeffs: Vec::new(),
        }
    }
}
