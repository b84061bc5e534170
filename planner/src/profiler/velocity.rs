//! Velocity control interface: only the target velocity and acceleration matter, velocity
//! limits are not applied (the target velocity may even lie outside them), acceleration and jerk
//! limits are.
//!
//! For a fixed duration the reachable final velocities (at the target acceleration) form an
//! interval `[Vmin(T), Vmax(T)]` (same convexity argument as for positions). The maximising
//! trajectory has the **UD** shape `+jmax, 0 (a = amax), -jmax`; the minimising one is its
//! mirror **DU**. Both are solved in closed form. They are stored in phases 1-3 of a [`Shape`].

use super::limits::State;
use super::profile::integrate_checked;
use super::shapes::{Goal, Problem, Shape};

fn tol_v(pr: &Problem) -> f64 {
    1e-9 * pr.v0.abs().max(pr.vf.abs()).max(1.0)
}

fn tol_a(pr: &Problem) -> f64 {
    1e-9 * pr.lim.amax.abs().max(pr.lim.amin.abs()).max(1.0)
}

fn validate(pr: &Problem, mut t: [f64; 7], goal: Goal) -> Option<Shape> {
    let lim = &pr.lim;
    let tt = 1e-10 * (lim.amax / lim.jmax).max(1.0);
    for ti in t.iter_mut() {
        if !ti.is_finite() || *ti < -tt {
            return None;
        }
        *ti = ti.max(0.0);
    }
    let j = lim.jmax;
    let jerks = [j, 0.0, -j, 0.0, -j, 0.0, j];
    let e = integrate_checked(State::new(0.0, pr.v0, pr.a0), &t, &jerks, lim, 1e-9, false)?;
    if (e.a - pr.af).abs() > tol_a(pr) {
        return None;
    }
    match goal {
        Goal::Position => {
            if (e.v - pr.vf).abs() > tol_v(pr) {
                return None;
            }
        }
        Goal::Duration(td) => {
            if (t.iter().sum::<f64>() - td).abs() > tt.max(1e-12 * td) {
                return None;
            }
        }
    }
    Some(Shape { t, dir: 1.0 })
}

/// UD shapes in the frame of `pr` meeting `goal` (`Goal::Position` here means: reach the target
/// velocity; the duration is free).
fn solve_ud(pr: &Problem, goal: Goal, out: &mut impl FnMut(Shape)) {
    let Problem {
        v0,
        a0,
        vf,
        af,
        lim,
        ..
    } = *pr;
    let j = lim.jmax;
    let amax = lim.amax;
    let dv = vf - v0;
    // Without plateau. Reaching the target velocity, the peak may be either root (a negative
    // peak is valid when both a0 and af are below it).
    let peaks = match goal {
        Goal::Position => {
            let sq = (2.0 * j * dv + a0 * a0 + af * af) / 2.0;
            if sq < 0.0 {
                [f64::NAN; 2]
            } else {
                [sq.sqrt(), -sq.sqrt()]
            }
        }
        Goal::Duration(td) => [(j * td + a0 + af) / 2.0, f64::NAN],
    };
    for a1 in peaks {
        if a1.is_finite() {
            let t = [(a1 - a0) / j, 0.0, (a1 - af) / j, 0.0, 0.0, 0.0, 0.0];
            if let Some(s) = validate(pr, t, goal) {
                out(s);
            }
        }
    }
    // With plateau at amax.
    let t1 = (amax - a0) / j;
    let t3 = (amax - af) / j;
    let t2 = match goal {
        Goal::Position => (dv - (2.0 * amax * amax - a0 * a0 - af * af) / (2.0 * j)) / amax,
        Goal::Duration(td) => td - t1 - t3,
    };
    if let Some(s) = validate(pr, [t1, t2, t3, 0.0, 0.0, 0.0, 0.0], goal) {
        out(s);
    }
}

/// Calls `out` with every UD (`dir = 1`) and DU (`dir = -1`) shape of `pr` meeting `goal`.
pub fn solve_all(pr: &Problem, goal: Goal, out: &mut impl FnMut(Shape)) {
    solve_ud(pr, goal, out);
    let m = pr.mirrored();
    solve_ud(&m, goal, &mut |s: Shape| out(Shape { t: s.t, dir: -1.0 }));
}

/// The shape of duration `td` with the largest (`dir = 1`) or smallest (`dir = -1`) final
/// velocity, with that velocity.
pub fn extreme_at(pr: &Problem, dir: f64, td: f64) -> Option<(f64, Shape)> {
    let frame = if dir > 0.0 { *pr } else { pr.mirrored() };
    let mut best: Option<(f64, Shape)> = None;
    let start = State::new(0.0, frame.v0, frame.a0);
    solve_ud(&frame, Goal::Duration(td), &mut |s: Shape| {
        let v = s.profile(start, frame.lim.jmax).end().v;
        if best.is_none_or(|(bv, _)| v > bv) {
            best = Some((v, s));
        }
    });
    best.map(|(v, s)| (dir * v, Shape { t: s.t, dir }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profiler::limits::Limits;

    fn shapes_of(v0: f64, a0: f64, vf: f64, af: f64) -> Vec<Shape> {
        let pr = Problem::new(
            &State::new(0.0, v0, a0),
            &State::new(0.0, vf, af),
            &Limits::symmetric(1.0, 1.0, 1.0),
        );
        let mut out = Vec::new();
        solve_all(&pr, Goal::Position, &mut |s: Shape| {
            let e = s.profile(State::new(0.0, v0, a0), 1.0).end();
            assert!((e.v - vf).abs() < 1e-12 && (e.a - af).abs() < 1e-12);
            out.push(s);
        });
        out
    }

    #[test]
    fn ud_without_plateau() {
        // dv = 0.5 < amax^2 / j: peak sqrt(0.5).
        let s = shapes_of(0.0, 0.0, 0.5, 0.0);
        let t = s.iter().map(|s| s.duration()).fold(f64::INFINITY, f64::min);
        assert!((t - 2.0 * 0.5f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn ud_with_plateau() {
        let s = shapes_of(0.5, 0.0, 2.0, 0.0);
        let t = s.iter().map(|s| s.duration()).fold(f64::INFINITY, f64::min);
        assert!((t - 2.5).abs() < 1e-12);
    }

    #[test]
    fn du_with_positive_trough() {
        // Both accelerations strongly positive: the minimising (DU) shape reaching the target
        // velocity keeps a positive trough (its mirrored peak is negative). This is a boundary
        // of the feasible set (a blocked interval starts there).
        let lim = Limits {
            vmax: 2.233,
            vmin: -2.479,
            amax: 3.4248,
            amin: -1.5961,
            jmax: 0.8428,
        };
        let (v0, a0, vf, af) = (-1.92018, 2.08541, 1.27833, 1.95189);
        let pr = Problem::new(&State::new(0.0, v0, a0), &State::new(0.0, vf, af), &lim);
        let mut found = false;
        solve_all(&pr, Goal::Position, &mut |s: Shape| {
            let prof = s.profile(State::new(0.0, v0, a0), lim.jmax);
            let e = prof.end();
            assert!((e.v - vf).abs() < 1e-9 && (e.a - af).abs() < 1e-9);
            let trough = a0 - lim.jmax * s.t[0];
            if s.dir < 0.0 && trough > 0.0 {
                found = true;
            }
        });
        assert!(found);
    }
}
