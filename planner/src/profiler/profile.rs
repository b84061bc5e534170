//! A one-DoF jerk profile: a start state followed by segments of constant jerk.
//!
//! Fixed capacity, `Copy`, no allocation. After its last segment the profile continues with
//! zero jerk (constant acceleration), which is what is evaluated past the duration.

use super::limits::{Limits, State};
use std::mem::MaybeUninit;

/// Maximal number of constant-jerk segments of a [`Profile`] (brake 2 + blend of two 7-phase
/// profiles: at most 13 segments, 14 if their durations differ by rounding; with margin).
pub const MAX_SEGMENTS: usize = 18;

/// Piecewise-constant-jerk trajectory of one degree of freedom.
///
/// Compact (about 350 bytes): the segments, the start and final states and the duration. The
/// state inside the profile is integrated from the start on demand, with the same operations in
/// the same order as when the profile was built, so the results are identical to caching the
/// state at every segment start. The segment arrays are initialised only up to the length (an
/// empty profile, e.g. for every unused DoF of a trajectory, costs no array initialisation).
#[derive(Clone, Copy)]
pub struct Profile {
    n: usize,
    /// Segment durations in s; `t[..n]` initialised.
    t: [MaybeUninit<f64>; MAX_SEGMENTS],
    /// Segment jerks in u/s^3; `j[..n]` initialised.
    j: [MaybeUninit<f64>; MAX_SEGMENTS],
    /// Start state.
    start: State,
    /// Final state (after the last segment).
    end: State,
    /// Duration in s (sum of the segment durations, accumulated in order).
    dur: f64,
}

/// Position extrema of one DoF over a time interval.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionExtrema {
    /// Minimal position in u.
    pub min: f64,
    /// Time of the minimal position in s.
    pub t_min: f64,
    /// Maximal position in u.
    pub max: f64,
    /// Time of the maximal position in s.
    pub t_max: f64,
}

impl std::fmt::Debug for Profile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Profile")
            .field("durations", &self.ts())
            .field("jerks", &self.js())
            .field("start", &self.start)
            .field("end", &self.end)
            .field("duration", &self.dur)
            .finish()
    }
}

impl Profile {
    /// An empty profile (duration 0) starting (and ending) at `start`.
    pub fn new(start: State) -> Self {
        Profile {
            n: 0,
            t: [MaybeUninit::uninit(); MAX_SEGMENTS],
            j: [MaybeUninit::uninit(); MAX_SEGMENTS],
            start,
            end: start,
            dur: 0.0,
        }
    }

    /// The segment durations (s).
    #[inline]
    fn ts(&self) -> &[f64] {
        // SAFETY: `t[..n]` is initialised (`push` and `copy_from` write an entry before the
        // length covers it); `MaybeUninit<f64>` has the layout of `f64`.
        unsafe { std::slice::from_raw_parts(self.t.as_ptr().cast::<f64>(), self.n) }
    }

    /// The segment jerks (u/s^3).
    #[inline]
    fn js(&self) -> &[f64] {
        // SAFETY: as for `ts`.
        unsafe { std::slice::from_raw_parts(self.j.as_ptr().cast::<f64>(), self.n) }
    }

    /// Appends a segment of `dur` seconds at jerk `jerk`. Non-positive durations are skipped.
    /// Returns false if the capacity is exhausted.
    #[inline]
    pub fn push(&mut self, dur: f64, jerk: f64) -> bool {
        if dur <= 0.0 {
            return true;
        }
        if self.n >= MAX_SEGMENTS {
            return false;
        }
        let i = self.n;
        self.t[i] = MaybeUninit::new(dur);
        self.j[i] = MaybeUninit::new(jerk);
        self.end = self.end.integrate(dur, jerk);
        self.dur += dur;
        self.n += 1;
        true
    }

    /// Makes this profile a copy of `other`, copying only the used entries (cheaper than an
    /// assignment of the whole fixed-capacity arrays; entries past the length are never read).
    #[inline]
    pub fn copy_from(&mut self, other: &Profile) {
        let n = other.n;
        self.n = n;
        self.t[..n].copy_from_slice(&other.t[..n]);
        self.j[..n].copy_from_slice(&other.j[..n]);
        self.start = other.start;
        self.end = other.end;
        self.dur = other.dur;
    }

    /// Appends all segments of `other` (whose start state is assumed to equal this end state).
    pub fn append(&mut self, other: &Profile) -> bool {
        other
            .ts()
            .iter()
            .zip(other.js())
            .all(|(t, j)| self.push(*t, *j))
    }

    /// Number of segments.
    pub fn len(&self) -> usize {
        self.n
    }

