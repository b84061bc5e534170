//! The supervision loop: one iceoryx2 WaitSet interval (20 ms) that watches the children, drains
//! heartbeats, status and driver states (recording), serves the control socket and runs programs.

use crate::config::{Backend, ProcessConfig, ProcessName, SupervisorConfig};
use crate::ctl::{self, Request};
use crate::experiment::Experiment;
use anyhow::{anyhow, Context, Result};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use pcr_control::{command_of_moves, simple_command, Accuracy, Measured, Recorder};
use pcr_messages::{
    command_kind, driver_flags, planner_state, program_id, services as s, task_flags, Command,
    DriverStateMsg, Heartbeat, MocapSample, NodeKind, PlannerStatus, Refusal, PROTOCOL_VERSION,
};
use pcr_nodes::{ChainNode, ProtocolGuard};
use std::collections::VecDeque;
use std::fs::File;
use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

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

struct Proc {
    cfg: ProcessConfig,
    child: Option<Child>,
    started: Instant,
    last_hb: Option<Instant>,
    hb: Heartbeat,
    prev_misses: u64,
    prev_cycles: u64,
    restarts: u32,
    failures: VecDeque<Instant>,
    backoff: Duration,
    restart_at: Option<Instant>,
    gave_up: bool,
}

impl Proc {
    fn name(&self) -> &'static str {
        self.cfg.name.as_str()
    }
    fn pid(&self) -> Option<u32> {
        self.child.as_ref().map(|c| c.id())
    }
    fn healthy(&self) -> bool {
        self.child.is_some() && self.last_hb.is_some_and(|h| h >= self.started)
    }
    fn misses(&self) -> u64 {
        self.prev_misses + self.hb.deadline_misses
    }
    fn cycles(&self) -> u64 {
        self.prev_cycles + self.hb.cycles
    }
}

struct Run {
    id: u32,
    name: String,
    path: PathBuf,
    recorder: Recorder<File>,
    /// Driver states waiting for the capture sample measured at their time (configurations
    /// with a capture system), with when they arrived.
    pending: VecDeque<(DriverStateMsg, Instant)>,
    acc: Accuracy,
    started: Instant,
    ended: Option<(Instant, &'static str)>,
    paused_by_supervisor: bool,
    user_paused: bool,
    duration_s: f64,
    progress_s: f64,
    /// The newest driver state of this run reports the motors at rest.
    settled: bool,
    /// The command that started the run (re-sent as RECOVER after a planner restart).
    cmd: Command,
    /// The pose the planner planned the program from (from its status).
    origin: Option<[f64; 3]>,
    /// The planned pose of the newest setpoint the drive executed in this run.
    executed: Option<[f64; 3]>,
    /// A recovery after a planner restart: `Some(false)` waits for the planner, `Some(true)`
    /// has sent RECOVER and waits for the run to be back (paused).
    recover: Option<bool>,
    /// Rows whose setpoint was flagged uncorrected (capture data lost or stale).
    uncorrected: u64,
    /// Rows without a measured pose.
    unmeasured: u64,
    /// The planner's state for this run (`None` before its first status).
    planner_state: Option<u32>,
    /// Why the planner refused a command of this run (its newest refusal).
    refusal: Option<String>,
    /// An experiment's further commands and its row annotator (`ctl run experiment`).
    experiment: Option<LiveExperiment>,
}

/// An experiment running live: its commands are sent one after the other as each is done.
struct LiveExperiment {
    /// The chain commands (run id set), in order.
    commands: Vec<Command>,
    /// What each command covers, for messages.
    labels: Vec<String>,
    /// The command to send next.
    next: usize,
    /// A command was sent and the planner has not yet reported it planning or running (its
    /// status may still say DONE for the previous one).
    awaiting_start: bool,
    /// Labels the rows (pose_id, rep, settled, set, segment ...).
    annotator: pcr_experiments::Annotator,
}

/// The columns an experiment's recording carries after the standard ones.
const EXPERIMENT_COLUMNS: [&str; 7] = [
    "pose_id",
    "rep",
    "settled",
    "set",
    "segment",
    "motor",
    "amplitude_steps",
];

impl Run {
    /// What the planner made of the run: `planning`, `running`, `paused`, `refused: <reason>`
    /// or how it ended.
    fn verdict(&self) -> String {
        match (self.ended, self.planner_state) {
            (Some((_, "refused")), _) => format!(
                "refused: {}",
                self.refusal.as_deref().unwrap_or("(no reason received)")
            ),
            (Some((_, how)), _) => how.to_string(),
            (None, None | Some(planner_state::PLANNING)) if self.recover.is_none() => {
                "planning".into()
            }
            (None, _) if self.user_paused || self.paused_by_supervisor => "paused".into(),
            (None, _) => "running".into(),
        }
    }

    /// The accuracy line's text: none over no measured row.
    fn accuracy_text(&self) -> String {
        if self.acc.n == 0 {
            "accuracy: no measured rows".into()
        } else {
            format!("accuracy over {}", self.acc)
        }
    }
}

/// Samples of the motion-capture bridge kept for matching driver-state rows.
const MOCAP_RING: usize = 32;

/// An experiment being designed: its run id, name and the design thread's answer.
type Preparing = (
    u32,
    String,
    std::sync::mpsc::Receiver<Result<Experiment, String>>,
);

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
    socket: UnixListener,
    socket_path: PathBuf,
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

fn ms(v: f64) -> Duration {
    Duration::from_secs_f64(v * 1e-3)
}

impl Supervisor {
    /// Sets up the supervisor's node, ports and control socket (no process started yet).
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
        let socket_path = cfg.socket_path();
        if socket_path.exists() {
            if UnixStream::connect(&socket_path).is_ok() {
                return Err(anyhow!(
                    "another supervisor is listening on {}",
                    socket_path.display()
                ));
            }
            let _ = std::fs::remove_file(&socket_path);
        }
        let socket = UnixListener::bind(&socket_path)
            .with_context(|| format!("control socket {}", socket_path.display()))?;
        socket.set_nonblocking(true)?;
        let now = Instant::now();
        let procs = cfg
            .process
            .iter()
            .map(|p| Proc {
                cfg: p.clone(),
                child: None,
                started: now,
                last_hb: None,
                hb: Heartbeat::default(),
                prev_misses: 0,
                prev_cycles: 0,
                restarts: 0,
                failures: VecDeque::new(),
                backoff: ms(cfg.restart.backoff_initial_ms),
                restart_at: Some(now),
                gave_up: false,
            })
            .collect();
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
            socket_path,
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

