//! The extremal profile shapes of one DoF and their solvers.
//!
//! For a fixed duration `T`, the trajectories from the start state to the target velocity and
//! acceleration form a convex set (linear dynamics, convex jerk/acceleration/velocity bounds),
//! so the reachable final positions are an interval `[Pmin(T), Pmax(T)]`. By Pontryagin's
//! principle the position-maximising trajectory has jerk `+j, -j, +j` (costate quadratic in
//! time), with plateaus inserted where a limit is active: the **UDDU** shape
//!
//! | phase | 1 | 2 | 3 | 4 | 5 | 6 | 7 |
//! |---|---|---|---|---|---|---|---|
//! | jerk | +jmax | 0 (a = amax) | -jmax | 0 (v = vmax, a = 0) | -jmax | 0 (a = amin) | +jmax |
//!
//! and the minimising one is its mirror (**DUUD**), obtained by solving the mirrored problem.
//! The time-optimal profile ends exactly on the boundary of that interval, so it is one of these
//! shapes; so is every boundary of a blocked duration interval.
//!
//! Which plateaus exist gives five sub-shapes; each is a one-parameter family (the parameter is
//! the duration, or equivalently one acceleration or plateau length):
//!
//! * [`Case::Ramps`] no plateau: peak `a1`, trough `a2`; parameter `u = a1 - a2` (all phase
//!   durations are then rational in `u`, handled by homogenising with powers of `u`);
//! * [`Case::PlateauAmax`] `a1 = amax`, parameter the trough `a2`;
//! * [`Case::PlateauAmin`] `a2 = amin`, parameter the peak `a1`;
//! * [`Case::PlateauBoth`] both, parameter the `amax` plateau length;
//! * [`Case::PlateauVmax`] cruise at `vmax` (closed form, position linear in the cruise length).
//!
//! For each of the first four, the durations are polynomials in the parameter, the final
//! position is a polynomial built by symbolic integration, and "final position = target" (step
//! 1) or "duration = T" (fixed duration) is solved for all real roots in the admissible range.
//!
//! Every root is turned into a profile and validated (durations >= 0, limits, final state).

use super::limits::{Limits, State};
use super::poly::{Poly, ROOTS_CAP};
use super::profile::{integrate_checked_fixed, Profile};

/// The sub-shapes of the UDDU family (see module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Case {
    /// No plateau.
    Ramps,
    /// Acceleration plateau at `amax`.
    PlateauAmax,
    /// Acceleration plateau at `amin`.
    PlateauAmin,
    /// Plateaus at `amax` and `amin`.
    PlateauBoth,
    /// Velocity plateau at `vmax` (with or without acceleration plateaus).
    PlateauVmax,
}

/// All sub-shapes.
pub const CASES: [Case; 5] = [
    Case::Ramps,
    Case::PlateauAmax,
    Case::PlateauAmin,
    Case::PlateauBoth,
    Case::PlateauVmax,
];

/// One DoF's problem in a frame where the shape is UDDU (the DUUD shapes are solved on the
/// mirrored problem). Positions relative to the start.
#[derive(Clone, Copy, Debug)]
pub struct Problem {
    /// Start state (position ignored: 0).
    pub v0: f64,
    /// Start acceleration.
    pub a0: f64,
    /// Target displacement `pf - p0`.
    pub d: f64,
    /// Target velocity.
    pub vf: f64,
    /// Target acceleration.
    pub af: f64,
    /// Limits.
    pub lim: Limits,
    /// Reciprocals `1 / jmax`, `1 / amax`, `1 / amin`, `1 / vmax` (divisions done once).
    inv: [f64; 4],
}

impl Problem {
    /// Problem from absolute start and target states.
    pub fn new(start: &State, target: &State, lim: &Limits) -> Self {
        Problem {
            v0: start.v,
            a0: start.a,
            d: target.p - start.p,
            vf: target.v,
            af: target.a,
            lim: *lim,
            inv: [
                1.0 / lim.jmax,
                1.0 / lim.amax,
                1.0 / lim.amin,
                1.0 / lim.vmax,
            ],
        }
    }

    /// The mirrored problem (positions negated, limits swapped).
    pub fn mirrored(&self) -> Self {
        Problem {
            v0: -self.v0,
            a0: -self.a0,
            d: -self.d,
            vf: -self.vf,
            af: -self.af,
            lim: self.lim.mirrored(),
            // amax' = -amin, amin' = -amax, vmax' = -vmin.
            inv: [
                self.inv[0],
                -self.inv[2],
                -self.inv[1],
                -1.0 / self.lim.vmin,
            ],
        }
    }

    /// Jerks of the seven UDDU phases.
    fn jerks(&self) -> [f64; 7] {
        let j = self.lim.jmax;
        [j, 0.0, -j, 0.0, -j, 0.0, j]
    }
}

/// A solved 7-phase shape: phase durations (s) in the UDDU frame `dir = 1` or mirrored
/// (DUUD, `dir = -1`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shape {
    /// Phase durations in s.
    pub t: [f64; 7],
    /// +1 for UDDU, -1 for DUUD.
    pub dir: f64,
}

impl Shape {
    /// Total duration in s.
    pub fn duration(&self) -> f64 {
        self.t.iter().sum()
    }

