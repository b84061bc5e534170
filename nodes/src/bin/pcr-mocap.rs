//! `pcr-mocap`: the correction process. PLACEHOLDER until the mocap bridge exists: it takes the
//! pose measured by the driver backend (interim plant: FK of the motor positions), republishes it
//! as the measured pose and publishes a zero (pass-through) correction.

use anyhow::{anyhow, Result};
use clap::Parser;
use iceoryx2::prelude::*;
use pcr_control::{measured_of, CorrectionStep};
use pcr_messages::{
    monotonic_ns, services as s, Correction, DriverStateMsg, Heartbeat, MeasuredPose, NodeKind,
};
use pcr_nodes::{ports::latest, CommonArgs, CycleStats};

#[derive(Parser, Debug)]
#[command(about = "pcr-mocap: measured pose and task-space correction (pass-through placeholder)")]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// Integral correction gain per cycle (0 = pass-through).
    #[arg(long, default_value_t = 0.0)]
    gain: f64,
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
    let (cn, guard) = pcr_nodes::startup(kind, c)?;
    let sub = cn.subscriber::<DriverStateMsg>(s::DRIVER_STATE)?;
    let listener = cn.listener(s::DRIVER_STATE)?;
    let pub_m = cn.publisher::<MeasuredPose>(s::MEASURED_POSE)?;
    let pub_c = cn.publisher::<Correction>(s::CORRECTION)?;
    let pub_hb = cn.publisher::<Heartbeat>(s::HEARTBEAT)?;
    pcr_nodes::realtime::apply(c.rt_priority, c.cpu, c.mlockall);

    let mut corr = CorrectionStep::new(a.gain, 5.0);
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
                let _ = pub_c.send_copy(corr.step(&m, &st.planned));
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
