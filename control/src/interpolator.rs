//! The interpolator step: runs a [`SetpointSource`] on the chain's clock, with pause, resume and
//! stop, and emits one [`TaskSetpoint`] per cycle. It is the stack's one interpolator: the
//! `pcr-planner` process and the in-process runtime step it on the chain's clock, `pcr plan`
//! on a simulated one ([`crate::offline`]).

use crate::setpoint::{paper_circle, paper_program, paper_square, Move, PlanError, SetpointSource};
use pcr_kinematics::Pose;
use pcr_messages::{
    command_kind, move_flags, move_kind, planner_state, program_id, task_flags, Command,
    Correction, MoveMsg, PlannerStatus, ProgramLimits, TaskSetpoint, MAX_MOVES, PROTOCOL_VERSION,
};
use pcr_planner::profiler::{calculate, ControlInterface, Input, Limits, State, Trajectory};
use pcr_planner::program::{JointSettings, PathLimits};

/// Why a command was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommandError {
    /// The program could not be planned.
    #[error("program refused: {0}")]
    Plan(#[from] PlanError),
    /// Unknown command kind, program id or move kind.
    #[error("malformed command: {0}")]
    Malformed(String),
    /// The command was sent by another protocol version.
    #[error("command of protocol v{0} refused")]
    Version(u32),
    /// A program is running or paused.
    #[error("run {0} is in progress: stop it first")]
    Busy(u32),
    /// The program was planned from a pose the interpolator no longer holds.
    #[error("program planned from a pose {0:.3e} away from the held pose: plan again")]
    Stale(f64),
}

/// A program planned away from the cycle (by [`prepare_run`], e.g. on a worker thread), ready
/// for [`InterpolatorStep::install`].
#[derive(Debug, Clone)]
pub struct PreparedRun<S> {
    source: S,
    duration_s: f64,
    run_id: u32,
    start: Pose,
    /// RECOVER: program time to continue at (paused), and the pose there.
    resume: Option<(f64, Pose)>,
}

impl<S> PreparedRun<S> {
    /// The run's id.
    pub fn run_id(&self) -> u32 {
        self.run_id
    }

    /// The program's duration, s.
    pub fn duration_s(&self) -> f64 {
        self.duration_s
    }

    /// The planned source (to drop it somewhere else than the cycle).
    pub fn into_source(self) -> S {
        self.source
    }
}

/// Plans the program of a RUN command from `start` on `source` (which may allocate and take
/// milliseconds: the checks sample the whole program finely). Meant to run off the real-time
/// cycle; the result is installed with [`InterpolatorStep::install`].
pub fn prepare_run<S: SetpointSource>(
    mut source: S,
    cmd: &Command,
    start: Pose,
) -> Result<PreparedRun<S>, CommandError> {
    if cmd.version != PROTOCOL_VERSION {
        return Err(CommandError::Version(cmd.version));
    }
    let recover = match cmd.kind {
        command_kind::RUN => false,
        command_kind::RECOVER => true,
        k => {
            return Err(CommandError::Malformed(format!(
                "command kind {k} is neither RUN nor RECOVER"
            )))
        }
    };
    let moves = moves_of(cmd)?;
    let start = if recover {
        let o = cmd.origin;
        Pose::new(o[0], o[1], o[2])
    } else {
        start
    };
    let duration_s = source.load(&moves, start)?;
    let resume = if recover {
        Some(find_resume_time(&source, duration_s, cmd)?)
    } else {
        None
    };
    Ok(PreparedRun {
        source,
        duration_s,
        run_id: cmd.run_id,
        start,
        resume,
    })
}

/// How far the executed pose may be from the re-planned program for a recovery, mm (rad x 100).
pub const RECOVER_TOLERANCE_MM: f64 = 0.5;

/// The program time near `cmd.resume_s` whose planned pose is `cmd.executed` (a recovery).
fn find_resume_time<S: SetpointSource>(
    source: &S,
    duration_s: f64,
    cmd: &Command,
) -> Result<(f64, Pose), CommandError> {
    let e = Pose::new(cmd.executed[0], cmd.executed[1], cmd.executed[2]);
    let dist = |tau: f64| {
        let p = source.sample(tau);
        (p.x - e.x).hypot(p.y - e.y) + 100.0 * (p.phi - e.phi).abs()
    };
    if !cmd.resume_s.is_finite() || cmd.executed.iter().any(|v| !v.is_finite()) {
        return Err(CommandError::Malformed(
            "recovery hint is not finite".into(),
        ));
    }
    // The status reports the program time every heartbeat, ahead of or behind the executed
    // setpoint by a few cycles: search +-2 s around the hint at 1 ms, then refine.
    let (lo, hi) = (
        (cmd.resume_s - 2.0).max(0.0),
        (cmd.resume_s + 2.0).min(duration_s),
    );
    let mut best = (f64::INFINITY, lo);
    let n = ((hi - lo) / 1e-3).ceil().max(1.0) as usize;
    for k in 0..=n {
        let tau = (lo + (hi - lo) * k as f64 / n as f64).min(hi);
        let d = dist(tau);
        // on ties (holds) prefer the time nearest the hint
        if d < best.0 - 1e-12
            || (d <= best.0 + 1e-12 && (tau - cmd.resume_s).abs() < (best.1 - cmd.resume_s).abs())
        {
            best = (d, tau);
        }
    }
    // golden-section refinement within one grid step
    let (mut a, mut b) = ((best.1 - 1e-3).max(lo), (best.1 + 1e-3).min(hi));
    for _ in 0..40 {
        let (m1, m2) = (a + 0.382 * (b - a), a + 0.618 * (b - a));
        if dist(m1) < dist(m2) {
            b = m2;
        } else {
            a = m1;
        }
    }
    let tau = if dist(0.5 * (a + b)) < best.0 {
        0.5 * (a + b)
    } else {
        best.1
    };
    let d = dist(tau);
    if d > RECOVER_TOLERANCE_MM {
        return Err(CommandError::Malformed(format!(
            "the executed pose is {d:.3} mm from the re-planned program near {:.2} s:              cannot recover",
            cmd.resume_s
        )));
    }
    Ok((tau, source.sample(tau)))
}

