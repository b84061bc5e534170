//! Time-optimal, jerk-limited trajectory profiler ("ruckig-style", written from the mathematics
//! of Berscheid & Kröger, RSS 2021).
//!
//! * [`calculate`] turns an [`Input`] (current and target states, limits, interface,
//!   synchronisation, minimum duration) into a [`Trajectory`].
//! * Per DoF ([`step1`]): a brake pre-trajectory if the current state violates the limits,
//!   then all extremal 7-phase shapes (UDDU / DUUD with acceleration and velocity plateaus) that
//!   reach the target; the shortest is time-optimal, and the gaps between them that are not
//!   feasible are blocked intervals.
//! * Synchronisation ([`step2`]): the smallest duration feasible for every DoF; each DoF then
//!   gets a profile of exactly that duration.
//!
//! No heap allocation anywhere: all buffers are fixed arrays (at most [`MAX_DOFS`] DoFs).

pub mod brake;
pub mod error;
pub mod limits;
pub mod poly;
pub mod profile;
pub mod shapes;
pub mod step1;
pub mod step2;
pub mod velocity;

pub use error::ProfileError;
pub use limits::{Limits, State};
pub use profile::{PositionExtrema, Profile};
pub use step1::Step1;

use std::mem::MaybeUninit;

/// Maximal number of degrees of freedom of one [`Input`].
pub const MAX_DOFS: usize = 8;

/// What the target prescribes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ControlInterface {
    /// Target position, velocity and acceleration.
    #[default]
    Position,
    /// Target velocity and acceleration only (velocity limits are not applied).
    Velocity,
}

/// How the DoFs are synchronised.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Synchronization {
    /// All DoFs reach their targets at the same time.
    #[default]
    Time,
    /// Same duration, and if the motion is a straight line in joint space (all start and target
    /// differences collinear) every DoF follows a scaled copy of the limiting DoF's profile;
    /// otherwise as [`Synchronization::Time`].
    Phase,
    /// Every DoF is time-optimal on its own; it continues with constant acceleration after
    /// reaching its target. The total duration is the longest one (at least the minimum
    /// duration).
    None,
}

/// A profiling request for up to [`MAX_DOFS`] DoFs.
#[derive(Clone, Copy, Debug)]
pub struct Input {
    /// Number of DoFs used (1 ..= MAX_DOFS).
    pub dofs: usize,
    /// Current states.
    pub current: [State; MAX_DOFS],
    /// Target states.
    pub target: [State; MAX_DOFS],
    /// Limits per DoF.
    pub limits: [Limits; MAX_DOFS],
    /// Control interface.
    pub control_interface: ControlInterface,
    /// Synchronisation.
    pub synchronization: Synchronization,
    /// Minimum duration in s (time and phase synchronisation).
    pub minimum_duration: Option<f64>,
}

impl Input {
    /// A request for `dofs` DoFs at rest at 0 with unit limits (to be filled in).
    pub fn new(dofs: usize) -> Self {
        Input {
            dofs,
            current: [State::default(); MAX_DOFS],
            target: [State::default(); MAX_DOFS],
            limits: [Limits::symmetric(1.0, 1.0, 1.0); MAX_DOFS],
            control_interface: ControlInterface::Position,
            synchronization: Synchronization::Time,
            minimum_duration: None,
        }
    }

