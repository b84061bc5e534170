//! Step 1 for one DoF: the minimal duration and the set of feasible durations.
//!
//! All extremal shapes that reach the target exactly (see `shapes.rs` / `velocity.rs`) are
//! collected; their durations are the boundaries of the feasible set, the shortest one is the
//! time-optimal profile. A duration `T` is feasible iff the target lies within
//! `[Pmin(T), Pmax(T)]` (fixed-duration extremes); beyond the last boundary every duration is
//! feasible. [`Step1::feasible_intervals`] rebuilds the whole set by testing the midpoint of every
//! gap between consecutive boundaries (the gaps that are not feasible are the *blocked
//! intervals*); synchronisation tests its candidate durations directly with
//! [`Step1::is_feasible`].

use super::brake::{position_brake, velocity_brake};
use super::limits::{Limits, State};
use super::profile::Profile;
use super::shapes::{self, Goal, Problem, Shape};
use super::velocity;
use super::ControlInterface;
use std::mem::MaybeUninit;

/// Maximal number of distinct candidate durations kept.
pub const MAX_CANDIDATES: usize = 24;
/// Maximal number of feasible intervals kept.
pub const MAX_INTERVALS: usize = 8;

/// Result of step 1 for one DoF.
#[derive(Clone, Copy, Debug)]
pub struct Step1 {
    interface: ControlInterface,
    /// Brake pre-trajectory (empty if the current state is within the limits).
    pub brake: Profile,
    problem: Problem,
    /// Absolute start state of the main profile (after the brake).
    start: State,
    /// Candidate shapes, ascending by duration; only the first `n_cand` are initialised
    /// (read through [`Step1::cands`]).
    cand: [MaybeUninit<Shape>; MAX_CANDIDATES],
    /// Their main-profile durations in s.
    cand_t: [f64; MAX_CANDIDATES],
    n_cand: usize,
}

impl Step1 {
    /// Solves step 1. Returns None if no profile was found.
    pub fn solve(
        interface: ControlInterface,
        current: &State,
        target: &State,
        lim: &Limits,
    ) -> Option<Step1> {
        let mut out = MaybeUninit::uninit();
        if Self::solve_into(&mut out, interface, current, target, lim) {
            // SAFETY: `solve_into` initialises `out` before it returns true.
            Some(unsafe { out.assume_init() })
        } else {
            None
        }
    }

    /// [`Step1::solve`] written in place into `out` (the result is a few kB); returns false if
    /// no profile was found (`out` is then initialised but not meaningful).
    pub fn solve_into(
        out: &mut MaybeUninit<Step1>,
        interface: ControlInterface,
        current: &State,
        target: &State,
        lim: &Limits,
    ) -> bool {
        let brake = match interface {
            ControlInterface::Position => position_brake(*current, lim),
            ControlInterface::Velocity => velocity_brake(*current, lim),
        };
        let start = brake.end();
        let problem = Problem::new(&start, target, lim);
        let s = out.write(Step1 {
            interface,
            brake,
            problem,
            start,
            cand: [MaybeUninit::uninit(); MAX_CANDIDATES],
            cand_t: [0.0; MAX_CANDIDATES],
            n_cand: 0,
        });
        // Scratch list of all solutions with their durations, kept sorted by duration as they
        // come (stable insertion: few entries); the shapes are left uninitialised (4 kB) until
        // written.
        let mut all = [MaybeUninit::<Shape>::uninit(); 64];
        let mut all_t = [0.0f64; 64];
        let mut order = [0u8; 64];
        let mut n = 0;
        let mut collect = |sh: Shape| {
            if n < all.len() {
                let d = sh.duration();
                all[n].write(sh);
                all_t[n] = d;
                let mut k = n;
                while k > 0 && all_t[order[k - 1] as usize] > d {
                    order[k] = order[k - 1];
                    k -= 1;
                }
                order[k] = n as u8;
                n += 1;
            }
        };
        // Already at the target: duration 0 is a solution.
        if s.zero_solution() {
            collect(Shape {
                t: [0.0; 7],
                dir: 1.0,
            });
        }
        match interface {
            ControlInterface::Position => shapes::solve_all(&problem, Goal::Position, &mut collect),
            ControlInterface::Velocity => {
                velocity::solve_all(&problem, Goal::Position, &mut collect)
            }
        }
        if n == 0 {
            return false;
        }
        for &i in &order[..n] {
            let i = i as usize;
            let d = all_t[i];
            if s.n_cand > 0 {
                let last = s.cand_t[s.n_cand - 1];
                if d - last <= 1e-11 * d.max(1e-3) {
                    continue;
                }
            }
            if s.n_cand < MAX_CANDIDATES {
                // SAFETY: entries below `n` were written by `collect`.
                s.cand[s.n_cand].write(unsafe { all[i].assume_init() });
                s.cand_t[s.n_cand] = d;
                s.n_cand += 1;
            }
        }
        true
    }