    /// The profile of this shape from `start` for jerk limit `jmax`.
    pub fn profile(&self, start: State, jmax: f64) -> Profile {
        let mut p = Profile::new(start);
        self.push_onto(&mut p, jmax);
        p
    }

    /// The phases of positive duration as `(durations, jerks, count)` (the segments a profile
    /// of this shape has) for jerk limit `jmax`.
    pub fn segments(&self, jmax: f64) -> ([f64; 7], [f64; 7], usize) {
        let j = self.dir * jmax;
        let jerks = [j, 0.0, -j, 0.0, -j, 0.0, j];
        let (mut t, mut jk, mut n) = ([0.0; 7], [0.0; 7], 0);
        for (ti, ji) in self.t.iter().zip(jerks) {
            if *ti > 0.0 {
                t[n] = *ti;
                jk[n] = ji;
                n += 1;
            }
        }
        (t, jk, n)
    }

    /// Appends the phases of this shape to `p` (from its end state) for jerk limit `jmax`.
    pub fn push_onto(&self, p: &mut Profile, jmax: f64) {
        let j = self.dir * jmax;
        let jerks = [j, 0.0, -j, 0.0, -j, 0.0, j];
        for (t, jk) in self.t.iter().zip(jerks) {
            p.push(*t, jk);
        }
    }
}

/// What a solver is asked to match besides the target velocity and acceleration.
#[derive(Clone, Copy, Debug)]
pub enum Goal {
    /// The final position must equal the target (step 1: the duration is free).
    Position,
    /// The duration must equal this value in s (the final position is free).
    Duration(f64),
}

/// The parameter range `range` restricted to the union of a negative branch `neg` (if `neg_ok`)
/// and a positive branch `pos` (if `pos_ok`), each widened by `margin`: the hull of the
/// non-empty intersections, or None if there is none (the case has no valid shape).
#[inline]
fn tighten(
    range: (f64, f64),
    neg: (f64, f64),
    neg_ok: bool,
    pos: (f64, f64),
    pos_ok: bool,
    margin: f64,
) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (ok, (a, b)) in [(neg_ok, neg), (pos_ok, pos)] {
        let (a, b) = ((a - margin).max(range.0), (b + margin).min(range.1));
        if ok && a <= b {
            lo = lo.min(a);
            hi = hi.max(b);
        }
    }
    (lo <= hi).then_some((lo, hi))
}

/// The range `range` without the open interval `(c - sqrt(disc), c + sqrt(disc))` (shrunk by
/// `margin`) where a monic quadratic with vertex `c` and reduced discriminant `disc` is
/// negative: cut at an end it overlaps, unchanged if it lies inside (the hull is kept), None if
/// it covers the whole range.
#[inline]
fn exclude(range: (f64, f64), c: f64, disc: f64, margin: f64) -> Option<(f64, f64)> {
    if disc <= 0.0 {
        return Some(range);
    }
    let h = disc.sqrt();
    let (r1, r2) = (c - h + margin, c + h - margin);
    let (lo, hi) = range;
    if r1 >= r2 {
        return Some(range);
    }
    match (r1 <= lo, r2 >= hi) {
        (true, true) => None,
        (true, false) => Some((lo.max(r2), hi)),
        (false, true) => Some((lo, hi.min(r1))),
        (false, false) => Some(range),
    }
}

/// A polynomial case of one problem: its parameter range and the constant of its plateau (or,
/// for [`Case::Ramps`], `K = 2 j (vf - v0) + a0^2 - af^2`). The phase durations are closed-form
/// functions of the parameter ([`CaseParam::durations`]).
#[derive(Clone, Copy, Debug)]
struct CaseParam {
    case: Case,
    k: f64,
    lo: f64,
    hi: f64,
    /// `1 / jmax`.
    ij: f64,
    /// `1 / amax` (`PlateauAmax`) or `1 / amin` (`PlateauAmin`, `PlateauBoth`).
    ia: f64,
}

