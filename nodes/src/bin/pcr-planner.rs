//! `pcr-planner`: the interpolator process. Every period (default 20 ms, iceoryx2 interval) it
//! applies pending commands and publishes one task setpoint (+ event); it reports status and
//! heartbeats. Source: the jerk-limited planner ([`PlannerSource`]).
//!
//! Planning a program (paths, speed profiles, and the fine check of every pose along it) takes
//! milliseconds, longer than a cycle may: it runs on a worker thread at normal scheduling, and
//! the cycle only hands the command over and later installs the checked program (status
//! `PLANNING` meanwhile). The cycle itself never plans.

use anyhow::{anyhow, Context, Result};
use clap::Parser;
use iceoryx2::prelude::*;
use pcr_control::{
    prepare_run, simple_command, CommandError, InterpolatorStep, MotionLimits, PlannerSource,
    PreparedRun,
};
use pcr_kinematics::{Pose, Robot};
use pcr_messages::{
    command_kind, driver_flags, monotonic_ns, planner_state, services as s, Command, Correction,
    DriverStateMsg, Heartbeat, NodeKind, PlannerStatus, Refusal, TaskSetpoint,
};
use pcr_nodes::cycle::planner_emit;
use pcr_nodes::{chain_time_s, ports::latest, publish, CommonArgs, CycleStats, PeriodicTimer};
use pcr_robot::RobotConfig;
use std::sync::{mpsc, Arc, Mutex};

type PlanResult = (u32, Result<PreparedRun<PlannerSource>, CommandError>);

/// Work for the planning thread. (Moved by value: boxing would allocate in the cycle.)
#[allow(clippy::large_enum_variant)]
enum Job {
    /// Plan this RUN command from this pose.
    Plan(Command, Pose),
    /// Drop a source the cycle no longer needs (freeing memory is not for the cycle either).
    Drop(PlannerSource),
}

/// The planning thread and the hand-over between it and the cycle. The cycle never waits on
/// the thread: it sends jobs over a channel (a send never blocks) and picks results up with
/// `try_lock`, trying again next cycle if the thread holds the lock just then. (A channel
/// receive could spin while the thread, at normal priority, is preempted mid-send.)
struct Planning {
    jobs: mpsc::Sender<Job>,
    done: Arc<Mutex<Option<PlanResult>>>,
}

impl Planning {
    /// Started before the real-time settings are applied, so the thread keeps normal
    /// scheduling.
    fn spawn(template: PlannerSource) -> Result<Self> {
        let (jobs, rx) = mpsc::channel::<Job>();
        let done = Arc::new(Mutex::new(None::<PlanResult>));
        let out = done.clone();
        std::thread::Builder::new()
            .name("planning".into())
            .spawn(move || {
                for job in rx {
                    match job {
                        Job::Plan(cmd, start) => {
                            let r = prepare_run(template.clone(), &cmd, start);
                            // One plan at a time: the slot is empty (the cycle took the last).
                            if let Ok(mut slot) = out.lock() {
                                *slot = Some((cmd.run_id, r));
                            }
                        }
                        Job::Drop(source) => drop(source),
                    }
                }
            })
            .context("starting the planning thread")?;
        Ok(Self { jobs, done })
    }

    fn send(&self, job: Job) -> bool {
        self.jobs.send(job).is_ok()
    }

    /// A finished plan, if there is one and the lock is free now.
    fn try_take(&self) -> Option<PlanResult> {
        self.done.try_lock().ok().and_then(|mut slot| slot.take())
    }
}

#[derive(Parser, Debug)]
#[command(about = "pcr-planner: the 20 ms interpolator process")]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
}

