//! The robot configuration file (`configs/robot.toml`): loading and validation.

use crate::effects::Effects;
use crate::tendon_map::{MapReading, TendonMapKind, TendonMapSpec};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Why a robot configuration could not be used. Every variant names the file and the key.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read robot configuration {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// The TOML did not parse or did not match the schema (unknown or missing key, wrong type).
    #[error("robot configuration {path}: {message}")]
    Parse {
        /// The file.
        path: String,
        /// toml's message, which names the key and the line.
        message: String,
    },
    /// A value is out of its allowed range.
    #[error("robot configuration {path}: key `{key}` = {value}: {reason}")]
    Invalid {
        /// The file.
        path: String,
        /// Dotted key, e.g. `legs[2].l_c_mm`.
        key: String,
        /// The offending value as written.
        value: String,
        /// What is wrong.
        reason: String,
    },
}

/// The sign of the passive joint angle gamma_i that selects a leg's IK branch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum WorkingMode {
    /// gamma_i < 0 (the prototype's branch).
    #[serde(rename = "-")]
    Negative,
    /// gamma_i > 0.
    #[serde(rename = "+")]
    Positive,
}

impl WorkingMode {
    /// -1.0 or +1.0.
    pub fn sign(self) -> f64 {
        match self {
            WorkingMode::Negative => -1.0,
            WorkingMode::Positive => 1.0,
        }
    }

    /// Parses "---", "-+-", ... into three modes.
    pub fn parse_triple(s: &str) -> Option<[WorkingMode; 3]> {
        let c: Vec<char> = s
            .chars()
            .filter(|c| !c.is_whitespace() && *c != ',')
            .collect();
        if c.len() != 3 {
            return None;
        }
        let mut out = [WorkingMode::Negative; 3];
        for (o, ch) in out.iter_mut().zip(c) {
            *o = match ch {
                '-' => WorkingMode::Negative,
                '+' => WorkingMode::Positive,
                _ => return None,
            };
        }
        Some(out)
    }

    /// "---" style text for three modes.
    pub fn triple_to_string(m: &[WorkingMode; 3]) -> String {
        m.iter()
            .map(|w| match w {
                WorkingMode::Negative => '-',
                WorkingMode::Positive => '+',
            })
            .collect()
    }
}

/// Actuation of one leg: tendon geometry and its stepper motor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Actuation {
    /// Tendon offset a from the backbone, mm.
    pub tendon_offset_mm: f64,
    /// Radius of the actuation roll r_act, mm.
    pub roll_radius_mm: f64,
    /// Motor steps per output revolution n_spr.
    pub steps_per_rev: u32,
    /// Maximum step rate of the drive, steps/s.
    pub max_step_rate: f64,
}

impl Default for Actuation {
    fn default() -> Self {
        Actuation {
            tendon_offset_mm: 7.0,
            roll_radius_mm: 5.0,
            steps_per_rev: 2048,
            max_step_rate: 600.0,
        }
    }
}

impl Actuation {
    /// Tendon displacement per motor step, mm/step: 2 pi r_act / n_spr.
    pub fn mm_per_step(&self) -> f64 {
        std::f64::consts::TAU * self.roll_radius_mm / self.steps_per_rev as f64
    }
}

/// Geometry, actuation and tendon map of one leg (geometry.md, per leg).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LegConfig {
    /// Radius of the circle through the base point B_i, mm.
    pub r_base_mm: f64,
    /// Polar angle of B_i, degrees.
    pub beta_deg: f64,
    /// Orientation of the segment base: base tangent = R(psi) (0, 1), degrees.
    pub psi_deg: f64,
    /// Continuum segment length l_C, mm.
    pub l_c_mm: f64,
    /// Rigid tip extension l_CE to the passive joint M_i, mm.
    pub l_ce_mm: f64,
    /// Rigid link length l_st between M_i and P_i, mm.
    pub l_st_mm: f64,
    /// Radius r_p of the platform joint P_i in frame E, mm.
    pub r_p_mm: f64,
    /// Polar angle theta_p of P_i in frame E, degrees.
    pub theta_p_deg: f64,
    /// Actuation of this leg.
    #[serde(default)]
    pub actuation: Actuation,
    /// Robot-dependent model: tendon displacement to curvature.
    #[serde(default)]
    pub tendon_map: TendonMapSpec,
}