    /// True if the profile has no segment.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Segment `i` as (duration s, jerk u/s^3).
    pub fn segment(&self, i: usize) -> (f64, f64) {
        if i < self.n {
            (self.ts()[i], self.js()[i])
        } else {
            (0.0, 0.0)
        }
    }

    /// Duration in s.
    pub fn duration(&self) -> f64 {
        self.dur
    }

    /// Start state.
    pub fn start(&self) -> State {
        self.start
    }

    /// Final state (at [`Profile::duration`]).
    pub fn end(&self) -> State {
        self.end
    }

    /// State and jerk at time `t` (s). Before 0 the start state is returned; after the
    /// duration the profile continues with zero jerk.
    pub fn at(&self, t: f64) -> (State, f64) {
        if t <= 0.0 {
            return (self.start, if self.n > 0 { self.js()[0] } else { 0.0 });
        }
        if t >= self.dur {
            return (self.end.integrate(t - self.dur, 0.0), 0.0);
        }
        // Walk the segments, integrating as `push` did (identical segment start states).
        let (ts, js) = (self.ts(), self.js());
        let (mut s, mut t0) = (self.start, 0.0);
        for i in 0..self.n {
            let t1 = t0 + ts[i];
            if t1 > t || i + 1 == self.n {
                return (s.integrate(t - t0, js[i]), js[i]);
            }
            s = s.integrate(ts[i], js[i]);
            t0 = t1;
        }
        (s, 0.0)
    }

    /// True if velocity and acceleration stay within `lim` (widened by `rel` times the limit
    /// magnitudes) over the whole profile, checking segment ends and interior velocity extrema.
    pub fn within_limits(&self, lim: &Limits, rel: f64) -> bool {
        self.within_limits_from(0, lim, rel, true)
    }

    /// Like [`Profile::within_limits`] from segment `first` on; `check_velocity = false` checks
    /// the acceleration only (velocity interface).
    pub fn within_limits_from(
        &self,
        first: usize,
        lim: &Limits,
        rel: f64,
        check_velocity: bool,
    ) -> bool {
        if first >= self.n {
            return true;
        }
        let mut s0 = self.start;
        for i in 0..first {
            s0 = s0.integrate(self.ts()[i], self.js()[i]);
        }
        integrate_checked(
            s0,
            &self.ts()[first..],
            &self.js()[first..],
            lim,
            rel,
            check_velocity,
        )
        .is_some()
    }

    /// Position extrema over `[0, duration]`.
    pub fn position_extrema(&self) -> PositionExtrema {
        let s0 = self.start;
        let mut ex = PositionExtrema {
            min: s0.p,
            t_min: 0.0,
            max: s0.p,
            t_max: 0.0,
        };
        let mut see = |p: f64, t: f64| {
            if p < ex.min {
                ex.min = p;
                ex.t_min = t;
            }
            if p > ex.max {
                ex.max = p;
                ex.t_max = t;
            }
        };
        let (mut s, mut t0) = (self.start, 0.0);
        for i in 0..self.n {
            let (j, d) = (self.js()[i], self.ts()[i]);
            // v(t) = s.v + s.a t + j t^2 / 2 = 0
            let mut roots = [f64::NAN; 2];
            if j.abs() > 0.0 {
                let disc = s.a * s.a - 2.0 * j * s.v;
                if disc >= 0.0 {
                    let sq = disc.sqrt();
                    roots = [(-s.a + sq) / j, (-s.a - sq) / j];
                }
            } else if s.a != 0.0 {
                roots[0] = -s.v / s.a;
            }
            for r in roots {
                if r > 0.0 && r < d {
                    see(s.integrate(r, j).p, t0 + r);
                }
            }
            s = s.integrate(d, j);
            t0 += d;
            see(s.p, t0);
        }
        ex
    }

    /// The convex combination `lambda * a + (1 - lambda) * b` of two profiles with the same
    /// start state: its jerk is the combination of the jerks on the union of both breakpoint
    /// sets, so (the dynamics being linear) its state is the combination of both states at
    /// every time. Limits that both respect are respected by the blend (they are convex).
    pub fn blend(a: &Profile, b: &Profile, lambda: f64) -> Profile {
        let mut r = Profile::new(a.start());
        r.push_blend((a.ts(), a.js()), (b.ts(), b.js()), lambda);
        r
    }

