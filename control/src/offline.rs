//! Offline planning: the chain's interpolator ([`InterpolatorStep`]) stepped on a simulated
//! clock, without IPC and without a drive. `pcr plan` writes its setpoint CSV from here, so a
//! program planned and checked offline gets the setpoints the running chain (the `pcr-planner`
//! process, or [`crate::InProcessChain`]) commands for it, cycle by cycle, including how a
//! pause, resume or stop requested at a given cycle brakes and accelerates along the path.

use crate::interpolator::{simple_command, CommandError, InterpolatorStep};
use crate::setpoint::{Move, SetpointSource};
use pcr_kinematics::Pose;
use pcr_messages::{planner_state, TaskSetpoint};

/// The chain's interpolation period, s (20 ms).
pub const CYCLE_S: f64 = 0.02;

/// One cycle of an offline plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannedCycle {
    /// The interpolator's output (its `nominal` is the planned pose the chain records as
    /// `xp_mm, yp_mm, phip_deg`).
    pub task: TaskSetpoint,
    /// Program time, s.
    pub progress_s: f64,
    /// Path speed of the nominal pose, mm/s (see [`InterpolatorStep::speed_mm_s`]).
    pub speed_mm_s: f64,
    /// The interpolator's state after the cycle ([`planner_state`]).
    pub state: u32,
}

impl PlannedCycle {
    /// The planned (nominal) pose.
    pub fn pose(&self) -> Pose {
        let n = self.task.nominal;
        Pose::new(n[0], n[1], n[2])
    }
}

/// A program planned offline.
#[derive(Debug)]
pub struct OfflinePlan<S> {
    /// Every cycle, from t = 0 (the start pose) to the first at rest.
    pub cycles: Vec<PlannedCycle>,
    /// The interpolator after the last cycle (its source holds the planned program).
    pub interp: InterpolatorStep<S>,
}

/// Cycles an offline plan runs at most beyond the program's duration and its last command.
pub const EXTRA_CYCLES: usize = 100_000;

/// Plans `moves` from `start` on `source` (refused as the chain refuses them) and steps the
/// interpolator every `period_s` from t = 0 until the program is done, or stopped and braked to
/// rest, or paused at rest with no command left, applying `commands` (`(cycle, command kind)`:
/// PAUSE, RESUME or STOP) just before their cycle, as the chain applies a command that arrives
/// between two cycles. Every cycle is returned, the first (t = 0, the start pose) and the last
/// (at rest) included.
pub fn plan_moves<S: SetpointSource>(
    source: S,
    start: Pose,
    moves: &[Move],
    commands: &[(usize, u32)],
    period_s: f64,
) -> Result<OfflinePlan<S>, CommandError> {
    let mut interp = InterpolatorStep::new(source, start);
    interp.run_moves(moves, 1)?;
    let duration = interp.status(0.0).duration_s;
    let max = commands.iter().map(|c| c.0).max().unwrap_or(0)
        + (duration / period_s).ceil() as usize
        + EXTRA_CYCLES;
    let cycles = step_to_rest(&mut interp, commands, period_s, max);
    Ok(OfflinePlan { cycles, interp })
}

/// Steps `interp` (a program started on it) from t = 0 as [`plan_moves`] does, at most
/// `max_cycles` cycles. `commands` are in cycle order.
pub fn step_to_rest<S: SetpointSource>(
    interp: &mut InterpolatorStep<S>,
    commands: &[(usize, u32)],
    period_s: f64,
    max_cycles: usize,
) -> Vec<PlannedCycle> {
    let run_id = interp.status(0.0).run_id;
    let mut out = Vec::new();
    let mut t = 0.0;
    let mut next = 0;
    for k in 0..max_cycles {
        while next < commands.len() && commands[next].0 <= k {
            // PAUSE, RESUME and STOP cannot fail
            let _ = interp.command(&simple_command(commands[next].1, 0, run_id));
            next += 1;
        }
        let task = interp.step(t);
        let status = interp.status(t);
        out.push(PlannedCycle {
            task,
            progress_s: status.progress_s,
            speed_mm_s: interp.speed_mm_s(),
            state: status.state,
        });
        t += period_s;
        let at_rest = interp.program_rate() == 0.0;
        let done = match status.state {
            planner_state::RUNNING => false,
            planner_state::PAUSED => next == commands.len() && at_rest,
            _ => interp.can_start().is_ok(),
        };
        if done {
            break;
        }
    }
    out
}
