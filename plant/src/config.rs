//! The plant configuration file (`configs/plant.toml`): every effect is a documented switch.
//!
//! Units: mm, degrees, N, N mm, seconds, motor steps. Arrays of three hold one value per leg.

use pcr_robot::RobotConfig;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Why a plant configuration could not be used. Every variant names the file and the key.
#[derive(Debug, thiserror::Error)]
pub enum PlantConfigError {
    /// The file could not be read.
    #[error("cannot read plant configuration {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// The TOML did not parse or did not match the schema (unknown or missing key, wrong type).
    #[error("plant configuration {path}: {message}")]
    Parse {
        /// The file.
        path: String,
        /// toml's message, which names the key and the line.
        message: String,
    },
    /// A value is out of its allowed range.
    #[error("plant configuration {path}: key `{key}` = {value}: {reason}")]
    Invalid {
        /// The file.
        path: String,
        /// Dotted key, e.g. `stepper.backlash_steps[2]`.
        key: String,
        /// The offending value.
        value: String,
        /// What is wrong.
        reason: String,
    },
}

/// Mechanics of the statics (always on).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mechanics {
    /// Bending stiffness EI of every segment, N mm^2.
    pub ei_n_mm2: f64,
    /// Passive joint spring stiffness at M_i, N mm/rad (0 = off).
    pub k_m_n_mm_per_rad: f64,
    /// Passive joint spring stiffness at P_i, N mm/rad (0 = off).
    pub k_p_n_mm_per_rad: f64,
    /// RK4 steps per segment (accuracy of the elastica integration).
    pub segment_steps: usize,
}

/// A constant external wrench on the platform at its centre E, base-frame components.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct ExternalWrench {
    /// Force along x, N.
    pub fx_n: f64,
    /// Force along y, N.
    pub fy_n: f64,
    /// Couple about z, N mm.
    pub mz_n_mm: f64,
}

/// Deviations of the true geometry from the robot configuration (added to it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeometryDeviation {
    /// Switch: false = the true robot is the robot configuration.
    pub enabled: bool,
    /// Added to r_base, mm.
    pub d_r_base_mm: [f64; 3],
    /// Added to beta, degrees.
    pub d_beta_deg: [f64; 3],
    /// Added to psi, degrees.
    pub d_psi_deg: [f64; 3],
    /// Added to l_C, mm.
    pub d_l_c_mm: [f64; 3],
    /// Added to l_CE, mm.
    pub d_l_ce_mm: [f64; 3],
    /// Added to l_st, mm.
    pub d_l_st_mm: [f64; 3],
    /// Added to r_p, mm.
    pub d_r_p_mm: [f64; 3],
    /// Added to theta_p, degrees.
    pub d_theta_p_deg: [f64; 3],
}

/// The family of the true tendon map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrueMapKind {
    /// phi_b = gain (dl - dl0) / a.
    Linear,
    /// phi_b = phi_sat tanh(gain (dl - dl0) / (a phi_sat)) (saturating, stiffening tendon).
    Tanh,
}

/// The plant's true tendon map g_i: effective tendon displacement dl (mm) to bending phi_b (rad).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrueTendonMap {
    /// `linear` or `tanh`.
    pub model: TrueMapKind,
    /// Slope at dl0 relative to the nominal 1/a (tendon offset a of the robot configuration);
    /// for dl >= dl0 when `gain_neg` is given.
    pub gain: [f64; 3],
    /// Slope for dl < dl0 relative to the nominal 1/a: the other tendon of the pair, for a leg
    /// that bends differently each way (pretension, friction and routing differ between the two
    /// tendons). Default: `gain` (a leg that bends alike both ways).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain_neg: Option<[f64; 3]>,
    /// Displacement offset dl0 (pretension asymmetry), mm.
    pub dl0_mm: [f64; 3],
    /// Saturation bending phi_sat of the `tanh` model, degrees (unused by `linear`).
    pub phi_sat_deg: [f64; 3],
    /// Tendon cross-coupling (default 0 = off): the tendon of leg i runs over the roll of leg
    /// i-1 (cyclic) and is pulled by this share of that leg's displacement as well. A coupling
    /// between legs the constant-curvature model and the residual tools' library deliberately
    /// lack.
    #[serde(default)]
    pub cross_coupling: f64,
}

