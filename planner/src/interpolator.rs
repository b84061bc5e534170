//! The 20 ms interpolator: turns a queue of motion commands (a path and speed limits each) into
//! one task-space setpoint per cycle, and can stop with a jerk-limited brake on request.
//!
//! No I/O and no allocation in the cycle: the queue is a fixed ring buffer; single paths and
//! their profiles are `Copy`, composite motions ([`CompositeMotion`], planned with continuous
//! speed through smooth junctions) are boxed when pushed. Speed profiles are planned when a
//! command is pushed, so [`Interpolator::step`] only evaluates (a stop request plans one
//! velocity-interface profile of one DoF, also allocation-free).
//! Workspace and kinematic checks are not made here (they belong to the kinematics crate).

use crate::composite::CompositeMotion;
use crate::path::{Path, Pose};
use crate::profiler::{step1::Step1, ControlInterface, Limits, Profile, State};
use crate::speed::{SpeedError, SpeedLimits, SpeedProfile};

/// Interpolation period in s.
pub const CYCLE_S: f64 = 0.02;

/// Maximal number of queued motion commands.
pub const QUEUE_CAPACITY: usize = 16;

/// One motion: follow `path` from rest to rest within `limits`.
#[derive(Clone, Copy, Debug)]
pub struct MotionCommand {
    /// The path (must start where the previous motion ends).
    pub path: Path,
    /// Speed limits along the path.
    pub limits: SpeedLimits,
}

/// Why a command was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InterpolatorError {
    /// The queue is full.
    #[error("motion queue is full ({QUEUE_CAPACITY} commands)")]
    QueueFull,
    /// The path does not start at the end of the previous motion.
    #[error("path starts at {start:?}, but the previous motion ends at {expected:?}")]
    Discontinuous {
        /// Start of the rejected path.
        start: Pose,
        /// End of the previous motion.
        expected: Pose,
    },
    /// Invalid speed limits.
    #[error(transparent)]
    Speed(#[from] SpeedError),
    /// A stop is in progress; commands are accepted again once stopped.
    #[error("a stop is in progress")]
    Stopping,
}

/// What the interpolator is doing in a cycle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// No motion: holding the last pose.
    Idle,
    /// Following a queued motion.
    Moving,
    /// Braking after [`Interpolator::request_stop`].
    Stopping,
}

/// One cycle's output.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setpoint {
    /// Time since the interpolator was created, s.
    pub t: f64,
    /// Commanded pose (mm, mm, rad).
    pub pose: Pose,
    /// Commanded pose rate (mm/s, mm/s, rad/s).
    pub velocity: Pose,
    /// Path length travelled in the current motion, mm.
    pub s: f64,
    /// Speed along the path, mm/s.
    pub speed: f64,
    /// State of the interpolator.
    pub phase: Phase,
}

/// A queued or active motion: one path with its speed profile (inline, so that queueing it
/// never allocates), or a composite (boxed: it is far larger).
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
enum Motion {
    Single {
        path: Path,
        profile: SpeedProfile,
        limits: SpeedLimits,
    },
    Composite(Box<CompositeMotion>),
}

impl Motion {
    fn duration(&self) -> f64 {
        match self {
            Motion::Single { profile, .. } => profile.duration(),
            Motion::Composite(c) => c.duration(),
        }
    }

    fn length(&self) -> f64 {
        match self {
            Motion::Single { path, .. } => path.length(),
            Motion::Composite(c) => c.path().length(),
        }
    }

    fn end(&self) -> Pose {
        match self {
            Motion::Single { path, .. } => path.end(),
            Motion::Composite(c) => c.path().end(),
        }
    }

    /// Path length, speed and path acceleration at time `t` of the motion.
    fn state(&self, t: f64) -> (f64, f64, f64) {
        match self {
            Motion::Single { profile, .. } => {
                let st = profile.at(t);
                (st.p, st.v, st.a)
            }
            Motion::Composite(c) => {
                let st = c.sample(t);
                (st.s, st.speed, st.acceleration)
            }
        }
    }

