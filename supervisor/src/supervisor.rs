//! The supervision loop: one iceoryx2 WaitSet interval (20 ms) that watches the children, drains
//! heartbeats, status and driver states (recording), serves the control socket and runs programs.
//!
//! One module per concern, each a part of [`Supervisor`]:
//! - [`processes`]: the process table and its restart policy (start, watch, fail, stop);
//! - [`lifecycle`]: the run lifecycle (start, the planner's status and refusals, pauses while
//!   processes restart, recovery, the end and its summary);
//! - [`recording`]: a run's recording through its sinks ([`RunSink`]: the CSV and the MCAP
//!   beside it) and the matching of rows with the capture system's samples;
//! - [`control`]: the control socket and its requests (`pcr-supervisor ctl ...`);
//! - [`live`]: the live view (`[live]`, Foxglove WebSocket), the cycle statistics, corrections,
//!   log lines and run events on the telemetry channels.

mod control;
mod lifecycle;
mod live;
mod processes;
mod recording;

pub use recording::{CsvSink, McapSink, RunSink, SinkError};

use crate::config::SupervisorConfig;
use anyhow::{anyhow, Context, Result};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use pcr_control::command_of_moves;
use pcr_messages::{
    services as s, Command, DriverStateMsg, Heartbeat, MocapSample, NodeKind, PlannerStatus,
    Refusal, PROTOCOL_VERSION,
};
use pcr_nodes::{ChainNode, ProtocolGuard};
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use control::ControlSocket;
use lifecycle::{Preparing, Run};
use live::Live;
use processes::{ms, Proc};
use recording::MOCAP_RING;

/// Exit code after a safe stop.
pub const EXIT_SAFE_STOP: i32 = 2;
/// Exit code when a `--run` program failed (refused, aborted, timed out).
pub const EXIT_RUN_FAILED: i32 = 1;

/// Options from the command line.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// Run this program (`paper`, `circle`, `square`) and exit.
    pub run: Option<String>,
    /// Run this program file (TOML, see [`program_command`]) and exit.
    pub run_file: Option<PathBuf>,
    /// Directory of the process binaries.
    pub bin_dir: PathBuf,
}

impl Options {
    /// True when the supervisor runs one program and exits (`--run` or `--run-file`).
    pub fn one_shot(&self) -> bool {
        self.run.is_some() || self.run_file.is_some()
    }
}

/// The name of a program file's runs (and recordings): its file stem.
pub fn program_name(file: &Path) -> String {
    file.file_stem()
        .map_or_else(|| "program".into(), |s| s.to_string_lossy().into_owned())
}

/// Reads a program file (TOML: lines, arcs, dwells, joint moves; see `docs/planner.md`) and
/// converts it into a RUN command (run id 0). Errors name the file, and the key or segment.
pub fn program_command(file: &Path) -> Result<Command, String> {
    let name = file.display().to_string();
    let prog = pcr_planner::program::load(&name, &pcr_planner::program::Defaults::default())
        .map_err(|e| e.to_string())?;
    let moves = pcr_control::moves_of_program(&prog);
    if moves.len() > pcr_messages::MAX_MOVES {
        return Err(format!(
            "{name}: {} segments, but one command holds at most {} moves: split the program",
            moves.len(),
            pcr_messages::MAX_MOVES
        ));
    }
    command_of_moves(0, &moves).map_err(|e| format!("{name}: {e}"))
}

/// The supervisor.
pub struct Supervisor {
    cfg: SupervisorConfig,
    opts: Options,
    robot_path: PathBuf,
    procs: Vec<Proc>,
    node: ChainNode,
    guard: ProtocolGuard,
    pub_cmd: Publisher<ipc::Service, Command, ()>,
    sub_hb: Subscriber<ipc::Service, Heartbeat, ()>,
    sub_state: Subscriber<ipc::Service, DriverStateMsg, ()>,
    sub_status: Subscriber<ipc::Service, PlannerStatus, ()>,
    sub_refusal: Subscriber<ipc::Service, Refusal, ()>,
    /// The verdict of the last finished run (`verdict N` after the run is over).
    last_verdict: Option<(u32, String)>,
    /// The bridge's samples (configurations with a capture system).
    sub_mocap: Option<Subscriber<ipc::Service, MocapSample, ()>>,
    /// The newest bridge samples, oldest first.
    mocap: VecDeque<MocapSample>,
    /// When the newest bridge sample arrived.
    mocap_at: Option<Instant>,
    /// The capture system's port (resolved when the configuration says 0).
    qtm_port: u16,
    socket: ControlSocket,
    /// The telemetry channels, the live server and what feeds them beyond the recording.
    live: Live,
    run: Option<Run>,
    next_run_id: u32,
    /// An experiment being designed off the loop (`ctl run experiment`): its run id, name and
    /// the worker's answer.
    preparing: Option<Preparing>,
    safe_stop: Option<String>,
    exit: Option<i32>,
    requested_run_started: bool,
    last_hello: Instant,
    start: Instant,
    last_summary: Option<String>,
    /// The PM QoS request (`[realtime] cpu_dma_latency_us`), held while the supervisor lives.
    _cpu_latency: Option<std::fs::File>,
}