    fn spawn(&mut self, i: usize) {
        let cfg = &self.cfg;
        let p = &self.procs[i];
        let bin = self.opts.bin_dir.join(p.cfg.name.binary());
        let mut cmd = std::process::Command::new(&bin);
        cmd.arg("--prefix")
            .arg(&cfg.iceoryx2_prefix)
            .arg("--period-ms")
            .arg(cfg.period_ms.to_string())
            .arg("--heartbeat-ms")
            .arg(cfg.heartbeat_ms.to_string())
            .arg("--robot")
            .arg(&self.robot_path)
            .arg("--rt-priority")
            .arg(p.cfg.priority.to_string());
        if let Some(c) = p.cfg.cpu {
            cmd.arg("--cpu").arg(c.to_string());
        }
        if cfg.realtime.mlockall {
            cmd.arg("--mlockall");
        }
        if let Some(cap) = &cfg.capture {
            match p.cfg.name {
                ProcessName::Driver if cap.simulate => {
                    cmd.arg("--qtm-port")
                        .arg(self.qtm_port.to_string())
                        .arg("--qtm-bind")
                        .arg(&cap.host);
                }
                ProcessName::Qtm => {
                    let reg = if cap.registration == "auto" {
                        cap.registration.clone()
                    } else {
                        std::fs::canonicalize(&cap.registration)
                            .map_or(cap.registration.clone(), |p| p.display().to_string())
                    };
                    cmd.arg("--host")
                        .arg(&cap.host)
                        .arg("--port")
                        .arg(self.qtm_port.to_string())
                        .arg("--registration")
                        .arg(reg)
                        .arg("--stale-ms")
                        .arg(cap.stale_ms.to_string());
                    if let Some(b) = &cap.body {
                        cmd.arg("--body").arg(b);
                    }
                    if let Some(f) = cap.frequency {
                        cmd.arg("--frequency").arg(f.to_string());
                    }
                }
                ProcessName::Mocap => {
                    cmd.arg("--source")
                        .arg("qtm")
                        .arg("--stale-ms")
                        .arg(cap.stale_ms.to_string());
                }
                _ => {}
            }
        }
        match p.cfg.backend {
            Some(Backend::Sim) => {
                cmd.arg("--backend").arg("sim");
            }
            Some(b @ (Backend::Plant | Backend::Fil)) => {
                cmd.arg("--backend")
                    .arg(if b == Backend::Plant { "plant" } else { "fil" });
                if let Some(plant) = &p.cfg.plant {
                    cmd.arg("--plant").arg(plant);
                }
            }
            Some(Backend::Serial) => {
                cmd.arg("--backend").arg("serial");
                cmd.arg("--port").arg(p.cfg.port.as_deref().unwrap_or(""));
            }
            None => {}
        }
        cmd.args(&p.cfg.args).stdin(Stdio::null()).process_group(0);
        // SAFETY: prctl is async-signal-safe; the child dies with the supervisor.
        unsafe {
            cmd.pre_exec(|| {
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
                Ok(())
            });
        }
        let now = Instant::now();
        let p = &mut self.procs[i];
        match cmd.spawn() {
            Ok(child) => {
                eprintln!(
                    "pcr-supervisor: started {} (pid {}){}",
                    p.name(),
                    child.id(),
                    if p.restarts > 0 {
                        format!(", restart #{}", p.restarts)
                    } else {
                        String::new()
                    }
                );
                p.child = Some(child);
                p.started = now;
                p.last_hb = None;
                p.restart_at = None;
            }
            Err(e) => {
                eprintln!("pcr-supervisor: cannot start {}: {e}", bin.display());
                self.failed(i, format!("cannot start: {e}"));
            }
        }
    }

    fn failed(&mut self, i: usize, why: String) {
        let now = Instant::now();
        let window = Duration::from_secs_f64(self.cfg.restart.window_s);
        let max_failures = self.cfg.restart.max_failures;
        let backoff_max = ms(self.cfg.restart.backoff_max_ms);
        let p = &mut self.procs[i];
        p.prev_misses += p.hb.deadline_misses;
        p.prev_cycles += p.hb.cycles;
        p.hb = Heartbeat::default();
        p.child = None;
        p.failures.push_back(now);
        while p.failures.front().is_some_and(|t| now - *t > window) {
            p.failures.pop_front();
        }
        let name = p.name();
        let is_planner = p.cfg.name == ProcessName::Planner;
        // Without the bridge the correction holds its offset: the robot goes on.
        let is_bridge = p.cfg.name == ProcessName::Qtm;
        if p.failures.len() as u32 > max_failures {
            p.gave_up = true;
            let msg = format!(
                "{name} failed {} times within {} s (last: {why})",
                p.failures.len(),
                self.cfg.restart.window_s
            );
            eprintln!("pcr-supervisor: {name} failed ({why}); giving up");
            self.safe_stop(msg);
            return;
        }
        p.restarts += 1;
        p.restart_at = Some(now + p.backoff);
        eprintln!(
            "pcr-supervisor: {name} failed ({why}); restart #{} in {} ms",
            p.restarts,
            p.backoff.as_millis()
        );
        p.backoff = (p.backoff * 2).min(backoff_max);
        if let Some(run) = &mut self.run {
            if run.ended.is_none() {
                if is_planner && (run.origin.is_none() || run.executed.is_none()) {
                    eprintln!(
                        "pcr-supervisor: run {} aborted: the planner failed before the run \
                         moved; the robot holds where it is",
                        run.id
                    );
                    run.ended = Some((now, "aborted (planner failed)"));
                } else if is_planner {
                    // The drive holds on the setpoint it executed last; the restarted planner
                    // re-plans the program and continues from there.
                    run.paused_by_supervisor = true;
                    run.recover = Some(false);
                    eprintln!(
                        "pcr-supervisor: run {} paused: the planner restarts; the robot holds and \
                         the run continues from where it stopped",
                        run.id
                    );
                } else if is_bridge {
                    eprintln!(
                        "pcr-supervisor: run {} continues while qtm restarts (correction held)",
                        run.id
                    );
                } else if !run.paused_by_supervisor {
                    run.paused_by_supervisor = true;
                    eprintln!(
                        "pcr-supervisor: run {} paused while {name} restarts",
                        run.id
                    );
                    let _ = pcr_nodes::publish(
                        &self.pub_cmd,
                        simple_command(command_kind::PAUSE, 0, run.id),
                    );
                }
            }
        }
    }