impl LegConfig {
    /// The nominal leg `i` (0-based) of geometry.md.
    pub fn nominal(i: usize) -> LegConfig {
        let k = i as f64;
        LegConfig {
            r_base_mm: 285.0,
            beta_deg: 210.0 + 120.0 * k,
            psi_deg: 120.0 * k,
            l_c_mm: 125.0,
            l_ce_mm: 36.0,
            l_st_mm: 164.0,
            r_p_mm: 59.0,
            theta_p_deg: 210.0 + 120.0 * k,
            actuation: Actuation::default(),
            tendon_map: TendonMapSpec::default(),
        }
    }

    /// Base point B_i in the base frame, mm.
    pub fn base_point(&self) -> [f64; 2] {
        let b = self.beta_deg.to_radians();
        [self.r_base_mm * b.cos(), self.r_base_mm * b.sin()]
    }

    /// Platform joint P_i in the platform frame E, mm.
    pub fn platform_point(&self) -> [f64; 2] {
        let t = self.theta_p_deg.to_radians();
        [self.r_p_mm * t.cos(), self.r_p_mm * t.sin()]
    }
}

/// Passive joint and bending limits, shared by the three legs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// Lower limit of the passive joints at M_i and P_i, degrees.
    pub joint_min_deg: f64,
    /// Upper limit of the passive joints, degrees.
    pub joint_max_deg: f64,
    /// Largest bending angle |kappa l_C| of a segment, degrees.
    pub bending_max_deg: f64,
    /// A configuration whose conditioning measure (see `pcr-kinematics::singularity`) is below
    /// this value is reported as singular. Dimensionless, in (0, 1).
    #[serde(default = "default_singularity_threshold")]
    pub singularity_threshold: f64,
}

fn default_singularity_threshold() -> f64 {
    1e-3
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            joint_min_deg: -132.0,
            joint_max_deg: 132.0,
            bending_max_deg: 180.0,
            singularity_threshold: default_singularity_threshold(),
        }
    }
}

/// The whole robot configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotConfig {
    /// Free text naming the robot.
    #[serde(default)]
    pub name: String,
    /// Working mode as three signs of gamma_i, e.g. "---".
    #[serde(with = "mode_serde")]
    pub working_mode: [WorkingMode; 3],
    /// Joint and bending limits.
    pub limits: Limits,
    /// The three legs in order i = 1, 2, 3.
    pub legs: Vec<LegConfig>,
    /// Effects beyond the constant-curvature model (found by `pcr residuals`); none by default.
    #[serde(default, skip_serializing_if = "Effects::is_empty")]
    pub effects: Effects,
}

mod mode_serde {
    use super::WorkingMode;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(m: &[WorkingMode; 3], s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&WorkingMode::triple_to_string(m))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<[WorkingMode; 3], D::Error> {
        let s = String::deserialize(d)?;
        WorkingMode::parse_triple(&s).ok_or_else(|| {
            serde::de::Error::custom(format!(
                "working_mode must be three signs such as \"---\", got {s:?}"
            ))
        })
    }
}

impl RobotConfig {
    /// The nominal prototype of geometry.md with the linear tendon map.
    pub fn nominal() -> RobotConfig {
        RobotConfig {
            name: "3-FbRR nominal (CAD values)".into(),
            working_mode: [WorkingMode::Negative; 3],
            limits: Limits::default(),
            legs: (0..3).map(LegConfig::nominal).collect(),
            effects: Effects::default(),
        }
    }