    /// Appends the blend (see [`Profile::blend`]) of two segment lists `(durations, jerks)`
    /// (positive durations) that start at this profile's end state.
    pub(crate) fn push_blend(&mut self, a: (&[f64], &[f64]), b: (&[f64], &[f64]), lambda: f64) {
        // Two pointers over the segments with their *remaining* durations (not cumulative
        // times): the merged durations of short high-jerk segments stay exact even deep into
        // a long profile.
        let ((at, aj), (bt, bj)) = (a, b);
        let (an, bn) = (at.len().min(aj.len()), bt.len().min(bj.len()));
        let mu = 1.0 - lambda;
        let (mut i, mut k) = (0, 0);
        let (mut ra, mut rb) = (
            if an > 0 { at[0] } else { 0.0 },
            if bn > 0 { bt[0] } else { 0.0 },
        );
        while i < an && k < bn {
            let dt = ra.min(rb);
            self.push(dt, lambda * aj[i] + mu * bj[k]);
            if ra <= dt {
                i += 1;
                ra = if i < an { at[i] } else { 0.0 };
            } else {
                ra -= dt;
            }
            if rb <= dt {
                k += 1;
                rb = if k < bn { bt[k] } else { 0.0 };
            } else {
                rb -= dt;
            }
        }
        // The longer list's tail (the other's jerk is 0 there).
        while i < an {
            self.push(ra, lambda * aj[i] + mu * 0.0);
            i += 1;
            ra = if i < an { at[i] } else { 0.0 };
        }
        while k < bn {
            self.push(rb, lambda * 0.0 + mu * bj[k]);
            k += 1;
            rb = if k < bn { bt[k] } else { 0.0 };
        }
    }

    /// The profile with every state and jerk multiplied by `k` (start state included).
    pub fn scaled(&self, k: f64) -> Profile {
        let s = self.start;
        let mut r = Profile::new(State::new(s.p * k, s.v * k, s.a * k));
        for i in 0..self.n {
            r.push(self.ts()[i], self.js()[i] * k);
        }
        r
    }

    /// Same profile with the start position replaced by `p0` (positions shifted).
    pub fn with_start_position(&self, p0: f64) -> Profile {
        let s = self.start;
        let mut r = Profile::new(State::new(p0, s.v, s.a));
        for i in 0..self.n {
            r.push(self.ts()[i], self.js()[i]);
        }
        r
    }

    /// The mirrored profile (all states and jerks negated).
    pub fn neg(&self) -> Profile {
        self.scaled(-1.0)
    }
}

/// Integrates constant-jerk segments (`durations` s, `jerks` u/s^3) from `start` and checks the
/// limits on the way (segment ends and interior velocity extrema, widened by `rel` times the limit
/// magnitudes; `check_velocity = false` checks the acceleration only). Returns the final state, or
/// None if a limit is violated. No profile is built (used by the shape solvers' validation).
///
/// A start velocity outside the limits (left by a brake pre-trajectory) is tolerated until the
/// velocity first enters the limits, as long as it stays on the side of the start and does not
/// move further out.
pub fn integrate_checked(
    start: State,
    durations: &[f64],
    jerks: &[f64],
    lim: &Limits,
    rel: f64,
    check_velocity: bool,
) -> Option<State> {
    let tv = rel * lim.vmax.abs().max(lim.vmin.abs());
    let ta = rel * lim.amax.abs().max(lim.amin.abs());
    let (vhi, vlo, ahi, alo) = (lim.vmax + tv, lim.vmin - tv, lim.amax + ta, lim.amin - ta);
    if !check_velocity || (start.v <= vhi && start.v >= vlo) {
        // Common case: the start is within the limits; plain checks at every phase end and
        // velocity extremum (the same checks as the general loop below).
        if !(start.a <= ahi && start.a >= alo) {
            return None;
        }
        let mut s = start;
        for (&d, &j) in durations.iter().zip(jerks) {
            if d <= 0.0 {
                continue;
            }
            if j != 0.0 && check_velocity && s.a * (s.a + j * d) < 0.0 {
                let tc = -s.a / j;
                if tc > 0.0 && tc < d {
                    let v = s.integrate(tc, j).v;
                    if !(v <= vhi && v >= vlo) {
                        return None;
                    }
                }
            }
            s = s.integrate(d, j);
            if !(s.a <= ahi && s.a >= alo) || (check_velocity && !(s.v <= vhi && s.v >= vlo)) {
                return None;
            }
        }
        return Some(s);
    }
    let vin = |v: f64| v <= lim.vmax + tv && v >= lim.vmin - tv;
    let aok = |a: f64| a <= lim.amax + ta && a >= lim.amin - ta;
    let v_start = start.v;
    let mut entered = !check_velocity || vin(v_start);
    let mut vok = |v: f64| {
        if !check_velocity {
            return true;
        }
        if entered {
            return vin(v);
        }
        if vin(v) {
            entered = true;
            return true;
        }
        if v_start > lim.vmax {
            v > lim.vmax && v <= v_start + tv
        } else {
            v < lim.vmin && v >= v_start - tv
        }
    };
    if !(aok(start.a) && vok(start.v)) {
        return None;
    }
    let mut s = start;
    for (&d, &j) in durations.iter().zip(jerks) {
        if d <= 0.0 {
            continue;
        }
        // Interior velocity extremum where the acceleration changes sign (at -a/j).
        if j != 0.0 && check_velocity && s.a * (s.a + j * d) < 0.0 {
            let tc = -s.a / j;
            if tc > 0.0 && tc < d && !vok(s.integrate(tc, j).v) {
                return None;
            }
        }
        s = s.integrate(d, j);
        if !(aok(s.a) && vok(s.v)) {
            return None;
        }
    }
    Some(s)
}

