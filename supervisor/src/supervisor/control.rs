//! The control socket (`pcr-supervisor ctl ...`): a Unix socket taking one request line per
//! connection and answering it (status, run, pause, resume, stop, reset, verdict, shutdown).

use super::lifecycle::builtin;
use super::Supervisor;
use super::{program_command, program_name};
use crate::ctl::{self, Request};
use anyhow::{anyhow, Context, Result};
use pcr_control::command_of_moves;
use pcr_messages::{command_kind, PROTOCOL_VERSION};
use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The listening control socket.
pub(super) struct ControlSocket {
    listener: UnixListener,
    path: PathBuf,
}

impl ControlSocket {
    /// Refuses when another supervisor listens on `path`.
    pub(super) fn check_free(path: &Path) -> Result<()> {
        if path.exists() && UnixStream::connect(path).is_ok() {
            return Err(anyhow!(
                "another supervisor is listening on {}",
                path.display()
            ));
        }
        Ok(())
    }

    /// Listens on `path` (non-blocking); refuses when another supervisor listens there, removes
    /// a stale socket file.
    pub(super) fn bind(path: &Path) -> Result<Self> {
        Self::check_free(path)?;
        if path.exists() {
            let _ = std::fs::remove_file(path);
        }
        let listener = UnixListener::bind(path)
            .with_context(|| format!("control socket {}", path.display()))?;
        listener.set_nonblocking(true)?;
        Ok(Self {
            listener,
            path: path.to_path_buf(),
        })
    }

    /// The next waiting connection, if any.
    fn accept(&self) -> Option<UnixStream> {
        let (stream, _) = self.listener.accept().ok()?;
        let _ = stream.set_nonblocking(false);
        let _ = stream.set_read_timeout(Some(Duration::from_millis(500)));
        Some(stream)
    }

    /// Removes the socket file.
    pub(super) fn remove(&self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Reads one request line from a connection.
fn read_request(stream: &UnixStream) -> Result<Request, String> {
    let mut line = String::new();
    BufReader::new(stream)
        .read_line(&mut line)
        .map_err(|e| e.to_string())?;
    ctl::parse(&line).map_err(|e| e.to_string())
}

/// Writes a reply, ending it with a newline.
fn reply(mut stream: &UnixStream, text: &str) {
    let _ = stream.write_all(text.as_bytes());
    if !text.ends_with('\n') {
        let _ = stream.write_all(b"\n");
    }
}

impl Supervisor {
    /// Answers every waiting request.
    pub(super) fn serve_socket(&mut self) {
        while let Some(stream) = self.socket.accept() {
            let text = match read_request(&stream) {
                Ok(req) => self.handle(req),
                Err(e) => format!("error: {e}"),
            };
            reply(&stream, &text);
        }
    }

    fn handle(&mut self, req: Request) -> String {
        match req {
            Request::Status => self.status_text(),
            Request::RunBuiltin(n) => {
                let c = builtin(&n);
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
                match self.command_run(k) {
                    Ok(()) => word.into(),
                    Err(e) => format!("error: {e}"),
                }
            }
            Request::Reset => {
                self.safe_stop = None;
                self.reset_processes();
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
                r.recording.rows(),
                r.accuracy_text()
            )),
            None => out.push_str("run: none\n"),
        }
        if let Some(l) = &self.last_summary {
            out.push_str(&format!("last run: {l}\n"));
        }
        if let Some(live) = self.live.status_text() {
            out.push_str(&format!("{live}\n"));
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
}