/// Stepper and gear effects.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Stepper {
    /// Switch: the firmware limits the step rate to `actuation.max_step_rate` of the robot.
    pub rate_limit: bool,
    /// Switch: steps commanded faster than `pull_out_rate` are missed with `miss_probability`.
    pub missed_steps: bool,
    /// Step rate above which the motor may lose steps, steps/s.
    pub pull_out_rate: f64,
    /// Probability that one step above the pull-out rate is lost.
    pub miss_probability: f64,
    /// Switch: gear backlash.
    pub backlash: bool,
    /// Play between motor and tendon roll per leg, motor steps.
    pub backlash_steps: [f64; 3],
    /// Periodic transmission errors of the gears (default none): each term makes the gear
    /// output of its motor lag the motor periodically in the motor's position (an eccentric
    /// gear or pinion, a worn tooth). Terms on the same motor add.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub periodic: Vec<PeriodicGearError>,
}

/// One periodic transmission error of a motor's gear: the gear output of motor `motor` is
/// `q - amplitude_steps sin(2 pi q / period_steps + phase)` where q is the rotor position
/// (steps, absolute: the drive's step counter less missed steps); the play, when there is one,
/// lies after it (between the gear and the tendon roll).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PeriodicGearError {
    /// Motor 1..3.
    pub motor: u8,
    /// Period, motor steps (a gear's revolution, a pinion's tooth, ...).
    pub period_steps: f64,
    /// Amplitude of the output's lag, motor steps; below period / (2 pi), so that the output
    /// still moves forward with the motor.
    pub amplitude_steps: f64,
    /// Phase at q = 0, degrees.
    pub phase_deg: f64,
}

/// Slow tendon creep: elongation e relaxes towards `compliance * tension` with a time constant.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Creep {
    /// Switch.
    pub enabled: bool,
    /// Final elongation per newton of tendon tension (tension = tendon moment / a), mm/N.
    pub compliance_mm_per_n: f64,
    /// Time constant, s.
    pub time_constant_s: f64,
}

/// Steady tendon drift: each tendon lengthens at a constant rate with the plant's time (a
/// slipping clamp, a slow relaxation, a thermal expansion of the roll), without limit, unlike
/// creep.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Drift {
    /// Switch.
    pub enabled: bool,
    /// Elongation rate per leg, mm/s (positive: the tendon lengthens).
    pub rate_mm_per_s: [f64; 3],
}

/// The lab's temperature cycle (air conditioning) seen by the tendons: each tendon's length
/// follows it, `e_i(t) = A_i (sin(2 pi t / P + phase) - sin(phase))` with the plant's time t
/// (zero at the plant's start), without limit of time but bounded, unlike drift; not in the
/// residual tools' library (whose drift and creep imitate it over part of a cycle).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Thermal {
    /// Switch.
    pub enabled: bool,
    /// Amplitude of the elongation per leg, mm (positive: the tendon lengthens while the sine
    /// is positive).
    pub amplitude_mm: [f64; 3],
    /// Period of the cycle, s.
    pub period_s: f64,
    /// Phase of the cycle at the plant's start, degrees.
    pub phase_deg: f64,
}

impl Default for Thermal {
    fn default() -> Thermal {
        Thermal {
            enabled: false,
            amplitude_mm: [0.0; 3],
            period_s: 1200.0,
            phase_deg: 0.0,
        }
    }
}