    fn safe_stop(&mut self, why: String) {
        if let Some(first) = &self.safe_stop {
            eprintln!("pcr-supervisor: (already in safe stop: {first}) also: {why}");
            return;
        }
        eprintln!("pcr-supervisor: SAFE STOP: {why}");
        let _ = pcr_nodes::publish(&self.pub_cmd, simple_command(command_kind::STOP, 0, 0));
        if let Some(run) = &mut self.run {
            if run.ended.is_none() {
                run.ended = Some((Instant::now(), "safe stop"));
            }
        }
        self.safe_stop = Some(why);
        if self.opts.one_shot() {
            self.exit = Some(EXIT_SAFE_STOP);
        }
    }

    fn all_healthy(&self) -> bool {
        self.procs.iter().all(Proc::healthy)
    }

    fn start_run(&mut self, name: &str, cmd: Result<Command, String>) -> Result<String, String> {
        if self.preparing.is_some() {
            return Err("a run is in progress; `stop` it first".into());
        }
        self.start_run_with(None, name, cmd, None)
    }

    /// Starts designing one of the paper's experiments (`ctl run experiment`) on a worker
    /// thread (the full calibration set takes about a second); the run starts when it is ready
    /// ([`Self::start_prepared`]). Its run number is given now.
    fn start_experiment(
        &mut self,
        kind: &str,
        options: &[(String, String)],
    ) -> Result<String, String> {
        if let Some(why) = &self.safe_stop {
            return Err(format!("safe stop ({why}); send `reset` first"));
        }
        if self.preparing.is_some() || self.run.as_ref().is_some_and(|r| r.ended.is_none()) {
            return Err("a run is in progress; `stop` it first".into());
        }
        if !self.all_healthy() {
            return Err("not all processes are up yet".into());
        }
        let robot = pcr_robot::RobotConfig::load(&self.robot_path)
            .map_err(|e| format!("robot {}: {e}", self.robot_path.display()))?;
        let spec = crate::experiment::spec(kind, options)?;
        let name = format!("experiment-{kind}");
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::Builder::new()
            .name("experiment design".into())
            .spawn(move || {
                let _ = tx.send(spec.build(&robot));
            })
            .map_err(|e| format!("cannot start the design thread: {e}"))?;
        let id = self.next_run_id;
        self.next_run_id += 1;
        self.preparing = Some((id, name.clone(), rx));
        Ok(format!(
            "run {id} ({name}) started; designing the experiment"
        ))
    }

    /// Starts the experiment whose design is ready (or reports why it could not be made).
    fn start_prepared(&mut self) {
        let Some((id, name, rx)) = &self.preparing else {
            return;
        };
        let (id, name) = (*id, name.clone());
        let e = match rx.try_recv() {
            Err(std::sync::mpsc::TryRecvError::Empty) => return,
            Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                Err("the design thread ended without a design".to_string())
            }
            Ok(e) => e,
        };
        self.preparing = None;
        let started = e.and_then(|e| {
            let mut commands = Vec::with_capacity(e.commands.len());
            for (i, c) in e.commands.iter().enumerate() {
                commands.push(command_of_moves(id, &c.moves).map_err(|err| {
                    format!("{name}: command {} ({}): {err}", i + 1, c.describe())
                })?);
            }
            let first = *commands.first().ok_or(format!("{name}: no command"))?;
            let live = LiveExperiment {
                labels: e.commands.iter().map(|c| c.describe()).collect(),
                commands,
                next: 1,
                awaiting_start: false,
                annotator: pcr_experiments::Annotator::new(
                    &e.design,
                    pcr_experiments::Tolerances::default(),
                ),
            };
            let mut meta = e.design.metadata(e.seed);
            meta.push(("commands".into(), live.commands.len().to_string()));
            meta.push((
                "period_s".into(),
                pcr_recording::number(self.cfg.period_ms * 1e-3),
            ));
            self.start_run_with(Some(id), &name, Ok(first), Some((live, meta)))
        });
        match started {
            Ok(msg) => eprintln!("pcr-supervisor: {msg}"),
            Err(e) => {
                eprintln!("pcr-supervisor: run {id} ({name}) refused: {e}");
                self.last_verdict = Some((id, format!("refused: {e}")));
            }
        }
    }

