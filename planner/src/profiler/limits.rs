//! Kinematic state and limits of one degree of freedom, input validation and mirroring.

use super::error::ProfileError;

/// Kinematic state of one DoF: position (unit u, e.g. mm or rad), velocity (u/s) and
/// acceleration (u/s^2).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct State {
    /// Position in u.
    pub p: f64,
    /// Velocity in u/s.
    pub v: f64,
    /// Acceleration in u/s^2.
    pub a: f64,
}

impl State {
    /// A state from its three components.
    pub const fn new(p: f64, v: f64, a: f64) -> Self {
        State { p, v, a }
    }

    /// The state after `t` seconds of constant jerk `j` (u/s^3).
    #[inline]
    pub fn integrate(&self, t: f64, j: f64) -> State {
        State {
            p: self.p + t * (self.v + t * (self.a * 0.5 + t * j * (1.0 / 6.0))),
            v: self.v + t * (self.a + t * j * 0.5),
            a: self.a + t * j,
        }
    }

    /// The mirrored state (all signs flipped).
    pub fn neg(&self) -> State {
        State::new(-self.p, -self.v, -self.a)
    }
}

/// Kinematic limits of one DoF. `vmin < 0 < vmax`, `amin < 0 < amax`, `jmax > 0`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Maximal velocity in u/s (> 0).
    pub vmax: f64,
    /// Minimal velocity in u/s (< 0).
    pub vmin: f64,
    /// Maximal acceleration in u/s^2 (> 0).
    pub amax: f64,
    /// Minimal acceleration in u/s^2 (< 0).
    pub amin: f64,
    /// Maximal absolute jerk in u/s^3 (> 0).
    pub jmax: f64,
}

impl Limits {
    /// Symmetric limits: `vmin = -vmax`, `amin = -amax`.
    pub const fn symmetric(vmax: f64, amax: f64, jmax: f64) -> Self {
        Limits {
            vmax,
            vmin: -vmax,
            amax,
            amin: -amax,
            jmax,
        }
    }

    /// Limits of the mirrored problem (positions negated).
    pub fn mirrored(&self) -> Limits {
        Limits {
            vmax: -self.vmin,
            vmin: -self.vmax,
            amax: -self.amin,
            amin: -self.amax,
            jmax: self.jmax,
        }
    }

    /// Checks signs and finiteness of the limits.
    pub fn validate(&self, dof: usize) -> Result<(), ProfileError> {
        let checks: [(&'static str, f64, bool, &'static str); 5] = [
            ("vmax", self.vmax, self.vmax > 0.0, "> 0"),
            ("vmin", self.vmin, self.vmin < 0.0, "< 0"),
            ("amax", self.amax, self.amax > 0.0, "> 0"),
            ("amin", self.amin, self.amin < 0.0, "< 0"),
            ("jmax", self.jmax, self.jmax > 0.0, "> 0"),
        ];
        for (what, value, ok, must) in checks {
            if !value.is_finite() {
                return Err(ProfileError::NotFinite { what, dof, value });
            }
            if !ok {
                return Err(ProfileError::BadLimit {
                    what,
                    dof,
                    must,
                    value,
                });
            }
        }
        Ok(())
    }
}

/// Checks that every component of a state is finite.
pub fn validate_state(s: &State, which: &'static str, dof: usize) -> Result<(), ProfileError> {
    let names: [&'static str; 3] = if which == "current" {
        [
            "current position",
            "current velocity",
            "current acceleration",
        ]
    } else {
        ["target position", "target velocity", "target acceleration"]
    };
    for (what, value) in names.into_iter().zip([s.p, s.v, s.a]) {
        if !value.is_finite() {
            return Err(ProfileError::NotFinite { what, dof, value });
        }
    }
    Ok(())
}