impl Supervisor {
    /// Sets up the supervisor's node, ports, control socket and live view (no process started
    /// yet).
    pub fn new(cfg: SupervisorConfig, opts: Options) -> Result<Self> {
        let robot_path = std::fs::canonicalize(&cfg.robot)
            .with_context(|| format!("key `robot`: robot configuration {:?}", cfg.robot))?;
        for p in &cfg.process {
            let b = opts.bin_dir.join(p.name.binary());
            if !b.exists() {
                return Err(anyhow!(
                    "process {}: binary {} not found (build with `cargo build -p pcr-nodes`, or \
                     set `bin_dir`)",
                    p.name.as_str(),
                    b.display()
                ));
            }
        }
        // The live view first: a busy port is refused before anything of the chain exists
        // (after the clearer refusal of a second supervisor of the same configuration).
        ControlSocket::check_free(&cfg.socket_path())?;
        let mut live = Live::new(&cfg, &robot_path)?;
        let node = ChainNode::new(
            &format!("pcr-supervisor-{}", std::process::id()),
            &cfg.iceoryx2_prefix,
            PROTOCOL_VERSION,
        )?;
        let guard = ProtocolGuard::new(&node, NodeKind::Supervisor)?;
        if let Err(m) = guard.handshake(Duration::from_millis(200)) {
            return Err(anyhow!("{}", m.message));
        }
        let pub_cmd = node.publisher::<Command>(s::COMMAND)?;
        let sub_hb = node.subscriber::<Heartbeat>(s::HEARTBEAT)?;
        let sub_state = node.subscriber::<DriverStateMsg>(s::DRIVER_STATE)?;
        let sub_status = node.subscriber::<PlannerStatus>(s::STATUS)?;
        let sub_refusal = node.subscriber::<Refusal>(s::REFUSAL)?;
        let sub_mocap = match &cfg.capture {
            Some(_) => Some(node.subscriber::<MocapSample>(s::MOCAP)?),
            None => None,
        };
        let qtm_port = match &cfg.capture {
            Some(c) if c.simulate && c.port == 0 => {
                let l = std::net::TcpListener::bind((c.host.as_str(), 0))
                    .with_context(|| format!("key `capture.host`: cannot listen on {}", c.host))?;
                l.local_addr()?.port()
            }
            Some(c) => c.port,
            None => 0,
        };
        if let Some(c) = &cfg.capture {
            eprintln!(
                "pcr-supervisor: capture system QTM at {}:{qtm_port}{}",
                c.host,
                if c.simulate {
                    " (simulated by the driver's plant)"
                } else {
                    ""
                }
            );
        }
        live.subscribe(&cfg, &node)?;
        let socket = ControlSocket::bind(&cfg.socket_path())?;
        let now = Instant::now();
        let procs = processes::table(&cfg, now);
        let cpu_latency = cfg
            .realtime
            .cpu_dma_latency_us
            .and_then(pcr_nodes::realtime::hold_cpu_dma_latency);
        Ok(Self {
            cfg,
            opts,
            robot_path,
            procs,
            node,
            guard,
            pub_cmd,
            sub_hb,
            sub_state,
            sub_status,
            sub_refusal,
            last_verdict: None,
            sub_mocap,
            mocap: VecDeque::with_capacity(MOCAP_RING),
            mocap_at: None,
            qtm_port,
            socket,
            live,
            run: None,
            next_run_id: 1,
            preparing: None,
            safe_stop: None,
            exit: None,
            requested_run_started: false,
            last_hello: now,
            start: now,
            last_summary: None,
            _cpu_latency: cpu_latency,
        })
    }