    fn start_run_with(
        &mut self,
        id: Option<u32>,
        name: &str,
        cmd: Result<Command, String>,
        experiment: Option<(LiveExperiment, Vec<(String, String)>)>,
    ) -> Result<String, String> {
        if let Some(why) = &self.safe_stop {
            return Err(format!("safe stop ({why}); send `reset` first"));
        }
        if self.run.as_ref().is_some_and(|r| r.ended.is_none()) {
            return Err("a run is in progress; `stop` it first".into());
        }
        if !self.all_healthy() {
            return Err("not all processes are up yet".into());
        }
        let mut cmd = cmd?;
        let id = id.unwrap_or_else(|| {
            self.next_run_id += 1;
            self.next_run_id - 1
        });
        cmd.run_id = id;
        let dir = PathBuf::from(&self.cfg.recording_dir);
        std::fs::create_dir_all(&dir).map_err(|e| format!("recording dir {dir:?}: {e}"))?;
        let stamp = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        let path = dir.join(format!("{name}-{stamp}-run{id}.csv"));
        let f = File::create(&path).map_err(|e| format!("recording {path:?}: {e}"))?;
        let backend = self
            .procs
            .iter()
            .find_map(|p| p.cfg.backend)
            .map_or("?", |b| match b {
                Backend::Sim => "pcr-supervisor, ideal drive (sim)",
                Backend::Plant => "pcr-supervisor, simulated plant",
                Backend::Fil => "pcr-supervisor, firmware in the loop (simavr) and simulated plant",
                Backend::Serial => "pcr-supervisor, serial driver",
            });
        let backend = match &self.cfg.capture {
            Some(_) => format!("{backend}; measured by QTM through pcr-qtm"),
            None => backend.to_string(),
        };
        let backend = backend.as_str();
        let created = stamp.to_string();
        let robot = self.robot_path.display().to_string();
        // The timing contract: the driver executes a row's command over the next cycle.
        let command_delay = pcr_recording::number(self.cfg.period_ms * 1e-3);
        // Unbuffered: every row is one write(2), flushed as it comes (a supervisor killed
        // mid-run leaves every row it recorded, none torn).
        let mut meta: Vec<(&str, &str)> = vec![
            ("robot", robot.as_str()),
            ("source", backend),
            ("created", created.as_str()),
            ("program", name),
            (pcr_recording::COMMAND_DELAY_KEY, command_delay.as_str()),
        ];
        let (experiment, extra_meta) = match experiment {
            Some((x, m)) => (Some(x), m),
            None => (None, Vec::new()),
        };
        meta.extend(extra_meta.iter().map(|(k, v)| (k.as_str(), v.as_str())));
        let columns: &[&str] = if experiment.is_some() {
            &EXPERIMENT_COLUMNS
        } else {
            &[]
        };
        let recorder =
            Recorder::with_extra(f, &meta, columns).map_err(|e| format!("recording: {e}"))?;
        let experiment = experiment.map(|mut x| {
            for c in &mut x.commands {
                c.run_id = id;
            }
            x
        });
        pcr_nodes::publish(&self.pub_cmd, cmd).map_err(|e| format!("command: {e:?}"))?;
        eprintln!(
            "pcr-supervisor: run {id} ({name}) started, recording {}",
            path.display()
        );
        self.run = Some(Run {
            id,
            name: name.into(),
            path: path.clone(),
            recorder,
            pending: VecDeque::new(),
            acc: Accuracy::default(),
            started: Instant::now(),
            ended: None,
            paused_by_supervisor: false,
            user_paused: false,
            duration_s: 0.0,
            progress_s: 0.0,
            settled: false,
            cmd,
            origin: None,
            executed: None,
            recover: None,
            uncorrected: 0,
            unmeasured: 0,
            planner_state: None,
            refusal: None,
            experiment,
        });
        Ok(format!(
            "run {id} ({name}) started; recording {}",
            path.display()
        ))
    }

    fn builtin(name: &str) -> Result<Command, String> {
        let p = match name {
            "paper" => program_id::PAPER,
            "circle" => program_id::CIRCLE,
            "square" => program_id::SQUARE,
            o => return Err(format!("unknown program {o:?} (paper, circle, square)")),
        };
        Ok(simple_command(command_kind::RUN, p, 0))
    }

    fn handle(&mut self, req: Request) -> String {
        let run_id = self.run.as_ref().map_or(0, |r| r.id);
        match req {
            Request::Status => self.status_text(),
            Request::RunBuiltin(n) => {
                let c = Self::builtin(&n);
                self.start_run(&n, c)
                    .unwrap_or_else(|e| format!("error: {e}"))
            }
            Request::RunMoves(m) => {
                let c = command_of_moves(0, &m).map_err(|e| e.to_string());
                self.start_run("moves", c)
                    .unwrap_or_else(|e| format!("error: {e}"))
            }
            Request::RunProgram(f) => {
                let c = program_command(&f);
                self.start_run(&program_name(&f), c)
                    .unwrap_or_else(|e| format!("error: {e}"))
            }
            Request::Pause | Request::Resume | Request::Stop => {
                let (k, word) = match req {
                    Request::Pause => (command_kind::PAUSE, "paused"),
                    Request::Resume => (command_kind::RESUME, "resumed"),
                    _ => (command_kind::STOP, "stopped"),
                };
                if let Some(r) = &mut self.run {
                    r.user_paused = k == command_kind::PAUSE;
                    if k == command_kind::STOP && r.recover.is_some() && r.ended.is_none() {
                        // Stopped while the planner restarts: nothing to continue.
                        r.recover = None;
                        r.ended = Some((Instant::now(), "stopped"));
                    }
                }
                match pcr_nodes::publish(&self.pub_cmd, simple_command(k, 0, run_id)) {
                    Ok(_) => word.into(),
                    Err(e) => format!("error: {e:?}"),
                }
            }
            Request::Reset => {
                self.safe_stop = None;
                let now = Instant::now();
                for p in &mut self.procs {
                    p.failures.clear();
                    p.backoff = ms(self.cfg.restart.backoff_initial_ms);
                    if p.gave_up {
                        p.gave_up = false;
                        p.restart_at = Some(now);
                    }
                }
                "reset: safe stop cleared, failed processes restart".into()
            }
            Request::RunExperiment { kind, options } => self
                .start_experiment(&kind, &options)
                .unwrap_or_else(|e| format!("error: {e}")),
            Request::Verdict(n) if self.preparing.as_ref().is_some_and(|p| p.0 == n) => {
                "planning".into()
            }
            Request::Verdict(n) => match (&self.run, &self.last_verdict) {
                (Some(r), _) if r.id == n => r.verdict(),
                (_, Some((id, v))) if *id == n => v.clone(),
                _ => format!("error: no run {n}"),
            },
            Request::Shutdown => {
                self.exit = Some(0);
                "shutting down".into()
            }
        }
    }

