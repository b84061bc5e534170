//! End-to-end tests of the process chain under `pcr-supervisor`: the paper run, a SIGKILLed
//! process restarted mid-run, a hung (SIGSTOPped) process, a version-mismatched process,
//! repeated failures escalating to a safe stop, Ctrl-C clean-up and malformed configurations.
//!
//! Every test uses its own iceoryx2 prefix (and so its own control socket) and a temporary
//! recording directory, and checks that no iceoryx2 file of its prefix is left behind. The
//! tests run one at a time (2 cores): heartbeat timing must not suffer from a neighbour's load.

use pcr_integration_tests::{chain_bin_dir, check_mcap, mcap_beside, workspace};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

static SERIAL: Mutex<()> = Mutex::new(());

/// The chain's binaries, built once per test binary.
fn bin_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(chain_bin_dir)
}

struct Chain {
    prefix: String,
    dir: tempfile::TempDir,
    config: PathBuf,
}

impl Chain {
    fn new(tag: &str, extra_top: &str, extra_tail: &str) -> Chain {
        let prefix = format!("pcrt{}{}_", std::process::id(), tag);
        let dir = tempfile::tempdir().unwrap();
        let config = dir.path().join("chain.toml");
        let text = format!(
            r#"{extra_top}
robot = "{robot}"
iceoryx2_prefix = "{prefix}"
recording_dir = "{rec}"
bin_dir = "{bin}"
heartbeat_ms = 100.0
startup_timeout_ms = 20000.0
[[process]]
name = "driver"
backend = "sim"
[[process]]
name = "ik"
[[process]]
name = "planner"
[[process]]
name = "mocap"
{extra_tail}
"#,
            robot = workspace().join("configs/robot.toml").display(),
            rec = dir.path().join("rec").display(),
            bin = bin_dir().display(),
        );
        std::fs::write(&config, text).unwrap();
        Chain {
            prefix,
            dir,
            config,
        }
    }