    /// One supervision cycle.
    fn tick(&mut self) {
        let now = Instant::now();
        self.drain_heartbeats(now);
        if now - self.last_hello > ms(self.cfg.heartbeat_ms) {
            self.last_hello = now;
            pcr_nodes::recheck(&self.guard);
        }
        self.watch_children(now);
        self.resume_after_restarts();
        // Motion-capture samples before the driver states they are matched with.
        self.drain_mocap(now);
        self.drain_driver_states(now);
        self.drain_corrections();
        // Refusals before the status that reports the run refused.
        self.drain_refusals();
        self.drain_status(now);
        self.finish_run_if_over(now);
        self.start_prepared();
        if self.opts.one_shot() {
            self.start_requested_run(now);
        }
        self.tick_recording();
        self.serve_socket();
    }

    /// Stops every child (SIGTERM, then SIGKILL after 3 s), closes the recording, the live view,
    /// cleans up dead nodes' resources and the control socket.
    fn shutdown(&mut self) {
        self.interrupt_run();
        self.stop_children();
        let _ = self.node.node.try_cleanup_dead_nodes();
        self.socket.remove();
        self.live.stop();
        eprintln!("pcr-supervisor: all processes stopped");
    }
}

/// Runs the supervisor until Ctrl-C / SIGTERM, `shutdown`, or the end of a `--run` program.
/// Returns the process exit code.
pub fn run(cfg: SupervisorConfig, opts: Options) -> Result<i32> {
    let prefix = cfg.iceoryx2_prefix.clone();
    let mut sup = Supervisor::new(cfg, opts)?;
    let ws = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .map_err(|e| anyhow!("waitset: {e:?}"))?;
    let tick = ws
        .attach_interval(Duration::from_millis(20))
        .map_err(|e| anyhow!("interval: {e:?}"))?;
    let r = pcr_nodes::run_waitset(&ws, |id| {
        if id.has_event_from(&tick) {
            sup.tick();
            if sup.exit.is_some() {
                return CallbackProgression::Stop;
            }
        }
        CallbackProgression::Continue
    })
    .map_err(|e| anyhow!("waitset: {e:?}"))?;
    let code = match r {
        WaitSetRunResult::Interrupt | WaitSetRunResult::TerminationRequest => {
            eprintln!("pcr-supervisor: {r:?}: shutting down");
            0
        }
        _ => sup.exit.unwrap_or(0),
    };
    sup.shutdown();
    drop(tick);
    drop(ws);
    drop(sup);
    let n = pcr_nodes::ports::remove_leftovers(&prefix);
    if n > 0 {
        tracing::debug!(removed = n, "removed leftover iceoryx2 files");
    }
    Ok(code)
}

#[cfg(test)]
mod tests {
    use super::*;
    use pcr_messages::{command_kind, program_id};

    fn workspace_file(rel: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)
    }

    #[test]
    fn a_program_file_becomes_a_run_command_named_after_it() {
        let f = workspace_file("configs/programs/slot.toml");
        assert_eq!(program_name(&f), "slot");
        let c = program_command(&f).unwrap();
        assert_eq!(c.kind, command_kind::RUN);
        assert_eq!(c.program, program_id::MOVES);
        assert_eq!(c.n_moves, 10);
        assert_eq!(c.limits.speed_mm_s, 40.0);
        assert_eq!(c.limits.joint_jerk, 20000.0);
    }

    #[test]
    fn bad_or_too_long_program_files_are_errors_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let long = dir.path().join("long.toml");
        let mut text = String::from("[limits]\nspeed = 10.0\n");
        for _ in 0..(pcr_messages::MAX_MOVES + 1) {
            text.push_str("[[segment]]\ntype = \"dwell\"\nseconds = 0.1\n");
        }
        std::fs::write(&long, text).unwrap();
        let e = program_command(&long).unwrap_err();
        assert!(e.contains("long.toml") && e.contains("at most 32"), "{e}");
        let bad = dir.path().join("bad.toml");
        std::fs::write(
            &bad,
            "[limits]\nspeed = 10.0\n[[segment]]\ntype = \"arc\"\n",
        )
        .unwrap();
        let e = program_command(&bad).unwrap_err();
        assert!(
            e.contains("bad.toml") && e.contains("segment[0] (arc)"),
            "{e}"
        );
        let e = program_command(&dir.path().join("none.toml")).unwrap_err();
        assert!(e.contains("none.toml"), "{e}");
    }
}