/// Converts a wire command's program into moves (allocates; between cycles only).
pub fn moves_of(cmd: &Command) -> Result<Vec<Move>, CommandError> {
    match cmd.program {
        program_id::PAPER => Ok(paper_program()),
        program_id::CIRCLE => Ok(paper_circle()),
        program_id::SQUARE => Ok(paper_square()),
        program_id::MOVES => {
            let n = cmd.n_moves as usize;
            if n == 0 || n > MAX_MOVES {
                return Err(CommandError::Malformed(format!("n_moves = {n}")));
            }
            cmd.moves[..n]
                .iter()
                .map(|m| move_of(m, &cmd.limits))
                .collect()
        }
        p => Err(CommandError::Malformed(format!("unknown program id {p}"))),
    }
}

fn move_of(m: &MoveMsg, l: &ProgramLimits) -> Result<Move, CommandError> {
    let limits = PathLimits {
        speed: l.speed_mm_s,
        acceleration: l.accel_mm_s2,
        jerk: l.jerk_mm_s3,
        blend_radius: l.blend_radius_mm,
        rotation_radius: l.rotation_radius_mm,
    };
    let phi = (m.flags & move_flags::KEEP_PHI == 0).then_some(m.a[2]);
    let speed_mm_s = (m.b[0] != 0.0).then_some(m.b[0]);
    let continues = m.flags & move_flags::CONTINUES != 0;
    Ok(match m.kind {
        move_kind::LINE => Move::Line {
            to: Pose::new(m.a[0], m.a[1], m.a[2]),
            speed_mm_s: m.b[0],
        },
        move_kind::CIRCLE => Move::Circle {
            centre: [m.a[0], m.a[1]],
            phi: m.a[2],
            radius_mm: m.b[0],
            speed_mm_s: m.b[1],
        },
        move_kind::DWELL => Move::Dwell { duration_s: m.b[0] },
        move_kind::PATH_LINE => Move::PathLine {
            to: [m.a[0], m.a[1]],
            phi,
            speed_mm_s,
            blend_radius_mm: (m.b[1] >= 0.0).then_some(m.b[1]),
            continues,
            limits,
        },
        move_kind::ARC => Move::Arc {
            centre: [m.a[0], m.a[1]],
            sweep_rad: m.b[1],
            phi,
            speed_mm_s,
            continues,
            limits,
        },
        move_kind::JOINT => {
            let mut steps = [0i64; 3];
            for (s, &a) in steps.iter_mut().zip(&m.a) {
                if !(a.is_finite() && a.fract() == 0.0 && a.abs() < 1e15) {
                    return Err(CommandError::Malformed(format!(
                        "joint move target {a} is not an integer number of steps"
                    )));
                }
                *s = a as i64;
            }
            Move::Joint {
                steps,
                limits: JointSettings {
                    acceleration: l.joint_accel,
                    jerk: l.joint_jerk,
                },
            }
        }
        k => return Err(CommandError::Malformed(format!("unknown move kind {k}"))),
    })
}