    /// Reads and validates a configuration file.
    pub fn load(path: impl AsRef<Path>) -> Result<RobotConfig, ConfigError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// Parses and validates configuration text; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<RobotConfig, ConfigError> {
        let cfg: RobotConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: origin.to_string(),
            message: e.to_string(),
        })?;
        cfg.validate(origin)?;
        Ok(cfg)
    }

    /// Serialises to TOML (used by calibration to write a calibrated robot).
    pub fn to_toml_string(&self) -> String {
        toml::to_string_pretty(self).expect("a RobotConfig always serialises")
    }

    /// Checks units, ranges and counts; names the offending key.
    pub fn validate(&self, origin: &str) -> Result<(), ConfigError> {
        let bad = |key: String, value: String, reason: &str| ConfigError::Invalid {
            path: origin.to_string(),
            key,
            value,
            reason: reason.to_string(),
        };
        if self.legs.len() != 3 {
            return Err(bad(
                "legs".into(),
                format!("{} entries", self.legs.len()),
                "the 3-FbRR has exactly three legs ([[legs]] tables)",
            ));
        }
        let l = &self.limits;
        let finite = |key: &str, v: f64| -> Result<(), ConfigError> {
            if v.is_finite() {
                Ok(())
            } else {
                Err(bad(key.into(), v.to_string(), "must be a finite number"))
            }
        };
        finite("limits.joint_min_deg", l.joint_min_deg)?;
        finite("limits.joint_max_deg", l.joint_max_deg)?;
        finite("limits.bending_max_deg", l.bending_max_deg)?;
        if !(l.joint_min_deg < 0.0 && l.joint_min_deg >= -180.0) {
            return Err(bad(
                "limits.joint_min_deg".into(),
                l.joint_min_deg.to_string(),
                "must be in [-180, 0) degrees",
            ));
        }
        if !(l.joint_max_deg > 0.0 && l.joint_max_deg <= 180.0) {
            return Err(bad(
                "limits.joint_max_deg".into(),
                l.joint_max_deg.to_string(),
                "must be in (0, 180] degrees",
            ));
        }
        if !(l.bending_max_deg > 0.0 && l.bending_max_deg <= 360.0) {
            return Err(bad(
                "limits.bending_max_deg".into(),
                l.bending_max_deg.to_string(),
                "must be in (0, 360] degrees",
            ));
        }
        if !(l.singularity_threshold > 0.0 && l.singularity_threshold < 1.0) {
            return Err(bad(
                "limits.singularity_threshold".into(),
                l.singularity_threshold.to_string(),
                "must be in (0, 1)",
            ));
        }
        for (i, leg) in self.legs.iter().enumerate() {
            let k = |name: &str| format!("legs[{}].{name}", i + 1);
            let positive = [
                ("r_base_mm", leg.r_base_mm),
                ("l_c_mm", leg.l_c_mm),
                ("l_st_mm", leg.l_st_mm),
                ("r_p_mm", leg.r_p_mm),
                ("actuation.tendon_offset_mm", leg.actuation.tendon_offset_mm),
                ("actuation.roll_radius_mm", leg.actuation.roll_radius_mm),
                ("actuation.max_step_rate", leg.actuation.max_step_rate),
            ];
            for (name, v) in positive {
                if !(v.is_finite() && v > 0.0) {
                    return Err(bad(
                        k(name),
                        v.to_string(),
                        "must be a finite length/rate > 0",
                    ));
                }
            }
            for (name, v) in [
                ("l_ce_mm", leg.l_ce_mm),
                ("beta_deg", leg.beta_deg),
                ("psi_deg", leg.psi_deg),
                ("theta_p_deg", leg.theta_p_deg),
            ] {
                if !v.is_finite() {
                    return Err(bad(k(name), v.to_string(), "must be a finite number"));
                }
            }
            if leg.l_ce_mm < 0.0 {
                return Err(bad(
                    k("l_ce_mm"),
                    leg.l_ce_mm.to_string(),
                    "must be >= 0 mm",
                ));
            }
            for (name, v) in [
                ("beta_deg", leg.beta_deg),
                ("psi_deg", leg.psi_deg),
                ("theta_p_deg", leg.theta_p_deg),
            ] {
                if v.abs() > 720.0 {
                    return Err(bad(k(name), v.to_string(), "must be within +-720 degrees"));
                }
            }
            if leg.r_base_mm > 1.0e5 || leg.l_c_mm > 1.0e5 || leg.l_st_mm > 1.0e5 {
                return Err(bad(
                    k("r_base_mm/l_c_mm/l_st_mm"),
                    "> 100 m".into(),
                    "lengths are in mm; values above 1e5 mm are certainly a unit error",
                ));
            }
            if leg.actuation.steps_per_rev == 0 {
                return Err(bad(
                    k("actuation.steps_per_rev"),
                    "0".into(),
                    "must be >= 1",
                ));
            }
            let tm = &leg.tendon_map;
            let want = tm.model.n_coeffs();
            let empty_linear = tm.model == TendonMapKind::Linear && tm.coeffs.is_empty();
            if !empty_linear && tm.coeffs.len() != want {
                return Err(bad(
                    k("tendon_map.coeffs"),
                    format!("{:?}", tm.coeffs),
                    &format!(
                        "model `{}` takes {want} coefficient(s), got {}",
                        tm.model,
                        tm.coeffs.len()
                    ),
                ));
            }
            if let Some(c) = tm.coeffs.iter().find(|c| !c.is_finite()) {
                return Err(bad(k("tendon_map.coeffs"), c.to_string(), "must be finite"));
            }
            match tm.reading {
                MapReading::Symmetric if !tm.coeffs_neg.is_empty() => {
                    return Err(bad(
                        k("tendon_map.coeffs_neg"),
                        format!("{:?}", tm.coeffs_neg),
                        "is read only with reading = \"asymmetric\"",
                    ));
                }
                MapReading::Asymmetric => {
                    let want = tm.model.n_direction_coeffs();
                    if empty_linear || tm.coeffs_neg.len() != want {
                        return Err(bad(
                            k("tendon_map.coeffs_neg"),
                            format!("{:?}", tm.coeffs_neg),
                            &format!(
                                "the asymmetric reading of model `{}` takes {} coefficient(s) in `coeffs` and {want} in `coeffs_neg` (the dl < 0 direction, without k0)",
                                tm.model,
                                tm.model.n_coeffs(),
                            ),
                        ));
                    }
                    if let Some(c) = tm.coeffs_neg.iter().find(|c| !c.is_finite()) {
                        return Err(bad(
                            k("tendon_map.coeffs_neg"),
                            c.to_string(),
                            "must be finite",
                        ));
                    }
                }
                MapReading::Symmetric => {}
            }
        }
        if let Err((key, value, reason)) = self.effects.check() {
            return Err(bad(key, value, &reason));
        }
        Ok(())
    }
}