impl CaseParam {
    /// The case's parameter range and constant, or None if the case cannot exist for `pr`.
    #[inline]
    fn new(case: Case, pr: &Problem) -> Option<CaseParam> {
        let Problem {
            v0,
            a0,
            vf,
            af,
            lim,
            ..
        } = *pr;
        let j = lim.jmax;
        let (amax, amin) = (lim.amax, lim.amin);
        let dv = vf - v0;
        let m = 1e-9; // relative widening of parameter ranges; roots are validated afterwards
        match case {
            Case::Ramps => {
                // a1 = (u^2 + K/2) / (2u), a2 = (K/2 - u^2) / (2u).
                let k = 2.0 * j * dv + a0 * a0 - af * af;
                // a1 <= amax and a2 >= amin restrict u to the intersection of two intervals.
                let d1 = amax * amax - k / 2.0;
                let d2 = amin * amin + k / 2.0;
                let w = m * (amax - amin);
                if d1 < -w * w || d2 < -w * w {
                    return None;
                }
                let (s1, s2) = (d1.max(0.0).sqrt(), d2.max(0.0).sqrt());
                let lo = (amax - s1).max(-amin - s2).max(0.0) - w;
                let hi = (amax + s1).min(-amin + s2).min(amax - amin) + w;
                if hi < lo {
                    return None;
                }
                // Non-negative ramps: a1 >= a0 is u^2 - 2 a0 u + K/2 >= 0 and a2 <= af is
                // u^2 + 2 af u - K/2 >= 0; each excludes the open interval between its roots.
                let e = 1e-6 * (amax - amin);
                let (lo, hi) = exclude((lo.max(0.0), hi), a0, a0 * a0 - 0.5 * k, e)?;
                let (lo, hi) = exclude((lo, hi), -af, af * af + 0.5 * k, e)?;
                Some(CaseParam {
                    case,
                    k,
                    lo,
                    hi,
                    ij: pr.inv[0],
                    ia: 0.0,
                })
            }
            Case::PlateauAmax | Case::PlateauBoth
                if v0 + (amax * amax - a0 * a0) * (0.5 * pr.inv[0])
                    > lim.vmax + m * (lim.vmax - lim.vmin) =>
            {
                // Reaching amax alone already exceeds vmax (the velocity keeps rising on the
                // plateau): no such shape.
                None
            }
            Case::PlateauAmin | Case::PlateauBoth
                if vf - (af * af - amin * amin) * (0.5 * pr.inv[0])
                    < lim.vmin - m * (lim.vmax - lim.vmin) =>
            {
                // Mirror: the final ramp up from amin would start below vmin.
                None
            }
            Case::PlateauAmax => {
                // parameter: trough a2; the plateau lasts (a2^2 / j + k) / amax.
                let k = dv - (2.0 * amax * amax - a0 * a0 + af * af) * (0.5 * pr.inv[0]);
                let w = m * (amax - amin);
                // Plateau >= 0: a2^2 >= -k j; for a negative trough the velocity peaks (at
                // a = 0) at v1 + (a2^2 / j + k) + amax^2 / (2 j) <= vmax, v1 the velocity at
                // amax: a2^2 <= j (vmax - v1 - k) - amax^2 / 2.
                let v1 = v0 + (amax * amax - a0 * a0) * (0.5 * pr.inv[0]);
                let smin = (-k * j).max(0.0).sqrt();
                let w2 = j * (lim.vmax - v1 - k) - 0.5 * amax * amax;
                let (lo, hi) = tighten(
                    (amin - w, af.min(amax) + w),
                    (-w2.max(0.0).sqrt(), -smin),
                    w2 >= smin * smin,
                    (smin, f64::INFINITY),
                    true,
                    1e-6 * (amax - amin),
                )?;
                Some(CaseParam {
                    case,
                    k,
                    lo,
                    hi,
                    ij: pr.inv[0],
                    ia: pr.inv[1],
                })
            }
            Case::PlateauAmin => {
                // parameter: peak a1; the plateau lasts (k - a1^2 / j) / amin.
                let k = dv - (-a0 * a0 - 2.0 * amin * amin + af * af) * (0.5 * pr.inv[0]);
                let w = m * (amax - amin);
                // Plateau >= 0: a1^2 >= k j; for a positive peak the velocity peaks (at a = 0)
                // at v0 + a1^2 / j - a0^2 / (2 j) <= vmax.
                let smin = (k * j).max(0.0).sqrt();
                let q = j * (lim.vmax - v0) + 0.5 * a0 * a0;
                let (lo, hi) = tighten(
                    (a0.max(amin) - w, amax + w),
                    (f64::NEG_INFINITY, -smin),
                    true,
                    (smin, q.max(0.0).sqrt()),
                    q >= smin * smin,
                    1e-6 * (amax - amin),
                )?;
                Some(CaseParam {
                    case,
                    k,
                    lo,
                    hi,
                    ij: pr.inv[0],
                    ia: pr.inv[2],
                })
            }
            Case::PlateauBoth => {
                // parameter: amax plateau length z; the amin plateau lasts (k - amax z) / amin.
                let hij = 0.5 * pr.inv[0];
                let iamax = pr.inv[1];
                let k = dv - (2.0 * amax * amax - a0 * a0 - 2.0 * amin * amin + af * af) * hij;
                let v1 = v0 + (amax * amax - a0 * a0) * hij;
                let zmax = (lim.vmax - v1 - amax * amax * hij) * iamax;
                let zmin = (k * iamax).max(0.0);
                let w = m * ((lim.vmax - lim.vmin) * iamax);
                if zmax < -w {
                    return None;
                }
                Some(CaseParam {
                    case,
                    k,
                    lo: zmin - w,
                    hi: zmax.max(zmin) + w,
                    ij: pr.inv[0],
                    ia: pr.inv[2],
                })
            }
            Case::PlateauVmax => None,
        }
    }