fn main() -> std::process::ExitCode {
    pcr_nodes::init_logging();
    match run(Args::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("pcr-planner: error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(a: Args) -> Result<()> {
    let kind = NodeKind::Planner;
    let c = &a.common;
    let robot_cfg = RobotConfig::load(&c.robot).with_context(|| format!("robot {}", c.robot))?;
    let robot = Robot::new(&robot_cfg).map_err(|e| anyhow!("robot model: {e}"))?;
    let (cn, guard) = pcr_nodes::startup(kind, c)?;
    let pub_sp = cn.publisher::<TaskSetpoint>(s::TASK_SETPOINT)?;
    let notify = cn.hop_notifier(s::TASK_SETPOINT)?;
    let pub_status = cn.publisher::<PlannerStatus>(s::STATUS)?;
    let pub_refusal = cn.publisher::<Refusal>(s::REFUSAL)?;
    // Whoever asked learns why a command was refused (the supervisor, `ctl run`).
    let refuse = |run_id: u32, why: &dyn std::fmt::Display| {
        tracing::error!(run_id, "command refused: {why}");
        let _ = pcr_nodes::publish(
            &pub_refusal,
            Refusal::new(chain_time_s(), run_id, &why.to_string()),
        );
    };
    let pub_hb = cn.publisher::<Heartbeat>(s::HEARTBEAT)?;
    let sub_cmd = cn.subscriber::<Command>(s::COMMAND)?;
    let sub_corr = cn.subscriber::<Correction>(s::CORRECTION)?;
    let sub_state = cn.subscriber::<DriverStateMsg>(s::DRIVER_STATE)?;
    let template = PlannerSource::new(robot.clone(), MotionLimits::default());
    let planner_thread = Planning::spawn(template.clone())?;
    pcr_nodes::realtime::apply(c.rt_priority, c.cpu, c.mlockall);

    let mut interp = InterpolatorStep::new(template, Pose::default());
    interp.set_lead(pcr_control::compensation::command_lead(
        &robot_cfg,
        c.period().as_secs_f64(),
    ));
    // The run being planned on the worker thread, and runs whose plans are to be dropped
    // (stopped while planning).
    let mut planning: Option<u32> = None;
    let mut cancelled: Option<u32> = None;
    let mut commanded = false;
    let mut hold_guess = Pose::default();
    let period_ns = c.period().as_nanos() as u64;
    let mut stats = CycleStats::new(kind, c.protocol_version, period_ns);
    let mut last_state = u32::MAX;
    let mut executed_seq = 0u64;
    let mut last_state_ns = monotonic_ns();
    let mut drive_holding = false;
    let mut auto_paused = false;
    // Taken back to the drive's setpoint since it stopped following.
    let mut rewound = false;

    let ws = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .map_err(|e| anyhow!("waitset: {e:?}"))?;
    // A precise timer (iceoryx2's intervals round to whole milliseconds).
    let timer = PeriodicTimer::new(c.period())?;
    let tick = ws
        .attach_notification(&timer)
        .map_err(|e| anyhow!("timer: {e:?}"))?;
    let hb = ws
        .attach_interval(c.heartbeat())
        .map_err(|e| anyhow!("interval: {e:?}"))?;

    let r = pcr_nodes::run_waitset(&ws, |id| {
        let t = chain_time_s();
        let due = if id.has_event_from(&tick) {
            timer.tick()
        } else {
            None
        };
        if let Some(due) = due {
            let wake = monotonic_ns();
            let latency = wake.saturating_sub(due.release_ns);
            stats.missed_periods(due.missed);
            // Driver states first: the last setpoint the drive executed.
            let newest_state = latest(&sub_state).ok().flatten();
            if let Some(st) = &newest_state {
                executed_seq = st.seq;
                last_state_ns = wake;
                drive_holding = st.flags & driver_flags::STALE_HOLD != 0;
            }
            // A program planned off the cycle: start it (or report why not).
            if let Some((run_id, r)) = planner_thread.try_take() {
                if planning == Some(run_id) {
                    planning = None;
                }
                let r = match r {
                    Ok(run) if cancelled == Some(run_id) => {
                        planner_thread.send(Job::Drop(run.into_source()));
                        Ok(())
                    }
                    Ok(run) => {
                        let (r, unused) = interp.install(run);
                        planner_thread.send(Job::Drop(unused));
                        r.map(|()| tracing::info!(run_id, "program planned and checked: running"))
                    }
                    Err(e) => Err(e),
                };
                if cancelled == Some(run_id) {
                    cancelled = None;
                } else if let Err(e) = r {
                    interp.refuse(run_id);
                    refuse(run_id, &e);
                }
            }
            while let Ok(Some(cmd)) = sub_cmd.receive() {
                let cmd = cmd.payload();
                if matches!(cmd.kind, command_kind::RUN | command_kind::RECOVER) {
                    // Plan on the worker thread, never in the cycle.
                    let busy = interp
                        .can_start()
                        .err()
                        .or(planning.map(CommandError::Busy));
                    if let Some(e) = busy {
                        refuse(cmd.run_id, &e);
                        continue;
                    }
                    commanded = true;
                    if planner_thread.send(Job::Plan(*cmd, interp.hold())) {
                        planning = Some(cmd.run_id);
                        tracing::info!(run_id = cmd.run_id, "planning a program");
                    } else {
                        interp.refuse(cmd.run_id);
                        refuse(cmd.run_id, &"the planning thread is gone");
                    }
                    continue;
                }
                if cmd.kind == command_kind::STOP && planning.is_some() {
                    cancelled = planning.take();
                    if let Some(id) = cancelled {
                        interp.mark_stopped(id);
                    }
                    tracing::info!(run_id = cancelled, "stopped while planning");
                }
                match interp.command(cmd) {
                    Ok(()) => {
                        commanded = true;
                        tracing::info!(kind = cmd.kind, run_id = cmd.run_id, "command");
                        // A commanded pause brakes along the path (if the drive does not
                        // follow, the check below takes it back to where the drive stopped).
                        if cmd.kind == command_kind::PAUSE {
                            auto_paused = false;
                        }
                    }
                    Err(e) => refuse(cmd.run_id, &e),
                }
            }
            if let Ok(Some(corr)) = latest(&sub_corr) {
                interp.set_correction(&corr);
            }
            if let Some(st) = newest_state {
                // Until the first command, hold where the robot is (after a restart the
                // drive may be anywhere): FK of the reported positions.
                if !commanded {
                    let kappa =
                        std::array::from_fn(|i| robot.steps_to_kappa(i, st.steps[i] as f64));
                    if let Ok(p) = robot.fk_warm(&kappa, &hold_guess) {
                        hold_guess = p;
                        interp.set_hold_commanded(p);
                    }
                }
            }
            // Self-protection: while a program runs or is paused, the drive must follow. If
            // its states stop (driver stalled or dead) or it holds on stale setpoints (IK gone),
            // the program goes back (once) to the setpoint the drive executed last, paused, so
            // that it continues from where the robot is; it resumes by itself once the drive
            // follows again unless somebody else paused it.
            let drive_ok = wake.saturating_sub(last_state_ns) <= 3 * period_ns && !drive_holding;
            let state = interp.status(t).state;
            if drive_ok {
                rewound = false;
            } else if !rewound && matches!(state, planner_state::RUNNING | planner_state::PAUSED) {
                if state == planner_state::RUNNING {
                    let _ = interp.command(&simple_command(command_kind::PAUSE, 0, 0));
                    auto_paused = true;
                }
                interp.rewind_to_seq(executed_seq);
                rewound = true;
                tracing::warn!(
                    seq = executed_seq,
                    "drive not following: held at its setpoint"
                );
            }
            if auto_paused && drive_ok && state == planner_state::PAUSED {
                let _ = interp.command(&simple_command(command_kind::RESUME, 0, 0));
                auto_paused = false;
                tracing::info!("drive following again: program resumed");
            }
            planner_emit(&mut interp, t, &pub_sp, &notify);
            let status = planning_status(interp.status(t), planning);
            if status.state != last_state {
                last_state = status.state;
                let _ = publish(&pub_status, status);
            }
            stats.record(monotonic_ns() - wake, latency);
        }
        if id.has_event_from(&hb) {
            let _ = publish(&pub_hb, stats.heartbeat(false));
            let _ = publish(&pub_status, planning_status(interp.status(t), planning));
            pcr_nodes::recheck(&guard);
        }
        CallbackProgression::Continue
    })
    .map_err(|e| anyhow!("waitset: {e:?}"))?;
    pcr_nodes::log_end(kind, r);
    eprintln!("{}", stats.summary());
    Ok(())
}

/// The status, showing a run being planned as `PLANNING` under its run id.
fn planning_status(mut st: PlannerStatus, planning: Option<u32>) -> PlannerStatus {
    if let Some(id) = planning {
        st.run_id = id;
        st.state = planner_state::PLANNING;
        st.progress_s = 0.0;
        st.duration_s = 0.0;
    }
    st
}
