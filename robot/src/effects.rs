//! Effects beyond the constant-curvature model that a robot file may declare (`[effects]`),
//! found by `pcr residuals` from measured data and used by the running system: the model (FK,
//! IK) and the drive compensate them.
//!
//! Every effect is optional; a robot file without `[effects]` is the plain calibrated model.
//! Geometry and tendon-map corrections need no entry here: they are written into the legs.
//! Units as in the rest of the file: mm, degrees, motor steps, seconds, N.

use serde::{Deserialize, Serialize};

/// Command-to-motion latency beyond the drive's own segment (which reaches a setpoint one
/// control period after it is commanded): the measured motion lags the command by one period
/// plus `latency_s` (capture latency included). The chain feeds it forward (the interpolator
/// commands the pose of `t + period + latency_s`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Latency {
    /// Latency, s.
    pub latency_s: f64,
}

/// Gear backlash (or friction hysteresis acting like it): the tendon roll follows the motor
/// only after the play of `steps` is taken up on a reversal. The drive compensates by adding
/// the play in the direction of motion.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Backlash {
    /// Play per motor, steps.
    pub steps: [f64; 3],
}

/// Slow drift: tendon creep. The effective tendon displacement is dl - e with
/// de/dt = (gain * dl_load - e) / time_constant, `dl_load` the displacement that loads the tendon
/// (the bending moment is proportional to the curvature, so the load is taken as proportional
/// to the commanded dl). The IK adds the predicted elongation to the command.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Creep {
    /// Final elongation per mm of commanded displacement, per leg (dimensionless).
    pub gain: [f64; 3],
    /// Time constant, s.
    pub time_constant_s: f64,
}

/// Steady drift of the tendon length: each tendon lengthens at a constant rate with the time
/// since the start of the recording (or of the run), so the segment sees `dl - rate * t`. Where
/// creep saturates, drift keeps growing: a slipping clamp, a tendon that relaxes over hours, a
/// thermal expansion of the roll. The IK adds the predicted elongation to the command.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Drift {
    /// Rate of elongation per leg, mm/s (positive: the tendon lengthens).
    pub rate_mm_per_s: [f64; 3],
}

/// Compliance: a kineto-static extension of the constant-curvature model (segments that bend
/// under the link forces, with their total bending fixed by the tendons), loaded by an external
/// wrench on the platform and by springs in the passive joints relaxed at the home pose.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Compliance {
    /// Bending stiffness of each segment, N mm^2.
    pub ei_n_mm2: f64,
    /// External force on the platform centre, base frame, N.
    #[serde(default)]
    pub force_n: [f64; 2],
    /// External couple on the platform, N mm.
    #[serde(default)]
    pub couple_n_mm: f64,
    /// Spring of the passive joints at M_i, N mm/rad.
    #[serde(default)]
    pub k_m_n_mm_per_rad: f64,
    /// Spring of the passive joints at P_i, N mm/rad.
    #[serde(default)]
    pub k_p_n_mm_per_rad: f64,
}

/// Capture-frame correction: a measured pose p (robot frame as registered) is corrected to
/// R(dphi) p + d. The pose sensor applies it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameCorrection {
    /// Offset x, mm.
    pub dx_mm: f64,
    /// Offset y, mm.
    pub dy_mm: f64,
    /// Rotation, degrees.
    pub dphi_deg: f64,
}

impl FrameCorrection {
    /// A measured pose (x mm, y mm, phi rad) corrected: R(dphi) p + d, phi + dphi.
    pub fn apply(&self, m: [f64; 3]) -> [f64; 3] {
        let a = self.dphi_deg.to_radians();
        let (s, c) = a.sin_cos();
        [
            c * m[0] - s * m[1] + self.dx_mm,
            s * m[0] + c * m[1] + self.dy_mm,
            m[2] + a,
        ]
    }

    /// This correction followed by `after`: one correction that takes every measurement where
    /// `after` takes this one's result (`R(a2) (R(a1) p + d1) + d2`).
    pub fn then(&self, after: &FrameCorrection) -> FrameCorrection {
        let d = after.apply([self.dx_mm, self.dy_mm, 0.0]);
        FrameCorrection {
            dx_mm: d[0],
            dy_mm: d[1],
            dphi_deg: self.dphi_deg + after.dphi_deg,
        }
    }
}

/// One periodic transmission error: the output of motor `motor` lags its position by
/// `amplitude_steps sin(2 pi q / period_steps + phase)`. The drive subtracts it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Periodic {
    /// Motor 1..3.
    pub motor: u8,
    /// Period, motor steps.
    pub period_steps: f64,
    /// Amplitude, steps.
    pub amplitude_steps: f64,
    /// Phase, degrees.
    pub phase_deg: f64,
}

