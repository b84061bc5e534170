//! The process table and its restart policy: each configured process is started with its
//! command line, watched (exit, heartbeat time-out) and restarted after a backoff that doubles
//! per failure; more than `max_failures` failures within `window_s` escalate to a safe stop. A
//! process that refused to connect (protocol version mismatch) is not restarted.

use super::live::{say, Level};
use super::{Supervisor, EXIT_SAFE_STOP};
use crate::config::{Backend, ProcessConfig, ProcessName, SupervisorConfig};
use pcr_control::simple_command;
use pcr_messages::{command_kind, Heartbeat, PROTOCOL_VERSION};
use pcr_telemetry::RunEventKind;
use std::collections::VecDeque;
use std::os::unix::process::CommandExt;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

/// Milliseconds as a duration.
pub(super) fn ms(v: f64) -> Duration {
    Duration::from_secs_f64(v * 1e-3)
}

/// One process of the table.
pub(super) struct Proc {
    pub(super) cfg: ProcessConfig,
    pub(super) child: Option<Child>,
    pub(super) started: Instant,
    pub(super) last_hb: Option<Instant>,
    pub(super) hb: Heartbeat,
    pub(super) prev_misses: u64,
    pub(super) prev_cycles: u64,
    pub(super) restarts: u32,
    pub(super) failures: VecDeque<Instant>,
    pub(super) backoff: Duration,
    pub(super) restart_at: Option<Instant>,
    pub(super) gave_up: bool,
}

impl Proc {
    pub(super) fn name(&self) -> &'static str {
        self.cfg.name.as_str()
    }
    pub(super) fn pid(&self) -> Option<u32> {
        self.child.as_ref().map(|c| c.id())
    }
    pub(super) fn healthy(&self) -> bool {
        self.child.is_some() && self.last_hb.is_some_and(|h| h >= self.started)
    }
    /// Deadline misses summed over restarts.
    pub(super) fn misses(&self) -> u64 {
        self.prev_misses + self.hb.deadline_misses
    }
    /// Cycles summed over restarts.
    pub(super) fn cycles(&self) -> u64 {
        self.prev_cycles + self.hb.cycles
    }
}

/// The table of a configuration, every process due to start now.
pub(super) fn table(cfg: &SupervisorConfig, now: Instant) -> Vec<Proc> {
    cfg.process
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
        .collect()
}

impl Supervisor {
    /// The command line of process `i`.
    fn command_of(&self, i: usize) -> std::process::Command {
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
        cmd
    }

    /// Starts process `i`.
    pub(super) fn spawn(&mut self, i: usize) {
        let mut cmd = self.command_of(i);
        let now = Instant::now();
        let p = &mut self.procs[i];
        match cmd.spawn() {
            Ok(child) => {
                say(
                    Level::Info,
                    &format!(
                        "started {} (pid {}){}",
                        p.name(),
                        child.id(),
                        if p.restarts > 0 {
                            format!(", restart #{}", p.restarts)
                        } else {
                            String::new()
                        }
                    ),
                );
                p.child = Some(child);
                p.started = now;
                p.last_hb = None;
                p.restart_at = None;
            }
            Err(e) => {
                say(
                    Level::Error,
                    &format!("cannot start {}: {e}", cmd.get_program().to_string_lossy()),
                );
                self.failed(i, format!("cannot start: {e}"));
            }
        }
    }

    /// Process `i` failed (`why`): schedule its restart after the backoff, or give up and go
    /// to a safe stop after too many failures; the run is told ([`Self::on_process_failed`]).
    pub(super) fn failed(&mut self, i: usize, why: String) {
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
        let process = p.cfg.name;
        if p.failures.len() as u32 > max_failures {
            p.gave_up = true;
            let msg = format!(
                "{name} failed {} times within {} s (last: {why})",
                p.failures.len(),
                self.cfg.restart.window_s
            );
            say(Level::Error, &format!("{name} failed ({why}); giving up"));
            self.safe_stop(msg);
            return;
        }
        p.restarts += 1;
        p.restart_at = Some(now + p.backoff);
        let text = format!(
            "{name} failed ({why}); restart #{} in {} ms",
            p.restarts,
            p.backoff.as_millis()
        );
        p.backoff = (p.backoff * 2).min(backoff_max);
        say(Level::Warning, &text);
        let run_id = self.run.as_ref().map(|r| r.id);
        self.live
            .event(RunEventKind::Restart, run_id, Some(name), &text);
        self.on_process_failed(process, now);
    }

    /// Safe stop: STOP to the planner (the driver holds), no more restarts until `reset`.
    pub(super) fn safe_stop(&mut self, why: String) {
        if let Some(first) = &self.safe_stop {
            say(
                Level::Error,
                &format!("(already in safe stop: {first}) also: {why}"),
            );
            return;
        }
        say(Level::Error, &format!("SAFE STOP: {why}"));
        let _ = pcr_nodes::publish(&self.pub_cmd, simple_command(command_kind::STOP, 0, 0));
        let run_id = self.run.as_ref().map(|r| r.id);
        if let Some(run) = &mut self.run {
            if run.ended.is_none() {
                run.ended = Some((Instant::now(), "safe stop"));
            }
        }
        self.live.event(
            RunEventKind::SafeStop,
            run_id,
            None,
            &format!("safe stop: {why}"),
        );
        self.safe_stop = Some(why);
        if self.opts.one_shot() {
            self.exit = Some(EXIT_SAFE_STOP);
        }
    }

    /// Every process is up and has sent a heartbeat since its start.
    pub(super) fn all_healthy(&self) -> bool {
        self.procs.iter().all(Proc::healthy)
    }

    /// Takes the heartbeats (of this protocol version) and passes them on to the live view.
    pub(super) fn drain_heartbeats(&mut self, now: Instant) {
        while let Ok(Some(smp)) = self.sub_hb.receive() {
            let hb = *smp.payload();
            let Some(i) = self.procs.iter().position(|p| p.pid() == Some(hb.pid)) else {
                continue;
            };
            if hb.version != PROTOCOL_VERSION {
                say(
                    Level::Error,
                    &pcr_messages::version_mismatch_message(
                        PROTOCOL_VERSION,
                        hb.version,
                        self.procs[i].name(),
                    ),
                );
                continue;
            }
            let p = &mut self.procs[i];
            p.last_hb = Some(now);
            p.hb = hb;
            self.live.cycle_stats(p);
        }
    }

    /// Children: exited, hung (killed), due for a restart.
    pub(super) fn watch_children(&mut self, now: Instant) {
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
    }

    /// `reset`: clears the failure counts and restarts the processes given up on.
    pub(super) fn reset_processes(&mut self) {
        let now = Instant::now();
        for p in &mut self.procs {
            p.failures.clear();
            p.backoff = ms(self.cfg.restart.backoff_initial_ms);
            if p.gave_up {
                p.gave_up = false;
                p.restart_at = Some(now);
            }
        }
    }

    /// SIGTERM to planner, bridge, mocap, IK, driver (the driver last, so that it holds while
    /// the others stop), SIGKILL to one that is still there after 3 s.
    pub(super) fn stop_children(&mut self) {
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
                            say(
                                Level::Warning,
                                &format!("{} ignores SIGTERM; killing", name.as_str()),
                            );
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
    }
}