/// Converts moves into the wire form (at most [`MAX_MOVES`]). All composite-path moves must
/// share one set of path limits and all joint moves one set of joint limits (one
/// [`Command::limits`]).
pub fn command_of_moves(run_id: u32, moves: &[Move]) -> Result<Command, CommandError> {
    if moves.is_empty() || moves.len() > MAX_MOVES {
        return Err(CommandError::Malformed(format!(
            "{} moves (1..={MAX_MOVES} allowed in one command)",
            moves.len()
        )));
    }
    let mut path: Option<PathLimits> = None;
    let mut joint: Option<JointSettings> = None;
    for m in moves {
        match *m {
            Move::PathLine { limits, .. } | Move::Arc { limits, .. } => {
                if path.is_some_and(|p| p != limits) {
                    return Err(CommandError::Malformed(
                        "composite moves with different path limits in one command".into(),
                    ));
                }
                path = Some(limits);
            }
            Move::Joint { limits, .. } => {
                if joint.is_some_and(|j| j != limits) {
                    return Err(CommandError::Malformed(
                        "joint moves with different joint limits in one command".into(),
                    ));
                }
                joint = Some(limits);
            }
            _ => {}
        }
    }
    let mut c = Command {
        kind: command_kind::RUN,
        program: program_id::MOVES,
        run_id,
        n_moves: moves.len() as u32,
        version: PROTOCOL_VERSION,
        ..Default::default()
    };
    if let Some(p) = path {
        c.limits.speed_mm_s = p.speed;
        c.limits.accel_mm_s2 = p.acceleration;
        c.limits.jerk_mm_s3 = p.jerk;
        c.limits.blend_radius_mm = p.blend_radius;
        c.limits.rotation_radius_mm = p.rotation_radius;
    }
    if let Some(j) = joint {
        c.limits.joint_accel = j.acceleration;
        c.limits.joint_jerk = j.jerk;
    }
    let flags = |continues: bool, phi: Option<f64>| {
        (if continues { move_flags::CONTINUES } else { 0 })
            | (if phi.is_none() {
                move_flags::KEEP_PHI
            } else {
                0
            })
    };
    for (w, m) in c.moves.iter_mut().zip(moves) {
        *w = match *m {
            Move::Line { to, speed_mm_s } => MoveMsg {
                kind: move_kind::LINE,
                a: to.to_array(),
                b: [speed_mm_s, 0.0],
                ..Default::default()
            },
            Move::Circle {
                centre,
                radius_mm,
                speed_mm_s,
                phi,
            } => MoveMsg {
                kind: move_kind::CIRCLE,
                a: [centre[0], centre[1], phi],
                b: [radius_mm, speed_mm_s],
                ..Default::default()
            },
            Move::Dwell { duration_s } => MoveMsg {
                kind: move_kind::DWELL,
                b: [duration_s, 0.0],
                ..Default::default()
            },
            Move::PathLine {
                to,
                phi,
                speed_mm_s,
                blend_radius_mm,
                continues,
                ..
            } => MoveMsg {
                kind: move_kind::PATH_LINE,
                flags: flags(continues, phi),
                a: [to[0], to[1], phi.unwrap_or(0.0)],
                b: [speed_mm_s.unwrap_or(0.0), blend_radius_mm.unwrap_or(-1.0)],
            },
            Move::Arc {
                centre,
                sweep_rad,
                phi,
                speed_mm_s,
                continues,
                ..
            } => MoveMsg {
                kind: move_kind::ARC,
                flags: flags(continues, phi),
                a: [centre[0], centre[1], phi.unwrap_or(0.0)],
                b: [speed_mm_s.unwrap_or(0.0), sweep_rad],
            },
            Move::Joint { steps, .. } => MoveMsg {
                kind: move_kind::JOINT,
                a: steps.map(|s| s as f64),
                ..Default::default()
            },
        };
    }
    Ok(c)
}

/// A simple command (pause, resume, stop, or a built-in program).
pub fn simple_command(kind: u32, program: u32, run_id: u32) -> Command {
    Command {
        kind,
        program,
        run_id,
        version: PROTOCOL_VERSION,
        ..Default::default()
    }
}

/// The interpolator step (one per chain): wraps a [`SetpointSource`].
#[derive(Debug)]
pub struct InterpolatorStep<S> {
    source: S,
    state: u32,
    run_id: u32,
    /// Program time at the last cycle, s.
    tau_s: f64,
    duration_s: f64,
    last_t_s: Option<f64>,
    hold: Pose,
    offset: [f64; 3],
    /// The last correction was held (no fresh measurement).
    correction_held: bool,
    seq: u64,
    done_sent: bool,
    /// (seq, program time) of the last [`HISTORY`] setpoints, for [`Self::rewind_to_seq`].
    history: [(u64, f64); HISTORY],
    /// Program-time rate: 1 while running, 0 while paused or stopped.
    rate: f64,
    /// A jerk-limited change of the rate in progress (pause/stop brake, resume ramp).
    ramp: Option<Ramp>,
    /// The pose the current program was planned from.
    origin: Pose,
    /// Command-to-motion latency fed forward: the commanded pose is the program's pose this much
    /// later (program time at the current rate); the nominal pose stays at the present, s.
    lead_s: f64,
}

/// A change of the program-time rate: program time follows the 1-DoF profile's position.
#[derive(Debug, Clone, Copy)]
struct Ramp {
    traj: Trajectory,
    /// Time since the ramp began, s.
    t: f64,
    /// Program time when it began, s.
    tau0: f64,
    /// The rate it ends at (exactly; the profile's end may differ by rounding).
    target: f64,
}

/// Setpoints remembered for rewinding (64 cycles = 1.28 s at 20 ms).
pub const HISTORY: usize = 64;