/// Coulomb friction (elastic-perfectly-plastic Jenkins elements: stick stiffness and slip limit).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Friction {
    /// Switch: Coulomb torque at the passive joints M_i and P_i.
    pub joints: bool,
    /// Slip torque of a passive joint, N mm.
    pub joint_torque_n_mm: f64,
    /// Stiffness while stuck, N mm/rad.
    pub joint_stick_stiffness_n_mm_per_rad: f64,
    /// Switch: sliding friction of the joint supports at M_i and P_i on the base plate.
    pub supports: bool,
    /// Slip force of one support, N.
    pub support_force_n: f64,
    /// Stiffness while stuck, N/mm.
    pub support_stick_stiffness_n_per_mm: f64,
}

/// The motion-capture system.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Capture {
    /// Switch: Gaussian noise on every measured coordinate.
    pub noise: bool,
    /// Standard deviation of a position coordinate, mm.
    pub sigma_mm: f64,
    /// Standard deviation of the platform angle, degrees.
    pub sigma_deg: f64,
    /// Probability that a rigid body (platform or one M_i marker) is missing from a sample.
    pub dropout_probability: f64,
    /// Fixed latency between the true state and its report, s.
    pub latency_s: f64,
    /// Measurement rate, Hz.
    pub rate_hz: f64,
    /// Capture frame: robot-frame point p is reported as R(dphi) p + (dx, dy); x offset, mm.
    pub frame_dx_mm: f64,
    /// y offset of the capture frame, mm.
    pub frame_dy_mm: f64,
    /// Rotation of the capture frame, degrees.
    pub frame_dphi_deg: f64,
    /// Misregistration: the capture-to-robot transform the measuring side uses is the true one
    /// off by this much (x offset, mm; default 0 = perfectly registered).
    #[serde(default)]
    pub registration_error_dx_mm: f64,
    /// Misregistration, y offset, mm.
    #[serde(default)]
    pub registration_error_dy_mm: f64,
    /// Misregistration, rotation, degrees.
    #[serde(default)]
    pub registration_error_dphi_deg: f64,
}

/// Time integration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Simulation {
    /// Control cycle, s (the firmware spreads each cycle's steps evenly over it).
    pub cycle_s: f64,
    /// Sub-steps per cycle at which the statics are solved.
    pub substeps_per_cycle: usize,
}

/// The whole plant configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlantConfig {
    /// Free text.
    #[serde(default)]
    pub name: String,
    /// The robot drawing (nominal geometry and actuation) this plant deviates from: a robot
    /// configuration file; the built-in nominal robot (= configs/robot.toml) when absent. It is
    /// the plant's own, independent of the model that drives it (a calibrated robot file must
    /// not move the true robot).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nominal_robot: Option<String>,
    /// Seed of every random effect (same seed, same run).
    pub seed: u64,
    /// Statics.
    pub mechanics: Mechanics,
    /// External wrench on the platform.
    pub external_wrench: ExternalWrench,
    /// Geometry deviations.
    pub geometry: GeometryDeviation,
    /// True tendon map.
    pub tendon_map: TrueTendonMap,
    /// Stepper and gear.
    pub stepper: Stepper,
    /// Tendon creep.
    pub creep: Creep,
    /// Steady tendon drift (off when absent).
    #[serde(default)]
    pub drift: Drift,
    /// The lab's temperature cycle on the tendons (off when absent).
    #[serde(default)]
    pub thermal: Thermal,
    /// Friction.
    pub friction: Friction,
    /// Motion capture.
    pub capture: Capture,
    /// Time stepping.
    pub simulation: Simulation,
}