    /// Checks the request: DoF count, finite numbers, limit signs, target within the limits.
    pub fn validate(&self) -> Result<(), ProfileError> {
        if self.dofs == 0 || self.dofs > MAX_DOFS {
            return Err(ProfileError::DofMismatch {
                what: "dofs",
                got: self.dofs,
                expected: self.dofs.clamp(1, MAX_DOFS),
                max: MAX_DOFS,
            });
        }
        if let Some(md) = self.minimum_duration {
            if !md.is_finite() || md < 0.0 {
                return Err(ProfileError::BadMinimumDuration(md));
            }
        }
        for i in 0..self.dofs {
            let lim = &self.limits[i];
            let (c, t) = (&self.current[i], &self.target[i]);
            // Fast path: everything finite and the limit signs right (then the detailed
            // checks below cannot fail); otherwise they name the first problem.
            let sane = (c.p + c.v + c.a + t.p + t.v + t.a).is_finite()
                && lim.vmax > 0.0
                && lim.vmin < 0.0
                && lim.amax > 0.0
                && lim.amin < 0.0
                && lim.jmax > 0.0
                && (lim.vmax - lim.vmin + lim.amax - lim.amin + lim.jmax).is_finite();
            if !sane {
                limits::validate_state(c, "current", i)?;
                limits::validate_state(t, "target", i)?;
                lim.validate(i)?;
            }
            let t = &self.target[i];
            if self.control_interface == ControlInterface::Position
                && (t.v > lim.vmax || t.v < lim.vmin)
            {
                return Err(ProfileError::TargetOutsideLimits {
                    what: "velocity",
                    dof: i,
                    value: t.v,
                    min: lim.vmin,
                    max: lim.vmax,
                });
            }
            if t.a > lim.amax || t.a < lim.amin {
                return Err(ProfileError::TargetOutsideLimits {
                    what: "acceleration",
                    dof: i,
                    value: t.a,
                    min: lim.amin,
                    max: lim.amax,
                });
            }
            if self.control_interface == ControlInterface::Position {
                let reached = t.v - t.a * t.a.abs() / (2.0 * lim.jmax);
                let tol = 1e-12 * lim.vmax.abs().max(lim.vmin.abs());
                if reached > lim.vmax + tol || reached < lim.vmin - tol {
                    return Err(ProfileError::TargetUnreachable {
                        dof: i,
                        v: t.v,
                        a: t.a,
                        reached,
                        min: lim.vmin,
                        max: lim.vmax,
                    });
                }
            }
        }
        Ok(())
    }
}

/// A multi-DoF trajectory: one [`Profile`] per DoF and the common duration.
#[derive(Clone, Copy, Debug)]
pub struct Trajectory {
    dofs: usize,
    duration: f64,
    profiles: [Profile; MAX_DOFS],
}

impl Trajectory {
    /// Number of DoFs.
    pub fn dofs(&self) -> usize {
        self.dofs
    }

    /// Total duration in s.
    pub fn duration(&self) -> f64 {
        self.duration
    }

    /// The profile of DoF `dof`.
    pub fn profile(&self, dof: usize) -> &Profile {
        &self.profiles[dof]
    }

    /// State and jerk of DoF `dof` at time `t` (s). Past the duration each DoF continues with
    /// constant acceleration.
    pub fn at_dof(&self, dof: usize, t: f64) -> (State, f64) {
        self.profiles[dof].at(t)
    }

    /// States of all DoFs at time `t` (s), written into `out[..dofs]`.
    pub fn at(&self, t: f64, out: &mut [State]) {
        for (o, p) in out.iter_mut().zip(&self.profiles[..self.dofs]) {
            *o = p.at(t).0;
        }
    }

    /// Position extrema of DoF `dof` over the trajectory.
    pub fn position_extrema(&self, dof: usize) -> PositionExtrema {
        self.profiles[dof].position_extrema()
    }
}

/// Computes the time-optimal (synchronised) trajectory for `input`.
pub fn calculate(input: &Input) -> Result<Trajectory, ProfileError> {
    // The trajectory (several kB) is filled in place in the return value rather than
    // assembled and moved.
    let mut res = Ok(Trajectory {
        dofs: input.dofs,
        duration: 0.0,
        profiles: [Profile::new(State::default()); MAX_DOFS],
    });
    if let Ok(traj) = &mut res {
        if let Err(e) = calculate_into(input, traj) {
            res = Err(e);
        }
    }
    res
}