/// Coulomb friction of the passive joints (a couple between the link and the body it joins)
/// and of the joints' supports on the base plate (a force against their sliding), each an
/// elastic-perfectly-plastic element: it sticks until its load reaches its limit, then slips,
/// so that the pose depends on the path that led to it. The segments bend under these loads
/// (the small-load statics of `pcr_kinematics::friction`); the IK feeds the deflection the path
/// predicts forward.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Friction {
    /// Coulomb couple of each passive joint (M_i and P_i), N mm.
    pub joint_torque_n_mm: f64,
    /// Coulomb force of each joint's support (M_i and P_i) on the base plate, N.
    pub support_force_n: f64,
    /// How far a joint turns while it sticks before it slips (its limit over its stick
    /// stiffness), rad.
    #[serde(default = "Friction::default_joint_presliding")]
    pub joint_presliding_rad: f64,
    /// How far a support moves while it sticks before it slips, mm.
    #[serde(default = "Friction::default_support_presliding")]
    pub support_presliding_mm: f64,
    /// Bending stiffness of each segment, N mm^2.
    #[serde(default = "Friction::default_ei")]
    pub ei_n_mm2: f64,
}

impl Friction {
    /// A joint's pre-sliding rotation assumed when the file gives none: 1 mrad (about the
    /// rotation over which the friction of a small plain or ball-bearing joint builds up).
    pub fn default_joint_presliding() -> f64 {
        1e-3
    }

    /// A support's pre-sliding displacement assumed when the file gives none: 5 um.
    pub fn default_support_presliding() -> f64 {
        5e-3
    }

    /// The segments' bending stiffness assumed when the file gives none, N mm^2 (the nominal
    /// value of the prototype's segments).
    pub fn default_ei() -> f64 {
        6.5e4
    }
}

/// Every effect a robot file can declare.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Effects {
    /// Command-to-motion latency.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latency: Option<Latency>,
    /// Gear backlash.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub backlash: Option<Backlash>,
    /// Tendon creep.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub creep: Option<Creep>,
    /// Steady drift of the tendon length.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drift: Option<Drift>,
    /// Kineto-static compliance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compliance: Option<Compliance>,
    /// Capture-frame correction.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<FrameCorrection>,
    /// Periodic transmission errors.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub periodic: Vec<Periodic>,
    /// Friction of the passive joints and their supports.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub friction: Option<Friction>,
}

impl Effects {
    /// Whether no effect is declared.
    pub fn is_empty(&self) -> bool {
        *self == Effects::default()
    }