impl PlantConfig {
    /// Nominal geometry, linear tendon map, every effect off (as `configs/plant-ideal.toml`).
    pub fn ideal() -> PlantConfig {
        PlantConfig {
            name: "ideal plant".into(),
            nominal_robot: None,
            seed: 1,
            mechanics: Mechanics {
                ei_n_mm2: 6.5e4,
                k_m_n_mm_per_rad: 0.0,
                k_p_n_mm_per_rad: 0.0,
                segment_steps: 50,
            },
            external_wrench: ExternalWrench::default(),
            geometry: GeometryDeviation {
                enabled: false,
                d_r_base_mm: [0.0; 3],
                d_beta_deg: [0.0; 3],
                d_psi_deg: [0.0; 3],
                d_l_c_mm: [0.0; 3],
                d_l_ce_mm: [0.0; 3],
                d_l_st_mm: [0.0; 3],
                d_r_p_mm: [0.0; 3],
                d_theta_p_deg: [0.0; 3],
            },
            tendon_map: TrueTendonMap {
                model: TrueMapKind::Linear,
                gain: [1.0; 3],
                gain_neg: None,
                dl0_mm: [0.0; 3],
                phi_sat_deg: [360.0; 3],
                cross_coupling: 0.0,
            },
            stepper: Stepper {
                rate_limit: false,
                missed_steps: false,
                pull_out_rate: 580.0,
                miss_probability: 0.0,
                backlash: false,
                backlash_steps: [0.0; 3],
                periodic: Vec::new(),
            },
            creep: Creep {
                enabled: false,
                compliance_mm_per_n: 0.0,
                time_constant_s: 30.0,
            },
            drift: Drift::default(),
            thermal: Thermal::default(),
            friction: Friction {
                joints: false,
                joint_torque_n_mm: 0.0,
                joint_stick_stiffness_n_mm_per_rad: 1.0e4,
                supports: false,
                support_force_n: 0.0,
                support_stick_stiffness_n_per_mm: 20.0,
            },
            capture: Capture {
                noise: false,
                sigma_mm: 0.05,
                sigma_deg: 0.05,
                dropout_probability: 0.0,
                latency_s: 0.0,
                rate_hz: 100.0,
                frame_dx_mm: 0.0,
                frame_dy_mm: 0.0,
                frame_dphi_deg: 0.0,
                registration_error_dx_mm: 0.0,
                registration_error_dy_mm: 0.0,
                registration_error_dphi_deg: 0.0,
            },
            simulation: Simulation {
                cycle_s: 0.02,
                substeps_per_cycle: 2,
            },
        }
    }

    /// The prototype-like defaults (as `configs/plant.toml`).
    pub fn prototype() -> PlantConfig {
        let mut c = PlantConfig::ideal();
        c.name = "prototype-like plant".into();
        c.seed = 20261122;
        c.geometry = GeometryDeviation {
            enabled: true,
            d_r_base_mm: [0.3, -0.2, 0.1],
            d_beta_deg: [0.2, -0.1, 0.15],
            d_psi_deg: [-0.4, 0.3, 0.2],
            d_l_c_mm: [0.5, -0.3, 0.2],
            d_l_ce_mm: [-0.2, 0.3, 0.1],
            d_l_st_mm: [0.2, -0.1, -0.3],
            d_r_p_mm: [-0.2, 0.1, 0.3],
            d_theta_p_deg: [0.3, -0.2, -0.1],
        };
        c.tendon_map = TrueTendonMap {
            model: TrueMapKind::Tanh,
            gain: [0.96, 0.93, 0.98],
            gain_neg: None,
            dl0_mm: [0.05, -0.08, 0.03],
            phi_sat_deg: [260.0, 240.0, 280.0],
            cross_coupling: 0.0,
        };
        c.stepper = Stepper {
            rate_limit: true,
            missed_steps: true,
            pull_out_rate: 580.0,
            miss_probability: 0.02,
            backlash: true,
            backlash_steps: [3.0, 4.0, 3.0],
            periodic: Vec::new(),
        };
        c.creep = Creep {
            enabled: true,
            compliance_mm_per_n: 2.0e-4,
            time_constant_s: 30.0,
        };
        c.friction = Friction {
            joints: true,
            joint_torque_n_mm: 2.0,
            joint_stick_stiffness_n_mm_per_rad: 1.0e4,
            supports: true,
            support_force_n: 0.04,
            support_stick_stiffness_n_per_mm: 20.0,
        };
        c.capture = Capture {
            noise: true,
            sigma_mm: 0.05,
            sigma_deg: 0.05,
            dropout_probability: 0.01,
            latency_s: 0.01,
            rate_hz: 100.0,
            frame_dx_mm: 12.5,
            frame_dy_mm: -7.3,
            frame_dphi_deg: 1.7,
            registration_error_dx_mm: 0.0,
            registration_error_dy_mm: 0.0,
            registration_error_dphi_deg: 0.0,
        };
        c
    }

