//! Program files through the chain: `configs/programs/slot.toml` (a composite slot traversed
//! without stopping, a dwell, a line home and two joint moves) runs under `pcr-supervisor
//! --run-file` on `configs/sim.toml` (the simulated plant) to "done" with a measured accuracy
//! and a recording named after the file; `ctl run program` starts the same from a running
//! supervisor; a malformed program file is refused with an error naming the file and the key.

use pcr_integration_tests::{chain_bin_dir, private_config, shm_leftovers, workspace};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

static SERIAL: Mutex<()> = Mutex::new(());

fn bin_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(chain_bin_dir)
}

/// A private copy of configs/sim.toml in a fresh folder: (folder, config, iceoryx2 prefix).
fn setup(tag: &str) -> (PathBuf, PathBuf, String) {
    let tmp =
        Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("pcr-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp).unwrap();
    let prefix = format!("pcr{tag}{}_", std::process::id());
    let config = tmp.join("chain.toml");
    std::fs::write(
        &config,
        private_config("configs/sim.toml", &prefix, &tmp.join("rec"), bin_dir()),
    )
    .unwrap();
    (tmp, config, prefix)
}

/// Shuts a supervisor down (SIGTERM, then SIGKILL) if a test fails while it runs.
struct Reaper(std::process::Child);

impl Drop for Reaper {
    fn drop(&mut self) {
        if self.0.try_wait().ok().flatten().is_none() {
            let _ = Command::new("kill")
                .args(["-TERM", &self.0.id().to_string()])
                .status();
            let t0 = Instant::now();
            while self.0.try_wait().ok().flatten().is_none()
                && t0.elapsed() < Duration::from_secs(10)
            {
                std::thread::sleep(Duration::from_millis(100));
            }
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

fn recordings(tmp: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(tmp.join("rec"))
        .map(|d| d.flatten().map(|e| e.path()).collect())
        .unwrap_or_default()
}

#[test]
fn the_slot_program_runs_on_the_simulated_plant() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let (tmp, config, prefix) = setup("progslot");
    let o = Command::new(bin_dir().join("pcr-supervisor"))
        .current_dir(workspace())
        .arg("--config")
        .arg(&config)
        .args(["--run-file", "configs/programs/slot.toml"])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{out}\n{err}");
    assert!(out.contains("run 1 (slot): done"), "{out}");
    let line = out
        .lines()
        .find(|l| l.starts_with("path accuracy (planned vs measured"))
        .unwrap_or_else(|| panic!("{out}"));
    let mean: f64 = line
        .split("position mean ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("{line}"));
    // The prototype plant is uncalibrated: millimetres of error, but a measured one.
    assert!(mean > 0.05 && mean < 10.0, "{out}");
    let csv = recordings(&tmp)
        .into_iter()
        .find(|p| {
            p.extension().is_some_and(|e| e == "csv")
                && p.file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with("slot-"))
        })
        .unwrap_or_else(|| panic!("no slot-*.csv recording: {:?}", recordings(&tmp)));
    let text = std::fs::read_to_string(csv).unwrap();
    assert!(
        text.contains("# program = slot"),
        "{}",
        &text[..400.min(text.len())]
    );
    // Several seconds of samples (the slot alone takes over 4 s).
    assert!(text.lines().count() > 300, "{} rows", text.lines().count());
    assert!(
        shm_leftovers(&prefix).is_empty(),
        "{:?}",
        shm_leftovers(&prefix)
    );
    let _ = std::fs::remove_dir_all(&tmp);
}

#[test]
fn a_malformed_program_file_is_refused_naming_the_file() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let (tmp, config, prefix) = setup("progbad");
    let bad = tmp.join("bad-program.toml");
    std::fs::write(
        &bad,
        "[limits]\nspeed = 20.0\n[[segment]]\ntype = \"line\"\nto = [1.0, 2.0]\nradius = 3.0\n",
    )
    .unwrap();
    let o = Command::new(bin_dir().join("pcr-supervisor"))
        .current_dir(workspace())
        .arg("--config")
        .arg(&config)
        .arg("--run-file")
        .arg(&bad)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("bad-program.toml") && err.contains("`segment[0].radius`"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    // A missing file too.
    let o = Command::new(bin_dir().join("pcr-supervisor"))
        .current_dir(workspace())
        .arg("--config")
        .arg(&config)
        .args(["--run-file", "no/such/program.toml"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("no/such/program.toml"), "{err}");
    assert!(
        shm_leftovers(&prefix).is_empty(),
        "{:?}",
        shm_leftovers(&prefix)
    );
    let _ = std::fs::remove_dir_all(&tmp);
}

#[test]
fn ctl_run_program_starts_a_program_file_and_refuses_a_bad_one() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let (tmp, config, prefix) = setup("progctl");
    let bad = tmp.join("broken.toml");
    std::fs::write(&bad, "[limits]\nspeed = 20.0\n").unwrap();
    let mut sup = Reaper(
        Command::new(bin_dir().join("pcr-supervisor"))
            .current_dir(workspace())
            .arg("--config")
            .arg(&config)
            .env("RUST_LOG", "warn")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    // The client runs from another folder: it sends the path made absolute.
    let ctl = |words: &[&str]| {
        let o = Command::new(bin_dir().join("pcr-supervisor"))
            .current_dir(workspace().join("configs"))
            .arg("--config")
            .arg(&config)
            .arg("ctl")
            .args(words)
            .output()
            .unwrap();
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let t0 = Instant::now();
    let bad_reply = loop {
        let r = ctl(&["run", "program", bad.to_str().unwrap()]);
        if !(r.is_empty() || r.contains("not all processes are up"))
            || t0.elapsed() > Duration::from_secs(60)
        {
            break r;
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    assert!(
        bad_reply.starts_with("error:") && bad_reply.contains("broken.toml"),
        "{bad_reply}"
    );
    assert!(bad_reply.contains("segment"), "{bad_reply}");
    let r = ctl(&["run", "program", "programs/slot.toml"]);
    assert!(r.contains("(slot) started"), "{r}");
    // Runs to the end.
    let t0 = Instant::now();
    let mut status = String::new();
    while t0.elapsed() < Duration::from_secs(60) {
        status = ctl(&["status"]);
        if status.contains("(slot): done") {
            break;
        }
        std::thread::sleep(Duration::from_millis(300));
    }
    assert!(status.contains("1 (slot): done"), "{status}");
    assert!(!ctl(&["shutdown"]).is_empty());
    let t0 = Instant::now();
    while sup.0.try_wait().unwrap().is_none() && t0.elapsed() < Duration::from_secs(20) {
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(
        sup.0.try_wait().unwrap().is_some(),
        "the supervisor did not shut down"
    );
    assert!(recordings(&tmp).iter().any(|p| p
        .file_name()
        .is_some_and(|n| n.to_string_lossy().starts_with("slot-"))));
    assert!(
        shm_leftovers(&prefix).is_empty(),
        "{:?}",
        shm_leftovers(&prefix)
    );
    let _ = std::fs::remove_dir_all(&tmp);
}