    fn status_text(&self) -> String {
        let mut out = String::new();
        let state = match (&self.safe_stop, self.all_healthy()) {
            (Some(w), _) => format!("safe-stop ({w})"),
            (None, true) => "ready".into(),
            (None, false) => "degraded (processes starting or restarting)".into(),
        };
        out.push_str(&format!(
            "state: {state}; protocol v{PROTOCOL_VERSION}; prefix {}; up {:.1} s\n",
            self.cfg.iceoryx2_prefix,
            self.start.elapsed().as_secs_f64()
        ));
        match &self.run {
            Some(r) => out.push_str(&format!(
                "run {} ({}): {}{}; progress {:.1}/{:.1} s; recorded rows {}; {}\n",
                r.id,
                r.name,
                r.verdict(),
                r.experiment.as_ref().map_or(String::new(), |x| format!(
                    "; command {}/{}",
                    x.next,
                    x.commands.len()
                )),
                r.progress_s,
                r.duration_s,
                r.recorder.rows(),
                r.accuracy_text()
            )),
            None => out.push_str("run: none\n"),
        }
        if let Some(l) = &self.last_summary {
            out.push_str(&format!("last run: {l}\n"));
        }
        if let Some(cap) = &self.cfg.capture {
            let age = self.mocap_at.map(|t| t.elapsed());
            let fresh = age.is_some_and(|a| a.as_secs_f64() * 1e3 <= cap.stale_ms);
            out.push_str(&format!(
                "capture: qtm {}:{}{}; {}; correction {}{}\n",
                cap.host,
                self.qtm_port,
                if cap.simulate { " (simulated)" } else { "" },
                match age {
                    Some(a) => format!(
                        "last frame {:.0} ms ago (frame {})",
                        a.as_secs_f64() * 1e3,
                        self.mocap.back().map_or(0, |m| m.frame_number)
                    ),
                    None => "no frame yet".into(),
                },
                if fresh {
                    "active"
                } else {
                    "held (no capture data: setpoints uncorrected)"
                },
                self.run.as_ref().map_or(String::new(), |r| format!(
                    "; this run: {} rows uncorrected, {} rows unmeasured",
                    r.uncorrected, r.unmeasured
                ))
            ));
        }
        for p in &self.procs {
            let h = &p.hb;
            out.push_str(&format!(
                "process {}: {} pid {}; restarts {}; deadline misses {} over {} cycles; cycle \
                 p50/p99/max {:.0}/{:.0}/{:.0} us; wake-up latency p50/p99/max {:.0}/{:.0}/{:.0} us; \
                 stale inputs {}; holding {}\n",
                p.name(),
                if p.gave_up {
                    "FAILED"
                } else if p.healthy() {
                    "up"
                } else {
                    "starting"
                },
                p.pid().map_or("-".into(), |x| x.to_string()),
                p.restarts,
                p.misses(),
                p.cycles(),
                h.cycle_ns[0] as f64 / 1e3,
                h.cycle_ns[1] as f64 / 1e3,
                h.cycle_ns[2] as f64 / 1e3,
                h.jitter_ns[0] as f64 / 1e3,
                h.jitter_ns[1] as f64 / 1e3,
                h.jitter_ns[2] as f64 / 1e3,
                h.stale_inputs,
                h.holding != 0
            ));
        }
        out
    }

    fn serve_socket(&mut self) {
        loop {
            let (stream, _) = match self.socket.accept() {
                Ok(s) => s,
                Err(_) => return,
            };
            let _ = stream.set_nonblocking(false);
            let _ = stream.set_read_timeout(Some(Duration::from_millis(500)));
            let mut line = String::new();
            let mut r = BufReader::new(&stream);
            let reply = match r.read_line(&mut line) {
                Ok(_) => match ctl::parse(&line) {
                    Ok(req) => self.handle(req),
                    Err(e) => format!("error: {e}"),
                },
                Err(e) => format!("error: {e}"),
            };
            let mut w = &stream;
            let _ = w.write_all(reply.as_bytes());
            if !reply.ends_with('\n') {
                let _ = w.write_all(b"\n");
            }
        }
    }

