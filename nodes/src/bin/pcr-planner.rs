//! `pcr-planner`: the interpolator process. Every period (default 20 ms, iceoryx2 interval) it
//! applies pending commands and publishes one task setpoint (+ event); it reports status and
//! heartbeats. Source: the interim path generator until `pcr-planner`'s interpolator lands.

use anyhow::{anyhow, Context, Result};
use clap::Parser;
use iceoryx2::prelude::*;
use pcr_control::{simple_command, InterpolatorStep, MotionLimits, PlannerSource};
use pcr_kinematics::{Pose, Robot};
use pcr_messages::{
    command_kind, driver_flags, monotonic_ns, planner_state, services as s, Command, Correction,
    DriverStateMsg, Heartbeat, NodeKind, PlannerStatus, TaskSetpoint,
};
use pcr_nodes::{chain_time_s, ports::latest, CommonArgs, CycleStats};
use pcr_robot::RobotConfig;

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
    let notify = cn.notifier(s::TASK_SETPOINT)?;
    let pub_status = cn.publisher::<PlannerStatus>(s::STATUS)?;
    let pub_hb = cn.publisher::<Heartbeat>(s::HEARTBEAT)?;
    let sub_cmd = cn.subscriber::<Command>(s::COMMAND)?;
    let sub_corr = cn.subscriber::<Correction>(s::CORRECTION)?;
    let sub_state = cn.subscriber::<DriverStateMsg>(s::DRIVER_STATE)?;
    pcr_nodes::realtime::apply(c.rt_priority, c.cpu, c.mlockall);

    let mut interp = InterpolatorStep::new(
        PlannerSource::new(robot.clone(), MotionLimits::default()),
        Pose::default(),
    );
    let mut commanded = false;
    let mut hold_guess = Pose::default();
    let period_ns = c.period().as_nanos() as u64;
    let mut stats = CycleStats::new(kind, c.protocol_version, period_ns);
    let mut last_wake: Option<u64> = None;
    let mut last_state = u32::MAX;
    let mut executed_seq = 0u64;
    let mut last_state_ns = monotonic_ns();
    let mut drive_holding = false;
    let mut auto_paused = false;

    let ws = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .map_err(|e| anyhow!("waitset: {e:?}"))?;
    let tick = ws
        .attach_interval(c.period())
        .map_err(|e| anyhow!("interval: {e:?}"))?;
    let hb = ws
        .attach_interval(c.heartbeat())
        .map_err(|e| anyhow!("interval: {e:?}"))?;

    let r = pcr_nodes::run_waitset(&ws, |id| {
        let t = chain_time_s();
        if id.has_event_from(&tick) {
            let wake = monotonic_ns();
            let jitter = last_wake.map_or(0, |l| (wake - l).abs_diff(period_ns));
            last_wake = Some(wake);
            // Driver states first: the last setpoint the drive executed.
            let newest_state = latest(&sub_state).ok().flatten();
            if let Some(st) = &newest_state {
                executed_seq = st.seq;
                last_state_ns = wake;
                drive_holding = st.flags & driver_flags::STALE_HOLD != 0;
            }
            while let Ok(Some(cmd)) = sub_cmd.receive() {
                match interp.command(cmd.payload()) {
                    Ok(()) => {
                        commanded = true;
                        tracing::info!(kind = cmd.kind, run_id = cmd.run_id, "command");
                        // A pause holds where the robot is: back to the setpoint the
                        // drive executed last (it may have stopped on stale setpoints).
                        if cmd.kind == command_kind::PAUSE {
                            auto_paused = false;
                        }
                        if cmd.kind == command_kind::PAUSE && interp.rewind_to_seq(executed_seq) {
                            tracing::info!(seq = executed_seq, "paused at the executed setpoint");
                        }
                    }
                    Err(e) => tracing::error!("command refused: {e}"),
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
                        interp.set_hold(p);
                    }
                }
            }
            // Self-protection: while a program runs, the drive must follow. If its states stop
            // (driver stalled or dead) or it holds on stale setpoints (IK gone), pause at the
            // setpoint it executed last; resume once it follows again.
            let drive_ok = wake.saturating_sub(last_state_ns) <= 3 * period_ns && !drive_holding;
            let state = interp.status(t).state;
            if state == planner_state::RUNNING && !drive_ok {
                let _ = interp.command(&simple_command(command_kind::PAUSE, 0, 0));
                interp.rewind_to_seq(executed_seq);
                auto_paused = true;
                tracing::warn!(seq = executed_seq, "drive not following: program paused");
            } else if auto_paused && drive_ok && state == planner_state::PAUSED {
                let _ = interp.command(&simple_command(command_kind::RESUME, 0, 0));
                auto_paused = false;
                tracing::info!("drive following again: program resumed");
            }
            let mut sp = interp.step(t);
            sp.stamps.interp_pub_ns = monotonic_ns();
            let _ = pub_sp.send_copy(sp);
            let _ = notify.notify();
            let status = interp.status(t);
            if status.state != last_state {
                last_state = status.state;
                let _ = pub_status.send_copy(status);
            }
            stats.record(monotonic_ns() - wake, jitter);
        }
        if id.has_event_from(&hb) {
            let _ = pub_hb.send_copy(stats.heartbeat(false));
            let _ = pub_status.send_copy(interp.status(t));
            pcr_nodes::recheck(&guard);
        }
        CallbackProgression::Continue
    })
    .map_err(|e| anyhow!("waitset: {e:?}"))?;
    pcr_nodes::log_end(kind, r);
    eprintln!("{}", stats.summary());
    Ok(())
}
