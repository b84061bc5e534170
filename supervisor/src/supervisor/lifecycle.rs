//! The run lifecycle: a run starts (a built-in program, moves, a program file or an experiment
//! designed off the loop), follows the planner's status and refusals, is paused while an IK,
//! driver or mocap process restarts and resumed when all are back, recovers after a planner
//! restart (RECOVER), and ends (done, stopped, refused, aborted, timed out), when its recording
//! is closed and its summary printed.

use super::live::{say, Level};
use super::processes::ms;
use super::recording::{RunRecording, EXPERIMENT_COLUMNS};
use super::{program_command, program_name, Supervisor, EXIT_RUN_FAILED};
use crate::config::{Backend, ProcessName};
use crate::experiment::Experiment;
use pcr_control::{command_of_moves, simple_command, Accuracy};
use pcr_messages::{command_kind, planner_state, program_id, Command, DriverStateMsg};
use pcr_telemetry::RunEventKind;
use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// An experiment being designed: its run id, name and the design thread's answer.
pub(super) type Preparing = (
    u32,
    String,
    std::sync::mpsc::Receiver<Result<Experiment, String>>,
);

/// A run: its program, recording, state and what the planner made of it.
pub(super) struct Run {
    pub(super) id: u32,
    pub(super) name: String,
    /// The recording (CSV and MCAP).
    pub(super) recording: RunRecording,
    /// Driver states waiting for the capture sample measured at their time (configurations
    /// with a capture system), with when they arrived.
    pub(super) pending: VecDeque<(DriverStateMsg, Instant)>,
    pub(super) acc: Accuracy,
    pub(super) started: Instant,
    pub(super) ended: Option<(Instant, &'static str)>,
    pub(super) paused_by_supervisor: bool,
    pub(super) user_paused: bool,
    pub(super) duration_s: f64,
    pub(super) progress_s: f64,
    /// The newest driver state of this run reports the motors at rest.
    pub(super) settled: bool,
    /// The command that started the run (re-sent as RECOVER after a planner restart).
    pub(super) cmd: Command,
    /// The pose the planner planned the program from (from its status).
    pub(super) origin: Option<[f64; 3]>,
    /// The planned pose of the newest setpoint the drive executed in this run.
    pub(super) executed: Option<[f64; 3]>,
    /// A recovery after a planner restart: `Some(false)` waits for the planner, `Some(true)`
    /// has sent RECOVER and waits for the run to be back (paused).
    pub(super) recover: Option<bool>,
    /// Rows whose setpoint was flagged uncorrected (capture data lost or stale).
    pub(super) uncorrected: u64,
    /// Rows without a measured pose.
    pub(super) unmeasured: u64,
    /// The planner's state for this run (`None` before its first status).
    pub(super) planner_state: Option<u32>,
    /// Why the planner refused a command of this run (its newest refusal).
    pub(super) refusal: Option<String>,
    /// An experiment's further commands and its row annotator (`ctl run experiment`).
    pub(super) experiment: Option<LiveExperiment>,
}

/// An experiment running live: its commands are sent one after the other as each is done.
pub(super) struct LiveExperiment {
    /// The chain commands (run id set), in order.
    pub(super) commands: Vec<Command>,
    /// What each command covers, for messages.
    pub(super) labels: Vec<String>,
    /// The command to send next.
    pub(super) next: usize,
    /// A command was sent and the planner has not yet reported it planning or running (its
    /// status may still say DONE for the previous one).
    pub(super) awaiting_start: bool,
    /// Labels the rows (pose_id, rep, settled, set, segment ...).
    pub(super) annotator: pcr_experiments::Annotator,
}

impl Run {
    /// What the planner made of the run: `planning`, `running`, `paused`, `refused: <reason>`
    /// or how it ended.
    pub(super) fn verdict(&self) -> String {
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
    pub(super) fn accuracy_text(&self) -> String {
        if self.acc.n == 0 {
            "accuracy: no measured rows".into()
        } else {
            format!("accuracy over {}", self.acc)
        }
    }
}

/// A run is over (and its recording closed) at least 300 ms after it ended, once the motors are
/// at rest, or 5 s after it ended if they do not come to rest.
pub(super) fn run_over(r: &Run, now: Instant) -> bool {
    r.ended.is_some_and(|e| {
        let after = now - e.0;
        after >= ms(300.0) && (r.settled || after >= ms(5000.0))
    })
}

/// The RUN command of a built-in program.
pub(super) fn builtin(name: &str) -> Result<Command, String> {
    let p = match name {
        "paper" => program_id::PAPER,
        "circle" => program_id::CIRCLE,
        "square" => program_id::SQUARE,
        o => return Err(format!("unknown program {o:?} (paper, circle, square)")),
    };
    Ok(simple_command(command_kind::RUN, p, 0))
}

impl Supervisor {
    /// Starts a run of `cmd` named `name` (a built-in program, moves, a program file).
    pub(super) fn start_run(
        &mut self,
        name: &str,
        cmd: Result<Command, String>,
    ) -> Result<String, String> {
        if self.preparing.is_some() {
            return Err("a run is in progress; `stop` it first".into());
        }
        self.start_run_with(None, name, cmd, None)
    }