impl<S: SetpointSource> InterpolatorStep<S> {
    /// A step holding `home` until a program runs.
    pub fn new(source: S, home: Pose) -> Self {
        Self {
            source,
            state: planner_state::IDLE,
            run_id: 0,
            tau_s: 0.0,
            duration_s: 0.0,
            last_t_s: None,
            hold: home,
            offset: [0.0; 3],
            correction_held: false,
            seq: 0,
            done_sent: false,
            history: [(0, 0.0); HISTORY],
            rate: 0.0,
            lead_s: 0.0,
            ramp: None,
            origin: home,
        }
    }

    /// The program-time rate and its derivative now.
    fn rate_state(&self) -> (f64, f64) {
        match &self.ramp {
            Some(r) => {
                let (st, _) = r.traj.at_dof(0, r.t);
                (st.v, st.a)
            }
            None => (self.rate, 0.0),
        }
    }

    /// Starts a jerk-limited change of the program-time rate to `target` (0 or 1): pauses and
    /// stops brake along the path, resumes accelerate along it, within the source's
    /// [`SetpointSource::braking`] limits (scaled by the program's peak speed).
    fn ramp_rate_to(&mut self, target: f64) {
        let (r, dr) = self.rate_state();
        let b = self.source.braking();
        let v = b.peak_speed.max(1e-3);
        let mut input = Input::new(1);
        input.control_interface = ControlInterface::Velocity;
        input.current[0] = State::new(0.0, r, dr);
        input.target[0] = State::new(0.0, target, 0.0);
        input.limits[0] = Limits::symmetric(1.0, b.amax / v, b.jmax / v);
        match calculate(&input) {
            Ok(traj) => {
                self.ramp = Some(Ramp {
                    traj,
                    t: 0.0,
                    tau0: self.tau_s,
                    target,
                })
            }
            Err(_) => {
                // (cannot happen for finite positive limits) change at once
                self.ramp = None;
                self.rate = target;
            }
        }
    }

    /// Advances program time by `dt` at the current rate (following a ramp if one runs).
    fn advance(&mut self, dt: f64) {
        match &mut self.ramp {
            Some(r) => {
                r.t += dt;
                let d = r.traj.duration();
                let (st, _) = r.traj.at_dof(0, r.t.min(d));
                let over = (r.t - d).max(0.0);
                self.tau_s = r.tau0 + st.p + r.target * over;
                if r.t >= d {
                    self.rate = r.target;
                    self.ramp = None;
                }
            }
            None => self.tau_s += self.rate * dt,
        }
    }

    /// Moves the program back to the setpoint with sequence number `seq` (the last one the drive
    /// executed), so that a paused program resumes from where the robot is rather than from
    /// where the interpolator had got to. Only while running or paused and if `seq` is among the
    /// last [`HISTORY`] setpoints; returns whether it rewound. Allocation-free.
    pub fn rewind_to_seq(&mut self, seq: u64) -> bool {
        if !matches!(self.state, planner_state::RUNNING | planner_state::PAUSED) || seq == 0 {
            return false;
        }
        let (s, tau) = self.history[(seq % HISTORY as u64) as usize];
        if s != seq || tau > self.tau_s {
            return false;
        }
        self.tau_s = tau;
        self.hold = self.source.sample(tau);
        // The drive stopped there already: no brake, rate 0 (a resume ramps up again).
        self.ramp = None;
        self.rate = 0.0;
        true
    }

    /// The wrapped source.
    pub fn source(&self) -> &S {
        &self.source
    }

    /// Applies a command (between cycles; RUN allocates while planning).
    pub fn command(&mut self, cmd: &Command) -> Result<(), CommandError> {
        if cmd.version != PROTOCOL_VERSION {
            return Err(CommandError::Version(cmd.version));
        }
        match cmd.kind {
            command_kind::RUN => {
                self.can_start()?;
                let moves = moves_of(cmd)?;
                self.run_moves(&moves, cmd.run_id)
            }
            command_kind::RECOVER => {
                self.can_start()?;
                let run = prepare_run(self.source.clone(), cmd, self.hold)?;
                self.install(run).0
            }
            command_kind::PAUSE => {
                if self.state == planner_state::RUNNING {
                    self.state = planner_state::PAUSED;
                    self.ramp_rate_to(0.0);
                }
                Ok(())
            }
            command_kind::RESUME => {
                if self.state == planner_state::PAUSED {
                    self.state = planner_state::RUNNING;
                    self.ramp_rate_to(1.0);
                }
                Ok(())
            }
            command_kind::STOP => {
                if matches!(self.state, planner_state::RUNNING | planner_state::PAUSED) {
                    self.state = planner_state::STOPPED;
                    if self.rate_state().0 > 0.0 {
                        self.ramp_rate_to(0.0);
                    }
                }
                Ok(())
            }
            k => Err(CommandError::Malformed(format!("unknown command kind {k}"))),
        }
    }

    /// Starts run `run_id` of `moves` from the held pose, as a RUN command of them does (plans
    /// them on the source, so it allocates: between cycles only). For programs that the wire
    /// form cannot carry in one command (e.g. `pcr plan` of a long program file).
    pub fn run_moves(&mut self, moves: &[Move], run_id: u32) -> Result<(), CommandError> {
        self.can_start()?;
        match self.source.load(moves, self.hold) {
            Ok(d) => {
                self.start_program(d, run_id);
                Ok(())
            }
            Err(e) => {
                self.refuse(run_id);
                Err(e.into())
            }
        }
    }