/// [`calculate`] into `traj` (whose `dofs` is set, profiles overwritten).
fn calculate_into(input: &Input, traj: &mut Trajectory) -> Result<(), ProfileError> {
    input.validate()?;
    let n = input.dofs;
    // Step 1 results are large (a brake profile and the candidate shapes); they are written in
    // place instead of copying a filled array.
    let mut st = [MaybeUninit::<Step1>::uninit(); MAX_DOFS];
    for (i, s) in st.iter_mut().enumerate().take(n) {
        let (c, t, l) = (&input.current[i], &input.target[i], &input.limits[i]);
        if !Step1::solve_into(s, input.control_interface, c, t, l) {
            return Err(ProfileError::NoSolution { dof: i });
        }
    }
    // SAFETY: the first `n` entries were initialised above (the loop returns early otherwise);
    // `MaybeUninit<Step1>` has the layout of `Step1`.
    let steps: &[Step1] = unsafe { std::slice::from_raw_parts(st.as_ptr().cast::<Step1>(), n) };
    let profiles = &mut traj.profiles;
    if input.synchronization == Synchronization::None || n == 1 && input.minimum_duration.is_none()
    {
        // As ruckig: with no synchronisation the minimum duration only extends the total.
        let mut duration: f64 = input.minimum_duration.unwrap_or(0.0);
        for i in 0..n {
            profiles[i] = steps[i].optimal_profile();
            duration = duration.max(profiles[i].duration());
        }
        traj.duration = duration;
        return Ok(());
    }
    let t_lower = steps
        .iter()
        .map(|s| s.t_min())
        .fold(input.minimum_duration.unwrap_or(0.0), f64::max);
    // The lower bound is the first synchronisation candidate and usually feasible for every
    // DoF: build the profiles directly (one fixed-duration solve per DoF instead of a
    // feasibility test followed by the same solve).
    let all_ok = (0..n).all(|i| steps[i].profile_at_checked_into(t_lower, &mut profiles[i]));
    let t_sync = if all_ok {
        t_lower
    } else {
        let t_sync =
            step2::synchronized_duration(steps, t_lower).ok_or(ProfileError::NoSynchronization)?;
        for i in 0..n {
            if !steps[i].profile_at_into(t_sync, &mut profiles[i]) {
                return Err(ProfileError::NoSolution { dof: i });
            }
        }
        t_sync
    };
    if input.synchronization == Synchronization::Phase {
        phase_synchronize(input, steps, t_sync, &mut profiles[..]);
    }
    traj.duration = t_sync;
    Ok(())
}

/// Replaces the profiles by scaled copies of the limiting DoF's profile if the motion is
/// collinear in joint space and the copies respect every limit.
fn phase_synchronize(input: &Input, steps: &[Step1], t_sync: f64, profiles: &mut [Profile]) {
    let n = input.dofs;
    if steps.iter().any(|s| !s.brake.is_empty()) {
        return;
    }
    // Direction vector components per DoF: (dp, v0, a0, vf, af).
    let comp = |i: usize| {
        let (c, t) = (&input.current[i], &input.target[i]);
        [t.p - c.p, c.v, c.a, t.v, t.a]
    };
    // Limiting DoF: the one with the largest minimal duration.
    let lim_dof = (0..n)
        .max_by(|&a, &b| steps[a].t_min().total_cmp(&steps[b].t_min()))
        .unwrap_or(0);
    let base = comp(lim_dof);
    let k_ref = (0..5)
        .max_by(|&a, &b| base[a].abs().total_cmp(&base[b].abs()))
        .unwrap_or(0);
    if base[k_ref] == 0.0 {
        return;
    }
    let mut scale = [0.0; MAX_DOFS];
    for (i, sc) in scale.iter_mut().enumerate().take(n) {
        let ci = comp(i);
        let k = ci[k_ref] / base[k_ref];
        for m in 0..5 {
            if (ci[m] - k * base[m]).abs() > 1e-12 * ci[m].abs().max(base[m].abs()).max(1.0) {
                return;
            }
        }
        *sc = k;
    }
    let base_profile = profiles[lim_dof];
    if (base_profile.duration() - t_sync).abs() > 1e-12 * t_sync.max(1.0) {
        return;
    }
    let mut out = [Profile::new(State::default()); MAX_DOFS];
    for i in 0..n {
        out[i] = base_profile
            .scaled(scale[i])
            .with_start_position(input.current[i].p);
        if !out[i].within_limits(&input.limits[i], 1e-12) {
            return;
        }
    }
    profiles[..n].copy_from_slice(&out[..n]);
}