impl RobotConfig {
    /// The same configuration with another name.
    pub fn with_name(mut self, name: &str) -> RobotConfig {
        self.name = name.to_string();
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const NOMINAL: &str = include_str!("../../configs/robot.toml");

    #[test]
    fn shipped_config_is_nominal() {
        let c = RobotConfig::from_toml_str(NOMINAL, "configs/robot.toml").unwrap();
        assert_eq!(c, RobotConfig::nominal().with_name(&c.name));
    }

    #[test]
    fn round_trip() {
        let c = RobotConfig::nominal();
        let back = RobotConfig::from_toml_str(&c.to_toml_string(), "x").unwrap();
        assert_eq!(c, back);
    }

    #[test]
    fn errors_name_the_key() {
        let text = NOMINAL.replacen("l_st_mm = 164.0", "l_st_mm = -1.0", 1);
        let e = RobotConfig::from_toml_str(&text, "r.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("legs[1].l_st_mm"), "{e}");
        let text = NOMINAL.replacen("l_c_mm", "l_cc_mm", 1);
        let e = RobotConfig::from_toml_str(&text, "r.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("l_cc_mm"), "{e}");
        let text = NOMINAL.replacen("working_mode = \"---\"", "working_mode = \"-x-\"", 1);
        let e = RobotConfig::from_toml_str(&text, "r.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("working_mode"), "{e}");
        let mut c = RobotConfig::nominal();
        c.legs.pop();
        let e = RobotConfig::from_toml_str(&c.to_toml_string(), "r.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("three legs"), "{e}");
        let mut c = RobotConfig::nominal();
        c.legs[2].tendon_map = TendonMapSpec::symmetric(TendonMapKind::Poly3, vec![1.0]);
        let e = RobotConfig::from_toml_str(&c.to_toml_string(), "r.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("legs[3].tendon_map.coeffs"), "{e}");
        let mut c = RobotConfig::nominal();
        c.legs[1].tendon_map = TendonMapSpec {
            reading: MapReading::Asymmetric,
            coeffs_neg: vec![1e-3],
            ..TendonMapSpec::symmetric(TendonMapKind::Poly2, vec![0.0, 1e-3, 1e-6])
        };
        let e = RobotConfig::from_toml_str(&c.to_toml_string(), "r.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("legs[2].tendon_map.coeffs_neg") && e.contains("2 in `coeffs_neg`"),
            "{e}"
        );
        c.legs[1].tendon_map.reading = MapReading::Symmetric;
        let e = RobotConfig::from_toml_str(&c.to_toml_string(), "r.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("only with reading"), "{e}");
    }

    #[test]
    fn an_asymmetric_map_round_trips() {
        let mut c = RobotConfig::nominal();
        c.legs[0].tendon_map = TendonMapSpec {
            reading: MapReading::Asymmetric,
            coeffs_neg: vec![1.1e-3, -2e-6],
            ..TendonMapSpec::symmetric(TendonMapKind::Poly2, vec![1e-5, 1e-3, 1e-6])
        };
        let text = c.to_toml_string();
        assert!(text.contains("reading = \"asymmetric\""), "{text}");
        let back = RobotConfig::from_toml_str(&text, "x").unwrap();
        assert_eq!(c, back);
        assert!(!RobotConfig::nominal().to_toml_string().contains("reading"));
    }
}