    /// The program-time rate now: 1 while running, 0 while paused or stopped, in between while
    /// a pause or stop brakes or a resume accelerates.
    pub fn program_rate(&self) -> f64 {
        match self.state {
            planner_state::RUNNING | planner_state::PAUSED | planner_state::STOPPED => {
                self.rate_state().0
            }
            _ => 0.0,
        }
    }

    /// Path speed of the nominal pose of the last setpoint, mm/s: the source's speed at the
    /// program time, times the program-time rate (0 when holding). Allocation-free.
    pub fn speed_mm_s(&self) -> f64 {
        let rate = self.program_rate();
        if rate == 0.0 || self.tau_s >= self.duration_s {
            0.0
        } else {
            self.source.speed(self.tau_s) * rate
        }
    }

    fn start_program(&mut self, duration_s: f64, run_id: u32) {
        self.origin = self.hold;
        self.duration_s = duration_s;
        self.tau_s = 0.0;
        self.rate = 1.0;
        self.ramp = None;
        self.run_id = run_id;
        self.state = planner_state::RUNNING;
        self.done_sent = false;
    }

    /// Whether a new program may start now: not while one runs or is paused (stop it first).
    pub fn can_start(&self) -> Result<(), CommandError> {
        // (a stopped program may still be braking)
        if matches!(self.state, planner_state::RUNNING | planner_state::PAUSED)
            || self.ramp.is_some()
        {
            return Err(CommandError::Busy(self.run_id));
        }
        Ok(())
    }

    /// The pose held now (while idle: where a new program starts).
    pub fn hold(&self) -> Pose {
        self.hold
    }

    /// Marks run `run_id` as refused (its program could not be planned).
    pub fn refuse(&mut self, run_id: u32) {
        if self.can_start().is_ok() {
            self.run_id = run_id;
            self.state = planner_state::REFUSED;
        }
    }

    /// Marks run `run_id` as stopped before it started (stopped while being planned).
    pub fn mark_stopped(&mut self, run_id: u32) {
        if self.can_start().is_ok() {
            self.run_id = run_id;
            self.state = planner_state::STOPPED;
        }
    }

    /// Starts a program planned off the cycle by [`prepare_run`]. Refused while another program
    /// runs or when the held pose moved since the program was planned from it. Neither
    /// allocates nor frees: it returns the source no longer needed (the previous one, or the
    /// refused run's) so that the caller can drop it off the cycle too.
    pub fn install(&mut self, run: PreparedRun<S>) -> (Result<(), CommandError>, S) {
        if let Err(e) = self.can_start() {
            return (Err(e), run.source);
        }
        if let Some((tau, pose)) = run.resume {
            // A recovery: continue the program, paused, where the drive stopped.
            let old = std::mem::replace(&mut self.source, run.source);
            self.start_program(run.duration_s, run.run_id);
            self.origin = run.start;
            self.tau_s = tau;
            self.hold = pose;
            self.rate = 0.0;
            self.state = planner_state::PAUSED;
            return (Ok(()), old);
        }
        let moved = (run.start.x - self.hold.x)
            .abs()
            .max((run.start.y - self.hold.y).abs())
            .max((run.start.phi - self.hold.phi).abs());
        if moved > 1e-9 {
            return (Err(CommandError::Stale(moved)), run.source);
        }
        let old = std::mem::replace(&mut self.source, run.source);
        self.start_program(run.duration_s, run.run_id);
        (Ok(()), old)
    }

    /// Feeds a command-to-motion latency forward (`[effects.latency]`): commanded poses lead the
    /// nominal ones by `lead_s` of program time, s.
    pub fn set_lead(&mut self, lead_s: f64) {
        if lead_s.is_finite() {
            self.lead_s = lead_s;
        }
    }

    /// Applies a task-space correction offset (x mm, y mm, phi rad) to later setpoints; a
    /// held correction ([`pcr_messages::correction_flags::HELD`]) flags them
    /// [`task_flags::UNCORRECTED`] until a fresh one arrives.
    pub fn set_correction(&mut self, c: &Correction) {
        if c.offset.iter().all(|v| v.is_finite()) {
            self.offset = c.offset;
        }
        self.correction_held = c.flags & pcr_messages::correction_flags::HELD != 0;
    }

    /// Sets the pose held while idle from a pose the robot was commanded to (e.g. FK of the
    /// drive's positions after a restart): the correction offset in it is taken out, so that
    /// holding there does not walk away while a correction is active.
    pub fn set_hold_commanded(&mut self, pose: Pose) {
        self.set_hold(Pose::new(
            pose.x - self.offset[0],
            pose.y - self.offset[1],
            pose.phi - self.offset[2],
        ));
    }

    /// Sets the pose held while idle (e.g. the measured pose after a restart).
    pub fn set_hold(&mut self, pose: Pose) {
        if self.state != planner_state::RUNNING && self.state != planner_state::PAUSED {
            self.hold = pose;
        }
    }