    /// Pose and unit tangent (d pose / ds) at path length `s`.
    fn at_length(&self, s: f64) -> (Pose, Pose) {
        match self {
            Motion::Single { path, .. } => path.sample(s),
            Motion::Composite(c) => c.path().sample(s),
        }
    }

    /// Trapezoidal (infinite-jerk) speed model, and the motion's own jerk limit.
    fn jerk(&self) -> Option<f64> {
        match self {
            Motion::Single {
                limits: SpeedLimits::JerkLimited { jmax, .. },
                ..
            } => Some(*jmax),
            Motion::Single { .. } => None,
            Motion::Composite(c) => Some(c.limits().jmax),
        }
    }

    fn trapezoidal_deceleration(&self) -> Option<f64> {
        match self {
            Motion::Single {
                profile: SpeedProfile::Trapezoidal { a, .. },
                ..
            } => Some(*a),
            _ => None,
        }
    }
}

#[derive(Clone, Debug)]
struct Active {
    motion: Motion,
    /// Time in the motion, s.
    t: f64,
}

#[derive(Clone, Debug)]
struct Stop {
    motion: Motion,
    /// Path length at the start of the stop.
    s0: f64,
    profile: Profile,
    t: f64,
}

/// The 20 ms setpoint generator.
#[derive(Clone, Debug)]
pub struct Interpolator {
    queue: [Option<Motion>; QUEUE_CAPACITY],
    head: usize,
    len: usize,
    active: Option<Active>,
    stop: Option<Stop>,
    /// Pose held when idle, and end of the last queued motion.
    hold: Pose,
    tail: Pose,
    t: f64,
    stop_limits: Limits,
}

