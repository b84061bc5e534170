//! The interpolator step: runs a [`SetpointSource`] on the chain's clock, with pause, resume and
//! stop, and emits one [`TaskSetpoint`] per cycle.

use crate::setpoint::{paper_circle, paper_program, paper_square, Move, PlanError, SetpointSource};
use pcr_kinematics::Pose;
use pcr_messages::{
    command_kind, move_kind, planner_state, program_id, task_flags, Command, Correction, MoveMsg,
    PlannerStatus, TaskSetpoint, MAX_MOVES, PROTOCOL_VERSION,
};

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
    if cmd.kind != command_kind::RUN {
        return Err(CommandError::Malformed(format!(
            "command kind {} is not RUN",
            cmd.kind
        )));
    }
    let moves = moves_of(cmd)?;
    let duration_s = source.load(&moves, start)?;
    Ok(PreparedRun {
        source,
        duration_s,
        run_id: cmd.run_id,
        start,
    })
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
            cmd.moves[..n].iter().map(move_of).collect()
        }
        p => Err(CommandError::Malformed(format!("unknown program id {p}"))),
    }
}

fn move_of(m: &MoveMsg) -> Result<Move, CommandError> {
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
        k => return Err(CommandError::Malformed(format!("unknown move kind {k}"))),
    })
}

/// Converts moves into the wire form (at most [`MAX_MOVES`]).
pub fn command_of_moves(run_id: u32, moves: &[Move]) -> Result<Command, CommandError> {
    if moves.is_empty() || moves.len() > MAX_MOVES {
        return Err(CommandError::Malformed(format!(
            "{} moves (1..={MAX_MOVES} allowed)",
            moves.len()
        )));
    }
    let mut c = Command {
        kind: command_kind::RUN,
        program: program_id::MOVES,
        run_id,
        n_moves: moves.len() as u32,
        version: PROTOCOL_VERSION,
        ..Default::default()
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
    seq: u64,
    done_sent: bool,
    /// (seq, program time) of the last [`HISTORY`] setpoints, for [`Self::rewind_to_seq`].
    history: [(u64, f64); HISTORY],
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
            seq: 0,
            done_sent: false,
            history: [(0, 0.0); HISTORY],
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
                match self.source.load(&moves, self.hold) {
                    Ok(d) => {
                        self.start_program(d, cmd.run_id);
                        Ok(())
                    }
                    Err(e) => {
                        self.refuse(cmd.run_id);
                        Err(e.into())
                    }
                }
            }
            command_kind::PAUSE => {
                if self.state == planner_state::RUNNING {
                    self.state = planner_state::PAUSED;
                }
                Ok(())
            }
            command_kind::RESUME => {
                if self.state == planner_state::PAUSED {
                    self.state = planner_state::RUNNING;
                }
                Ok(())
            }
            command_kind::STOP => {
                if matches!(self.state, planner_state::RUNNING | planner_state::PAUSED) {
                    self.state = planner_state::STOPPED;
                }
                Ok(())
            }
            k => Err(CommandError::Malformed(format!("unknown command kind {k}"))),
        }
    }

    fn start_program(&mut self, duration_s: f64, run_id: u32) {
        self.duration_s = duration_s;
        self.tau_s = 0.0;
        self.run_id = run_id;
        self.state = planner_state::RUNNING;
        self.done_sent = false;
    }

    /// Whether a new program may start now: not while one runs or is paused (stop it first).
    pub fn can_start(&self) -> Result<(), CommandError> {
        if matches!(self.state, planner_state::RUNNING | planner_state::PAUSED) {
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

    /// Starts a program planned off the cycle by [`prepare_run`]. Refused while another program
    /// runs or when the held pose moved since the program was planned from it. Neither
    /// allocates nor frees: it returns the source no longer needed (the previous one, or the
    /// refused run's) so that the caller can drop it off the cycle too.
    pub fn install(&mut self, run: PreparedRun<S>) -> (Result<(), CommandError>, S) {
        if let Err(e) = self.can_start() {
            return (Err(e), run.source);
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

    /// Applies a task-space correction offset (x mm, y mm, phi rad) to later setpoints.
    pub fn set_correction(&mut self, c: &Correction) {
        if c.offset.iter().all(|v| v.is_finite()) {
            self.offset = c.offset;
        }
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
                self.tau_s += dt;
                self.hold = self.source.sample(self.tau_s);
                flags |= task_flags::ACTIVE;
                if self.tau_s >= self.duration_s {
                    self.state = planner_state::DONE;
                    flags |= task_flags::DONE;
                    self.done_sent = true;
                }
            }
            planner_state::PAUSED => flags |= task_flags::ACTIVE | task_flags::PAUSED,
            _ => {}
        }
        self.seq += 1;
        self.history[(self.seq % HISTORY as u64) as usize] = (self.seq, self.tau_s);
        let p = self.hold;
        TaskSetpoint {
            t_s,
            x_mm: p.x + self.offset[0],
            y_mm: p.y + self.offset[1],
            phi_rad: p.phi + self.offset[2],
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
    fn pause_freezes_and_resume_continues() {
        let mut s = InterpolatorStep::new(InterimPathSource::new(), Pose::default());
        s.command(&simple_command(command_kind::RUN, program_id::CIRCLE, 7))
            .unwrap();
        let mut t = 0.0;
        for _ in 0..100 {
            s.step(t);
            t += 0.02;
        }
        s.command(&simple_command(command_kind::PAUSE, 0, 7))
            .unwrap();
        let a = s.step(t);
        let b = s.step(t + 1.0);
        assert_eq!((a.x_mm, a.y_mm), (b.x_mm, b.y_mm));
        assert!(b.flags & task_flags::PAUSED != 0);
        s.command(&simple_command(command_kind::RESUME, 0, 7))
            .unwrap();
        let c = s.step(t + 1.02);
        assert!(c.x_mm != b.x_mm || c.y_mm != b.y_mm);
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
        // only RUN commands are planned
        let pause = simple_command(command_kind::PAUSE, 0, 1);
        assert!(prepare_run(InterimPathSource::new(), &pause, Pose::default()).is_err());
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