    /// Phase durations at parameter `x` (closed form).
    #[inline]
    fn durations(&self, pr: &Problem, x: f64) -> [f64; 7] {
        let lim = &pr.lim;
        let (amax, amin) = (lim.amax, lim.amin);
        let (k, ij, ia) = (self.k, self.ij, self.ia);
        let mut t = [0.0; 7];
        match self.case {
            Case::Ramps => {
                let iju = ij / x;
                t[0] = (0.5 * (x * x + 0.5 * k) - pr.a0 * x) * iju;
                t[2] = x * ij;
                t[6] = (pr.af * x - 0.5 * (0.5 * k - x * x)) * iju;
            }
            Case::PlateauAmax => {
                t[0] = (amax - pr.a0) * ij;
                t[1] = (x * x * ij + k) * ia;
                t[2] = (amax - x) * ij;
                t[6] = (pr.af - x) * ij;
            }
            Case::PlateauAmin => {
                t[0] = (x - pr.a0) * ij;
                t[2] = (x - amin) * ij;
                t[5] = (k - x * x * ij) * ia;
                t[6] = (pr.af - amin) * ij;
            }
            Case::PlateauBoth => {
                t[0] = (amax - pr.a0) * ij;
                t[1] = x;
                t[2] = (amax - amin) * ij;
                t[5] = (k - amax * x) * ia;
                t[6] = (pr.af - amin) * ij;
            }
            Case::PlateauVmax => {}
        }
        t
    }

    /// The step-1 equation "final position = target" as a polynomial in the parameter, in
    /// closed form (derived by integrating the phases symbolically; see `docs/planner.md`):
    ///
    /// * `Ramps`: `u^4 + 2 (2 j (v0 + vf) - a0^2 - af^2) u^2
    ///   - 4/3 (3 j^2 d + af^3 - a0^3 + 3 j (a0 v0 - af vf)) u - K^2 / 4`
    ///   (the homogenised sextic divided by `u^2`; `u = 0` is not admissible);
    /// * `PlateauAmax` (trough `x`): `x^4 - 2 amax x^3 + (amax^2 - af^2 + 2 j vf) x^2
    ///   - 2 amax (2 j vf - af^2) x + 2 j^2 amax (P0 - d)`;
    /// * `PlateauAmin` (peak `x`): `x^4 - 2 amin x^3 + (amin^2 - a0^2 + 2 j v0) x^2
    ///   - 2 amin (2 j v0 - a0^2) x - 2 j^2 amin (P0 - d)`;
    /// * `PlateauBoth` (plateau `z`): `j amax z^2 + (2 amax^2 - amax amin + 2 j v0 - a0^2) z
    ///   - 2 j amin (P0 - d) / (amax - amin)`,
    ///
    /// where `P0` is the final position of the case's shape at parameter 0, integrated directly
    /// (the constant terms are otherwise long sums with cancellation).
    fn position_equation(&self, pr: &Problem) -> Poly {
        let Problem {
            v0,
            a0,
            d,
            vf,
            af,
            lim,
            ..
        } = *pr;
        let j = lim.jmax;
        let (amax, amin) = (lim.amax, lim.amin);
        let mut p = Poly::constant(0.0);
        match self.case {
            Case::Ramps => {
                p.deg = 4;
                p.c[4] = 1.0;
                p.c[2] = 2.0 * (2.0 * j * (v0 + vf) - a0 * a0 - af * af);
                p.c[1] = -(4.0 / 3.0)
                    * (3.0 * j * j * d + af * af * af - a0 * a0 * a0
                        + 3.0 * j * (a0 * v0 - af * vf));
                p.c[0] = -0.25 * self.k * self.k;
            }
            Case::PlateauAmax => {
                let p0 = self.p0(pr);
                let w = 2.0 * j * vf - af * af;
                p.deg = 4;
                p.c[4] = 1.0;
                p.c[3] = -2.0 * amax;
                p.c[2] = amax * amax + w;
                p.c[1] = -2.0 * amax * w;
                p.c[0] = 2.0 * j * j * amax * (p0 - d);
            }
            Case::PlateauAmin => {
                let p0 = self.p0(pr);
                let w = 2.0 * j * v0 - a0 * a0;
                p.deg = 4;
                p.c[4] = 1.0;
                p.c[3] = -2.0 * amin;
                p.c[2] = amin * amin + w;
                p.c[1] = -2.0 * amin * w;
                p.c[0] = -2.0 * j * j * amin * (p0 - d);
            }
            Case::PlateauBoth => {
                let p0 = self.p0(pr);
                p.deg = 2;
                p.c[2] = j * amax;
                p.c[1] = 2.0 * amax * amax - amax * amin + 2.0 * j * v0 - a0 * a0;
                p.c[0] = -2.0 * j * amin * (p0 - d) / (amax - amin);
            }
            Case::PlateauVmax => {}
        }
        p
    }

