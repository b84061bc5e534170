//! Brake pre-trajectory: when the current state violates the limits (or will inevitably violate
//! the velocity limit because of its acceleration), a short trajectory at full jerk first brings
//! it back inside; the time-optimal profile then starts from the state at its end.
//!
//! Rules (upper side; the lower side is mirrored; the lower side is examined first when the
//! acceleration is negative):
//! * `a0 > amax`: jerk `-jmax` until `a = amax`; if the velocity would then still exceed `vmax`
//!   (`v > vmax`, or `a > 0` and `v + a^2 / (2 jmax) > vmax`), the velocity brake below is used
//!   from the start instead.
//! * velocity brake: jerk `-jmax` until the velocity comes back down to `vmax`; if the
//!   acceleration reaches `amin` first, hold `amin` until `v = vmax`. Either phase ends early
//!   when going on would force an undershoot of `vmin` later (narrow velocity range).

use super::limits::{Limits, State};
use super::profile::Profile;

/// Relative tolerance below which a limit is not considered violated.
const EPS: f64 = 1e-12;

/// True if the state exceeds `vmax` now or will because of its positive acceleration.
fn exceeds_vmax(s: &State, lim: &Limits) -> bool {
    let tol = EPS * lim.vmax.abs().max(1.0);
    s.v > lim.vmax + tol || (s.a > 0.0 && s.v + s.a * s.a / (2.0 * lim.jmax) > lim.vmax + tol)
}

/// Velocity brake downwards (see module doc), appended to `out`. The brake also ends as soon
/// as continuing it would make the velocity undershoot `vmin` afterwards
/// (`v - a^2 / (2 jmax) = vmin` with `a < 0`), so that the profile after it stays feasible.
fn brake_velocity_down(s: &State, lim: &Limits, out: &mut Profile) {
    let j = lim.jmax;
    let disc = (s.a * s.a + 2.0 * j * (s.v - lim.vmax)).max(0.0);
    let t_v = (s.a + disc.sqrt()) / j;
    let t_opp = (s.a + (s.a * s.a / 2.0 + j * (s.v - lim.vmin)).max(0.0).sqrt()) / j;
    let t_amin = ((s.a - lim.amin) / j).max(0.0);
    let t = t_v.min(t_opp);
    if t <= t_amin {
        out.push(t, -j);
    } else {
        let s1 = s.integrate(t_amin, -j);
        out.push(t_amin, -j);
        let v_end = lim.vmax.max(lim.vmin + lim.amin * lim.amin / (2.0 * j));
        out.push(((s1.v - v_end) / -lim.amin).max(0.0), 0.0);
    }
}

/// True if [`brake_upper`] would brake.
fn needs_upper(s: &State, lim: &Limits) -> bool {
    let ta = EPS * lim.amax.abs().max(1.0);
    s.a > lim.amax + ta || (exceeds_vmax(s, lim) && s.a >= lim.amin - ta)
}

/// Upper-side brake (see module doc); returns true if anything was done.
fn brake_upper(s: &State, lim: &Limits, out: &mut Profile) -> bool {
    let ta = EPS * lim.amax.abs().max(1.0);
    if s.a > lim.amax + ta {
        let t1 = (s.a - lim.amax) / lim.jmax;
        let s1 = s.integrate(t1, -lim.jmax);
        if exceeds_vmax(&s1, lim) {
            brake_velocity_down(s, lim, out);
        } else {
            out.push(t1, -lim.jmax);
            if s1.v < lim.vmin {
                // Still below the lower velocity limit: hold amax until it is reached, or until
                // ramping the acceleration down would overshoot vmax.
                let v_end = lim
                    .vmin
                    .min(lim.vmax - lim.amax * lim.amax / (2.0 * lim.jmax));
                out.push(((v_end - s1.v) / lim.amax).max(0.0), 0.0);
            }
        }
        return true;
    }
    if exceeds_vmax(s, lim) && s.a >= lim.amin - ta {
        brake_velocity_down(s, lim, out);
        return true;
    }
    false
}

/// Brake pre-trajectory for the position interface. The returned profile is empty if the state
/// is within the limits.
pub fn position_brake(s: State, lim: &Limits) -> Profile {
    // Fast path (the usual case): neither side needs a brake.
    if !needs_upper(&s, lim) && !needs_upper(&s.neg(), &lim.mirrored()) {
        return Profile::new(s);
    }
    // With a negative acceleration the lower side is the one that matters first (an upper
    // violation resolves itself), and vice versa.
    let lower_first = s.a < 0.0;
    for lower in [lower_first, !lower_first] {
        if lower {
            let mut mirrored = Profile::new(s.neg());
            if brake_upper(&s.neg(), &lim.mirrored(), &mut mirrored) {
                return mirrored.neg();
            }
        } else {
            let mut out = Profile::new(s);
            if brake_upper(&s, lim, &mut out) {
                return out;
            }
        }
    }
    Profile::new(s)
}

/// Brake pre-trajectory for the velocity interface (acceleration limits only).
pub fn velocity_brake(s: State, lim: &Limits) -> Profile {
    let mut out = Profile::new(s);
    let ta = EPS * lim.amax.abs().max(1.0);
    if s.a > lim.amax + ta {
        out.push((s.a - lim.amax) / lim.jmax, -lim.jmax);
    } else if s.a < lim.amin - ta {
        out.push((lim.amin - s.a) / lim.jmax, lim.jmax);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lim() -> Limits {
        Limits::symmetric(1.0, 1.0, 1.0)
    }

    #[test]
    fn no_brake_inside_limits() {
        assert!(position_brake(State::new(0.0, 0.5, 1.0), &lim()).is_empty());
        assert!(position_brake(State::new(0.0, -1.0, 0.0), &lim()).is_empty());
    }

    #[test]
    fn velocity_brake_with_acceleration_plateau() {
        let b = position_brake(State::new(0.0, 3.0, 0.5), &lim());
        assert_eq!(b.len(), 2);
        assert!((b.duration() - 3.125).abs() < 1e-12);
        assert!((b.end().v - 1.0).abs() < 1e-12);
        assert!((b.end().a + 1.0).abs() < 1e-12);
    }

    #[test]
    fn acceleration_brake_continues_into_velocity_brake() {
        let b = position_brake(State::new(0.0, 0.0, 1.5), &lim());
        assert!((b.duration() - 2.0).abs() < 1e-12);
        let b = position_brake(
            State::new(0.0, 0.0, 1.5),
            &Limits::symmetric(10.0, 1.0, 1.0),
        );
        assert!((b.duration() - 0.5).abs() < 1e-12);
        let b = position_brake(State::new(0.0, -1.2, -2.0), &lim());
        assert!((b.duration() - 4.7).abs() < 1e-12);
        assert!((b.end().v + 1.0).abs() < 1e-12);
    }
}