    /// One supervision cycle.
    fn tick(&mut self) {
        let now = Instant::now();
        // Heartbeats.
        while let Ok(Some(smp)) = self.sub_hb.receive() {
            let hb = *smp.payload();
            if let Some(i) = self.procs.iter().position(|p| p.pid() == Some(hb.pid)) {
                if hb.version != PROTOCOL_VERSION {
                    eprintln!(
                        "pcr-supervisor: {}",
                        pcr_messages::version_mismatch_message(
                            PROTOCOL_VERSION,
                            hb.version,
                            self.procs[i].name()
                        )
                    );
                    continue;
                }
                self.procs[i].last_hb = Some(now);
                self.procs[i].hb = hb;
            }
        }
        if now - self.last_hello > ms(self.cfg.heartbeat_ms) {
            self.last_hello = now;
            pcr_nodes::recheck(&self.guard);
        }
        // Children: exited, hung, due for a restart.
        let hb_timeout = ms(self.cfg.heartbeat_timeout_ms);
        let startup_timeout = ms(self.cfg.startup_timeout_ms);
        for i in 0..self.procs.len() {
            let p = &mut self.procs[i];
            if let Some(child) = &mut p.child {
                if let Ok(Some(status)) = child.try_wait() {
                    if status.code() == Some(pcr_nodes::EXIT_VERSION_MISMATCH) {
                        // Restarting the same binary cannot help.
                        let name = p.name();
                        p.child = None;
                        p.gave_up = true;
                        self.safe_stop(format!(
                            "{name} refused to connect: protocol version mismatch (its binary \
                             is from another revision); not restarting"
                        ));
                        continue;
                    }
                    self.failed(i, format!("exited: {status}"));
                    continue;
                }
                let hung = match p.last_hb {
                    Some(h) if h >= p.started => now - h > hb_timeout,
                    _ => now - p.started > startup_timeout,
                };
                if hung {
                    let silent = now - p.last_hb.unwrap_or(p.started);
                    let _ = child.kill();
                    let _ = child.wait();
                    self.failed(
                        i,
                        format!("hung: no heartbeat for {} ms; killed", silent.as_millis()),
                    );
                    continue;
                }
                if p.healthy()
                    && p.failures.is_empty()
                    && p.backoff > ms(self.cfg.restart.backoff_initial_ms)
                {
                    p.backoff = ms(self.cfg.restart.backoff_initial_ms);
                }
            } else if !p.gave_up
                && self.safe_stop.is_none()
                && p.restart_at.is_some_and(|t| t <= now)
            {
                self.spawn(i);
            }
        }
        // Resume a run paused by the supervisor once everybody is back.
        let healthy = self.all_healthy();
        if let Some(run) = &mut self.run {
            if run.ended.is_none() && run.recover == Some(false) && healthy {
                // The planner is back: it re-plans the program and continues it, paused, at
                // the setpoint the drive executed last (both known: checked when it failed).
                let mut c = run.cmd;
                let origin = run.origin.unwrap_or(c.origin);
                let executed = run.executed.unwrap_or(origin);
                c.kind = command_kind::RECOVER;
                c.origin = origin;
                c.executed = executed;
                c.resume_s = run.progress_s;
                run.recover = Some(true);
                eprintln!(
                    "pcr-supervisor: run {} recovering near {:.2} s of the program",
                    run.id, run.progress_s
                );
                let _ = pcr_nodes::publish(&self.pub_cmd, c);
            }
            if run.ended.is_none() && run.paused_by_supervisor && run.recover.is_none() && healthy {
                run.paused_by_supervisor = false;
                if !run.user_paused {
                    eprintln!("pcr-supervisor: run {} resumed", run.id);
                    let _ = pcr_nodes::publish(
                        &self.pub_cmd,
                        simple_command(command_kind::RESUME, 0, run.id),
                    );
                }
            }
        }
        // Motion-capture samples (before the driver states they are matched with).
        if let Some(sub) = &self.sub_mocap {
            while let Ok(Some(smp)) = sub.receive() {
                if self.mocap.len() == MOCAP_RING {
                    self.mocap.pop_front();
                }
                self.mocap.push_back(*smp.payload());
                self.mocap_at = Some(now);
            }
        }
        // Driver states: record (with a capture system, once the sample measured at the row's
        // time has arrived: see `Capture::measured`).
        let mut stop = false;
        let capture = self.cfg.capture.as_ref().map(|c| CaptureMatch {
            half_period_s: self.cfg.period_ms * 0.5e-3,
            stale_s: c.stale_ms * 1e-3,
            latency_s: c.latency_ms.unwrap_or(0.0) * 1e-3,
        });
        while let Ok(Some(smp)) = self.sub_state.receive() {
            if let Some(run) = &mut self.run {
                let st = smp.payload();
                if st.run_id == run.id && !run_over(run, now) {
                    run.executed = Some(st.planned);
                    run.settled = st.flags & pcr_messages::driver_flags::MOVING == 0;
                    if st.flags & pcr_messages::driver_flags::FAULT != 0 && run.ended.is_none() {
                        run.ended = Some((now, "drive fault"));
                        eprintln!(
                            "pcr-supervisor: run {} stopped: drive fault (latched in the drive, \
                             which holds position; clear it at the drive)",
                            run.id
                        );
                        stop = true;
                    }
                    match &capture {
                        Some(_) => run.pending.push_back((*st, now)),
                        None => run.record(st, Measured::of_state(st)),
                    }
                }
            }
        }
        if let (Some(run), Some(c)) = (&mut self.run, &capture) {
            run.record_pending(&self.mocap, c, now, false);
        }
        if stop {
            let _ = pcr_nodes::publish(&self.pub_cmd, simple_command(command_kind::STOP, 0, 0));
        }
        // Refusals (before the status that reports the run refused).
        while let Ok(Some(smp)) = self.sub_refusal.receive() {
            let r = smp.payload();
            let why = r.reason().to_string();
            match &mut self.run {
                Some(run) if run.id == r.run_id => {
                    eprintln!("pcr-supervisor: run {}: the planner refused: {why}", run.id);
                    run.refusal = Some(why);
                }
                _ => eprintln!(
                    "pcr-supervisor: the planner refused a command (run {}): {why}",
                    r.run_id
                ),
            }
        }
        // Planner status.
        while let Ok(Some(smp)) = self.sub_status.receive() {
            let st = *smp.payload();
            if let Some(run) = &mut self.run {
                if st.run_id == run.id {
                    run.planner_state = Some(st.state);
                    if let Some(x) = &mut run.experiment {
                        if matches!(
                            st.state,
                            planner_state::PLANNING
                                | planner_state::RUNNING
                                | planner_state::PAUSED
                        ) {
                            x.awaiting_start = false;
                        }
                    }
                    run.progress_s = st.progress_s;
                    run.duration_s = st.duration_s;
                    if matches!(st.state, planner_state::RUNNING | planner_state::PAUSED) {
                        run.origin = Some(st.origin);
                    }
                    if run.recover == Some(true) && run.ended.is_none() {
                        match st.state {
                            planner_state::PAUSED => {
                                run.recover = None;
                                eprintln!("pcr-supervisor: run {} recovered", run.id);
                            }
                            planner_state::REFUSED => {
                                eprintln!(
                                    "pcr-supervisor: run {} aborted: the restarted planner \
                                     could not continue it; the robot holds where it is",
                                    run.id
                                );
                                run.ended = Some((now, "aborted (recovery refused)"));
                            }
                            planner_state::STOPPED => {
                                run.recover = None;
                                run.ended = Some((now, "stopped"));
                            }
                            _ => {}
                        }
                        continue;
                    }
                    if run.ended.is_none() {
                        match st.state {
                            planner_state::DONE if run.experiment.is_some() => {
                                let Some(x) = &mut run.experiment else {
                                    continue;
                                };
                                if x.awaiting_start {
                                    // The previous command's DONE: the next is being planned.
                                } else if x.next < x.commands.len() {
                                    let c = x.commands[x.next];
                                    tracing::info!(
                                        "run {}: command {}/{} ({})",
                                        run.id,
                                        x.next + 1,
                                        x.commands.len(),
                                        x.labels[x.next]
                                    );
                                    x.next += 1;
                                    x.awaiting_start = true;
                                    run.cmd = c;
                                    run.started = now;
                                    if let Err(e) = pcr_nodes::publish(&self.pub_cmd, c) {
                                        run.ended = Some((now, "aborted (command not sent)"));
                                        eprintln!("pcr-supervisor: run {}: {e:?}", run.id);
                                    }
                                } else {
                                    run.ended = Some((now, "done"));
                                }
                            }
                            planner_state::DONE => run.ended = Some((now, "done")),
                            planner_state::STOPPED => run.ended = Some((now, "stopped")),
                            planner_state::REFUSED => run.ended = Some((now, "refused")),
                            _ => {}
                        }
                    }
                }
            }
        }
        self.finish_run_if_over(now);
        self.start_prepared();
        // Start the requested program once everybody is up.
        if self.opts.one_shot() {
            if !self.requested_run_started && self.all_healthy() && self.safe_stop.is_none() {
                // Give the planner a few cycles to connect to the command service, and the
                // capture system (if any) time to deliver its first frame.
                let capture_ready = self.cfg.capture.is_none()
                    || self.mocap_at.is_some()
                    || now - self.start > startup_timeout;
                if self.procs.iter().all(|p| p.hb.seq >= 3) && capture_ready {
                    self.requested_run_started = true;
                    let (name, c) = match (&self.opts.run_file, &self.opts.run) {
                        (Some(f), _) => (program_name(f), program_command(f)),
                        (None, Some(n)) => (n.clone(), Self::builtin(n)),
                        (None, None) => unreachable!("one_shot() implies --run or --run-file"),
                    };
                    if let Err(e) = self.start_run(&name, c) {
                        eprintln!("pcr-supervisor: cannot run {name}: {e}");
                        self.exit = Some(EXIT_RUN_FAILED);
                    }
                }
            }
            if !self.requested_run_started
                && now - self.start > startup_timeout + ms(5000.0)
                && self.exit.is_none()
            {
                eprintln!("pcr-supervisor: the chain did not come up; giving up on --run");
                self.exit = Some(EXIT_RUN_FAILED);
            }
        }
        self.serve_socket();
    }