    /// The robot drawing this plant deviates from (`nominal_robot`, or the built-in nominal
    /// robot).
    pub fn drawing(&self) -> Result<RobotConfig, PlantConfigError> {
        match &self.nominal_robot {
            None => Ok(RobotConfig::nominal()),
            Some(p) => RobotConfig::load(p).map_err(|e| PlantConfigError::Invalid {
                path: self.name.clone(),
                key: "nominal_robot".into(),
                value: p.clone(),
                reason: e.to_string(),
            }),
        }
    }

    /// Reads and validates a configuration file.
    pub fn load(path: impl AsRef<Path>) -> Result<PlantConfig, PlantConfigError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| PlantConfigError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// Parses and validates configuration text; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<PlantConfig, PlantConfigError> {
        let cfg: PlantConfig = toml::from_str(text).map_err(|e| PlantConfigError::Parse {
            path: origin.to_string(),
            message: e.to_string(),
        })?;
        cfg.validate(origin)?;
        Ok(cfg)
    }

    /// Serialises to TOML.
    pub fn to_toml_string(&self) -> String {
        toml::to_string_pretty(self).expect("a PlantConfig always serialises")
    }

    /// Checks ranges; names the offending key.
    pub fn validate(&self, origin: &str) -> Result<(), PlantConfigError> {
        let bad = |key: &str, value: String, reason: &str| PlantConfigError::Invalid {
            path: origin.to_string(),
            key: key.to_string(),
            value,
            reason: reason.to_string(),
        };
        let check = |key: &str, v: f64, ok: bool, reason: &str| -> Result<(), PlantConfigError> {
            if v.is_finite() && ok {
                Ok(())
            } else {
                Err(bad(key, v.to_string(), reason))
            }
        };
        let check3 = |key: &str, v: &[f64; 3], lo: f64, hi: f64| -> Result<(), PlantConfigError> {
            for (i, &x) in v.iter().enumerate() {
                if !(x.is_finite() && x >= lo && x <= hi) {
                    return Err(bad(
                        &format!("{key}[{}]", i + 1),
                        x.to_string(),
                        &format!("must be in [{lo}, {hi}]"),
                    ));
                }
            }
            Ok(())
        };
        check(
            "tendon_map.cross_coupling",
            self.tendon_map.cross_coupling,
            self.tendon_map.cross_coupling.abs() < 0.5,
            "must be within (-0.5, 0.5)",
        )?;
        for (k, v) in [
            (
                "capture.registration_error_dx_mm",
                self.capture.registration_error_dx_mm,
            ),
            (
                "capture.registration_error_dy_mm",
                self.capture.registration_error_dy_mm,
            ),
            (
                "capture.registration_error_dphi_deg",
                self.capture.registration_error_dphi_deg,
            ),
        ] {
            check(
                k,
                v,
                v.abs() <= 1000.0,
                "must be a finite number within +-1000",
            )?;
        }
        let m = &self.mechanics;
        check(
            "mechanics.ei_n_mm2",
            m.ei_n_mm2,
            m.ei_n_mm2 > 0.0,
            "must be > 0",
        )?;
        check(
            "mechanics.k_m_n_mm_per_rad",
            m.k_m_n_mm_per_rad,
            m.k_m_n_mm_per_rad >= 0.0,
            "must be >= 0",
        )?;
        check(
            "mechanics.k_p_n_mm_per_rad",
            m.k_p_n_mm_per_rad,
            m.k_p_n_mm_per_rad >= 0.0,
            "must be >= 0",
        )?;
        if !(8..=10_000).contains(&m.segment_steps) {
            return Err(bad(
                "mechanics.segment_steps",
                m.segment_steps.to_string(),
                "must be in [8, 10000]",
            ));
        }
        let w = &self.external_wrench;
        check("external_wrench.fx_n", w.fx_n, true, "must be finite")?;
        check("external_wrench.fy_n", w.fy_n, true, "must be finite")?;
        check("external_wrench.mz_n_mm", w.mz_n_mm, true, "must be finite")?;
        let g = &self.geometry;
        check3("geometry.d_r_base_mm", &g.d_r_base_mm, -20.0, 20.0)?;
        check3("geometry.d_beta_deg", &g.d_beta_deg, -10.0, 10.0)?;
        check3("geometry.d_psi_deg", &g.d_psi_deg, -10.0, 10.0)?;
        check3("geometry.d_l_c_mm", &g.d_l_c_mm, -20.0, 20.0)?;
        check3("geometry.d_l_ce_mm", &g.d_l_ce_mm, -20.0, 20.0)?;
        check3("geometry.d_l_st_mm", &g.d_l_st_mm, -20.0, 20.0)?;
        check3("geometry.d_r_p_mm", &g.d_r_p_mm, -20.0, 20.0)?;
        check3("geometry.d_theta_p_deg", &g.d_theta_p_deg, -10.0, 10.0)?;
        let t = &self.tendon_map;
        check3("tendon_map.gain", &t.gain, 0.1, 10.0)?;
        if let Some(g) = &t.gain_neg {
            check3("tendon_map.gain_neg", g, 0.1, 10.0)?;
        }
        check3("tendon_map.dl0_mm", &t.dl0_mm, -10.0, 10.0)?;
        check3("tendon_map.phi_sat_deg", &t.phi_sat_deg, 30.0, 3600.0)?;
        let s = &self.stepper;
        check(
            "stepper.pull_out_rate",
            s.pull_out_rate,
            s.pull_out_rate > 0.0,
            "must be > 0 steps/s",
        )?;
        check(
            "stepper.miss_probability",
            s.miss_probability,
            (0.0..=1.0).contains(&s.miss_probability),
            "must be in [0, 1]",
        )?;
        check3("stepper.backlash_steps", &s.backlash_steps, 0.0, 200.0)?;
        for (k, p) in s.periodic.iter().enumerate() {
            let key = |f: &str| format!("stepper.periodic[{}].{f}", k + 1);
            if !(1..=3).contains(&p.motor) {
                return Err(bad(&key("motor"), p.motor.to_string(), "must be 1, 2 or 3"));
            }
            check(
                &key("period_steps"),
                p.period_steps,
                (2.0..=1e6).contains(&p.period_steps),
                "must be in [2, 1e6] steps",
            )?;
            check(
                &key("amplitude_steps"),
                p.amplitude_steps,
                p.amplitude_steps.abs() < p.period_steps / std::f64::consts::TAU,
                "must be below period_steps / (2 pi) in magnitude (the output must move forward with the motor)",
            )?;
            check(&key("phase_deg"), p.phase_deg, true, "must be finite")?;
        }
        check3("drift.rate_mm_per_s", &self.drift.rate_mm_per_s, -1.0, 1.0)?;
        let th = &self.thermal;
        check3("thermal.amplitude_mm", &th.amplitude_mm, -10.0, 10.0)?;
        check(
            "thermal.period_s",
            th.period_s,
            th.period_s > 0.0,
            "must be > 0 s",
        )?;
        check("thermal.phase_deg", th.phase_deg, true, "must be finite")?;
        let c = &self.creep;
        check(
            "creep.compliance_mm_per_n",
            c.compliance_mm_per_n,
            c.compliance_mm_per_n >= 0.0,
            "must be >= 0",
        )?;
        check(
            "creep.time_constant_s",
            c.time_constant_s,
            c.time_constant_s > 0.0,
            "must be > 0",
        )?;
        let f = &self.friction;
        check(
            "friction.joint_torque_n_mm",
            f.joint_torque_n_mm,
            f.joint_torque_n_mm >= 0.0,
            "must be >= 0",
        )?;
        check(
            "friction.joint_stick_stiffness_n_mm_per_rad",
            f.joint_stick_stiffness_n_mm_per_rad,
            f.joint_stick_stiffness_n_mm_per_rad > 0.0,
            "must be > 0",
        )?;
        check(
            "friction.support_force_n",
            f.support_force_n,
            f.support_force_n >= 0.0,
            "must be >= 0",
        )?;
        check(
            "friction.support_stick_stiffness_n_per_mm",
            f.support_stick_stiffness_n_per_mm,
            f.support_stick_stiffness_n_per_mm > 0.0,
            "must be > 0",
        )?;
        let k = &self.capture;
        check(
            "capture.sigma_mm",
            k.sigma_mm,
            k.sigma_mm >= 0.0,
            "must be >= 0",
        )?;
        check(
            "capture.sigma_deg",
            k.sigma_deg,
            k.sigma_deg >= 0.0,
            "must be >= 0",
        )?;
        check(
            "capture.dropout_probability",
            k.dropout_probability,
            (0.0..1.0).contains(&k.dropout_probability),
            "must be in [0, 1)",
        )?;
        check(
            "capture.latency_s",
            k.latency_s,
            (0.0..=1.0).contains(&k.latency_s),
            "must be in [0, 1] s",
        )?;
        check(
            "capture.rate_hz",
            k.rate_hz,
            k.rate_hz > 0.0 && k.rate_hz <= 10_000.0,
            "must be in (0, 10000] Hz",
        )?;
        check("capture.frame_dx_mm", k.frame_dx_mm, true, "must be finite")?;
        check("capture.frame_dy_mm", k.frame_dy_mm, true, "must be finite")?;
        check(
            "capture.frame_dphi_deg",
            k.frame_dphi_deg,
            true,
            "must be finite",
        )?;
        let sim = &self.simulation;
        check(
            "simulation.cycle_s",
            sim.cycle_s,
            sim.cycle_s > 0.0 && sim.cycle_s <= 1.0,
            "must be in (0, 1] s",
        )?;
        if !(1..=1000).contains(&sim.substeps_per_cycle) {
            return Err(bad(
                "simulation.substeps_per_cycle",
                sim.substeps_per_cycle.to_string(),
                "must be in [1, 1000]",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PLANT: &str = include_str!("../../configs/plant.toml");
    const IDEAL: &str = include_str!("../../configs/plant-ideal.toml");

    #[test]
    fn shipped_configs_match_the_builtin_ones() {
        let c = PlantConfig::from_toml_str(PLANT, "configs/plant.toml").unwrap();
        assert_eq!(c, PlantConfig::prototype());
        let c = PlantConfig::from_toml_str(IDEAL, "configs/plant-ideal.toml").unwrap();
        assert_eq!(c, PlantConfig::ideal());
    }

    #[test]
    fn round_trip() {
        let c = PlantConfig::prototype();
        assert_eq!(
            PlantConfig::from_toml_str(&c.to_toml_string(), "x").unwrap(),
            c
        );
    }

    #[test]
    fn errors_name_the_key() {
        let text = PLANT.replacen("ei_n_mm2 = 6.5e4", "ei_n_mm2 = -1.0", 1);
        let e = PlantConfig::from_toml_str(&text, "p.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("mechanics.ei_n_mm2"), "{e}");
        let text = PLANT.replacen("sigma_mm", "sigma_mmm", 1);
        let e = PlantConfig::from_toml_str(&text, "p.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("sigma_mmm"), "{e}");
        let mut c = PlantConfig::prototype();
        c.stepper.backlash_steps[1] = -2.0;
        let e = PlantConfig::from_toml_str(&c.to_toml_string(), "p.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("stepper.backlash_steps[2]"), "{e}");
    }
}
