//! `pcr-mocap`: the motion-capture correction process. The measured pose comes either from
//! the driver states (`--source driver`: the pose sensor of the driver backend, i.e. the
//! simulated plant's capture view or FK of the motor positions on the ideal drive) or from the
//! motion-capture bridge (`--source qtm`: `pcr-qtm`'s [`MocapSample`]s, in every configuration
//! with a capture system). The process republishes it as the measured pose and runs the
//! correction step ([`CorrectionStep`]): the error against the pose planned at the
//! measurement's time (latency compensated) is integrated into a task-space offset that the
//! planner adds to later setpoints. Gain 0 (the default) only reports the error.
//!
//! With `--source qtm` each driver cycle is integrated at most once, with the newest sample
//! that arrives after it; when no sample is newer than `--stale-ms` at a driver cycle, the
//! correction is held (offset kept, nothing integrated, [`correction_flags::HELD`]: the planner
//! flags its setpoints uncorrected) until samples return.

use anyhow::{anyhow, Result};
use clap::{Parser, ValueEnum};
use iceoryx2::prelude::*;
use pcr_control::{CorrectionConfig, CorrectionStep};
use pcr_messages::{
    correction_flags, monotonic_ns, services as s, Correction, DriverStateMsg, Heartbeat,
    MeasuredPose, MocapSample, NodeKind, PROTOCOL_VERSION,
};
use pcr_nodes::{cycle::mocap_on_state, ports::latest, publish, CommonArgs, CycleStats};

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
    /// Where the measured pose comes from.
    #[arg(long, value_enum, default_value = "driver")]
    source: Source,
    /// `--source qtm`: no sample for this long at a driver cycle holds the correction, ms.
    #[arg(long, default_value_t = 100.0)]
    stale_ms: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Source {
    /// The driver backend's pose sensor (in the driver states).
    Driver,
    /// The motion-capture bridge (`pcr-qtm`).
    Qtm,
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
    if a.source == Source::Qtm {
        return run_qtm(&a, cfg);
    }
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
            if let Some(rx) = mocap_on_state(&listener, &sub, &mut corr, &pub_m, &pub_c) {
                last_rx = rx;
                stats.record(monotonic_ns() - rx, 0);
            }
        }
        if id.has_event_from(&hb) {
            let stale = monotonic_ns() - last_rx > 2 * period_ns;
            if stale {
                stats.stale_input();
            }
            let _ = publish(&pub_hb, stats.heartbeat(stale));
            pcr_nodes::recheck(&guard);
        }
        CallbackProgression::Continue
    })
    .map_err(|e| anyhow!("waitset: {e:?}"))?;
    pcr_nodes::log_end(kind, r);
    eprintln!("{}", stats.summary());
    Ok(())
}

/// `--source qtm`: driver states give the planned poses, bridge samples the measurements.
fn run_qtm(a: &Args, cfg: CorrectionConfig) -> Result<()> {
    let kind = NodeKind::Mocap;
    let c = &a.common;
    let (cn, guard) = pcr_nodes::startup(kind, c)?;
    let sub_st = cn.subscriber::<DriverStateMsg>(s::DRIVER_STATE)?;
    let lis_st = cn.listener(s::DRIVER_STATE)?;
    let sub_m = cn.subscriber::<MocapSample>(s::MOCAP)?;
    let lis_m = cn.listener(s::MOCAP)?;
    let pub_m = cn.publisher::<MeasuredPose>(s::MEASURED_POSE)?;
    let pub_c = cn.publisher::<Correction>(s::CORRECTION)?;
    let pub_hb = cn.publisher::<Heartbeat>(s::HEARTBEAT)?;
    pcr_nodes::realtime::apply(c.rt_priority, c.cpu, c.mlockall);

    let mut corr = CorrectionStep::new(cfg);
    let period_ns = c.period().as_nanos() as u64;
    let stale_ns = (a.stale_ms.max(1.0) * 1e6) as u64;
    let mut stats = CycleStats::new(kind, c.protocol_version, period_ns);
    // pub_ns of the newest sample, and the newest driver cycle not yet integrated
    let mut last_sample_ns = 0u64;
    let mut pending = false;
    let mut held = false;

    let ws = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .map_err(|e| anyhow!("waitset: {e:?}"))?;
    let ev_st = ws
        .attach_notification(&lis_st)
        .map_err(|e| anyhow!("attach: {e:?}"))?;
    let ev_m = ws
        .attach_notification(&lis_m)
        .map_err(|e| anyhow!("attach: {e:?}"))?;
    let hb = ws
        .attach_interval(c.heartbeat())
        .map_err(|e| anyhow!("interval: {e:?}"))?;
    let r = pcr_nodes::run_waitset(&ws, |id| {
        if id.has_event_from(&ev_st) {
            let _ = lis_st.try_wait(|_| {});
            let rx = monotonic_ns();
            if let Ok(Some(st)) = latest(&sub_st) {
                corr.observe(st.t_s, &st.planned);
                pending = true;
                if rx.saturating_sub(last_sample_ns) > stale_ns {
                    if !held {
                        tracing::warn!("no motion-capture data: correction held (uncorrected)");
                        held = true;
                    }
                    stats.stale_input();
                    let _ = publish(&pub_c, corr.hold(st.t_s, st.seq));
                }
                stats.record(monotonic_ns() - rx, 0);
            }
        }
        if id.has_event_from(&ev_m) {
            let _ = lis_m.try_wait(|_| {});
            let rx = monotonic_ns();
            if let Ok(Some(m)) = latest(&sub_m) {
                last_sample_ns = rx;
                if held {
                    tracing::info!("motion-capture data back: correction resumes");
                    held = false;
                }
                let pose = m.pose();
                let meas = MeasuredPose {
                    t_s: m.t_s,
                    pose: pose.unwrap_or([f64::NAN; 3]),
                    seq: m.seq,
                    valid: u32::from(pose.is_some()),
                    version: PROTOCOL_VERSION,
                };
                let _ = publish(&pub_m, meas);
                if pending {
                    pending = false;
                    let out = corr.measure(&meas);
                    debug_assert_eq!(out.flags & correction_flags::HELD, 0);
                    let _ = publish(&pub_c, out);
                }
            }
        }
        if id.has_event_from(&hb) {
            let _ = publish(&pub_hb, stats.heartbeat(held));
            pcr_nodes::recheck(&guard);
        }
        CallbackProgression::Continue
    })
    .map_err(|e| anyhow!("waitset: {e:?}"))?;
    pcr_nodes::log_end(kind, r);
    eprintln!("{}", stats.summary());
    Ok(())
}