    /// Current status.
    pub fn status(&self, t_s: f64) -> PlannerStatus {
        PlannerStatus {
            t_s,
            progress_s: self.tau_s,
            duration_s: self.duration_s,
            origin: self.origin.to_array(),
            run_id: self.run_id,
            state: self.state,
            version: PROTOCOL_VERSION,
            reserved: 0,
        }
    }

    /// One cycle at chain time `t_s`: advances the program (unless paused) and returns the
    /// setpoint. Allocation-free.
    pub fn step(&mut self, t_s: f64) -> TaskSetpoint {
        let dt = self.last_t_s.map_or(0.0, |l| (t_s - l).max(0.0));
        self.last_t_s = Some(t_s);
        let mut flags = 0;
        match self.state {
            planner_state::RUNNING => {
                self.advance(dt);
                self.hold = self.source.sample(self.tau_s);
                flags |= task_flags::ACTIVE;
                if self.tau_s >= self.duration_s {
                    // (a resume ramp that has not ended with the program ends here: it would
                    // never be stepped again, and the next program would wait for it)
                    self.ramp = None;
                    self.state = planner_state::DONE;
                    flags |= task_flags::DONE;
                    self.done_sent = true;
                }
            }
            planner_state::PAUSED | planner_state::STOPPED => {
                // Braking along the path until the program-time rate is 0.
                if self.ramp.is_some() {
                    self.advance(dt);
                    self.tau_s = self.tau_s.min(self.duration_s);
                    self.hold = self.source.sample(self.tau_s);
                }
                if self.state == planner_state::PAUSED {
                    flags |= task_flags::ACTIVE | task_flags::PAUSED;
                }
            }
            _ => {}
        }
        if self.correction_held {
            flags |= task_flags::UNCORRECTED;
        }
        self.seq += 1;
        self.history[(self.seq % HISTORY as u64) as usize] = (self.seq, self.tau_s);
        let p = self.hold;
        let active = self.state == planner_state::RUNNING || self.ramp.is_some();
        let c = if self.lead_s != 0.0 && active {
            let tau = (self.tau_s + self.lead_s * self.rate).clamp(0.0, self.duration_s);
            self.source.sample(tau)
        } else {
            p
        };
        TaskSetpoint {
            t_s,
            x_mm: c.x + self.offset[0],
            y_mm: c.y + self.offset[1],
            phi_rad: c.phi + self.offset[2],
            nominal: [p.x, p.y, p.phi],
            seq: self.seq,
            run_id: self.run_id,
            flags,
            stamps: Default::default(),
            version: PROTOCOL_VERSION,
            reserved: 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::setpoint::InterimPathSource;

    #[test]
    fn pause_brakes_along_the_path_and_resume_accelerates_again() {
        let mut s = InterpolatorStep::new(InterimPathSource::new(), Pose::default());
        s.command(&simple_command(command_kind::RUN, program_id::CIRCLE, 7))
            .unwrap();
        let mut t = 0.0;
        let mut last = s.step(t);
        let mut v_last = 0.0;
        for _ in 0..300 {
            t += 0.02;
            let sp = s.step(t);
            v_last = (sp.x_mm - last.x_mm).hypot(sp.y_mm - last.y_mm) / 0.02;
            last = sp;
        }
        assert!(v_last > 10.0, "moving at {v_last} mm/s");
        s.command(&simple_command(command_kind::PAUSE, 0, 7))
            .unwrap();
        // braking: the speed falls smoothly (at most the braking acceleration per cycle),
        // staying on the program's path, until it stops
        let b = s.source().braking();
        let mut v_prev = v_last;
        let mut stopped_at = None;
        for k in 0..200 {
            t += 0.02;
            let sp = s.step(t);
            assert!(sp.flags & task_flags::PAUSED != 0);
            let v = (sp.x_mm - last.x_mm).hypot(sp.y_mm - last.y_mm) / 0.02;
            assert!(
                v <= v_prev + 1e-6,
                "speeds up while braking: {v_prev} -> {v}"
            );
            assert!(
                v_prev - v <= (b.amax * 2.0) * 0.02 + 1e-6,
                "{v_prev} -> {v}"
            );
            let on_path = s.source().sample(s.status(t).progress_s);
            assert!((on_path.x - sp.x_mm).abs() < 1e-12);
            if v == 0.0 && stopped_at.is_none() {
                stopped_at = Some(k);
            }
            v_prev = v;
            last = sp;
        }
        let k = stopped_at.expect("stops");
        assert!(k > 3, "stopped at once (k = {k}), not braked");
        // a paused program holds
        let a = s.step(t + 1.0);
        assert_eq!((a.x_mm, a.y_mm), (last.x_mm, last.y_mm));
        // resume: the speed rises gradually, then the program continues
        s.command(&simple_command(command_kind::RESUME, 0, 7))
            .unwrap();
        t += 1.0;
        let mut prev = a;
        let first = s.step(t + 0.02);
        let v1 = (first.x_mm - prev.x_mm).hypot(first.y_mm - prev.y_mm) / 0.02;
        assert!(v1 < 2.0, "jumped to {v1} mm/s");
        prev = first;
        let mut v = v1;
        for k in 2..100 {
            let sp = s.step(t + 0.02 * k as f64);
            v = (sp.x_mm - prev.x_mm).hypot(sp.y_mm - prev.y_mm) / 0.02;
            prev = sp;
        }
        assert!((v - v_last).abs() < 1.0, "back to speed: {v} vs {v_last}");
    }

    #[test]
    fn a_program_that_ends_while_resuming_lets_the_next_one_start() {
        // 1 s of program; a pause early, and a resume whose ramp (rate limits 1/s^2, 10/s^3
        // with the default braking) outlasts the rest of the program
        let run = command_of_moves(1, &[Move::Dwell { duration_s: 1.0 }]).unwrap();
        let mut s = InterpolatorStep::new(InterimPathSource::new(), Pose::default());
        s.command(&run).unwrap();
        let mut t = 0.0;
        for k in 0..400 {
            match k {
                10 => s
                    .command(&simple_command(command_kind::PAUSE, 0, 1))
                    .unwrap(),
                200 => s
                    .command(&simple_command(command_kind::RESUME, 0, 1))
                    .unwrap(),
                _ => {}
            }
            s.step(t);
            t += 0.02;
        }
        assert_eq!(s.status(t).state, planner_state::DONE);
        assert_eq!(s.program_rate(), 0.0);
        assert!(s.can_start().is_ok());
        let mut next = run;
        next.run_id = 2;
        s.command(&next).unwrap();
    }

    #[test]
    fn a_stop_brakes_and_a_new_program_waits_for_it() {
        let mut s = InterpolatorStep::new(InterimPathSource::new(), Pose::default());
        let run = simple_command(command_kind::RUN, program_id::CIRCLE, 1);
        s.command(&run).unwrap();
        let mut t = 0.0;
        for _ in 0..300 {
            s.step(t);
            t += 0.02;
        }
        s.command(&simple_command(command_kind::STOP, 0, 1))
            .unwrap();
        assert_eq!(s.status(t).state, planner_state::STOPPED);
        let a = s.step(t);
        assert!(matches!(s.command(&run), Err(CommandError::Busy(_))));
        let b = s.step(t + 0.02);
        assert!(a.x_mm != b.x_mm || a.y_mm != b.y_mm, "still braking");
        for k in 2..200 {
            s.step(t + 0.02 * k as f64);
        }
        let c = s.step(t + 4.0);
        let d = s.step(t + 4.02);
        assert_eq!((c.x_mm, c.y_mm), (d.x_mm, d.y_mm));
        s.command(&run).unwrap();
    }

    #[test]
    fn rewind_returns_to_an_executed_setpoint() {
        let mut s = InterpolatorStep::new(InterimPathSource::new(), Pose::default());
        s.command(&simple_command(command_kind::RUN, program_id::CIRCLE, 1))
            .unwrap();
        let mut t = 0.0;
        let mut at_60 = None;
        for _ in 0..80 {
            let sp = s.step(t);
            if sp.seq == 60 {
                at_60 = Some(sp);
            }
            t += 0.02;
        }
        s.command(&simple_command(command_kind::PAUSE, 0, 1))
            .unwrap();
        assert!(s.rewind_to_seq(60));
        let a = at_60.unwrap();
        let b = s.step(t);
        assert_eq!((a.x_mm, a.y_mm), (b.x_mm, b.y_mm));
        assert!(!s.rewind_to_seq(1), "too old");
    }

    #[test]
    fn a_program_planned_off_the_cycle_runs_like_a_direct_one() {
        let cmd = simple_command(command_kind::RUN, program_id::CIRCLE, 4);
        let mut direct = InterpolatorStep::new(InterimPathSource::new(), Pose::default());
        direct.command(&cmd).unwrap();
        let mut off = InterpolatorStep::new(InterimPathSource::new(), Pose::default());
        let run = prepare_run(InterimPathSource::new(), &cmd, off.hold()).unwrap();
        assert_eq!(run.run_id(), 4);
        off.install(run).0.unwrap();
        let mut t = 0.0;
        for _ in 0..200 {
            let (a, b) = (direct.step(t), off.step(t));
            assert_eq!((a.x_mm, a.y_mm, a.phi_rad), (b.x_mm, b.y_mm, b.phi_rad));
            t += 0.02;
        }
        assert_eq!(off.status(t).state, planner_state::RUNNING);
        assert_eq!(off.status(t).run_id, 4);
    }

    #[test]
    fn a_new_program_waits_for_the_running_one_and_a_stale_plan_is_refused() {
        let cmd = simple_command(command_kind::RUN, program_id::CIRCLE, 1);
        let mut s = InterpolatorStep::new(InterimPathSource::new(), Pose::default());
        s.command(&cmd).unwrap();
        s.step(0.0);
        s.step(0.02);
        assert_eq!(s.command(&cmd), Err(CommandError::Busy(1)));
        let run = prepare_run(InterimPathSource::new(), &cmd, Pose::default()).unwrap();
        assert!(matches!(s.install(run).0, Err(CommandError::Busy(1))));
        // planned from home, but the robot now holds elsewhere
        let mut idle = InterpolatorStep::new(InterimPathSource::new(), Pose::new(5.0, 0.0, 0.0));
        let run = prepare_run(InterimPathSource::new(), &cmd, Pose::default()).unwrap();
        assert!(matches!(idle.install(run).0, Err(CommandError::Stale(_))));
        idle.refuse(9);
        assert_eq!(idle.status(0.0).state, planner_state::REFUSED);
        assert_eq!(idle.status(0.0).run_id, 9);
        idle.mark_stopped(10);
        assert_eq!(
            (idle.status(0.0).state, idle.status(0.0).run_id),
            (planner_state::STOPPED, 10)
        );
        // a running program is not marked
        s.mark_stopped(11);
        assert_eq!(s.status(0.0).run_id, 1);
        // only RUN commands are planned
        let pause = simple_command(command_kind::PAUSE, 0, 1);
        assert!(prepare_run(InterimPathSource::new(), &pause, Pose::default()).is_err());
    }

    #[test]
    fn a_restarted_interpolator_recovers_the_run_where_the_drive_stopped() {
        use crate::planned::{MotionLimits, PlannerSource};
        use pcr_kinematics::Robot;
        let src = || PlannerSource::new(Robot::nominal(), MotionLimits::default());
        let run = simple_command(command_kind::RUN, program_id::CIRCLE, 3);
        let mut a = InterpolatorStep::new(src(), Pose::default());
        a.command(&run).unwrap();
        let mut t = 0.0;
        let mut last = a.step(t);
        for _ in 0..150 {
            t += 0.02;
            last = a.step(t);
        }
        let status = a.status(t);
        assert_eq!(status.origin, [0.0; 3]);
        // the interpolator dies; a new one holds elsewhere and gets RECOVER with a stale hint
        let mut b = InterpolatorStep::new(src(), Pose::new(1.0, 2.0, 0.0));
        let mut rec = run;
        rec.kind = command_kind::RECOVER;
        rec.origin = status.origin;
        rec.executed = last.nominal;
        rec.resume_s = status.progress_s + 0.3;
        b.command(&rec).unwrap();
        let st = b.status(t);
        assert_eq!((st.state, st.run_id), (planner_state::PAUSED, 3));
        assert!(
            (st.progress_s - status.progress_s).abs() < 1e-6,
            "{st:?} vs {status:?}"
        );
        let held = b.step(t);
        assert!((held.x_mm - last.x_mm).abs() < 1e-6 && (held.y_mm - last.y_mm).abs() < 1e-6);
        // resumed, it finishes the same program at the same place
        b.command(&simple_command(command_kind::RESUME, 0, 3))
            .unwrap();
        let (mut end_a, mut end_b) = (last, held);
        for k in 1..2000 {
            end_a = a.step(t + 0.02 * k as f64);
            end_b = b.step(t + 0.02 * k as f64);
        }
        assert_eq!(b.status(t).state, planner_state::DONE);
        assert!((end_a.x_mm - end_b.x_mm).abs() < 1e-9 && (end_a.y_mm - end_b.y_mm).abs() < 1e-9);
        // a pose that is not on the program is refused
        rec.executed = [30.0, -30.0, 0.0];
        let mut c = InterpolatorStep::new(src(), Pose::default());
        assert!(c.command(&rec).is_err());
    }

    #[test]
    fn holding_the_commanded_pose_under_a_correction_does_not_walk_away() {
        let mut s = InterpolatorStep::new(InterimPathSource::new(), Pose::default());
        let corr = Correction {
            offset: [0.4, -0.3, 0.002],
            version: PROTOCOL_VERSION,
            ..Default::default()
        };
        s.set_correction(&corr);
        let mut t = 0.0;
        for _ in 0..100 {
            // the drive reaches what it is commanded; the planner re-holds there each cycle
            let sp = s.step(t);
            s.set_hold_commanded(Pose::new(sp.x_mm, sp.y_mm, sp.phi_rad));
            t += 0.02;
        }
        let sp = s.step(t);
        assert!(
            sp.nominal[0].abs() < 1e-12 && sp.nominal[1].abs() < 1e-12,
            "{sp:?}"
        );
        assert!((sp.x_mm - 0.4).abs() < 1e-12);
    }

    #[test]
    fn moves_round_trip_through_the_wire() {
        let m = paper_square();
        let c = command_of_moves(3, &m).unwrap();
        assert_eq!(moves_of(&c).unwrap(), m);
    }

    #[test]
    fn wrong_version_is_refused() {
        let mut s = InterpolatorStep::new(InterimPathSource::new(), Pose::default());
        let mut c = simple_command(command_kind::RUN, program_id::PAPER, 1);
        c.version = 99;
        assert_eq!(s.command(&c), Err(CommandError::Version(99)));
    }
}
