//! The live view and the telemetry beyond the recording: the channels of `pcr-telemetry`
//! served over the Foxglove WebSocket protocol (`[live]`), fed with the processes' cycle
//! statistics, the corrections, the supervisor's log lines ([`say`]) and run events; outside a
//! run, the driver states (no file is attached then). During a run the same channels also go to
//! the run's MCAP ([`super::McapSink`]).

use super::processes::Proc;
use super::Supervisor;
use crate::config::{ProcessName, SupervisorConfig};
use anyhow::{anyhow, Result};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use pcr_messages::{services as s, Correction, DriverStateMsg};
use pcr_nodes::ChainNode;
use pcr_telemetry::{CycleStats, LiveServer, LogLines, RunEvent, RunEventKind, Telemetry};
use std::cell::RefCell;
use std::path::Path;
use std::rc::Rc;
use std::sync::Mutex;

pub(super) use pcr_telemetry::LogLevel as Level;

/// The log channel of the supervisor's telemetry (set by [`Live::new`]).
static LOG: Mutex<Option<LogLines>> = Mutex::new(None);

/// A line of the supervisor's log: on stderr (`pcr-supervisor: ...`) and on the `/log`
/// channel (`foxglove.Log`, chain time).
pub(super) fn say(level: Level, msg: &str) {
    eprintln!("pcr-supervisor: {msg}");
    if let Some(l) = LOG.lock().unwrap_or_else(|e| e.into_inner()).as_ref() {
        l.line(level, "pcr-supervisor", msg, pcr_nodes::chain_time_s());
    }
}

/// The telemetry channels, the live server (if configured) and the correction subscriber.
pub(super) struct Live {
    telemetry: Rc<RefCell<Telemetry>>,
    server: Option<LiveServer>,
    sub_correction: Option<Subscriber<ipc::Service, Correction, ()>>,
}

impl Live {
    /// The channels (the robot drawn from `robot`), and the live server of `[live]`.
    pub(super) fn new(cfg: &SupervisorConfig, robot: &Path) -> Result<Self> {
        let scene = match pcr_telemetry::convert::robot_scene(robot) {
            Ok(s) => Some(s),
            Err(e) => {
                tracing::warn!("the robot is not drawn on /robot: {e}");
                None
            }
        };
        let telemetry = Telemetry::new(scene)?;
        *LOG.lock().unwrap_or_else(|e| e.into_inner()) = Some(telemetry.log_lines());
        let server = match &cfg.live {
            Some(l) => {
                let server = LiveServer::start(&telemetry, "pcr-supervisor", &l.host, l.port)
                    .map_err(|e| anyhow!("key `live` (host, port): {e}"))?;
                eprintln!(
                    "pcr-supervisor: live view at {} (Foxglove: Open connection, Foxglove \
                     WebSocket; layout docs/foxglove-layout.json)",
                    server.url()
                );
                Some(server)
            }
            None => None,
        };
        Ok(Self {
            telemetry: Rc::new(RefCell::new(telemetry)),
            server,
            sub_correction: None,
        })
    }

    /// Subscribes to the corrections (configurations with a mocap process).
    pub(super) fn subscribe(&mut self, cfg: &SupervisorConfig, node: &ChainNode) -> Result<()> {
        if cfg.process.iter().any(|p| p.name == ProcessName::Mocap) {
            self.sub_correction = Some(node.subscriber::<Correction>(s::CORRECTION)?);
        }
        Ok(())
    }

    /// The channels (shared with a run's MCAP sink).
    pub(super) fn telemetry(&self) -> Rc<RefCell<Telemetry>> {
        self.telemetry.clone()
    }

    /// A run event.
    pub(super) fn event(
        &self,
        kind: RunEventKind,
        run_id: Option<u32>,
        process: Option<&str>,
        text: &str,
    ) {
        self.telemetry.borrow().event(
            &RunEvent {
                kind,
                run_id,
                process,
                text,
            },
            pcr_nodes::chain_time_s(),
        );
    }

    /// A process's newest heartbeat as its cycle statistics.
    pub(super) fn cycle_stats(&self, p: &Proc) {
        let r = self.telemetry.borrow_mut().cycle_stats(
            &CycleStats {
                process: p.name(),
                heartbeat: &p.hb,
                total_deadline_misses: p.misses(),
                restarts: p.restarts,
            },
            pcr_nodes::chain_time_s(),
        );
        if let Err(e) = r {
            tracing::warn!("cycle statistics of {}: {e}", p.name());
        }
    }

    /// A driver state outside a run (live view only).
    pub(super) fn idle_state(&self, st: &DriverStateMsg) {
        if self.server.is_some() {
            self.telemetry.borrow_mut().idle_state(st);
        }
    }

    /// The status line (`ctl status`), with a live server.
    pub(super) fn status_text(&self) -> Option<String> {
        self.server
            .as_ref()
            .map(|s| format!("live: {} ({} clients)", s.url(), s.clients()))
    }

    /// Stops the live server.
    pub(super) fn stop(&mut self) {
        if let Some(s) = self.server.take() {
            s.stop();
        }
        *LOG.lock().unwrap_or_else(|e| e.into_inner()) = None;
    }
}

impl Supervisor {
    /// The corrections of the outer loop, on their channel.
    pub(super) fn drain_corrections(&mut self) {
        let Some(sub) = &self.live.sub_correction else {
            return;
        };
        while let Ok(Some(smp)) = sub.receive() {
            self.live.telemetry.borrow().correction(smp.payload());
        }
    }
}