    /// Final position (relative to the start) of the shape at parameter 0 (plateau cases).
    ///
    /// The acceleration at every phase start is known from the case (e.g. `a0, amax, amax, 0`
    /// for `PlateauAmax`), so each phase's velocity gain `t (a + j t / 2)` and own displacement
    /// `t^2 (a / 2 + j t / 6)` are independent; the position is
    /// `sum_k (v_k t_k + own_k)` with `v_k` the prefix sums of the gains: the same quantities as
    /// integrating the state phase by phase, without its long chain of dependent operations.
    fn p0(&self, pr: &Problem) -> f64 {
        let t = self.durations(pr, 0.0);
        let lim = &pr.lim;
        let (j, amax, amin) = (lim.jmax, lim.amax, lim.amin);
        // (duration, jerk, start acceleration) of the four phases used.
        let ph: [(f64, f64, f64); 4] = match self.case {
            Case::PlateauAmax => [
                (t[0], j, pr.a0),
                (t[1], 0.0, amax),
                (t[2], -j, amax),
                (t[6], j, 0.0),
            ],
            Case::PlateauAmin => [
                (t[0], j, pr.a0),
                (t[2], -j, 0.0),
                (t[5], 0.0, amin),
                (t[6], j, amin),
            ],
            _ => [
                (t[0], j, pr.a0),
                (t[2], -j, amax),
                (t[5], 0.0, amin),
                (t[6], j, amin),
            ],
        };
        let gain = ph.map(|(d, jk, a)| d * (a + jk * d * 0.5));
        let own = ph.map(|(d, jk, a)| d * d * (a * 0.5 + jk * d * (1.0 / 6.0)));
        let v1 = pr.v0 + gain[0];
        let v2 = v1 + gain[1];
        let v3 = v2 + gain[2];
        (pr.v0 * ph[0].0 + v1 * ph[1].0)
            + (v2 * ph[2].0 + v3 * ph[3].0)
            + ((own[0] + own[1]) + (own[2] + own[3]))
    }

    /// The fixed-duration equation "total duration = td" as a polynomial in the parameter
    /// (degree <= 2; for `Ramps` the homogenised one divided by `u`, which is linear).
    fn duration_equation(&self, pr: &Problem, td: f64) -> Poly {
        let lim = &pr.lim;
        let (amax, amin) = (lim.amax, lim.amin);
        let [ij, iamax, iamin, _] = pr.inv;
        let (a0, af, k) = (pr.a0, pr.af, self.k);
        match self.case {
            // (2u + af - a0) / j = td
            Case::Ramps => Poly::linear((af - a0) * ij - td, 2.0 * ij),
            Case::PlateauAmax => {
                let mut p = Poly::constant((amax - a0) * ij + k * iamax + (amax + af) * ij - td);
                p.deg = 2;
                p.c[1] = -2.0 * ij;
                p.c[2] = ij * iamax;
                p
            }
            Case::PlateauAmin => {
                let mut p = Poly::constant((af - a0 - 2.0 * amin) * ij + k * iamin - td);
                p.deg = 2;
                p.c[1] = 2.0 * ij;
                p.c[2] = -ij * iamin;
                p
            }
            Case::PlateauBoth => Poly::linear(
                (amax - a0) * ij + (amax - amin) * ij + k * iamin + (af - amin) * ij - td,
                1.0 - amax * iamin,
            ),
            Case::PlateauVmax => Poly::constant(1.0),
        }
    }

    /// Final position error at parameter `x`, by direct integration (better conditioned than
    /// the expanded polynomial when the limits differ by orders of magnitude).
    fn position_error(&self, pr: &Problem, x: f64) -> f64 {
        let t = self.durations(pr, x);
        let mut s = State::new(0.0, pr.v0, pr.a0);
        for (ti, jk) in t.iter().zip(pr.jerks()) {
            // Phases a case never uses are skipped (the same branch every call).
            if *ti != 0.0 {
                s = s.integrate(*ti, jk);
            }
        }
        s.p - pr.d
    }

    /// Newton refinement of a root `r0` of the polynomial `eq` on the directly integrated final
    /// position error `err`; the derivative comes from the polynomial
    /// (`eq = factor * err`, with `factor` constant, or `4 j^2 u` for `Ramps`). Keeps the best
    /// point seen.
    fn polish(&self, pr: &Problem, eq: &Poly, r0: f64) -> f64 {
        let deq = eq.deriv();
        let j = pr.lim.jmax;
        let (amax, amin) = (pr.lim.amax, pr.lim.amin);
        let mut x = r0;
        let mut f = self.position_error(pr, x);
        let mut best = (x, f.abs());
        for _ in 0..6 {
            if f == 0.0 {
                break;
            }
            // err' = (eq' - err * factor') / factor.
            let d = match self.case {
                Case::Ramps => (deq.eval(x) - f * 4.0 * j * j) / (4.0 * j * j * x),
                Case::PlateauAmax => deq.eval(x) / (2.0 * j * j * amax),
                Case::PlateauAmin => deq.eval(x) / (-2.0 * j * j * amin),
                _ => deq.eval(x) / (-2.0 * j * amin / (amax - amin)),
            };
            if d == 0.0 || !d.is_finite() {
                break;
            }
            let xn = x - f / d;
            if !xn.is_finite() || (xn - x).abs() <= 1e-16 * x.abs() {
                break;
            }
            let fnew = self.position_error(pr, xn);
            if fnew.is_nan() || fnew.abs() >= best.1 {
                break;
            }
            best = (xn, fnew.abs());
            (x, f) = (xn, fnew);
        }
        best.0
    }
}

/// Validation tolerances (absolute) for the final state of a problem.
struct Tol {
    p: f64,
    v: f64,
    a: f64,
    t: f64,
}

fn tolerances(pr: &Problem) -> Tol {
    let l = &pr.lim;
    let vs = l.vmax.abs().max(l.vmin.abs()).max(pr.v0.abs()).max(1e-300);
    let as_ = l.amax.abs().max(l.amin.abs()).max(pr.a0.abs());
    Tol {
        p: 1e-9 * pr.d.abs().max(1.0),
        v: 1e-9 * vs.max(1.0),
        a: 1e-9 * as_.max(1.0),
        t: 1e-10 * (vs / as_ + as_ * pr.inv[0]).max(1.0),
    }
}

