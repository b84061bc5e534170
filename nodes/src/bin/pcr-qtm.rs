//! `pcr-qtm`: the motion-capture bridge process. Streams 6DOF Euler and 3-D frames from a
//! Qualisys QTM RT server (the lab's, or the simulator the driver's plant backend serves),
//! maps them into the robot base frame with a registration, and publishes every frame as a
//! [`MocapSample`] (+ event) on iceoryx2: the platform pose and the base and joint markers.
//!
//! A lost or stalled connection is re-established with back-off (`pcr_mocap_bridge::QtmSource`);
//! meanwhile nothing is published and the heartbeat reports the process as holding, so that
//! the correction holds its offset. `--registration auto` registers from the base markers
//! at every (re)connection (simulation); a file from `pcr qtm register` is applied as it is
//! (lab).

use anyhow::{anyhow, Context, Result};
use clap::Parser;
use pcr_messages::{mocap_valid, monotonic_ns, services as s, Heartbeat, MocapSample, NodeKind};
use pcr_mocap_bridge::{
    ClientConfig, Frame, Mapper, MarkerLabels, QtmSource, Registration, SourceEvent, StreamRate,
};
use pcr_nodes::{publish, CommonArgs, CycleStats};
use pcr_robot::RobotConfig;
use std::time::{Duration, Instant};

#[derive(Parser, Debug)]
#[command(about = "pcr-qtm: Qualisys QTM RT bridge (measured pose and markers on iceoryx2)")]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// QTM host.
    #[arg(long, default_value = "127.0.0.1")]
    host: String,
    /// QTM RT port (little-endian).
    #[arg(long, default_value_t = pcr_mocap_bridge::wire::DEFAULT_PORT)]
    port: u16,
    /// Registration file (`pcr qtm register`), or `auto`: register from the base markers at
    /// every connection.
    #[arg(long, default_value = "auto")]
    registration: String,
    /// The platform's 6DOF body (default: the first body).
    #[arg(long)]
    body: Option<String>,
    /// A frame older than this no longer counts as a measurement, ms.
    #[arg(long, default_value_t = 100.0)]
    stale_ms: f64,
    /// No frame for this long: the stream has stalled (reconnect), ms.
    #[arg(long, default_value_t = 500.0)]
    stall_ms: f64,
    /// Ask QTM for about this many frames per second (default: all frames).
    #[arg(long)]
    frequency: Option<u32>,
    /// Automatic registration: frames averaged.
    #[arg(long, default_value_t = 50)]
    register_frames: usize,
    /// Automatic registration: the largest residual accepted, mm.
    #[arg(long, default_value_t = pcr_mocap_bridge::registration::DEFAULT_MAX_RESIDUAL_MM)]
    max_residual_mm: f64,
}

