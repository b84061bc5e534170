//! `pcr-mocap`: the motion-capture correction process. Every driver state carries the pose
//! measured in that cycle (the simulated plant's capture view, or FK of the motor positions on
//! the ideal drive); the process republishes it as the measured pose and runs the correction
//! step ([`CorrectionStep`]): the error against the pose planned at the measurement's time
//! (latency compensated) is integrated into a task-space offset that the planner adds to later
//! setpoints. Gain 0 (the default) only reports the error.

use anyhow::{anyhow, Result};
use clap::Parser;
use iceoryx2::prelude::*;
use pcr_control::{measured_of, CorrectionConfig, CorrectionStep};
use pcr_messages::{
    monotonic_ns, services as s, Correction, DriverStateMsg, Heartbeat, MeasuredPose, NodeKind,
};
use pcr_nodes::{ports::latest, CommonArgs, CycleStats};

#[derive(Parser, Debug)]
#[command(about = "pcr-mocap: measured pose and task-space correction")]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// Integral correction gain per cycle, 0..=1 (0 = report the error only).
    #[arg(long, default_value_t = 0.0)]
    gain: f64,
    /// Bound of the correction offset, mm (orientation: this / 100 rad).
    #[arg(long, default_value_t = 5.0)]
    limit_mm: f64,
    /// Age of a measurement when reported (capture latency), ms.
    #[arg(long, default_value_t = 10.0)]
    latency_ms: f64,
}

fn main() -> std::process::ExitCode {
    pcr_nodes::init_logging();
    match run(Args::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("pcr-mocap: error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(a: Args) -> Result<()> {
    let kind = NodeKind::Mocap;
    let c = &a.common;
    let cfg = CorrectionConfig {
        gain: a.gain,
        limit_mm: a.limit_mm,
        latency_s: a.latency_ms * 1e-3,
    };
    cfg.validate()
        .map_err(|e| anyhow!("--{}", e.to_string().replace('_', "-")))?;
    let (cn, guard) = pcr_nodes::startup(kind, c)?;
    let sub = cn.subscriber::<DriverStateMsg>(s::DRIVER_STATE)?;
    let listener = cn.listener(s::DRIVER_STATE)?;
    let pub_m = cn.publisher::<MeasuredPose>(s::MEASURED_POSE)?;
    let pub_c = cn.publisher::<Correction>(s::CORRECTION)?;
    let pub_hb = cn.publisher::<Heartbeat>(s::HEARTBEAT)?;
    pcr_nodes::realtime::apply(c.rt_priority, c.cpu, c.mlockall);

    let mut corr = CorrectionStep::new(cfg);
    let period_ns = c.period().as_nanos() as u64;
    let mut stats = CycleStats::new(kind, c.protocol_version, period_ns);
    let mut last_rx = monotonic_ns();

    let ws = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .map_err(|e| anyhow!("waitset: {e:?}"))?;
    let ev = ws
        .attach_notification(&listener)
        .map_err(|e| anyhow!("attach: {e:?}"))?;
    let hb = ws
        .attach_interval(c.heartbeat())
        .map_err(|e| anyhow!("interval: {e:?}"))?;
    let r = pcr_nodes::run_waitset(&ws, |id| {
        if id.has_event_from(&ev) {
            let _ = listener.try_wait(|_| {});
            let rx = monotonic_ns();
            if let Ok(Some(st)) = latest(&sub) {
                last_rx = rx;
                let m = measured_of(&st);
                let _ = pub_m.send_copy(m);
                let _ = pub_c.send_copy(corr.step(&m, st.t_s, &st.planned));
                stats.record(monotonic_ns() - rx, 0);
            }
        }
        if id.has_event_from(&hb) {
            let stale = monotonic_ns() - last_rx > 2 * period_ns;
            if stale {
                stats.stale_input();
            }
            let _ = pub_hb.send_copy(stats.heartbeat(stale));
            pcr_nodes::recheck(&guard);
        }
        CallbackProgression::Continue
    })
    .map_err(|e| anyhow!("waitset: {e:?}"))?;
    pcr_nodes::log_end(kind, r);
    eprintln!("{}", stats.summary());
    Ok(())
}
