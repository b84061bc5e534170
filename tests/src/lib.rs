//! Integration tests live in `tests/tests/`; this library holds what they share: the chain's
//! binaries, configurations and checkers below, and [`plant_recordings`] (the simulated plant's
//! recordings for the analysis tests).

pub mod plant_recordings;

use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository root.
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Builds the process binaries and the supervisor and returns their folder. They are built with
/// the test profile, as `cargo test` builds the libraries they link: the two builds share every
/// library (the workspace-hack crate keeps the features the same), where a dev build of the
/// chain compiled it all a second time.
pub fn chain_bin_dir() -> PathBuf {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let st = Command::new(cargo)
        .current_dir(workspace())
        .args([
            "build",
            "-q",
            "--profile",
            "test",
            "-p",
            "pcr-nodes",
            "-p",
            "pcr-supervisor",
            "--bins",
        ])
        .status()
        .expect("cargo build");
    assert!(st.success(), "cannot build the chain binaries");
    let exe = std::env::current_exe().expect("test executable");
    exe.ancestors().nth(3).expect("target folder").join("debug")
}

/// A shipped supervisor configuration made private to one test: its own iceoryx2 prefix and
/// recording folder, no real-time settings, a lenient heartbeat time-out (the 2 cores are shared),
/// the live view (if any) on a free port.
pub fn private_config(shipped: &str, prefix: &str, rec_dir: &Path, bin_dir: &Path) -> String {
    let text = std::fs::read_to_string(workspace().join(shipped)).expect("shipped config");
    let mut section = String::new();
    let body: Vec<String> = text
        .lines()
        .filter(|l| {
            let t = l.trim_start();
            if t.starts_with('[') {
                section = t.to_string();
            }
            if section == "[live]" && t.starts_with("port") {
                return false;
            }
            !t.starts_with("priority")
                && !t.starts_with("cpu")
                && !t.starts_with("iceoryx2_prefix")
                && !t.starts_with("recording_dir")
                && !t.starts_with("heartbeat_timeout_ms")
        })
        .map(|l| match l.trim_start() {
            "[live]" => "[live]\nport = 0".to_string(),
            _ => l.replace("mlockall = true", "mlockall = false"),
        })
        .collect();
    format!(
        "bin_dir = {:?}\niceoryx2_prefix = {prefix:?}\nrecording_dir = {:?}\nheartbeat_timeout_ms = 5000.0\n{}\n",
        bin_dir.display().to_string(),
        rec_dir.display().to_string(),
        body.join("\n")
    )
}

/// Files in /dev/shm left behind by an iceoryx2 prefix.
pub fn shm_leftovers(prefix: &str) -> Vec<String> {
    std::fs::read_dir("/dev/shm")
        .map(|d| {
            d.flatten()
                .map(|e| e.file_name().to_string_lossy().to_string())
                .filter(|n| n.starts_with(prefix))
                .collect()
        })
        .unwrap_or_default()
}

/// The test venv's Python (`scripts/setup.sh`: the `mcap` reader and the `websockets` client of
/// `scripts/requirements.txt`); its absence fails the test, saying so.
pub fn venv_python() -> PathBuf {
    let p = workspace().join(".venv/bin/python");
    assert!(
        p.exists(),
        "{} is missing: run `bash scripts/setup.sh` (installs the Python checkers' packages of \
         scripts/requirements.txt)",
        p.display()
    );
    p
}

/// Checks a run's MCAP against its CSV with the independent reader (`tests/py/check_mcap.py`,
/// options `more`); fails the test with the checker's message. Returns its summary line.
pub fn check_mcap(mcap: &Path, csv: &Path, more: &[&str]) -> String {
    let o = Command::new(venv_python())
        .arg(workspace().join("tests/py/check_mcap.py"))
        .arg(mcap)
        .arg(csv)
        .args(more)
        .output()
        .expect("python runs");
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        o.status.success(),
        "{out}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    out
}

/// The MCAP beside a recording (`<same stem>.mcap`).
pub fn mcap_beside(csv: &Path) -> PathBuf {
    csv.with_extension("mcap")
}