    /// The candidate shapes (ascending by duration).
    fn cands(&self) -> &[Shape] {
        // SAFETY: the first `n_cand` entries are initialised by `solve_into`;
        // `MaybeUninit<Shape>` has the layout of `Shape`.
        unsafe { std::slice::from_raw_parts(self.cand.as_ptr().cast::<Shape>(), self.n_cand) }
    }

    fn zero_solution(&self) -> bool {
        let pr = &self.problem;
        let tv = 1e-12 * pr.v0.abs().max(pr.vf.abs()).max(1.0);
        let ta = 1e-12 * pr.lim.amax.abs().max(1.0);
        let pos_ok = match self.interface {
            ControlInterface::Position => pr.d.abs() <= 1e-12 * pr.d.abs().max(1.0),
            ControlInterface::Velocity => true,
        };
        pos_ok && (pr.v0 - pr.vf).abs() <= tv && (pr.a0 - pr.af).abs() <= ta
    }

    /// Extremal final position (velocity for the velocity interface) over main-profile
    /// durations `td`, with the shape attaining it.
    fn extreme_at(&self, dir: f64, td: f64) -> Option<(f64, Shape)> {
        match self.interface {
            ControlInterface::Position => shapes::extreme_at(&self.problem, dir, td),
            ControlInterface::Velocity => velocity::extreme_at(&self.problem, dir, td),
        }
    }

    fn goal_value(&self) -> f64 {
        match self.interface {
            ControlInterface::Position => self.problem.d,
            ControlInterface::Velocity => self.problem.vf,
        }
    }

    fn goal_tol(&self) -> f64 {
        1e-9 * self.goal_value().abs().max(1.0)
    }

    /// True if the main-profile duration `td` admits a trajectory to the target.
    fn feasible_main(&self, td: f64) -> bool {
        let g = self.goal_value();
        let tol = self.goal_tol();
        match (self.extreme_at(1.0, td), self.extreme_at(-1.0, td)) {
            (Some((hi, _)), Some((lo, _))) => lo <= g + tol && hi >= g - tol,
            _ => false,
        }
    }

    /// Duration of the brake pre-trajectory in s.
    pub fn brake_duration(&self) -> f64 {
        self.brake.duration()
    }

    /// Minimal total duration (brake included) in s.
    pub fn t_min(&self) -> f64 {
        self.brake_duration() + self.cand_t[0]
    }