impl Interpolator {
    /// An idle interpolator holding `pose`. Stops use `stop_amax` (mm/s^2) and `stop_jmax`
    /// (mm/s^3) along the path (both > 0).
    pub fn new(pose: Pose, stop_amax: f64, stop_jmax: f64) -> Result<Self, SpeedError> {
        for (n, v) in [("stop_amax", stop_amax), ("stop_jmax", stop_jmax)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(SpeedError(n, v));
            }
        }
        Ok(Interpolator {
            queue: std::array::from_fn(|_| None),
            head: 0,
            len: 0,
            active: None,
            stop: None,
            hold: pose,
            tail: pose,
            t: 0.0,
            stop_limits: Limits::symmetric(f64::MAX, stop_amax, stop_jmax),
        })
    }

    /// Queues a motion (plans its speed profile). The path must start at the end of the last
    /// queued motion (or the held pose), within 1e-6 mm / rad.
    pub fn push(&mut self, cmd: MotionCommand) -> Result<(), InterpolatorError> {
        self.check_push(cmd.path.start())?;
        let profile = SpeedProfile::plan(cmd.path.length(), &cmd.limits)?;
        self.enqueue(Motion::Single {
            path: cmd.path,
            profile,
            limits: cmd.limits,
        });
        Ok(())
    }

    /// Queues a composite motion (planned already, with continuous speed through its smooth
    /// junctions; see [`CompositeMotion::plan`]). It must start at the end of the last queued
    /// motion (or the held pose). Moves the motion into a box: call between cycles.
    pub fn push_composite(&mut self, motion: CompositeMotion) -> Result<(), InterpolatorError> {
        self.check_push(motion.path().start())?;
        self.enqueue(Motion::Composite(Box::new(motion)));
        Ok(())
    }

    fn check_push(&self, start: Pose) -> Result<(), InterpolatorError> {
        if self.stop.is_some() {
            return Err(InterpolatorError::Stopping);
        }
        if self.len == QUEUE_CAPACITY {
            return Err(InterpolatorError::QueueFull);
        }
        if start.max_diff(&self.tail) > 1e-6 {
            return Err(InterpolatorError::Discontinuous {
                start,
                expected: self.tail,
            });
        }
        Ok(())
    }

    fn enqueue(&mut self, m: Motion) {
        self.tail = m.end();
        self.queue[(self.head + self.len) % QUEUE_CAPACITY] = Some(m);
        self.len += 1;
    }

    /// Number of queued motions (not counting the active one).
    pub fn queued(&self) -> usize {
        self.len
    }

    /// True if nothing is moving and nothing is queued.
    pub fn is_idle(&self) -> bool {
        self.active.is_none() && self.stop.is_none() && self.len == 0
    }

    fn pop(&mut self) -> Option<Motion> {
        if self.len == 0 {
            return None;
        }
        let item = self.queue[self.head].take();
        self.head = (self.head + 1) % QUEUE_CAPACITY;
        self.len -= 1;
        item
    }

    /// Requests a stop: the queue is cleared and the current motion brakes along its path as
    /// fast as the stop limits allow (jerk-limited for jerk-limited motions, with at least the
    /// motion's own jerk; at once for trapezoidal ones). If that brake would have to reverse
    /// (the motion is already decelerating hard) or would run past the path end, the motion's
    /// own planned deceleration to its path end is kept instead.
    pub fn request_stop(&mut self) {
        self.len = 0;
        self.head = 0;
        for q in &mut self.queue {
            *q = None;
        }
        if self.stop.is_some() {
            return;
        }
        if let Some(act) = self.active.take() {
            let (p, v, a) = act.motion.state(act.t);
            let profile = match act.motion.trapezoidal_deceleration() {
                Some(a) => {
                    // Same (infinite-jerk) model as the motion: decelerate at once.
                    let dec = self.stop_limits.amax.max(a);
                    let mut pr = Profile::new(State::new(0.0, v, -dec));
                    pr.push(v / dec, 0.0);
                    pr
                }
                None => {
                    let mut lim = self.stop_limits;
                    // Brake at least as hard as the motion itself may, and keep the current
                    // acceleration admissible.
                    if let Some(jmax) = act.motion.jerk() {
                        lim.jmax = lim.jmax.max(jmax);
                    }
                    lim.amax = lim.amax.max(a.abs());
                    lim.amin = -lim.amax;
                    Step1::solve(
                        ControlInterface::Velocity,
                        &State::new(0.0, v, a),
                        &State::new(0.0, 0.0, 0.0),
                        &lim,
                    )
                    .map(|s| s.optimal_profile())
                    .unwrap_or_else(|| Profile::new(State::default()))
                }
            };
            // A brake that would have to reverse (already decelerating hard) or would run past
            // the path end is not better than the planned deceleration: keep the motion, which
            // stops at its path end (the queue is cleared).
            let (mut vmin, mut t) = (0.0f64, 0.0);
            for i in 0..profile.len() {
                t += profile.segment(i).0;
                vmin = vmin.min(profile.at(t).0.v);
            }
            let reverses =
                vmin < -1e-9 * v.abs().max(1e-9) || profile.position_extrema().min < -1e-12;
            let overruns = p + profile.end().p > act.motion.length();
            if reverses || overruns {
                self.active = Some(act);
            } else {
                self.stop = Some(Stop {
                    motion: act.motion,
                    s0: p,
                    profile,
                    t: 0.0,
                });
            }
        }
        self.tail = if self.stop.is_some() {
            self.hold
        } else {
            self.active.as_ref().map_or(self.hold, |a| a.motion.end())
        };
    }

    /// Advances one cycle ([`CYCLE_S`]) and returns the setpoint for its end.
    pub fn step(&mut self) -> Setpoint {
        self.t += CYCLE_S;
        if let Some(mut stop) = self.stop.take() {
            stop.t += CYCLE_S;
            let (st, _) = stop.profile.at(stop.t);
            let len = stop.motion.length();
            let s = (stop.s0 + st.p).min(len);
            let done = stop.t >= stop.profile.duration();
            let v = if done || s >= len { 0.0 } else { st.v };
            let (pose, d) = stop.motion.at_length(s);
            self.hold = pose;
            self.tail = pose;
            if !done {
                self.stop = Some(stop);
            }
            return self.setpoint(
                pose,
                d,
                s,
                v,
                if done { Phase::Idle } else { Phase::Stopping },
            );
        }
        // Carry the time left over from a finished motion into the next one.
        let mut carry = CYCLE_S;
        loop {
            let mut act = match self.active.take() {
                Some(a) => a,
                None => match self.pop() {
                    Some(motion) => Active { motion, t: 0.0 },
                    None => {
                        return self.setpoint(self.hold, Pose::default(), 0.0, 0.0, Phase::Idle);
                    }
                },
            };
            let dur = act.motion.duration();
            if act.t + carry < dur {
                act.t += carry;
                let (p, v, _) = act.motion.state(act.t);
                let (pose, d) = act.motion.at_length(p);
                self.hold = pose;
                self.active = Some(act);
                return self.setpoint(pose, d, p, v, Phase::Moving);
            }
            carry -= dur - act.t;
            self.hold = act.motion.end();
            if self.len == 0 {
                let len = act.motion.length();
                return self.setpoint(self.hold, Pose::default(), len, 0.0, Phase::Idle);
            }
        }
    }

    fn setpoint(&self, pose: Pose, d: Pose, s: f64, speed: f64, phase: Phase) -> Setpoint {
        Setpoint {
            t: self.t,
            pose,
            velocity: Pose::new(d.x * speed, d.y * speed, d.phi * speed),
            s,
            speed,
            phase,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn jl() -> SpeedLimits {
        SpeedLimits::JerkLimited {
            vmax: 20.0,
            amax: 50.0,
            jmax: 500.0,
        }
    }

    #[test]
    fn follows_queue_to_the_end() {
        let start = Pose::new(0.0, 0.0, 0.0);
        let mut ip = Interpolator::new(start, 100.0, 1000.0).unwrap();
        let line = Path::line(start, Pose::new(10.0, 0.0, 0.0)).unwrap();
        let arc = Path::arc(10.0, 5.0, 5.0, -std::f64::consts::FRAC_PI_2, 3.0, 0.0, 0.2).unwrap();
        ip.push(MotionCommand {
            path: line,
            limits: jl(),
        })
        .unwrap();
        ip.push(MotionCommand {
            path: arc,
            limits: SpeedLimits::Trapezoidal {
                vmax: 10.0,
                amax: 40.0,
            },
        })
        .unwrap();
        let total = SpeedProfile::plan(line.length(), &jl()).unwrap().duration()
            + SpeedProfile::plan(
                arc.length(),
                &SpeedLimits::Trapezoidal {
                    vmax: 10.0,
                    amax: 40.0,
                },
            )
            .unwrap()
            .duration();
        let mut last = start;
        let mut n = 0;
        loop {
            let sp = ip.step();
            n += 1;
            // Never faster than the larger cruise speed (combined metric >= xy distance).
            let dxy = ((sp.pose.x - last.x).powi(2) + (sp.pose.y - last.y).powi(2)).sqrt();
            assert!(
                dxy <= 20.0 * CYCLE_S * (1.0 + 1e-9),
                "jump {dxy} at {}",
                sp.t
            );
            last = sp.pose;
            if sp.phase == Phase::Idle {
                break;
            }
            assert!(n < 100_000);
        }
        assert_eq!(n, (total / CYCLE_S).ceil() as usize);
        assert!(last.max_diff(&arc.end()) < 1e-9);
        assert!(ip.is_idle());
        // Idle: holds.
        assert_eq!(ip.step().pose, last);
    }

    #[test]
    fn rejects_discontinuous_paths() {
        let mut ip = Interpolator::new(Pose::default(), 1.0, 1.0).unwrap();
        let bad = Path::line(Pose::new(1.0, 0.0, 0.0), Pose::new(2.0, 0.0, 0.0)).unwrap();
        assert!(matches!(
            ip.push(MotionCommand {
                path: bad,
                limits: jl()
            }),
            Err(InterpolatorError::Discontinuous { .. })
        ));
    }

    #[test]
    fn stop_request_brakes_smoothly_on_the_path() {
        let start = Pose::new(0.0, 0.0, 0.0);
        let mut ip = Interpolator::new(start, 50.0, 500.0).unwrap();
        let line = Path::line(start, Pose::new(100.0, 0.0, 0.0)).unwrap();
        for _ in 0..2 {
            ip.push(MotionCommand {
                path: if ip.queued() == 0 {
                    line
                } else {
                    Path::line(line.end(), start).unwrap()
                },
                limits: jl(),
            })
            .unwrap();
        }
        for _ in 0..100 {
            ip.step();
        }
        let before = ip.step();
        assert_eq!(before.phase, Phase::Moving);
        assert!((before.speed - 20.0).abs() < 1e-9);
        ip.request_stop();
        assert_eq!(ip.queued(), 0);
        let mut prev_speed = before.speed;
        let mut prev_a = 0.0;
        let mut steps = 0;
        loop {
            let sp = ip.step();
            steps += 1;
            assert!(sp.pose.y.abs() < 1e-12 && sp.pose.x <= 100.0);
            let a = (sp.speed - prev_speed) / CYCLE_S;
            assert!((-50.0 * (1.0 + 1e-9)..=1e-9).contains(&a), "decel {a}");
            assert!((a - prev_a).abs() / CYCLE_S <= 500.0 * (1.0 + 1e-6) + 1e-6);
            prev_speed = sp.speed;
            prev_a = a;
            if sp.phase == Phase::Idle {
                break;
            }
        }
        // 20 mm/s with 50 mm/s^2 and 500 mm/s^3: 0.5 s (+ 2 jerk phases of 0.1 s).
        assert!(steps <= 31, "{steps}");
        assert!(ip.is_idle());
        // New commands start where it stopped.
        let here = ip.step().pose;
        let back = Path::line(here, start).unwrap();
        ip.push(MotionCommand {
            path: back,
            limits: jl(),
        })
        .unwrap();
    }

    #[test]
    fn random_commands_and_stops_stay_smooth() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..20 {
            let mut ip = Interpolator::new(Pose::default(), 80.0, 800.0).unwrap();
            let mut here = Pose::default();
            let vmax = 15.0;
            for _ in 0..4 {
                let path = match rng.random_range(0..3) {
                    0 => {
                        let to = Pose::new(
                            rng.random_range(-20.0..20.0),
                            rng.random_range(-20.0..20.0),
                            rng.random_range(-0.3..0.3),
                        );
                        Path::line(here, to).unwrap()
                    }
                    1 => {
                        let r = rng.random_range(2.0..10.0);
                        let th: f64 = rng.random_range(-3.0..3.0);
                        let (cx, cy) = (here.x - r * th.cos(), here.y - r * th.sin());
                        let sweep = rng.random_range(-4.0..4.0);
                        Path::arc(cx, cy, r, th, sweep, here.phi, here.phi + 0.1).unwrap()
                    }
                    _ => Path::rectangle(here, 5.0, 3.0, rng.random_range(0.0..1.0)).unwrap(),
                };
                let limits = if rng.random_bool(0.5) {
                    SpeedLimits::JerkLimited {
                        vmax,
                        amax: 60.0,
                        jmax: 600.0,
                    }
                } else {
                    SpeedLimits::Trapezoidal { vmax, amax: 60.0 }
                };
                ip.push(MotionCommand { path, limits }).unwrap();
                here = path.end();
            }
            let stop_at = rng.random_range(10..400);
            let mut last = Pose::default();
            let mut stopped = false;
            for k in 0..20_000 {
                if k == stop_at {
                    ip.request_stop();
                    stopped = true;
                }
                let sp = ip.step();
                assert!(
                    sp.speed <= vmax * (1.0 + 1e-9) && sp.speed >= -1e-9,
                    "speed {} phase {:?} k {k} stop {stop_at}",
                    sp.speed,
                    sp.phase
                );
                let d = ((sp.pose.x - last.x).powi(2)
                    + (sp.pose.y - last.y).powi(2)
                    + (50.0 * (sp.pose.phi - last.phi)).powi(2))
                .sqrt();
                assert!(d <= vmax * CYCLE_S * (1.0 + 1e-9) + 1e-9, "jump {d}");
                last = sp.pose;
                if sp.phase == Phase::Idle && (stopped || ip.is_idle()) && k > stop_at {
                    break;
                }
            }
            assert!(ip.is_idle());
            if !stopped {
                assert!(last.max_diff(&here) < 1e-9);
            }
        }
    }
}