    fn supervisor(&self, args: &[&str]) -> (Child, Receiver<String>, Receiver<String>) {
        let mut c = Command::new(bin_dir().join("pcr-supervisor"))
            .current_dir(workspace())
            .arg("--config")
            .arg(&self.config)
            .args(args)
            .env("RUST_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let out = lines(c.stdout.take().unwrap());
        let err = lines(c.stderr.take().unwrap());
        (c, out, err)
    }

    /// Waits until every process started and `ctl status` reports the chain ready.
    fn wait_ready(&self, err: &Receiver<String>, seen: &mut Vec<String>) {
        assert!(
            wait_for(err, "started mocap", Duration::from_secs(30), seen),
            "{seen:?}"
        );
        let end = Instant::now() + Duration::from_secs(30);
        while !self.ctl("status").starts_with("state: ready") {
            assert!(Instant::now() < end, "chain not ready");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    fn ctl_output(&self, words: &str) -> std::process::Output {
        Command::new(bin_dir().join("pcr-supervisor"))
            .arg("--config")
            .arg(&self.config)
            .arg("ctl")
            .args(words.split(' '))
            .output()
            .unwrap()
    }

    fn ctl(&self, words: &str) -> String {
        let o = Command::new(bin_dir().join("pcr-supervisor"))
            .arg("--config")
            .arg(&self.config)
            .arg("ctl")
            .args(words.split(' '))
            .output()
            .unwrap();
        String::from_utf8_lossy(&o.stdout).into_owned()
    }

    /// Pid of a chain process from `ctl status`.
    fn pid_of(&self, name: &str) -> Option<i32> {
        let s = self.ctl("status");
        let l = s
            .lines()
            .find(|l| l.starts_with(&format!("process {name}: up pid ")))?;
        l.split_whitespace()
            .nth(4)?
            .trim_end_matches(';')
            .parse()
            .ok()
    }

    fn leftovers(&self) -> Vec<String> {
        let mut v = Vec::new();
        for d in ["/dev/shm", "/tmp/iceoryx2"] {
            if let Ok(rd) = std::fs::read_dir(d) {
                for e in rd.flatten() {
                    let n = e.file_name().to_string_lossy().into_owned();
                    if n.starts_with(&self.prefix) {
                        v.push(n);
                    }
                }
            }
        }
        v
    }

    fn processes_left(&self) -> usize {
        let o = Command::new("pgrep")
            .args(["-f", &format!("--prefix {}", self.prefix)])
            .output()
            .unwrap();
        String::from_utf8_lossy(&o.stdout).lines().count()
    }
}

fn lines(r: impl std::io::Read + Send + 'static) -> Receiver<String> {
    let (tx, rx) = channel();
    std::thread::spawn(move || {
        for l in BufReader::new(r).lines().map_while(Result::ok) {
            eprintln!("| {l}");
            if tx.send(l).is_err() {
                break;
            }
        }
    });
    rx
}

/// Waits for a line containing `pat`; returns everything read so far.
fn wait_for(rx: &Receiver<String>, pat: &str, timeout: Duration, seen: &mut Vec<String>) -> bool {
    let end = Instant::now() + timeout;
    while let Some(left) = end.checked_duration_since(Instant::now()) {
        match rx.recv_timeout(left) {
            Ok(l) => {
                let hit = l.contains(pat);
                seen.push(l);
                if hit {
                    return true;
                }
            }
            Err(_) => return false,
        }
    }
    false
}

fn wait_exit(c: &mut Child, timeout: Duration) -> ExitStatus {
    let end = Instant::now() + timeout;
    loop {
        if let Some(s) = c.try_wait().unwrap() {
            return s;
        }
        if Instant::now() > end {
            let _ = c.kill();
            panic!("supervisor did not exit within {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn drain(rx: &Receiver<String>, seen: &mut Vec<String>) {
    while let Ok(l) = rx.recv_timeout(Duration::from_millis(200)) {
        seen.push(l);
    }
}

fn kill(pid: i32, sig: i32) {
    // SAFETY: kill(2) on a pid of our test's own chain.
    assert_eq!(unsafe { libc::kill(pid, sig) }, 0, "kill {pid} {sig}");
}

fn lock() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

#[test]
fn run_paper_prints_the_summary_and_exits_zero() {
    let _g = lock();
    let chain = Chain::new("paper", "heartbeat_timeout_ms = 2000.0", "");
    let (mut sup, out, err) = chain.supervisor(&["--run", "paper"]);
    let st = wait_exit(&mut sup, Duration::from_secs(120));
    let mut o = Vec::new();
    drain(&out, &mut o);
    let mut e = Vec::new();
    drain(&err, &mut e);
    assert!(st.success(), "exit {st:?}\n{}", e.join("\n"));
    let text = o.join("\n");
    assert!(text.contains("run 1 (paper): done"), "{text}");
    let acc = o
        .iter()
        .find(|l| l.starts_with("path accuracy"))
        .expect("accuracy line");
    for w in ["mean", "max", "RMS", "orientation"] {
        assert!(acc.contains(w), "{acc}");
    }
    // The recording exists in the recording format.
    let rec = std::fs::read_dir(chain.dir.path().join("rec"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "csv"))
        .expect("a recording");
    let csv = std::fs::read_to_string(rec).unwrap();
    let header = csv.lines().find(|l| !l.starts_with('#')).unwrap();
    assert_eq!(
        header,
        "t_s,q1,q2,q3,x_mm,y_mm,phi_deg,m1x_mm,m1y_mm,m2x_mm,m2y_mm,m3x_mm,m3y_mm,xp_mm,yp_mm,\
         phip_deg"
    );
    assert!(csv.lines().count() > 500);
    // The timing contract: the driver executes each row's command over the next 20 ms cycle.
    let r = pcr_recording::Recording::read(csv.as_bytes(), "run").unwrap();
    assert_eq!(r.command_delay_s().unwrap(), 0.02);
    assert!(chain.leftovers().is_empty(), "{:?}", chain.leftovers());
    assert_eq!(chain.processes_left(), 0);
}

/// The run's recording (the only CSV of the chain's recording directory).
fn recording_of(chain: &Chain) -> Option<PathBuf> {
    std::fs::read_dir(chain.dir.path().join("rec"))
        .ok()?
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "csv"))
}

/// Time of the last complete row of a recording being written (a line ending in a newline).
fn last_row_time(path: &Path) -> Option<f64> {
    let text = std::fs::read_to_string(path).ok()?;
    let complete = &text[..text.rfind('\n')?];
    complete.lines().last()?.split(',').next()?.parse().ok()
}

#[test]
fn a_supervisor_killed_mid_run_leaves_every_row_it_recorded() {
    let _g = lock();
    let chain = Chain::new("sk", "heartbeat_timeout_ms = 2000.0", "");
    let (mut sup, _out, err) = chain.supervisor(&["--run", "paper"]);
    let mut e = Vec::new();
    assert!(
        wait_for(
            &err,
            "run 1 (paper) started",
            Duration::from_secs(60),
            &mut e
        ),
        "{e:?}"
    );
    let rec = recording_of(&chain).expect("the run's recording");
    // Well into the run: the recording holds a few seconds of rows.
    let end = Instant::now() + Duration::from_secs(30);
    while last_row_time(&rec).unwrap_or(0.0) < 3.0 {
        assert!(Instant::now() < end, "the recording does not grow");
        std::thread::sleep(Duration::from_millis(50));
    }
    let before = last_row_time(&rec).unwrap();
    let read_at = Instant::now();
    kill(sup.id() as i32, libc::SIGKILL);
    let gap = read_at.elapsed().as_secs_f64();
    let _ = sup.wait();
    // The children stop (SIGTERM on their parent's death) and the drive holds.
    assert!(
        wait_for(
            &err,
            "the drive holds at steps",
            Duration::from_secs(10),
            &mut e
        ),
        "{e:?}"
    );
    let end = Instant::now() + Duration::from_secs(10);
    while chain.processes_left() > 0 {
        assert!(
            Instant::now() < end,
            "chain processes left after the supervisor died"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    // Every row parses, and the file ends within a cycle or two of the kill.
    let r = pcr_recording::Recording::read_path(&rec)
        .unwrap_or_else(|err| panic!("the killed run's recording does not read: {err}"));
    let text = std::fs::read_to_string(&rec).unwrap();
    assert!(
        text.ends_with('\n'),
        "torn last row: {:?}",
        text.lines().last()
    );
    let last = r.rows.last().expect("rows").t_s;
    assert!(
        last >= before && last <= before + gap + 0.05,
        "last row at {last} s; {before} s was on file {gap:.3} s before the kill"
    );
    assert!(r.rows.len() > 100, "{} rows", r.rows.len());
    for (i, w) in r.rows.windows(2).enumerate() {
        assert!(w[1].t_s > w[0].t_s, "row {i}: time goes back");
    }
    // The MCAP beside it has no summary (never closed); its complete chunks read in order
    // (as `mcap recover` does) are the CSV's first rows, to within a second of its last.
    let summary = check_mcap(&mcap_beside(&rec), &rec, &["--killed"]);
    eprintln!("{summary}");
    // The dead supervisor's iceoryx2 files: a later start cleans them; here, by hand.
    for d in ["/dev/shm", "/tmp/iceoryx2"] {
        for n in chain.leftovers() {
            let p = Path::new(d).join(n);
            let _ = std::fs::remove_file(&p).or_else(|_| std::fs::remove_dir_all(&p));
        }
    }
}

#[test]
fn sigkill_mid_run_restarts_the_process_and_the_motion_resumes() {
    let _g = lock();
    let chain = Chain::new("kill", "heartbeat_timeout_ms = 2000.0", "");
    let (mut sup, out, err) = chain.supervisor(&["--run", "circle"]);
    let mut e = Vec::new();
    assert!(
        wait_for(
            &err,
            "run 1 (circle) started",
            Duration::from_secs(60),
            &mut e
        ),
        "{e:?}"
    );
    std::thread::sleep(Duration::from_secs(2));
    let ik = chain.pid_of("ik").expect("ik pid");
    kill(ik, libc::SIGKILL);
    assert!(
        wait_for(
            &err,
            "ik failed (exited: signal: 9",
            Duration::from_secs(30),
            &mut e
        ),
        "{e:?}"
    );
    assert!(
        wait_for(&err, "run 1 resumed", Duration::from_secs(20), &mut e),
        "{e:?}"
    );
    let st = wait_exit(&mut sup, Duration::from_secs(90));
    let mut o = Vec::new();
    drain(&out, &mut o);
    drain(&err, &mut e);
    assert!(st.success(), "exit {st:?}\n{}", e.join("\n"));
    assert!(e
        .iter()
        .any(|l| l.contains("started ik") && l.contains("restart #1")));
    assert!(
        o.iter().any(|l| l.contains("run 1 (circle): done")),
        "{o:?}"
    );
    assert!(
        o.iter().any(|l| l.contains("process ik: restarts 1")),
        "{o:?}"
    );
    assert!(chain.leftovers().is_empty(), "{:?}", chain.leftovers());
    assert_eq!(chain.processes_left(), 0);
}

#[test]
fn a_hung_process_is_detected_killed_and_restarted() {
    let _g = lock();
    let chain = Chain::new("hang", "heartbeat_timeout_ms = 600.0", "");
    let (mut sup, _out, err) = chain.supervisor(&[]);
    let mut e = Vec::new();
    chain.wait_ready(&err, &mut e);
    let ik = chain.pid_of("ik").unwrap();
    kill(ik, libc::SIGSTOP);
    assert!(
        wait_for(
            &err,
            "ik failed (hung: no heartbeat",
            Duration::from_secs(10),
            &mut e
        ),
        "{e:?}"
    );
    assert!(wait_for(
        &err,
        "started ik",
        Duration::from_secs(10),
        &mut e
    ));
    let end = Instant::now() + Duration::from_secs(20);
    loop {
        let s = chain.ctl("status");
        if s.contains("process ik: up") && s.contains("restarts 1") {
            break;
        }
        assert!(Instant::now() < end, "{s}");
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_ne!(chain.pid_of("ik"), Some(ik));
    assert!(chain.ctl("shutdown").contains("shutting down"));
    let st = wait_exit(&mut sup, Duration::from_secs(30));
    assert!(st.success(), "{st:?}");
    assert!(chain.leftovers().is_empty(), "{:?}", chain.leftovers());
    assert_eq!(chain.processes_left(), 0);
}

#[test]
fn a_version_mismatched_process_is_refused() {
    let _g = lock();
    let chain = Chain::new("ver", "heartbeat_timeout_ms = 2000.0", "");
    let (mut sup, _out, err) = chain.supervisor(&[]);
    let mut e = Vec::new();
    chain.wait_ready(&err, &mut e);
    let o = Command::new(bin_dir().join("pcr-ik"))
        .current_dir(workspace())
        .args(["--prefix", &chain.prefix, "--protocol-version", "99"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{stderr}");
    assert!(stderr.contains("protocol version mismatch"), "{stderr}");
    assert!(
        stderr.contains("v99") && stderr.contains(&format!("v{}", pcr_messages::PROTOCOL_VERSION)),
        "{stderr}"
    );
    // The chain is unaffected.
    assert!(chain.ctl("status").starts_with("state: ready"));
    // SIGINT (Ctrl-C) shuts the chain down cleanly.
    kill(sup.id() as i32, libc::SIGINT);
    let st = wait_exit(&mut sup, Duration::from_secs(30));
    assert!(st.success(), "{st:?}");
    assert!(chain.leftovers().is_empty(), "{:?}", chain.leftovers());
    assert_eq!(chain.processes_left(), 0);
}

#[test]
fn repeated_failures_escalate_to_a_safe_stop() {
    let _g = lock();
    let chain = Chain::new(
        "safe",
        "heartbeat_timeout_ms = 2000.0",
        "[restart]\nmax_failures = 1\nbackoff_initial_ms = 50.0\n",
    );
    let (mut sup, _out, err) = chain.supervisor(&["--run", "paper"]);
    let mut e = Vec::new();
    assert!(wait_for(
        &err,
        "run 1 (paper) started",
        Duration::from_secs(60),
        &mut e
    ));
    for round in 0..2 {
        let end = Instant::now() + Duration::from_secs(20);
        let pid = loop {
            if let Some(p) = chain.pid_of("ik") {
                break p;
            }
            assert!(Instant::now() < end, "ik not up (round {round})");
            std::thread::sleep(Duration::from_millis(50));
        };
        kill(pid, libc::SIGKILL);
        assert!(wait_for(&err, "ik failed", Duration::from_secs(30), &mut e));
    }
    assert!(
        wait_for(&err, "SAFE STOP", Duration::from_secs(30), &mut e),
        "{e:?}"
    );
    let st = wait_exit(&mut sup, Duration::from_secs(30));
    assert_eq!(st.code(), Some(2), "{st:?}");
    assert!(chain.leftovers().is_empty(), "{:?}", chain.leftovers());
    assert_eq!(chain.processes_left(), 0);
}

#[test]
fn malformed_configs_are_refused_naming_the_key() {
    let _g = lock();
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("period_ms = \"fast\"\n", "period_ms"),
        (
            "[[process]]\nname = \"planner\"\n[[process]]\nname = \"ik\"\n[[process]]\nname = \"driver\"\nbackend = \"warp\"\n",
            "process[2].backend",
        ),
        ("[restart]\nmax_failure = 3\n", "max_failure"),
        ("heartbeat_ms = 100.0\nheartbeat_timeout_ms = 150.0\n[[process]]\nname = \"planner\"\n[[process]]\nname = \"ik\"\n[[process]]\nname = \"driver\"\nbackend = \"sim\"\n", "heartbeat_timeout_ms"),
        ("[[process]]\nname = \"planner\"\n[[process]]\nname = \"ik\"\n[[process]]\nname = \"driver\"\nbackend = \"serial\"\n", "process[2].port"),
        ("period_ms = [\n", "not valid TOML"),
    ];
    for (i, (text, key)) in cases.iter().enumerate() {
        let p = dir.path().join(format!("bad{i}.toml"));
        std::fs::write(&p, text).unwrap();
        let o = Command::new(bin_dir().join("pcr-supervisor"))
            .arg("--config")
            .arg(&p)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(78), "case {i}: {stderr}");
        assert!(
            stderr.contains(key),
            "case {i}: expected {key:?} in {stderr}"
        );
    }
}

#[test]
fn a_killed_planner_is_restarted_and_the_run_continues_where_the_robot_stopped() {
    let _g = lock();
    let chain = Chain::new("plan", "heartbeat_timeout_ms = 2000.0", "");
    let (mut sup, out, err) = chain.supervisor(&["--run", "circle"]);
    let mut e = Vec::new();
    assert!(
        wait_for(
            &err,
            "run 1 (circle) started",
            Duration::from_secs(60),
            &mut e
        ),
        "{e:?}"
    );
    std::thread::sleep(Duration::from_secs(2));
    let planner = chain.pid_of("planner").expect("planner pid");
    kill(planner, libc::SIGKILL);
    assert!(
        wait_for(&err, "run 1 recovered", Duration::from_secs(30), &mut e),
        "{e:?}"
    );
    let st = wait_exit(&mut sup, Duration::from_secs(60));
    let mut o = Vec::new();
    drain(&out, &mut o);
    drain(&err, &mut e);
    // The run completed (exit 0) after the restart, and no row jumps: the robot held while
    // the planner was away and continued from there.
    assert_eq!(st.code(), Some(0), "{e:?}");
    assert!(
        o.iter().any(|l| l.contains("run 1 (circle): done")),
        "{o:?}"
    );
    assert!(
        e.iter().any(|l| l.contains("planner failed")),
        "the planner was restarted: {e:?}"
    );
    let rec = std::fs::read_dir(chain.dir.path().join("rec"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "csv"))
        .expect("a recording");
    let csv = std::fs::read_to_string(rec).unwrap();
    let q: Vec<(f64, [i64; 3])> = csv
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("t_s"))
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (
                f[0].parse().unwrap(),
                [1, 2, 3].map(|k| f[k].parse().unwrap()),
            )
        })
        .collect();
    // No jump: within the drives' 600 steps/s plus one cycle's motion, whatever the row spacing.
    for w in q.windows(2) {
        let dt = w[1].0 - w[0].0;
        for k in 0..3 {
            let d = (w[1].1[k] - w[0].1[k]).abs() as f64;
            assert!(d <= 600.0 * dt + 15.0, "jump {:?} -> {:?}", w[0], w[1]);
        }
    }
    assert!(chain.leftovers().is_empty(), "{:?}", chain.leftovers());
    assert_eq!(chain.processes_left(), 0);
}

#[test]
fn a_mismatched_binary_started_by_the_supervisor_is_not_restarted() {
    let _g = lock();
    // The IK of "another revision": it speaks protocol v99.
    let chain = Chain::new("mism", "heartbeat_timeout_ms = 2000.0", "");
    let text = std::fs::read_to_string(&chain.config).unwrap().replace(
        "name = \"ik\"\n",
        "name = \"ik\"\nargs = [\"--protocol-version\", \"99\"]\n",
    );
    std::fs::write(&chain.config, text).unwrap();
    let (mut sup, _out, err) = chain.supervisor(&["--run", "paper"]);
    let st = wait_exit(&mut sup, Duration::from_secs(60));
    let mut e = Vec::new();
    drain(&err, &mut e);
    assert_eq!(st.code(), Some(2), "{e:?}");
    assert!(
        e.iter().any(|l| l.contains("protocol version mismatch")),
        "{e:?}"
    );
    assert!(e.iter().any(|l| l.contains("SAFE STOP")), "{e:?}");
    assert!(!e.iter().any(|l| l.contains("restart #")), "{e:?}");
    // Only the stray binary refused; the processes of this revision connected.
    for other in ["pcr-planner", "pcr-driver", "pcr-mocap"] {
        assert!(
            !e.iter().any(|l| l.starts_with(&format!("{other}: error"))),
            "{e:?}"
        );
    }
    assert!(chain.leftovers().is_empty(), "{:?}", chain.leftovers());
    assert_eq!(chain.processes_left(), 0);
}

#[test]
fn ctl_runs_a_list_of_moves_with_pause_and_resume() {
    let _g = lock();
    let chain = Chain::new("ctl", "heartbeat_timeout_ms = 2000.0", "");
    let (mut sup, out, err) = chain.supervisor(&[]);
    let mut e = Vec::new();
    chain.wait_ready(&err, &mut e);
    let r = chain.ctl("run moves line 20 10 0 30; dwell 0.5; circle 0 0 20 40; line 0 0 0 30");
    assert!(r.contains("run 1 (moves) started"), "{r}");
    assert!(
        chain.ctl("run paper").starts_with("error"),
        "one run at a time"
    );
    std::thread::sleep(Duration::from_millis(500));
    assert_eq!(chain.ctl("pause").trim(), "paused");
    let at_pause = chain.ctl("status");
    // The pause brakes along the path (well under a second), then holds.
    std::thread::sleep(Duration::from_millis(1500));
    let a = chain.ctl("status");
    assert!(a.contains("run 1 (moves): paused"), "{a}");
    std::thread::sleep(Duration::from_millis(500));
    let b = chain.ctl("status");
    let progress = |s: &str| -> f64 {
        s.split("progress ")
            .nth(1)
            .unwrap()
            .split('/')
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    assert_eq!(
        progress(&a),
        progress(&b),
        "paused program time must not advance"
    );
    // Braking from rate 1 to 0 here (peak 40 mm/s) covers about 0.25 s of program time; a
    // freeze or a rewind would add at most the status's staleness (< 0.1 s).
    assert!(
        progress(&a) > progress(&at_pause) + 0.1,
        "a pause brakes forward along the path, it neither freezes nor goes back: {at_pause} {a}"
    );
    assert_eq!(chain.ctl("resume").trim(), "resumed");
    let mut o = Vec::new();
    assert!(
        wait_for(&out, "run 1 (moves): done", Duration::from_secs(30), &mut o),
        "{o:?}"
    );
    let st = chain.ctl("status");
    assert!(st.contains("last run: 1 (moves): done"), "{st}");
    // A refused program: `ctl run` waits for the planner's verdict, prints the reason and
    // fails; the status keeps the reason and reports no accuracy over no measured row.
    let o = chain.ctl_output("run moves line 500 0 0 30");
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(!o.status.success(), "{text}");
    assert!(
        text.contains("run 2: refused: ") && text.contains("unreachable"),
        "{text}"
    );
    let end = Instant::now() + Duration::from_secs(10);
    let st = loop {
        let st = chain.ctl("status");
        if st.contains("last run: 2") || Instant::now() > end {
            break st;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    assert!(st.contains("last run: 2 (moves): refused: "), "{st}");
    assert!(
        st.contains("unreachable") && st.contains("accuracy: no measured rows"),
        "{st}"
    );
    assert!(chain.ctl("verdict 2").contains("refused: "));
    assert!(chain.ctl("bogus").starts_with("error"));
    assert!(chain.ctl("shutdown").contains("shutting down"));
    let st = wait_exit(&mut sup, Duration::from_secs(30));
    assert!(st.success(), "{st:?}");
    assert!(chain.leftovers().is_empty(), "{:?}", chain.leftovers());
}

#[test]
fn ctl_runs_an_experiment_live_and_labels_its_rows() {
    let _g = lock();
    let chain = Chain::new("exp", "heartbeat_timeout_ms = 2000.0", "");
    let (mut sup, out, err) = chain.supervisor(&[]);
    let mut e = Vec::new();
    chain.wait_ready(&err, &mut e);
    // A bad option is refused by name before anything moves.
    let o = chain.ctl_output("run experiment calibration pionts=3");
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stdout).contains("pionts"));
    // Three poses (one boundary at scale 0.2, phi 0) approached four times each, short
    // dwells: 12 visits, more than one chain command (10 visits per command).
    let o = chain.ctl_output(
        "run experiment repeatability points=3 phis-deg=0 scales=0.2 test-per-group=1 reps=4 \
         settle=0.3 measure=0.3 speed=40",
    );
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        text.contains("run 1 (experiment-repeatability) started"),
        "{text}"
    );
    let mut lines = Vec::new();
    assert!(
        wait_for(
            &out,
            "run 1 (experiment-repeatability): done",
            Duration::from_secs(90),
            &mut lines
        ),
        "{lines:?}"
    );
    let rec = recording_of(&chain).expect("the experiment's recording");
    let r = pcr_recording::Recording::read_path(&rec).unwrap();
    assert_eq!(r.meta("experiment"), Some("repeatability"));
    assert_eq!(r.meta("commands"), Some("2"));
    let poses = pcr_recording::settled_poses(&r, "live").unwrap();
    assert_eq!(poses.len(), 12, "{poses:?}");
    let mut ids: Vec<(u64, u64)> = poses
        .iter()
        .map(|p| (p.pose_id.unwrap(), p.rep.unwrap()))
        .collect();
    ids.sort_unstable();
    ids.dedup();
    assert_eq!(ids.len(), 12, "every (pose, rep) visited once: {ids:?}");
    for p in &poses {
        assert!(p.rows >= 5, "{p:?}");
        // The ideal drive reaches the target: the measured pose is the planned one.
        let (m, pl) = (p.pose.unwrap(), p.planned.unwrap());
        assert!((m[0] - pl[0]).hypot(m[1] - pl[1]) < 0.5, "{p:?}");
    }
    assert!(chain.ctl("shutdown").contains("shutting down"));
    let st = wait_exit(&mut sup, Duration::from_secs(30));
    assert!(st.success(), "{st:?}");
    assert!(chain.leftovers().is_empty(), "{:?}", chain.leftovers());
}

#[test]
fn a_briefly_stalled_driver_rearms_its_watchdog_and_the_run_completes() {
    let _g = lock();
    let chain = Chain::new("stall", "heartbeat_timeout_ms = 3000.0", "");
    let (mut sup, out, err) = chain.supervisor(&["--run", "circle"]);
    let mut e = Vec::new();
    assert!(
        wait_for(
            &err,
            "run 1 (circle) started",
            Duration::from_secs(60),
            &mut e
        ),
        "{e:?}"
    );
    std::thread::sleep(Duration::from_secs(2));
    let drv = chain.pid_of("driver").expect("driver pid");
    // Stalled for longer than its watchdog (100 ms), shorter than the heartbeat timeout.
    kill(drv, libc::SIGSTOP);
    std::thread::sleep(Duration::from_millis(500));
    kill(drv, libc::SIGCONT);
    let st = wait_exit(&mut sup, Duration::from_secs(90));
    let mut o = Vec::new();
    drain(&out, &mut o);
    drain(&err, &mut e);
    assert!(st.success(), "exit {st:?}\n{}", e.join("\n"));
    assert!(e.iter().any(|l| l.contains("watchdog re-armed")), "{e:?}");
    assert!(
        o.iter().any(|l| l.contains("run 1 (circle): done")),
        "{o:?}"
    );
    let rows: u64 = o
        .iter()
        .find_map(|l| l.strip_prefix("recording: "))
        .and_then(|l| l.split(" (").nth(1))
        .and_then(|l| l.split(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap();
    assert!(
        rows > 400,
        "{rows} rows: the driver must keep recording after the stall"
    );
    assert!(chain.leftovers().is_empty(), "{:?}", chain.leftovers());
}