    /// Total durations (brake included, s) of all extremal profiles reaching the target,
    /// ascending: the boundaries of the feasible set.
    pub fn boundaries(&self) -> impl Iterator<Item = f64> + '_ {
        let tb = self.brake_duration();
        self.cand_t[..self.n_cand].iter().map(move |c| c + tb)
    }

    /// Feasible intervals of the total duration (brake included) in s, ascending; the last one
    /// is unbounded. Rebuilt from the boundaries by testing the midpoint of every gap (cost:
    /// a few fixed-duration solves; not needed for synchronisation, which tests candidates
    /// directly).
    pub fn feasible_intervals(&self) -> ([(f64, f64); MAX_INTERVALS], usize) {
        let tb = self.brake_duration();
        let mut out = [(0.0, 0.0); MAX_INTERVALS];
        let mut n = 0;
        let mut lo = self.cand_t[0];
        for i in 0..self.n_cand - 1 {
            let (a, b) = (self.cand_t[i], self.cand_t[i + 1]);
            if !self.feasible_main(0.5 * (a + b)) && n < MAX_INTERVALS - 1 {
                out[n] = (lo + tb, a + tb);
                n += 1;
                lo = b;
            }
        }
        out[n] = (lo + tb, f64::INFINITY);
        (out, n + 1)
    }

    /// True if the total duration `t` (s, brake included) admits a trajectory to the target.
    /// Durations within 1e-12 (relative) of a boundary count as feasible.
    pub fn is_feasible(&self, t: f64) -> bool {
        let td = t - self.brake_duration();
        let tol = 1e-12 * td.abs().max(1.0);
        if td < self.cand_t[0] - tol {
            return false;
        }
        self.cand_t[..self.n_cand]
            .iter()
            .any(|c| (c - td).abs() <= tol)
            || self.feasible_main(td)
    }

    /// [`Step1::profile_at`] if `t` is feasible ([`Step1::is_feasible`]), None otherwise: one
    /// fixed-duration solve instead of a feasibility test followed by the same solve.
    pub fn profile_at_checked(&self, t: f64) -> Option<Profile> {
        let mut p = Profile::new(State::default());
        self.profile_at_checked_into(t, &mut p).then_some(p)
    }

    /// [`Step1::profile_at_checked`] written into `out` (no copies of whole profiles); returns
    /// false (and leaves `out` unspecified) if `t` is not feasible.
    pub fn profile_at_checked_into(&self, t: f64, out: &mut Profile) -> bool {
        let td = t - self.brake_duration();
        let tol = 1e-12 * td.abs().max(1.0);
        if td < self.cand_t[0] - tol {
            return false;
        }
        self.profile_at_into(t, out)
    }

    /// The time-optimal profile (brake included).
    pub fn optimal_profile(&self) -> Profile {
        self.with_brake(&self.cands()[0].profile(self.start, self.problem.lim.jmax))
    }

    fn with_brake(&self, main: &Profile) -> Profile {
        let mut p = self.brake;
        p.append(main);
        p
    }

    /// A profile of total duration `t` (s, brake included) reaching the target, or None if `t`
    /// is not feasible. On a boundary of the feasible set the extremal shape itself is used;
    /// inside, the convex combination of the position-maximal and position-minimal shapes of
    /// that duration that lands exactly on the target.
    pub fn profile_at(&self, t: f64) -> Option<Profile> {
        let mut p = Profile::new(State::default());
        self.profile_at_into(t, &mut p).then_some(p)
    }

    /// [`Step1::profile_at`] written into `out`; returns false (and leaves `out` unspecified)
    /// if `t` is not feasible.
    pub fn profile_at_into(&self, t: f64, out: &mut Profile) -> bool {
        let td = t - self.brake_duration();
        let tol = 1e-12 * td.abs().max(1.0);
        let jmax = self.problem.lim.jmax;
        for (c, ct) in self.cands().iter().zip(&self.cand_t) {
            if (ct - td).abs() <= tol {
                // The brake ends at `start`: the phases continue from its end state.
                out.copy_from(&self.brake);
                c.push_onto(out, jmax);
                return true;
            }
        }
        let Some((hi, shi)) = self.extreme_at(1.0, td) else {
            return false;
        };
        let Some((lo, slo)) = self.extreme_at(-1.0, td) else {
            return false;
        };
        let g = self.goal_value();
        let tolg = self.goal_tol();
        if g > hi + tolg || g < lo - tolg {
            return false;
        }
        out.copy_from(&self.brake);
        if hi - lo <= 1e-14 * g.abs().max(1.0) {
            shi.push_onto(out, jmax);
        } else {
            // The blend of the two extremal shapes, pushed directly after the brake (the same
            // segments as `Profile::blend` of their profiles).
            let (ta, ja, na) = shi.segments(jmax);
            let (tb, jb, nb) = slo.segments(jmax);
            let lambda = ((g - lo) / (hi - lo)).clamp(0.0, 1.0);
            out.push_blend((&ta[..na], &ja[..na]), (&tb[..nb], &jb[..nb]), lambda);
        }
        true
    }
}