    fn finish_run_if_over(&mut self, now: Instant) {
        let over = self.run.as_ref().is_some_and(|r| run_over(r, now));
        // A run without progress for far longer than planned is stuck.
        let stuck = self.run.as_ref().is_some_and(|r| {
            r.ended.is_none()
                && !r.user_paused
                && now - r.started > Duration::from_secs_f64(r.duration_s * 3.0 + 60.0)
        });
        if stuck {
            if let Some(r) = &mut self.run {
                r.ended = Some((now, "timed out"));
            }
            return;
        }
        if !over {
            return;
        }
        let Some(mut run) = self.run.take() else {
            return;
        };
        self.record_pending_now(&mut run);
        let how = run.ended.map_or("?", |e| e.1);
        let rows = run.recorder.rows();
        let verdict = run.verdict();
        let accuracy = run.accuracy_text();
        let _ = run.recorder.finish();
        println!("run {} ({}): {verdict}", run.id, run.name);
        self.last_summary = Some(format!(
            "{} ({}): {verdict}; {} rows in {}; {}",
            run.id,
            run.name,
            rows,
            run.path.display(),
            accuracy
        ));
        self.last_verdict = Some((run.id, verdict));
        println!("recording: {} ({rows} rows)", run.path.display());
        if run.acc.n > 0 {
            match crate::figure::run_figure(&run.path) {
                Ok(f) => println!("figure: {}", f.display()),
                Err(e) => tracing::warn!("no figure of the run: {e}"),
            }
        }
        if run.acc.n == 0 {
            println!(
                "path accuracy: not measured (no measured pose: no capture data, and the serial \
                 backend has no pose sensor)"
            );
        } else {
            println!(
            "path accuracy (planned vs measured, {} rows): position mean {:.3} mm, max {:.3} mm, \
             RMS {:.3} mm; orientation mean {:.3} deg, max {:.3} deg, RMS {:.3} deg",
            run.acc.n,
            run.acc.mean_pos_mm(),
            run.acc.max_pos_mm,
            run.acc.rms_pos_mm(),
            run.acc.mean_phi_deg(),
            run.acc.max_phi_deg,
            run.acc.rms_phi_deg()
        );
        }
        if self.cfg.capture.is_some() {
            println!(
                "capture (QTM bridge): {} of {rows} rows measured, {} rows with the correction \
                 held (uncorrected)",
                rows.saturating_sub(run.unmeasured),
                run.uncorrected
            );
        }
        for p in &self.procs {
            println!(
                "process {}: restarts {}, deadline misses {} over {} cycles",
                p.name(),
                p.restarts,
                p.misses(),
                p.cycles()
            );
        }
        // Keep the run for `status` as a finished one? Report only.
        if self.opts.one_shot() && self.exit.is_none() {
            self.exit = Some(if how == "done" { 0 } else { EXIT_RUN_FAILED });
        }
    }

    /// Records every row still waiting for its capture sample (the run ends).
    fn record_pending_now(&self, run: &mut Run) {
        if let Some(c) = &self.cfg.capture {
            let m = CaptureMatch {
                half_period_s: self.cfg.period_ms * 0.5e-3,
                stale_s: c.stale_ms * 1e-3,
                latency_s: c.latency_ms.unwrap_or(0.0) * 1e-3,
            };
            run.record_pending(&self.mocap, &m, Instant::now(), true);
        }
    }