fn main() -> std::process::ExitCode {
    pcr_nodes::init_logging();
    match run(Args::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("pcr-qtm: error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(a: Args) -> Result<()> {
    let kind = NodeKind::Qtm;
    let c = &a.common;
    let robot = RobotConfig::load(&c.robot).with_context(|| format!("robot {}", c.robot))?;
    let base: [[f64; 2]; 3] = std::array::from_fn(|i| robot.legs[i].base_point());
    let fixed = match a.registration.as_str() {
        "auto" => None,
        f => Some(Registration::load(f)?),
    };
    let labels = MarkerLabels::default();
    let (cn, guard) = pcr_nodes::startup(kind, c)?;
    let pub_s = cn.publisher::<MocapSample>(s::MOCAP)?;
    let notify = cn.notifier(s::MOCAP)?;
    let pub_hb = cn.publisher::<Heartbeat>(s::HEARTBEAT)?;
    pcr_nodes::realtime::apply(c.rt_priority, c.cpu, c.mlockall);

    let mut cfg = ClientConfig::new(&a.host, a.port);
    cfg.stall_timeout = Duration::from_secs_f64(a.stall_ms.max(10.0) * 1e-3);
    cfg.rate = a
        .frequency
        .map_or(StreamRate::AllFrames, StreamRate::Frequency);
    let mut src = QtmSource::new(cfg);
    let stale_ns = (a.stale_ms.max(1.0) * 1e6) as u64;
    let mut stats = CycleStats::new(kind, c.protocol_version, c.period().as_nanos() as u64);
    let hb_period = c.heartbeat();
    let mut next_hb = Instant::now() + hb_period;
    let mut mapper: Option<Mapper> = None;
    let mut collecting: Vec<Frame> = Vec::new();
    let mut seq = 0u64;
    let mut last_pub_ns = 0u64;
    let mut was_lost = false;
    tracing::info!(host = %a.host, port = a.port, registration = %a.registration, "pcr-qtm");
    loop {
        match cn.node.wait(Duration::ZERO) {
            Err(iceoryx2::node::NodeWaitFailure::TerminationRequest) => break,
            Err(iceoryx2::node::NodeWaitFailure::Interrupt) | Ok(()) => {}
        }
        let until = next_hb.min(Instant::now() + Duration::from_millis(50));
        match src.poll(until) {
            SourceEvent::Connected => {
                let p = src.parameters().cloned().unwrap_or_default();
                tracing::info!(
                    version = ?src.version(),
                    labels = %p.labels.join(","),
                    bodies = %p.bodies.join(","),
                    frequency_hz = ?p.frequency_hz,
                    "QTM connected"
                );
                was_lost = false;
                collecting.clear();
                mapper = match &fixed {
                    Some(r) => Some(
                        Mapper::new(&p, a.body.as_deref(), &labels, r.clone())
                            .map_err(|e| anyhow!("{e}"))?,
                    ),
                    None => None,
                };
            }
            SourceEvent::Frame => {
                let rx = src.rx_ns();
                let Some(f) = src.frame() else { continue };
                if mapper.is_none() {
                    collecting.push(f.clone());
                    if collecting.len() >= a.register_frames.max(3) {
                        let p = src.parameters().cloned().unwrap_or_default();
                        match Registration::from_frames(
                            &p,
                            &collecting,
                            &labels,
                            &base,
                            a.max_residual_mm,
                        ) {
                            Ok(r) => {
                                let (dx, dy, dphi) = r.planar_capture_frame();
                                tracing::info!(
                                    residuals = %r.residuals_text(),
                                    "registered: capture frame dx {dx:.3} mm, dy {dy:.3} mm, \
                                     dphi {:.4} deg",
                                    dphi.to_degrees()
                                );
                                mapper = Some(
                                    Mapper::new(&p, a.body.as_deref(), &labels, r)
                                        .map_err(|e| anyhow!("{e}"))?,
                                );
                            }
                            Err(e) => tracing::error!("automatic registration: {e}"),
                        }
                        collecting.clear();
                    }
                    continue;
                }
                let Some(m) = &mapper else { continue };
                let r = m.map(f);
                let mut valid = mocap_valid::LINK;
                let v3 = |o: Option<[f64; 3]>| o.unwrap_or([f64::NAN; 3]);
                if r.pose.is_some() {
                    valid |= mocap_valid::POSE;
                }
                for i in 0..3 {
                    if r.base[i].is_some() {
                        valid |= mocap_valid::BASE << i;
                    }
                    if r.joints[i].is_some() {
                        valid |= mocap_valid::JOINT << i;
                    }
                }
                seq += 1;
                let sample = MocapSample {
                    t_s: src.frame_time_ns() as f64 * 1e-9,
                    rx_ns: rx,
                    pub_ns: 0,
                    qtm_timestamp_us: f.timestamp_us,
                    seq,
                    frame_number: f.frame_number,
                    valid,
                    pose: r.pose.unwrap_or([f64::NAN; 3]),
                    base: r.base.map(v3),
                    joints: r.joints.map(v3),
                    version: c.protocol_version,
                    reserved: 0,
                };
                let now = monotonic_ns();
                let _ = publish(
                    &pub_s,
                    MocapSample {
                        pub_ns: now,
                        ..sample
                    },
                );
                let _ = notify.notify();
                last_pub_ns = now;
                stats.record(now.saturating_sub(rx), 0);
            }
            SourceEvent::Lost(e) => {
                if !was_lost {
                    tracing::warn!("QTM link lost: {e}; reconnecting with back-off");
                    was_lost = true;
                }
            }
            SourceEvent::NoMoreData => tracing::debug!("QTM: no measurement running"),
            SourceEvent::Event(e) => tracing::info!(event = e, "QTM event"),
            SourceEvent::Idle => {}
        }
        if Instant::now() >= next_hb {
            next_hb += hb_period;
            if next_hb < Instant::now() {
                next_hb = Instant::now() + hb_period;
            }
            let stale = monotonic_ns().saturating_sub(last_pub_ns) > stale_ns;
            if stale {
                stats.stale_input();
            }
            let _ = publish(&pub_hb, stats.heartbeat(stale));
            pcr_nodes::recheck(&guard);
        }
    }
    tracing::info!(kind = kind.name(), "terminating cleanly");
    eprintln!(
        "{} (QTM connections {}, losses {}, frames {})",
        stats.summary(),
        src.stats.connects,
        src.stats.losses,
        src.stats.frames
    );
    Ok(())
}