    /// Checks ranges; returns the dotted key and the reason of the first problem.
    pub fn check(&self) -> Result<(), (String, String, String)> {
        let bad = |k: &str, v: String, why: &str| Err((format!("effects.{k}"), v, why.to_string()));
        if let Some(l) = &self.latency {
            if !(l.latency_s.is_finite() && l.latency_s.abs() <= 1.0) {
                return bad(
                    "latency.latency_s",
                    l.latency_s.to_string(),
                    "must be within +-1 s",
                );
            }
        }
        if let Some(b) = &self.backlash {
            if let Some(v) = b
                .steps
                .iter()
                .find(|v| !(v.is_finite() && **v >= 0.0 && **v <= 1e3))
            {
                return bad(
                    "backlash.steps",
                    v.to_string(),
                    "must be in [0, 1000] steps",
                );
            }
        }
        if let Some(c) = &self.creep {
            if !(c.time_constant_s.is_finite() && c.time_constant_s > 0.0) {
                return bad(
                    "creep.time_constant_s",
                    c.time_constant_s.to_string(),
                    "must be > 0 s",
                );
            }
            if let Some(v) = c.gain.iter().find(|v| !(v.is_finite() && v.abs() < 1.0)) {
                return bad("creep.gain", v.to_string(), "must be within (-1, 1)");
            }
        }
        if let Some(d) = &self.drift {
            if let Some(v) = d
                .rate_mm_per_s
                .iter()
                .find(|v| !(v.is_finite() && v.abs() <= 1.0))
            {
                return bad(
                    "drift.rate_mm_per_s",
                    v.to_string(),
                    "must be within +-1 mm/s",
                );
            }
        }
        if let Some(c) = &self.compliance {
            if !(c.ei_n_mm2.is_finite() && c.ei_n_mm2 > 0.0) {
                return bad("compliance.ei_n_mm2", c.ei_n_mm2.to_string(), "must be > 0");
            }
            for (k, v) in [
                ("force_n", c.force_n[0]),
                ("force_n", c.force_n[1]),
                ("couple_n_mm", c.couple_n_mm),
                ("k_m_n_mm_per_rad", c.k_m_n_mm_per_rad),
                ("k_p_n_mm_per_rad", c.k_p_n_mm_per_rad),
            ] {
                if !v.is_finite() {
                    return bad(&format!("compliance.{k}"), v.to_string(), "must be finite");
                }
            }
        }
        if let Some(f) = &self.frame {
            for (k, v) in [
                ("dx_mm", f.dx_mm),
                ("dy_mm", f.dy_mm),
                ("dphi_deg", f.dphi_deg),
            ] {
                if !v.is_finite() {
                    return bad(&format!("frame.{k}"), v.to_string(), "must be finite");
                }
            }
        }
        if let Some(f) = &self.friction {
            for (k, v, why, ok) in [
                (
                    "joint_torque_n_mm",
                    f.joint_torque_n_mm,
                    "must be in [0, 1000] N mm",
                    f.joint_torque_n_mm >= 0.0 && f.joint_torque_n_mm <= 1e3,
                ),
                (
                    "support_force_n",
                    f.support_force_n,
                    "must be in [0, 100] N",
                    f.support_force_n >= 0.0 && f.support_force_n <= 1e2,
                ),
                (
                    "joint_presliding_rad",
                    f.joint_presliding_rad,
                    "must be in (0, 0.1] rad",
                    f.joint_presliding_rad > 0.0 && f.joint_presliding_rad <= 0.1,
                ),
                (
                    "support_presliding_mm",
                    f.support_presliding_mm,
                    "must be in (0, 1] mm",
                    f.support_presliding_mm > 0.0 && f.support_presliding_mm <= 1.0,
                ),
                ("ei_n_mm2", f.ei_n_mm2, "must be > 0", f.ei_n_mm2 > 0.0),
            ] {
                if !(v.is_finite() && ok) {
                    return bad(&format!("friction.{k}"), v.to_string(), why);
                }
            }
        }
        for (i, p) in self.periodic.iter().enumerate() {
            let k = |n: &str| format!("periodic[{}].{n}", i + 1);
            if !(1..=3).contains(&p.motor) {
                return bad(&k("motor"), p.motor.to_string(), "must be 1, 2 or 3");
            }
            if !(p.period_steps.is_finite() && p.period_steps >= 2.0) {
                return bad(
                    &k("period_steps"),
                    p.period_steps.to_string(),
                    "must be >= 2 steps",
                );
            }
            if !(p.amplitude_steps.is_finite() && p.phase_deg.is_finite()) {
                return bad(
                    &k("amplitude_steps"),
                    p.amplitude_steps.to_string(),
                    "must be finite",
                );
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::RobotConfig;

    #[test]
    fn two_frame_corrections_compose_into_one() {
        let a = super::FrameCorrection {
            dx_mm: 1.5,
            dy_mm: -0.7,
            dphi_deg: 2.0,
        };
        let b = super::FrameCorrection {
            dx_mm: -0.4,
            dy_mm: 0.9,
            dphi_deg: -0.5,
        };
        let ab = a.then(&b);
        for m in [[10.0, -20.0, 0.1], [-35.0, 4.0, -0.3]] {
            let (one, two) = (ab.apply(m), b.apply(a.apply(m)));
            for k in 0..3 {
                assert!((one[k] - two[k]).abs() < 1e-12, "{one:?} {two:?}");
            }
        }
    }

    #[test]
    fn effects_round_trip_and_bad_values_name_the_key() {
        let mut r = RobotConfig::nominal();
        let text = r.to_toml_string();
        assert!(
            !text.contains("effects"),
            "no effects section when there are none"
        );
        r.effects.backlash = Some(super::Backlash {
            steps: [3.0, 4.0, 3.0],
        });
        r.effects.latency = Some(super::Latency { latency_s: 0.05 });
        r.effects.periodic.push(super::Periodic {
            motor: 2,
            period_steps: 32.0,
            amplitude_steps: 0.4,
            phase_deg: 30.0,
        });
        r.effects.friction = Some(super::Friction {
            joint_torque_n_mm: 2.0,
            support_force_n: 0.04,
            joint_presliding_rad: 1e-3,
            support_presliding_mm: 5e-3,
            ei_n_mm2: 6.5e4,
        });
        let text = r.to_toml_string();
        let back = RobotConfig::from_toml_str(&text, "x.toml").unwrap();
        assert_eq!(back, r);
        // The pre-sliding and the stiffness are the library's assumptions when a file gives
        // only the limits.
        let short = "[effects.friction]\njoint_torque_n_mm = 2.0\nsupport_force_n = 0.04\n";
        let mut only = RobotConfig::nominal().to_toml_string();
        only.push_str(short);
        let f = RobotConfig::from_toml_str(&only, "y.toml")
            .unwrap()
            .effects
            .friction
            .unwrap();
        assert_eq!(f, back.effects.friction.clone().unwrap());
        let e = RobotConfig::from_toml_str(&only.replace("= 0.04", "= -0.04"), "y.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("effects.friction.support_force_n"), "{e}");
        let bad = text.replace("latency_s = 0.05", "latency_s = 5.0");
        let e = RobotConfig::from_toml_str(&bad, "x.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("effects.latency.latency_s") && e.contains("x.toml"),
            "{e}"
        );
        let bad = text.replace("motor = 2", "motor = 4");
        let e = RobotConfig::from_toml_str(&bad, "x.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("periodic[1].motor"), "{e}");
    }
}