    /// Stops every child (SIGTERM, then SIGKILL after 3 s), cleans up dead nodes' resources and
    /// the control socket.
    fn shutdown(&mut self) {
        let _ = pcr_nodes::publish(&self.pub_cmd, simple_command(command_kind::STOP, 0, 0));
        if let Some(r) = &mut self.run {
            if r.ended.is_none() {
                r.ended = Some((Instant::now(), "interrupted"));
            }
        }
        if let Some(mut run) = self.run.take() {
            self.record_pending_now(&mut run);
            let _ = run.recorder.finish();
        }
        // The driver goes last so that it holds while the others stop.
        let order = [
            ProcessName::Planner,
            ProcessName::Qtm,
            ProcessName::Mocap,
            ProcessName::Ik,
            ProcessName::Driver,
        ];
        for name in order {
            for p in self.procs.iter_mut().filter(|p| p.cfg.name == name) {
                if let Some(c) = &mut p.child {
                    // SAFETY: plain kill(2) on our own child.
                    unsafe { libc::kill(c.id() as i32, libc::SIGTERM) };
                    let end = Instant::now() + Duration::from_secs(3);
                    loop {
                        if let Ok(Some(_)) = c.try_wait() {
                            break;
                        }
                        if Instant::now() > end {
                            eprintln!("pcr-supervisor: {} ignores SIGTERM; killing", name.as_str());
                            let _ = c.kill();
                            let _ = c.wait();
                            break;
                        }
                        std::thread::sleep(Duration::from_millis(10));
                    }
                }
                p.child = None;
            }
        }
        let _ = self.node.node.try_cleanup_dead_nodes();
        let _ = std::fs::remove_file(&self.socket_path);
        eprintln!("pcr-supervisor: all processes stopped");
    }
}

/// How driver-state rows are matched with the bridge's samples.
struct CaptureMatch {
    /// Half the chain's period, s.
    half_period_s: f64,
    /// Capture data older than this is not a measurement of the row, s.
    stale_s: f64,
    /// The capture system's declared latency (`[capture] latency_ms`), s.
    latency_s: f64,
}

impl CaptureMatch {
    /// The bridge sample measured at the row's time: the one whose capture time (its chain
    /// time less the declared latency) is nearest the row's time, within half a period.
    fn sample<'a>(
        &self,
        st: &DriverStateMsg,
        ring: &'a VecDeque<MocapSample>,
    ) -> Option<&'a MocapSample> {
        ring.iter()
            .map(|m| ((m.t_s - self.latency_s - st.t_s).abs(), m))
            .filter(|(d, _)| *d <= self.half_period_s.min(self.stale_s))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, m)| m)
    }

    /// Whether the match of a row is final: a sample captured at or after its time has
    /// arrived (later ones are farther), or it has waited longer than the stale limit.
    fn settled(&self, st: &DriverStateMsg, ring: &VecDeque<MocapSample>, waited: Duration) -> bool {
        ring.back()
            .is_some_and(|m| m.t_s - self.latency_s >= st.t_s)
            || waited.as_secs_f64() > self.stale_s + self.latency_s
    }
}

/// The measurement of a driver-state row taken from the bridge's sample `sample`. Returns the
/// row with that pose as its measured pose (for the accuracy) and the recording's measured
/// cells.
fn measured_by_bridge(
    st: &DriverStateMsg,
    sample: Option<&MocapSample>,
) -> (DriverStateMsg, Measured) {
    let mut row = *st;
    row.flags &= !driver_flags::POSE_VALID;
    let mut measured = Measured::default();
    if let Some(m) = sample {
        if let Some(p) = m.pose() {
            row.measured = p;
            row.flags |= driver_flags::POSE_VALID;
            measured.pose = Some(p);
        }
        measured.joints = std::array::from_fn(|i| m.joint(i).map(|j| [j[0], j[1]]));
    }
    (row, measured)
}

impl Run {
    /// Records one row (and counts it in the accuracy).
    fn record(&mut self, st: &DriverStateMsg, measured: Measured) {
        let mut row = *st;
        row.flags &= !driver_flags::POSE_VALID;
        if let Some(p) = measured.pose {
            row.measured = p;
            row.flags |= driver_flags::POSE_VALID;
        }
        let written = match &mut self.experiment {
            None => self.recorder.row_with(&row, &measured),
            Some(x) => match self.recorder.row_of(&row, &measured) {
                Some(mut r) => {
                    let cells = x.annotator.annotate(&mut r).extra_cells();
                    let cells: [Option<&str>; 3] = std::array::from_fn(|i| cells[i].as_deref());
                    self.recorder.write(&r, &cells)
                }
                None => Ok(()),
            },
        };
        if let Err(e) = written {
            tracing::error!("recording {}: {e}", self.path.display());
        }
        self.acc.add(&row);
        if st.task_flags & task_flags::UNCORRECTED != 0 {
            self.uncorrected += 1;
        }
        if measured.pose.is_none() {
            self.unmeasured += 1;
        }
    }

    /// Records the waiting rows whose capture sample is known (all of them with `all`).
    fn record_pending(
        &mut self,
        ring: &VecDeque<MocapSample>,
        c: &CaptureMatch,
        now: Instant,
        all: bool,
    ) {
        while let Some((st, at)) = self.pending.front().copied() {
            if !all && !c.settled(&st, ring, now - at) {
                break;
            }
            self.pending.pop_front();
            let (_, measured) = measured_by_bridge(&st, c.sample(&st, ring));
            self.record(&st, measured);
        }
    }
}

/// A run is over (and its recording closed) at least 300 ms after it ended, once the motors are
/// at rest, or 5 s after it ended if they do not come to rest.
fn run_over(r: &Run, now: Instant) -> bool {
    r.ended.is_some_and(|e| {
        let after = now - e.0;
        after >= ms(300.0) && (r.settled || after >= ms(5000.0))
    })
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

use iceoryx2::waitset::WaitSetRunResult;

#[cfg(test)]
mod tests {
    use super::*;

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