    /// Starts designing one of the paper's experiments (`ctl run experiment`) on a worker
    /// thread (the full calibration set takes about a second); the run starts when it is ready
    /// ([`Self::start_prepared`]). Its run number is given now.
    pub(super) fn start_experiment(
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
    pub(super) fn start_prepared(&mut self) {
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
            Ok(msg) => say(Level::Info, &msg),
            Err(e) => {
                say(Level::Error, &format!("run {id} ({name}) refused: {e}"));
                self.last_verdict = Some((id, format!("refused: {e}")));
            }
        }
    }

    /// The recording's `source` metadata: the backend and the capture system.
    fn recording_source(&self) -> String {
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
        match &self.cfg.capture {
            Some(_) => format!("{backend}; measured by QTM through pcr-qtm"),
            None => backend.to_string(),
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
        let stamp = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        let source = self.recording_source();
        // The timing contract: the driver executes a row's command over the next cycle.
        let command_delay = pcr_recording::number(self.cfg.period_ms * 1e-3);
        let mut meta: Vec<(String, String)> = vec![
            ("robot".into(), self.robot_path.display().to_string()),
            ("source".into(), source),
            ("created".into(), stamp.to_string()),
            ("program".into(), name.into()),
            (pcr_recording::COMMAND_DELAY_KEY.into(), command_delay),
        ];
        let (experiment, extra_meta) = match experiment {
            Some((x, m)) => (Some(x), m),
            None => (None, Vec::new()),
        };
        meta.extend(extra_meta);
        let columns: &[&str] = if experiment.is_some() {
            &EXPERIMENT_COLUMNS
        } else {
            &[]
        };
        let stem = format!("{name}-{stamp}-run{id}");
        let recording = RunRecording::open(
            std::path::Path::new(&self.cfg.recording_dir),
            &stem,
            &meta,
            columns,
            &self.live,
        )?;
        let experiment = experiment.map(|mut x| {
            for c in &mut x.commands {
                c.run_id = id;
            }
            x
        });
        pcr_nodes::publish(&self.pub_cmd, cmd).map_err(|e| format!("command: {e:?}"))?;
        let files = recording.files_text();
        say(
            Level::Info,
            &format!("run {id} ({name}) started, recording {files}"),
        );
        self.live.event(
            RunEventKind::Start,
            Some(id),
            None,
            &format!("run {id} ({name}) started"),
        );
        let reply = format!(
            "run {id} ({name}) started; recording {}",
            recording.csv_path().display()
        );
        self.run = Some(Run {
            id,
            name: name.into(),
            recording,
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
        Ok(reply)
    }

    /// `pause`, `resume`, `stop` from the control socket.
    pub(super) fn command_run(&mut self, kind: u32) -> Result<(), String> {
        let run_id = self.run.as_ref().map_or(0, |r| r.id);
        if let Some(r) = &mut self.run {
            r.user_paused = kind == command_kind::PAUSE;
            if kind == command_kind::STOP && r.recover.is_some() && r.ended.is_none() {
                // Stopped while the planner restarts: nothing to continue.
                r.recover = None;
                r.ended = Some((Instant::now(), "stopped"));
            }
        }
        let (event, word) = match kind {
            command_kind::PAUSE => (RunEventKind::Pause, "paused"),
            command_kind::RESUME => (RunEventKind::Resume, "resumed"),
            _ => (RunEventKind::Stop, "stopped"),
        };
        pcr_nodes::publish(&self.pub_cmd, simple_command(kind, 0, run_id))
            .map_err(|e| format!("{e:?}"))?;
        self.live.event(
            event,
            (run_id != 0).then_some(run_id),
            None,
            &format!("{word} by the operator"),
        );
        Ok(())
    }

    /// A process failed and restarts: the run is paused (IK, driver, mocap), recovers later
    /// (planner) or goes on (the bridge: the correction holds).
    pub(super) fn on_process_failed(&mut self, process: ProcessName, now: Instant) {
        let Some(run) = &mut self.run else {
            return;
        };
        if run.ended.is_some() {
            return;
        }
        let is_planner = process == ProcessName::Planner;
        if is_planner && (run.origin.is_none() || run.executed.is_none()) {
            say(
                Level::Error,
                &format!(
                    "run {} aborted: the planner failed before the run moved; the robot holds \
                     where it is",
                    run.id
                ),
            );
            run.ended = Some((now, "aborted (planner failed)"));
        } else if is_planner {
            // The drive holds on the setpoint it executed last; the restarted planner re-plans
            // the program and continues from there.
            run.paused_by_supervisor = true;
            run.recover = Some(false);
            let text = format!(
                "run {} paused: the planner restarts; the robot holds and the run continues \
                 from where it stopped",
                run.id
            );
            say(Level::Warning, &text);
            self.live
                .event(RunEventKind::Pause, Some(run.id), Some("planner"), &text);
        } else if process == ProcessName::Qtm {
            // Without the bridge the correction holds its offset: the robot goes on.
            say(
                Level::Warning,
                &format!(
                    "run {} continues while qtm restarts (correction held)",
                    run.id
                ),
            );
        } else if !run.paused_by_supervisor {
            run.paused_by_supervisor = true;
            let text = format!("run {} paused while {} restarts", run.id, process.as_str());
            say(Level::Warning, &text);
            self.live.event(
                RunEventKind::Pause,
                Some(run.id),
                Some(process.as_str()),
                &text,
            );
            let _ = pcr_nodes::publish(
                &self.pub_cmd,
                simple_command(command_kind::PAUSE, 0, run.id),
            );
        }
    }

    /// Resumes a run paused by the supervisor once everybody is back (after a planner restart:
    /// RECOVER first).
    pub(super) fn resume_after_restarts(&mut self) {
        let healthy = self.all_healthy();
        let Some(run) = &mut self.run else {
            return;
        };
        if run.ended.is_none() && run.recover == Some(false) && healthy {
            // The planner is back: it re-plans the program and continues it, paused, at the
            // setpoint the drive executed last (both known: checked when it failed).
            let mut c = run.cmd;
            let origin = run.origin.unwrap_or(c.origin);
            let executed = run.executed.unwrap_or(origin);
            c.kind = command_kind::RECOVER;
            c.origin = origin;
            c.executed = executed;
            c.resume_s = run.progress_s;
            run.recover = Some(true);
            say(
                Level::Info,
                &format!(
                    "run {} recovering near {:.2} s of the program",
                    run.id, run.progress_s
                ),
            );
            let _ = pcr_nodes::publish(&self.pub_cmd, c);
        }
        if run.ended.is_none() && run.paused_by_supervisor && run.recover.is_none() && healthy {
            run.paused_by_supervisor = false;
            if !run.user_paused {
                let text = format!("run {} resumed", run.id);
                say(Level::Info, &text);
                self.live
                    .event(RunEventKind::Resume, Some(run.id), None, &text);
                let _ = pcr_nodes::publish(
                    &self.pub_cmd,
                    simple_command(command_kind::RESUME, 0, run.id),
                );
            }
        }
    }

    /// The planner's refusals (before the status that reports the run refused).
    pub(super) fn drain_refusals(&mut self) {
        while let Ok(Some(smp)) = self.sub_refusal.receive() {
            let r = smp.payload();
            let why = r.reason().to_string();
            let text = match &mut self.run {
                Some(run) if run.id == r.run_id => {
                    let text = format!("run {}: the planner refused: {why}", run.id);
                    run.refusal = Some(why);
                    text
                }
                _ => format!("the planner refused a command (run {}): {why}", r.run_id),
            };
            say(Level::Warning, &text);
            self.live.event(
                RunEventKind::Refusal,
                Some(r.run_id),
                Some("planner"),
                &text,
            );
        }
    }

    /// The planner's status: the run's state and progress, its recovery, its end; an
    /// experiment's next command.
    pub(super) fn drain_status(&mut self, now: Instant) {
        while let Ok(Some(smp)) = self.sub_status.receive() {
            let st = *smp.payload();
            let Some(run) = &mut self.run else {
                continue;
            };
            if st.run_id != run.id {
                continue;
            }
            run.planner_state = Some(st.state);
            if let Some(x) = &mut run.experiment {
                if matches!(
                    st.state,
                    planner_state::PLANNING | planner_state::RUNNING | planner_state::PAUSED
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
                        say(Level::Info, &format!("run {} recovered", run.id));
                    }
                    planner_state::REFUSED => {
                        say(
                            Level::Error,
                            &format!(
                                "run {} aborted: the restarted planner could not continue it; \
                                 the robot holds where it is",
                                run.id
                            ),
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
            if run.ended.is_some() {
                continue;
            }
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
                            say(Level::Error, &format!("run {}: {e:?}", run.id));
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

    /// Starts the `--run` / `--run-file` program once everybody is up (or gives up).
    pub(super) fn start_requested_run(&mut self, now: Instant) {
        let startup_timeout = ms(self.cfg.startup_timeout_ms);
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
                    (None, Some(n)) => (n.clone(), builtin(n)),
                    (None, None) => unreachable!("one_shot() implies --run or --run-file"),
                };
                if let Err(e) = self.start_run(&name, c) {
                    say(Level::Error, &format!("cannot run {name}: {e}"));
                    self.exit = Some(EXIT_RUN_FAILED);
                }
            }
        }
        if !self.requested_run_started
            && now - self.start > startup_timeout + ms(5000.0)
            && self.exit.is_none()
        {
            say(
                Level::Error,
                "the chain did not come up; giving up on --run",
            );
            self.exit = Some(EXIT_RUN_FAILED);
        }
    }

    /// Ends the run when it is over: closes its recording and prints its summary.
    pub(super) fn finish_run_if_over(&mut self, now: Instant) {
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
        let rows = run.recording.rows();
        let verdict = run.verdict();
        let accuracy = run.accuracy_text();
        let text = format!("run {} ({}): {verdict}", run.id, run.name);
        self.live
            .event(RunEventKind::End, Some(run.id), None, &text);
        let csv = run.recording.csv_path().to_path_buf();
        let mcap = run.recording.mcap_path().map(|p| p.to_path_buf());
        run.recording.finish();
        println!("{text}");
        self.last_summary = Some(format!(
            "{} ({}): {verdict}; {} rows in {}; {}",
            run.id,
            run.name,
            rows,
            csv.display(),
            accuracy
        ));
        self.last_verdict = Some((run.id, verdict));
        println!("recording: {} ({rows} rows)", csv.display());
        if let Some(m) = mcap {
            println!("mcap: {}", m.display());
        }
        if run.acc.n > 0 {
            match crate::figure::run_figure(&csv) {
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
                "path accuracy (planned vs measured, {} rows): position mean {:.3} mm, max \
                 {:.3} mm, RMS {:.3} mm; orientation mean {:.3} deg, max {:.3} deg, RMS {:.3} deg",
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
        if self.opts.one_shot() && self.exit.is_none() {
            self.exit = Some(if how == "done" { 0 } else { EXIT_RUN_FAILED });
        }
    }

    /// Shutdown: STOP, the run interrupted, its recording closed.
    pub(super) fn interrupt_run(&mut self) {
        let _ = pcr_nodes::publish(&self.pub_cmd, simple_command(command_kind::STOP, 0, 0));
        if let Some(r) = &mut self.run {
            if r.ended.is_none() {
                r.ended = Some((Instant::now(), "interrupted"));
            }
        }
        if let Some(mut run) = self.run.take() {
            self.record_pending_now(&mut run);
            self.live.event(
                RunEventKind::End,
                Some(run.id),
                None,
                &format!("run {} ({}): interrupted", run.id, run.name),
            );
            run.recording.finish();
        }
    }
}
