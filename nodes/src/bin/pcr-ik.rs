//! `pcr-ik`: the IK process. Wakes on the task-setpoint event (its hop listener,
//! [`pcr_nodes::hop`]), solves the newest setpoint and publishes the joint setpoint (+ event);
//! heartbeats when its ticker says so.

use anyhow::{anyhow, Context, Result};
use clap::Parser;
use pcr_control::IkStep;
use pcr_kinematics::Robot;
use pcr_messages::{monotonic_ns, services as s, Heartbeat, JointSetpoint, NodeKind, TaskSetpoint};
use pcr_nodes::hop;
use pcr_nodes::{cycle::ik_on_setpoint, publish, CommonArgs, CycleStats};
use pcr_robot::RobotConfig;

#[derive(Parser, Debug)]
#[command(about = "pcr-ik: task setpoint -> motor steps")]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
}

fn main() -> std::process::ExitCode {
    pcr_nodes::init_logging();
    match run(Args::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("pcr-ik: error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(a: Args) -> Result<()> {
    let kind = NodeKind::Ik;
    let c = &a.common;
    let robot_cfg = RobotConfig::load(&c.robot).with_context(|| format!("robot {}", c.robot))?;
    let robot = Robot::new(&robot_cfg).map_err(|e| anyhow!("robot model: {e}"))?;
    let (cn, guard) = pcr_nodes::startup(kind, c)?;
    let sub = cn.subscriber::<TaskSetpoint>(s::TASK_SETPOINT)?;
    let listener = cn.hop_listener(s::TASK_SETPOINT)?;
    let pub_j = cn.publisher::<JointSetpoint>(s::JOINT_SETPOINT)?;
    let notify = cn.hop_notifier(s::JOINT_SETPOINT)?;
    let pub_hb = cn.publisher::<Heartbeat>(s::HEARTBEAT)?;
    pcr_nodes::realtime::apply(c.rt_priority, c.cpu, c.mlockall);

    let mut ik = IkStep::new(robot);
    let period_ns = c.period().as_nanos() as u64;
    let mut stats = CycleStats::new(kind, c.protocol_version, period_ns);
    let mut last_rx = monotonic_ns();

    let _ticker = hop::start("pcr-ik", c, s::TASK_SETPOINT, None)?;

    loop {
        let w = hop::wait(&listener)?;
        if w.terminate {
            break;
        }
        if w.sample {
            if let Some((rx, latency)) = ik_on_setpoint(&sub, &mut ik, &pub_j, &notify) {
                last_rx = rx;
                stats.record(monotonic_ns() - rx, latency);
            }
        }
        if w.heartbeat {
            let stale = monotonic_ns() - last_rx > 2 * period_ns;
            if stale {
                stats.stale_input();
            }
            let _ = publish(&pub_hb, stats.heartbeat(stale));
            pcr_nodes::recheck(&guard);
        }
    }
    tracing::info!(kind = kind.name(), "terminating cleanly");
    eprintln!("{} ({} IK failures)", stats.summary(), ik.failures());
    Ok(())
}
