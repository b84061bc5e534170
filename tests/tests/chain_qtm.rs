//! The chain measuring through the QTM bridge (`configs/sim-corrected.toml`: the driver's
//! plant serves a simulated QTM, `pcr-qtm` streams and registers it, `pcr-mocap` corrects with
//! it, the recorder writes its pose and M_i): a QTM restart in the middle of the circle
//! (SIGUSR1 to the driver: connections closed, refused for 1 s) holds the correction, loses
//! no recording row, does not stop the robot, and the correction resumes when data returns.

use pcr_integration_tests::{chain_bin_dir, private_config, shm_leftovers, workspace};
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn ctl(config: &std::path::Path, bin: &std::path::Path, words: &str) -> String {
    let o = Command::new(bin.join("pcr-supervisor"))
        .arg("--config")
        .arg(config)
        .arg("ctl")
        .args(words.split(' '))
        .output()
        .unwrap();
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[test]
fn a_qtm_restart_mid_run_holds_the_correction_and_loses_no_row() {
    let tmp = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("pcr-qtm-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let prefix = format!("pcrqtm{}_", std::process::id());
    let bin = chain_bin_dir();
    let config = tmp.join("chain.toml");
    std::fs::write(
        &config,
        private_config(
            "configs/sim-corrected.toml",
            &prefix,
            &tmp.join("rec"),
            &bin,
        ),
    )
    .unwrap();
    let mut sup = Command::new(bin.join("pcr-supervisor"))
        .current_dir(workspace())
        .arg("--config")
        .arg(&config)
        .args(["--run", "circle"])
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let err = sup.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for l in BufReader::new(err).lines().map_while(Result::ok) {
            let _ = tx.send(l);
        }
    });
    let mut seen = Vec::new();
    let end = Instant::now() + Duration::from_secs(60);
    while !seen
        .iter()
        .any(|l: &String| l.contains("run 1 (circle) started"))
    {
        assert!(Instant::now() < end, "{seen:?}");
        if let Ok(l) = rx.recv_timeout(Duration::from_millis(100)) {
            seen.push(l);
        }
    }
    // The bridge delivers before the run starts.
    let status = ctl(&config, &bin, "status");
    assert!(status.contains("capture: qtm 127.0.0.1:"), "{status}");
    std::thread::sleep(Duration::from_millis(1500));
    let driver: i32 = status
        .lines()
        .find(|l| l.starts_with("process driver: up pid "))
        .and_then(|l| l.split_whitespace().nth(4))
        .and_then(|p| p.trim_end_matches(';').parse().ok())
        .expect(&status);
    // SAFETY: a signal to the driver this test's supervisor started.
    assert_eq!(unsafe { libc::kill(driver, libc::SIGUSR1) }, 0);
    let mut held_status = String::new();
    let end = Instant::now() + Duration::from_secs(5);
    while Instant::now() < end {
        let s = ctl(&config, &bin, "status");
        if s.contains("correction held") {
            held_status = s;
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = sup.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    while let Ok(l) = rx.try_recv() {
        seen.push(l);
    }
    assert!(out.status.success(), "{stdout}\n{seen:#?}");
    assert!(stdout.contains("run 1 (circle): done"), "{stdout}");
    assert!(
        held_status.contains("correction held"),
        "the status never said the correction was held"
    );
    assert!(
        !seen.iter().any(|l| l.contains("paused")),
        "the robot was paused: {seen:#?}"
    );
    let summary = stdout
        .lines()
        .find(|l| l.starts_with("capture (QTM bridge):"))
        .expect(&stdout);
    let held: u64 = summary
        .split(" rows with the correction held")
        .next()
        .and_then(|s| s.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .expect(summary);
    assert!(held >= 10, "{summary}");
    // The recording: no row lost (one per 20 ms cycle), measured before and after the
    // outage, not measured during it, M_i columns from the bridge.
    let rec = std::fs::read_dir(tmp.join("rec"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "csv"))
        .expect("a recording");
    let csv = std::fs::read_to_string(&rec).unwrap();
    assert!(csv.contains("measured by QTM through pcr-qtm"));
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    let t: Vec<f64> = rows.iter().map(|r| r[0].parse().unwrap()).collect();
    let worst_gap = t.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
    assert!(worst_gap < 0.1, "a gap of {worst_gap} s in the recording");
    let measured: Vec<bool> = rows.iter().map(|r| !r[4].is_empty()).collect();
    let first_gap = measured.iter().position(|m| !m).unwrap_or(0);
    let outage = measured
        .windows(30)
        .position(|w| w.iter().all(|m| !m))
        .expect("no outage of the capture data in the recording");
    assert!(
        outage > 20,
        "outage at row {outage} (first gap {first_gap})"
    );
    assert!(
        measured[outage + 30..].iter().filter(|m| **m).count() > 100,
        "measurements did not come back"
    );
    assert!(
        rows.iter().filter(|r| !r[7].is_empty()).count() > 200,
        "M1 column"
    );
    assert!(
        shm_leftovers(&prefix).is_empty(),
        "{:?}",
        shm_leftovers(&prefix)
    );
    let _ = std::fs::remove_dir_all(&tmp);
}