/// [`integrate_checked`] for a fixed number of phases (the shape solvers' seven), inlined so
/// that the loop is unrolled with the jerk pattern known; the same checks and results.
#[inline(always)]
pub(crate) fn integrate_checked_fixed<const N: usize>(
    start: State,
    durations: &[f64; N],
    jerks: &[f64; N],
    lim: &Limits,
    rel: f64,
    check_velocity: bool,
) -> Option<State> {
    let tv = rel * lim.vmax.abs().max(lim.vmin.abs());
    let ta = rel * lim.amax.abs().max(lim.amin.abs());
    let (vhi, vlo, ahi, alo) = (lim.vmax + tv, lim.vmin - tv, lim.amax + ta, lim.amin - ta);
    if check_velocity && !(start.v <= vhi && start.v >= vlo) {
        // Start outside the velocity limits (after a brake): the general routine.
        return integrate_checked(start, durations, jerks, lim, rel, check_velocity);
    }
    if !(start.a <= ahi && start.a >= alo) {
        return None;
    }
    let mut s = start;
    for i in 0..N {
        let (d, j) = (durations[i], jerks[i]);
        if d <= 0.0 {
            continue;
        }
        if j != 0.0 && check_velocity && s.a * (s.a + j * d) < 0.0 {
            let tc = -s.a / j;
            if tc > 0.0 && tc < d {
                let v = s.integrate(tc, j).v;
                if !(v <= vhi && v >= vlo) {
                    return None;
                }
            }
        }
        s = s.integrate(d, j);
        if !(s.a <= ahi && s.a >= alo) || (check_velocity && !(s.v <= vhi && s.v >= vlo)) {
            return None;
        }
    }
    Some(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integrates_segments_and_extrapolates() {
        let mut p = Profile::new(State::new(0.0, 0.0, 0.0));
        p.push(1.0, 1.0);
        p.push(1.0, -1.0);
        assert_eq!(p.len(), 2);
        let e = p.end();
        assert!((e.a).abs() < 1e-15 && (e.v - 1.0).abs() < 1e-15 && (e.p - 1.0).abs() < 1e-15);
        let (s, j) = p.at(3.0);
        assert_eq!(j, 0.0);
        assert!((s.p - 2.0).abs() < 1e-15);
        let (s, _) = p.at(0.5);
        assert!((s.a - 0.5).abs() < 1e-15);
    }

    #[test]
    fn segments_past_the_length_read_as_zero() {
        let mut p = Profile::new(State::new(1.0, 0.0, 0.0));
        assert_eq!(p.segment(0), (0.0, 0.0));
        p.push(0.5, 2.0);
        let mut q = Profile::new(State::default());
        q.copy_from(&p);
        assert_eq!(q.segment(0), (0.5, 2.0));
        assert_eq!(q.segment(1), (0.0, 0.0));
        assert_eq!(q.segment(MAX_SEGMENTS - 1), (0.0, 0.0));
        assert!(format!("{q:?}").contains("durations: [0.5]"));
    }

    #[test]
    fn blend_is_convex_combination() {
        let mut a = Profile::new(State::new(0.0, 0.0, 0.0));
        a.push(1.0, 1.0);
        a.push(2.0, -1.0);
        let mut b = Profile::new(State::new(0.0, 0.0, 0.0));
        b.push(2.5, -0.5);
        b.push(0.5, 0.3);
        let m = Profile::blend(&a, &b, 0.25);
        for k in 0..=30 {
            let t = k as f64 * 0.1;
            let (sa, _) = a.at(t);
            let (sb, _) = b.at(t);
            let (sm, _) = m.at(t);
            assert!((sm.p - (0.25 * sa.p + 0.75 * sb.p)).abs() < 1e-12);
            assert!((sm.v - (0.25 * sa.v + 0.75 * sb.v)).abs() < 1e-12);
        }
    }

    #[test]
    fn extrema_inside_segment() {
        let mut p = Profile::new(State::new(0.0, 1.0, 0.0));
        p.push(2.0, -1.0); // v = 1 - t^2/2 -> zero at sqrt(2)
        let ex = p.position_extrema();
        let t = 2f64.sqrt();
        assert!((ex.t_max - t).abs() < 1e-12);
        assert!((ex.max - (t - t * t * t / 6.0)).abs() < 1e-12);
    }
}