/// Turns phase durations into a validated shape with its final state, or None.
fn validate(pr: &Problem, mut t: [f64; 7], goal: Goal, tol: &Tol) -> Option<(Shape, State)> {
    for ti in t.iter_mut() {
        if !ti.is_finite() || *ti < -tol.t {
            return None;
        }
        *ti = ti.max(0.0);
    }
    let start = State::new(0.0, pr.v0, pr.a0);
    let e = integrate_checked_fixed(start, &t, &pr.jerks(), &pr.lim, 1e-9, true)?;
    if (e.v - pr.vf).abs() > tol.v || (e.a - pr.af).abs() > tol.a {
        return None;
    }
    match goal {
        Goal::Position => {
            if (e.p - pr.d).abs() > tol.p {
                return None;
            }
        }
        Goal::Duration(td) => {
            if (t.iter().sum::<f64>() - td).abs() > tol.t.max(1e-12 * td) {
                return None;
            }
        }
    }
    Some((Shape { t, dir: 1.0 }, e))
}

/// Solves one sub-shape of the UDDU family of `pr` for `goal`; calls `out` with every valid
/// solution.
pub fn solve_case(pr: &Problem, case: Case, goal: Goal, out: &mut impl FnMut(Shape)) {
    solve_case_with(
        pr,
        case,
        goal,
        &tolerances(pr),
        &mut |s: Shape, _: &State| out(s),
    );
}

/// [`solve_case`] with precomputed tolerances; `out` also gets the final state of the shape.
fn solve_case_with(
    pr: &Problem,
    case: Case,
    goal: Goal,
    tol: &Tol,
    out: &mut impl FnMut(Shape, &State),
) {
    if case == Case::PlateauVmax {
        if let Some((s, e)) = solve_vmax(pr, goal, tol) {
            out(s, &e);
        }
        return;
    }
    let Some(cp) = CaseParam::new(case, pr) else {
        return;
    };
    let eq = match goal {
        Goal::Position => cp.position_equation(pr),
        Goal::Duration(td) => cp.duration_equation(pr, td),
    };
    let mut roots = [0.0; ROOTS_CAP];
    let n = eq.roots_in(cp.lo, cp.hi, &mut roots);
    for &r in &roots[..n] {
        if case == Case::Ramps && r <= 0.0 {
            continue;
        }
        let r = match goal {
            Goal::Position => {
                // Roots with a clearly negative phase are not worth polishing (polishing moves
                // the durations by far less than this margin).
                let t = cp.durations(pr, r);
                let scale = t.iter().fold(0.0f64, |m, x| m + x.abs());
                if t.iter().any(|x| *x < -1e-6 * scale - tol.t) {
                    continue;
                }
                cp.polish(pr, &eq, r)
            }
            Goal::Duration(_) => r,
        };
        if let Some((s, e)) = validate(pr, cp.durations(pr, r), goal, tol) {
            out(s, &e);
        }
    }
}

/// Velocity-plateau case: accelerate to (vmax, 0), cruise, decelerate to the target.
fn solve_vmax(pr: &Problem, goal: Goal, tol: &Tol) -> Option<(Shape, State)> {
    let Problem {
        v0,
        a0,
        vf,
        af,
        lim,
        ..
    } = *pr;
    let j = lim.jmax;
    let [ij, iamax, iamin, ivmax] = pr.inv;
    let (amax, amin, vmax) = (lim.amax, lim.amin, lim.vmax);
    let mut t = [0.0; 7];
    let a1sq = j * (vmax - v0) + a0 * a0 * 0.5;
    if a1sq < 0.0 {
        return None;
    }
    let a2sq = j * (vmax - vf) + af * af * 0.5;
    if a2sq < 0.0 {
        return None;
    }
    let a1 = a1sq.sqrt();
    let peak = if a1 > amax {
        t[0] = (amax - a0) * ij;
        t[1] = (vmax - v0 - (2.0 * amax * amax - a0 * a0) * 0.5 * ij) * iamax;
        t[2] = amax * ij;
        amax
    } else {
        t[0] = (a1 - a0) * ij;
        t[2] = a1 * ij;
        a1
    };
    let a2 = -a2sq.sqrt();
    let trough = if a2 < amin {
        t[4] = -amin * ij;
        t[5] = (vf - vmax + (2.0 * amin * amin - af * af) * 0.5 * ij) * iamin;
        t[6] = (af - amin) * ij;
        amin
    } else {
        t[4] = -a2 * ij;
        t[6] = (af - a2) * ij;
        a2
    };
    if t.iter().any(|x| *x < -tol.t) {
        return None;
    }
    match goal {
        Goal::Position => {
            // End position of the shape without cruise, from independent per-phase terms
            // (start accelerations known: a0, peak, peak, 0, trough, trough), see
            // `CaseParam::p0`; phases of negative (rounding) duration are left out.
            let ph = [
                (t[0].max(0.0), j, a0),
                (t[1].max(0.0), 0.0, peak),
                (t[2].max(0.0), -j, peak),
                (t[4].max(0.0), -j, 0.0),
                (t[5].max(0.0), 0.0, trough),
                (t[6].max(0.0), j, trough),
            ];
            let gain = ph.map(|(d, jk, a)| d * (a + jk * d * 0.5));
            let own = ph.map(|(d, jk, a)| d * d * (a * 0.5 + jk * d * (1.0 / 6.0)));
            let v1 = v0 + gain[0];
            let v2 = v1 + gain[1];
            let v3 = v2 + gain[2];
            let v4 = v3 + gain[3];
            let v5 = v4 + gain[4];
            let p = (v0 * ph[0].0 + v1 * ph[1].0)
                + (v2 * ph[2].0 + v3 * ph[3].0)
                + (v4 * ph[4].0 + v5 * ph[5].0)
                + ((own[0] + own[1]) + (own[2] + own[3]) + (own[4] + own[5]));
            t[3] = (pr.d - p) * ivmax;
        }
        Goal::Duration(td) => {
            t[3] = td - t.iter().sum::<f64>();
            if t[3] < -tol.t {
                return None;
            }
        }
    }
    validate(pr, t, goal, tol)
}

