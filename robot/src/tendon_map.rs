//! Specification of the robot-dependent model: the map from tendon displacement to curvature.
//!
//! Only the *specification* (which function, which coefficients) lives here; evaluation,
//! derivatives and inversion are in `pcr-kinematics::tendon`. The thirteen candidate functions
//! are the regression functions of the paper's Table I (Nuelle et al.), in its order and forms:
//! polynomials, root series and logarithmic forms.
//!
//! The paper writes them for dl as it is; roots and logarithms are undefined for dl <= 0, and the
//! tendons of the robot move both ways. Our extension (docs/calibration.md, "Table I"):
//! every non-constant basis function is odd, `b(-dl) = -b(dl)`, and the constant `k0` stays an
//! offset. So `dl^2` reads `dl |dl|`, `dl^(1/n)` reads `sgn(dl) |dl|^(1/n)`, and `ln(dl)` reads
//! `sgn(dl) ln(1 + |dl|)` (ln(dl) has a pole at dl = 0, inside the tendons' travel; `ln(1 + dl)`
//! is finite there, has slope 1 at zero from both sides, and tends to ln(dl) for large dl).

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
    /// kappa = k0 + k1 dl + k2 dl|dl| + k3 sgn(dl) ln(1 + |dl|)
    /// (paper: k0 + k1 dl + k2 dl^2 + k3 ln(dl))
    PolyLog,
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
        TendonMapKind::PolyLog,
    ];

    /// Number of coefficients k0, k1, ... the family takes (Linear and Log have no k0).
    pub fn n_coeffs(self) -> usize {
        match self {
            TendonMapKind::Linear | TendonMapKind::Log => 1,
            TendonMapKind::Affine | TendonMapKind::LogAffine => 2,
            TendonMapKind::Poly2 | TendonMapKind::LinLog => 3,
            TendonMapKind::Poly3 | TendonMapKind::PolyLog => 4,
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
            TendonMapKind::PolyLog => "poly_log",
        }
    }

    /// The function's number in the paper's Table I (1..=13).
    pub fn table_index(self) -> usize {
        Self::ALL
            .iter()
            .position(|k| *k == self)
            .map_or(0, |i| i + 1)
    }

    /// The family with Table I number `index` (1..=13).
    pub fn from_table_index(index: usize) -> Option<TendonMapKind> {
        index.checked_sub(1).and_then(|i| Self::ALL.get(i).copied())
    }

    /// The form as the paper's Table I writes it (valid for dl > 0).
    pub fn paper_form(self) -> &'static str {
        match self {
            TendonMapKind::Linear => "k0 dl",
            TendonMapKind::Affine => "k0 + k1 dl",
            TendonMapKind::Poly2 => "k0 + k1 dl + k2 dl^2",
            TendonMapKind::Poly3 => "k0 + k1 dl + k2 dl^2 + k3 dl^3",
            TendonMapKind::Root2 => "k0 + k1 dl + k2 dl^(1/2)",
            TendonMapKind::Root3 => "k0 + k1 dl + k2 dl^(1/2) + k3 dl^(1/3)",
            TendonMapKind::Root4 => "k0 + k1 dl + k2 dl^(1/2) + k3 dl^(1/3) + k4 dl^(1/4)",
            TendonMapKind::Root5 => "k0 + k1 dl + k2 dl^(1/2) + ... + k5 dl^(1/5)",
            TendonMapKind::Root6 => "k0 + k1 dl + k2 dl^(1/2) + ... + k6 dl^(1/6)",
            TendonMapKind::Log => "k0 ln(dl)",
            TendonMapKind::LogAffine => "k0 + k1 ln(dl)",
            TendonMapKind::LinLog => "k0 + k1 dl + k2 ln(dl)",
            TendonMapKind::PolyLog => "k0 + k1 dl + k2 dl^2 + k3 ln(dl)",
        }
    }

    /// The form as evaluated for every dl (the odd extension of the paper's form), with the
    /// coefficients named in the order they are stored (k0 first, as in the paper).
    pub fn extended_form(self) -> &'static str {
        match self {
            TendonMapKind::Linear => "k0 dl",
            TendonMapKind::Affine => "k0 + k1 dl",
            TendonMapKind::Poly2 => "k0 + k1 dl + k2 dl|dl|",
            TendonMapKind::Poly3 => "k0 + k1 dl + k2 dl|dl| + k3 dl^3",
            TendonMapKind::Root2 => "k0 + k1 dl + k2 s|dl|^(1/2)",
            TendonMapKind::Root3 => "k0 + k1 dl + k2 s|dl|^(1/2) + k3 s|dl|^(1/3)",
            TendonMapKind::Root4 => "k0 + k1 dl + k2 s|dl|^(1/2) + k3 s|dl|^(1/3) + k4 s|dl|^(1/4)",
            TendonMapKind::Root5 => "k0 + k1 dl + k2 s|dl|^(1/2) + ... + k5 s|dl|^(1/5)",
            TendonMapKind::Root6 => "k0 + k1 dl + k2 s|dl|^(1/2) + ... + k6 s|dl|^(1/6)",
            TendonMapKind::Log => "k0 s ln(1 + |dl|)",
            TendonMapKind::LogAffine => "k0 + k1 s ln(1 + |dl|)",
            TendonMapKind::LinLog => "k0 + k1 dl + k2 s ln(1 + |dl|)",
            TendonMapKind::PolyLog => "k0 + k1 dl + k2 dl|dl| + k3 s ln(1 + |dl|)",
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
/// `coeffs` are the coefficients in the order the paper's form names them, k0 first (kappa in
/// 1/mm, dl in mm; the units of each coefficient follow from its basis function). An empty `coeffs` with `model = "linear"` means the nominal map
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
