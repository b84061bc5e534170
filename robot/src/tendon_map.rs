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
//!
//! That extension assumes a leg that bends alike both ways. Each form has a second reading,
//! [`MapReading::Asymmetric`], for legs that do not (pretension, friction and tendon routing
//! differ between the two tendons of a pair): for dl >= 0 the form exactly as the paper writes it
//! (`coeffs`), for dl < 0 the same odd-extended form with its own coefficients (`coeffs_neg`,
//! the other tendon's map); the two share the offset k0, so the map stays continuous at dl = 0.
//! The symmetric reading is the asymmetric one with `coeffs_neg` equal to `coeffs` without k0.

use serde::{Deserialize, Serialize};

/// The regression families. `dl` is the signed tendon displacement in mm, kappa in 1/mm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
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

    /// Number of coefficients of one bending direction in the asymmetric reading: all but the
    /// shared offset k0.
    pub fn n_direction_coeffs(self) -> usize {
        self.n_coeffs() - usize::from(self.has_offset())
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

/// How a Table I form is read for the two bending directions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MapReading {
    /// One set of coefficients for both directions: the odd extension of the paper's form
    /// (a leg that bends alike both ways).
    #[default]
    Symmetric,
    /// Separate coefficients per direction, sharing the offset k0: the paper's form for
    /// dl >= 0, its odd extension with other coefficients for dl < 0.
    Asymmetric,
}

impl MapReading {
    /// Both readings, symmetric first.
    pub const ALL: [MapReading; 2] = [MapReading::Symmetric, MapReading::Asymmetric];

    /// Whether this is the symmetric reading (the default, not written to files).
    pub fn is_symmetric(&self) -> bool {
        *self == MapReading::Symmetric
    }

    /// The name used in configuration files and reports.
    pub fn name(self) -> &'static str {
        match self {
            MapReading::Symmetric => "symmetric",
            MapReading::Asymmetric => "asymmetric",
        }
    }
}

impl std::fmt::Display for MapReading {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A Table I function in one reading: the shape a leg's map is fitted as.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub struct MapForm {
    /// The Table I function.
    pub kind: TendonMapKind,
    /// How it is read for dl < 0.
    pub reading: MapReading,
}

impl MapForm {
    /// The symmetric (odd-extended) reading of `kind`.
    pub const fn symmetric(kind: TendonMapKind) -> MapForm {
        MapForm {
            kind,
            reading: MapReading::Symmetric,
        }
    }

    /// The asymmetric (per-direction) reading of `kind`.
    pub const fn asymmetric(kind: TendonMapKind) -> MapForm {
        MapForm {
            kind,
            reading: MapReading::Asymmetric,
        }
    }

    /// Number of coefficients of the form: `coeffs`, then `coeffs_neg` in the asymmetric
    /// reading (the flat order of [`TendonMapSpec::flat_coeffs`]).
    pub fn n_coeffs(self) -> usize {
        match self.reading {
            MapReading::Symmetric => self.kind.n_coeffs(),
            MapReading::Asymmetric => self.kind.n_coeffs() + self.kind.n_direction_coeffs(),
        }
    }

    /// Name of flat coefficient `j`: `k0`, `k1`, ... then `k1_neg`, ... (families without an
    /// offset: `k0_neg`).
    pub fn coeff_name(self, j: usize) -> String {
        let n = self.kind.n_coeffs();
        if j < n {
            format!("k{j}")
        } else {
            let off = usize::from(self.kind.has_offset());
            format!("k{}_neg", j - n + off)
        }
    }

    /// The coefficient of `coeffs` that flat coefficient `j` mirrors (the same power of dl).
    pub fn mirrored(self, j: usize) -> usize {
        let n = self.kind.n_coeffs();
        if j < n {
            j
        } else {
            j - n + usize::from(self.kind.has_offset())
        }
    }

    /// The form as evaluated for every dl.
    pub fn evaluated_form(self) -> String {
        match self.reading {
            MapReading::Symmetric => self.kind.extended_form().to_string(),
            MapReading::Asymmetric => format!(
                "{} for dl >= 0; k_neg for dl < 0, sharing k0",
                self.kind.paper_form()
            ),
        }
    }

    /// Short label: the Table I number, `a` for the asymmetric reading (`13`, `13a`).
    pub fn label(self) -> String {
        match self.reading {
            MapReading::Symmetric => self.kind.table_index().to_string(),
            MapReading::Asymmetric => format!("{}a", self.kind.table_index()),
        }
    }
}

impl std::fmt::Display for MapForm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ({})", self.kind, self.reading)
    }
}

/// A tendon map of one leg as written in the robot configuration.
///
/// `coeffs` are the coefficients in the order the paper's form names them, k0 first (kappa in
/// 1/mm, dl in mm; the units of each coefficient follow from its basis function). An empty `coeffs` with `model = "linear"` means the nominal map
/// kappa = dl / (a l_C) of geometry.md.
///
/// With `reading = "asymmetric"`, `coeffs` apply for dl >= 0 (the paper's form as written) and
/// `coeffs_neg` for dl < 0: the non-constant coefficients of the other direction (k1, k2, ...;
/// for the families without an offset, k0), evaluated in the odd-extended form, so that equal
/// lists give the symmetric map.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TendonMapSpec {
    /// Which regression family.
    pub model: TendonMapKind,
    /// How the family is read for dl < 0 (default: symmetric).
    #[serde(default, skip_serializing_if = "MapReading::is_symmetric")]
    pub reading: MapReading,
    /// Its coefficients (see the family for their order); for dl >= 0 in the asymmetric reading.
    #[serde(default)]
    pub coeffs: Vec<f64>,
    /// The asymmetric reading's coefficients for dl < 0 (without k0).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub coeffs_neg: Vec<f64>,
}

impl Default for TendonMapSpec {
    fn default() -> Self {
        TendonMapSpec::symmetric(TendonMapKind::Linear, Vec::new())
    }
}

impl TendonMapSpec {
    /// A symmetric map of `model` with `coeffs`.
    pub fn symmetric(model: TendonMapKind, coeffs: Vec<f64>) -> TendonMapSpec {
        TendonMapSpec {
            model,
            reading: MapReading::Symmetric,
            coeffs,
            coeffs_neg: Vec::new(),
        }
    }

    /// The map of `form` with the flat coefficient vector `x` (`coeffs`, then `coeffs_neg`).
    pub fn from_flat(form: MapForm, x: &[f64]) -> TendonMapSpec {
        let n = form.kind.n_coeffs().min(x.len());
        TendonMapSpec {
            model: form.kind,
            reading: form.reading,
            coeffs: x[..n].to_vec(),
            coeffs_neg: match form.reading {
                MapReading::Symmetric => Vec::new(),
                MapReading::Asymmetric => x[n..].to_vec(),
            },
        }
    }

    /// The family and reading.
    pub fn form(&self) -> MapForm {
        MapForm {
            kind: self.model,
            reading: self.reading,
        }
    }

    /// Every coefficient in the flat order of [`MapForm::n_coeffs`]: `coeffs`, then `coeffs_neg`.
    pub fn flat_coeffs(&self) -> Vec<f64> {
        self.coeffs
            .iter()
            .chain(&self.coeffs_neg)
            .copied()
            .collect()
    }
}