/// Calls `out` with every UDDU (`dir = 1`) and DUUD (`dir = -1`) shape of `pr` meeting `goal`.
pub fn solve_all(pr: &Problem, goal: Goal, out: &mut impl FnMut(Shape)) {
    // The tolerances are symmetric under mirroring.
    let tol = tolerances(pr);
    for case in CASES {
        solve_case_with(pr, case, goal, &tol, &mut |s: Shape, _: &State| out(s));
    }
    let m = pr.mirrored();
    for case in CASES {
        solve_case_with(&m, case, goal, &tol, &mut |s: Shape, _: &State| {
            out(Shape { t: s.t, dir: -1.0 })
        });
    }
}

/// The extremal shape of duration `td`: the one with the largest final position if `dir = 1`,
/// the smallest if `dir = -1`; with that position. None if `td` is too short to reach the target
/// velocity and acceleration.
///
/// The first valid shape found is returned: for a fixed duration, maximising the final position
/// is a convex problem (linear objective, convex constraints), and every valid UDDU shape
/// satisfies Pontryagin's conditions for it (the acceleration costate is an upward quadratic,
/// jerk `+j, -j, +j` between its roots, plateaus where a limit is active), which are sufficient
/// here; so all valid shapes of that duration reach the same, maximal, position. The cases are
/// tried in the order of how often they are the extreme in random motions (cruise first).
pub fn extreme_at(pr: &Problem, dir: f64, td: f64) -> Option<(f64, Shape)> {
    let frame = if dir > 0.0 { *pr } else { pr.mirrored() };
    let tol = tolerances(&frame);
    let mut best: Option<(f64, Shape)> = None;
    for case in [
        Case::PlateauVmax,
        Case::PlateauBoth,
        Case::Ramps,
        Case::PlateauAmax,
        Case::PlateauAmin,
    ] {
        solve_case_with(
            &frame,
            case,
            Goal::Duration(td),
            &tol,
            &mut |s: Shape, e: &State| {
                if best.is_none_or(|(bp, _)| e.p > bp) {
                    best = Some((e.p, s));
                }
            },
        );
        if best.is_some() {
            break;
        }
    }
    best.map(|(p, s)| (dir * p, Shape { t: s.t, dir }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Solves `case` for the target position; checks every solution's invariants (no negative
    /// duration, limits, final state) and that the fixed-duration solver of the same case at the
    /// shortest solution's duration lands on the target too. Returns the shortest duration.
    fn check_case(pr: &Problem, case: Case) -> f64 {
        let mut best: Option<Shape> = None;
        solve_case(pr, case, Goal::Position, &mut |s: Shape| {
            assert!(s.t.iter().all(|t| *t >= 0.0));
            let prof = s.profile(State::new(0.0, pr.v0, pr.a0), pr.lim.jmax);
            assert!(prof.within_limits(&pr.lim, 1e-9));
            let e = prof.end();
            assert!((e.p - pr.d).abs() < 1e-8 * pr.d.abs().max(1.0));
            assert!((e.v - pr.vf).abs() < 1e-8 && (e.a - pr.af).abs() < 1e-8);
            if best.is_none_or(|b| s.duration() < b.duration()) {
                best = Some(s);
            }
        });
        let best = best.unwrap_or_else(|| panic!("{case:?} found no solution"));
        let td = best.duration();
        let (p, _) = extreme_at(pr, 1.0, td).expect("extreme at the optimum");
        assert!(
            (p - pr.d).abs() < 1e-8 * pr.d.abs().max(1.0),
            "{p} vs {}",
            pr.d
        );
        // Nothing shorter over all cases and both directions.
        solve_all(pr, Goal::Position, &mut |s: Shape| {
            assert!(s.duration() >= td - 1e-9, "{case:?}: shorter shape {s:?}");
        });
        td
    }

    fn problem(d: f64, lim: Limits) -> Problem {
        Problem::new(&State::new(0.0, 0.0, 0.0), &State::new(d, 0.0, 0.0), &lim)
    }

    #[test]
    fn ramps_only() {
        let pr = problem(0.3, Limits::symmetric(10.0, 10.0, 2.0));
        let td = check_case(&pr, Case::Ramps);
        assert!((td - 4.0 * (0.3f64 / 4.0).cbrt()).abs() < 1e-12);
    }

    #[test]
    fn plateau_amax_only() {
        // Small amax, large |amin|: only the acceleration phase saturates.
        let lim = Limits {
            vmax: 100.0,
            vmin: -100.0,
            amax: 0.5,
            amin: -5.0,
            jmax: 1.0,
        };
        check_case(&problem(3.0, lim), Case::PlateauAmax);
    }

    #[test]
    fn plateau_amin_only() {
        let lim = Limits {
            vmax: 100.0,
            vmin: -100.0,
            amax: 5.0,
            amin: -0.5,
            jmax: 1.0,
        };
        check_case(&problem(3.0, lim), Case::PlateauAmin);
    }

    #[test]
    fn plateau_both_accelerations() {
        let pr = problem(5.0, Limits::symmetric(100.0, 1.0, 4.0));
        check_case(&pr, Case::PlateauBoth);
    }

    #[test]
    fn plateau_vmax() {
        let pr = problem(10.0, Limits::symmetric(1.0, 2.0, 10.0));
        let td = check_case(&pr, Case::PlateauVmax);
        assert!((td - (10.0 + 0.5 + 0.2)).abs() < 1e-12);
    }

    #[test]
    fn mirrored_shape_for_negative_motion() {
        let pr = problem(-10.0, Limits::symmetric(1.0, 2.0, 10.0));
        let mut found = false;
        solve_all(&pr, Goal::Position, &mut |s: Shape| {
            if s.dir < 0.0 && (s.duration() - 10.7).abs() < 1e-12 {
                found = true;
            }
        });
        assert!(found);
    }

    #[test]
    fn fixed_duration_extremes_bracket_the_target() {
        // For durations above the optimum the target lies between Pmin and Pmax.
        let pr = Problem::new(
            &State::new(0.0, 0.4, -0.3),
            &State::new(1.0, 0.2, 0.1),
            &Limits::symmetric(1.0, 1.0, 1.0),
        );
        let mut tmin = f64::INFINITY;
        solve_all(&pr, Goal::Position, &mut |s: Shape| {
            tmin = tmin.min(s.duration())
        });
        for k in 1..20 {
            let t = tmin * (1.0 + 0.1 * k as f64);
            let (hi, _) = extreme_at(&pr, 1.0, t).unwrap();
            let (lo, _) = extreme_at(&pr, -1.0, t).unwrap();
            assert!(
                lo <= pr.d + 1e-12 && pr.d <= hi + 1e-12,
                "t {t}: [{lo}, {hi}]"
            );
        }
        let (hi, _) = extreme_at(&pr, 1.0, tmin * 0.99).unwrap_or((
            f64::NEG_INFINITY,
            Shape {
                t: [0.0; 7],
                dir: 1.0,
            },
        ));
        assert!(hi < pr.d);
    }
}
#[cfg(test)]
mod closed_form {
    use super::*;

    /// The closed-form step-1 equations agree with the directly integrated final position:
    /// `eq(x)` is `position_error(x)` times a factor that depends on the problem and the
    /// parameter only through known powers, checked at random parameters of random problems.
    #[test]
    fn position_equations_match_direct_integration() {
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        let mut n = 0;
        for _ in 0..2000 {
            let j = 10f64.powf(rnd());
            let lim = Limits {
                vmax: 3.0 + 2.0 * rnd(),
                vmin: -3.0 + 2.0 * rnd(),
                amax: 3.0 + 2.0 * rnd(),
                amin: -3.0 + 2.0 * rnd(),
                jmax: j,
            };
            let pr = Problem::new(
                &State::new(0.0, rnd(), rnd()),
                &State::new(3.0 * rnd(), rnd(), rnd()),
                &lim,
            );
            for case in [
                Case::Ramps,
                Case::PlateauAmax,
                Case::PlateauAmin,
                Case::PlateauBoth,
            ] {
                let Some(cp) = CaseParam::new(case, &pr) else {
                    continue;
                };
                let eq = cp.position_equation(&pr);
                let (amax, amin) = (lim.amax, lim.amin);
                for _ in 0..3 {
                    let x = match case {
                        Case::Ramps => 0.1 + 3.0 * rnd().abs(),
                        _ => 2.0 * rnd(),
                    };
                    let err = cp.position_error(&pr, x);
                    // (p - d) times the factor that turns it into the equation.
                    let factor = match case {
                        Case::Ramps => 4.0 * j * j * x,
                        Case::PlateauAmax => 2.0 * j * j * amax,
                        Case::PlateauAmin => -2.0 * j * j * amin,
                        _ => -2.0 * j * amin / (amax - amin),
                    };
                    let (lhs, rhs) = (eq.eval(x), factor * err);
                    let scale = eq.c.iter().fold(1.0f64, |m, c| m.max(c.abs())) * 1e2;
                    assert!(
                        (lhs - rhs).abs() <= 1e-10 * scale,
                        "{case:?} x {x}: {lhs} vs {rhs}"
                    );
                    n += 1;
                }
            }
        }
        assert!(n > 5000, "{n}");
    }
}
