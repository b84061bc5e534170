//! Speed profiles along a path: path length `s` (mm) as a function of time, from rest to rest.
//!
//! * [`SpeedLimits::JerkLimited`]: constant speed with jerk-limited start and stop; this is the
//!   time-optimal profile of the profiler for one DoF from rest at 0 to rest at the length.
//! * [`SpeedLimits::Trapezoidal`]: acceleration-limited (infinite jerk) trapezoid, or triangle if
//!   the path is too short to reach the speed.

use crate::profiler::{step1::Step1, ControlInterface, Limits, Profile, State};

/// Limits of the motion along the path (mm/s, mm/s^2, mm/s^3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SpeedLimits {
    /// Jerk-limited start and stop, cruise at `vmax`.
    JerkLimited {
        /// Cruise speed in mm/s.
        vmax: f64,
        /// Maximal acceleration in mm/s^2.
        amax: f64,
        /// Maximal jerk in mm/s^3.
        jmax: f64,
    },
    /// Trapezoidal speed (acceleration jumps).
    Trapezoidal {
        /// Cruise speed in mm/s.
        vmax: f64,
        /// Maximal acceleration in mm/s^2.
        amax: f64,
    },
}

/// Invalid speed limits.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("speed limit {0} must be a finite number > 0 (got {1})")]
pub struct SpeedError(pub &'static str, pub f64);

/// A planned speed profile over a path of given length.
// Fixed size on purpose: profiles are Copy and never allocate.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug)]
pub enum SpeedProfile {
    /// Jerk-limited profile (one DoF of the profiler).
    JerkLimited(Profile),
    /// Trapezoid: acceleration time, cruise time, cruise speed, acceleration.
    Trapezoidal {
        /// Acceleration (and deceleration) time in s.
        ta: f64,
        /// Cruise time in s.
        tc: f64,
        /// Peak speed in mm/s.
        vp: f64,
        /// Acceleration in mm/s^2.
        a: f64,
    },
}

fn positive(name: &'static str, v: f64) -> Result<f64, SpeedError> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(SpeedError(name, v))
    }
}

impl SpeedProfile {
    /// Plans the profile over `length` mm (>= 0).
    pub fn plan(length: f64, limits: &SpeedLimits) -> Result<SpeedProfile, SpeedError> {
        let length = if length.is_finite() && length >= 0.0 {
            length
        } else {
            return Err(SpeedError("length", length));
        };
        match *limits {
            SpeedLimits::JerkLimited { vmax, amax, jmax } => {
                let lim = Limits::symmetric(
                    positive("vmax", vmax)?,
                    positive("amax", amax)?,
                    positive("jmax", jmax)?,
                );
                let s = Step1::solve(
                    ControlInterface::Position,
                    &State::default(),
                    &State::new(length, 0.0, 0.0),
                    &lim,
                )
                .ok_or(SpeedError("length", length))?;
                Ok(SpeedProfile::JerkLimited(s.optimal_profile()))
            }
            SpeedLimits::Trapezoidal { vmax, amax } => {
                let (vmax, amax) = (positive("vmax", vmax)?, positive("amax", amax)?);
                let vp = vmax.min((length * amax).sqrt());
                let ta = vp / amax;
                let tc = if vp > 0.0 {
                    (length / vp - ta).max(0.0)
                } else {
                    0.0
                };
                Ok(SpeedProfile::Trapezoidal {
                    ta,
                    tc,
                    vp,
                    a: amax,
                })
            }
        }
    }

    /// Duration in s.
    pub fn duration(&self) -> f64 {
        match self {
            SpeedProfile::JerkLimited(p) => p.duration(),
            SpeedProfile::Trapezoidal { ta, tc, .. } => 2.0 * ta + tc,
        }
    }

    /// Path length (mm), speed (mm/s) and acceleration (mm/s^2) at time `t` s (held at the end
    /// after the duration).
    pub fn at(&self, t: f64) -> State {
        let t = t.clamp(0.0, self.duration());
        match *self {
            SpeedProfile::JerkLimited(p) => {
                let (s, _) = p.at(t);
                if t >= p.duration() {
                    State::new(p.end().p, 0.0, 0.0)
                } else {
                    s
                }
            }
            SpeedProfile::Trapezoidal { ta, tc, vp, a } => {
                if t < ta {
                    State::new(0.5 * a * t * t, a * t, a)
                } else if t < ta + tc {
                    State::new(0.5 * vp * ta + vp * (t - ta), vp, 0.0)
                } else if t < 2.0 * ta + tc {
                    let r = 2.0 * ta + tc - t;
                    let total = vp * ta + vp * tc;
                    State::new(total - 0.5 * a * r * r, a * r, -a)
                } else {
                    State::new(vp * ta + vp * tc, 0.0, 0.0)
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trapezoid_reaches_length() {
        let p = SpeedProfile::plan(
            100.0,
            &SpeedLimits::Trapezoidal {
                vmax: 10.0,
                amax: 5.0,
            },
        )
        .unwrap();
        assert!((p.duration() - (10.0 + 2.0)).abs() < 1e-12);
        assert!((p.at(p.duration()).p - 100.0).abs() < 1e-12);
        assert!((p.at(6.0).v - 10.0).abs() < 1e-12);
        // Triangle.
        let p = SpeedProfile::plan(
            1.0,
            &SpeedLimits::Trapezoidal {
                vmax: 10.0,
                amax: 1.0,
            },
        )
        .unwrap();
        assert!((p.duration() - 2.0).abs() < 1e-12);
        assert!((p.at(2.0).p - 1.0).abs() < 1e-12);
    }

    #[test]
    fn jerk_limited_cruises_at_vmax() {
        let lim = SpeedLimits::JerkLimited {
            vmax: 10.0,
            amax: 20.0,
            jmax: 100.0,
        };
        let p = SpeedProfile::plan(100.0, &lim).unwrap();
        assert!((p.duration() - (10.0 + 0.5 + 0.2)).abs() < 1e-12);
        assert!((p.at(5.0).v - 10.0).abs() < 1e-12);
        assert!((p.at(1e3).p - 100.0).abs() < 1e-9);
        let z = SpeedProfile::plan(0.0, &lim).unwrap();
        assert_eq!(z.duration(), 0.0);
    }

    #[test]
    fn bad_limits_are_errors() {
        let lim = SpeedLimits::Trapezoidal {
            vmax: 0.0,
            amax: 1.0,
        };
        assert!(SpeedProfile::plan(1.0, &lim).is_err());
        assert!(SpeedProfile::plan(f64::NAN, &lim).is_err());
    }
}
