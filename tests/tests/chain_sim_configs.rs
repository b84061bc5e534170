//! The shipped simulation configurations end to end: `configs/sim.toml` (the chain on the
//! simulated plant, the README's main job), `configs/sim-corrected.toml` (the same with the
//! motion-capture correction closed) and `configs/sim-fil.toml` (firmware in the loop)
//! run the paper's circle, print a measured path accuracy and write a recording and a figure.

use pcr_integration_tests::{chain_bin_dir, private_config, shm_leftovers, workspace};
use std::process::Command;

fn run_circle(shipped: &str, tag: &str) -> (std::process::Output, std::path::PathBuf) {
    let tmp = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("pcr-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let prefix = format!("pcr{tag}{}_", std::process::id());
    let bin = chain_bin_dir();
    let config = tmp.join("chain.toml");
    std::fs::write(
        &config,
        private_config(shipped, &prefix, &tmp.join("rec"), &bin),
    )
    .unwrap();
    let o = Command::new(bin.join("pcr-supervisor"))
        .current_dir(workspace())
        .arg("--config")
        .arg(&config)
        .args(["--run", "circle"])
        .output()
        .unwrap();
    assert!(
        shm_leftovers(&prefix).is_empty(),
        "{:?}",
        shm_leftovers(&prefix)
    );
    (o, tmp)
}

fn accuracy_mm(out: &str) -> f64 {
    let line = out
        .lines()
        .find(|l| l.starts_with("path accuracy (planned vs measured"))
        .expect(out);
    let mean = line.split("position mean ").nth(1).unwrap();
    mean.split(' ').next().unwrap().parse().unwrap()
}

#[test]
fn the_corrected_sim_config_closes_the_capture_loop_and_is_more_accurate() {
    let (o, tmp) = run_circle("configs/sim-corrected.toml", "simcorr");
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(out.contains("run 1 (circle): done"), "{out}");
    // Open loop the prototype plant is off by about 2.4 mm on average (sim.toml); the
    // correction leaves about a quarter of that.
    let mean = accuracy_mm(&out);
    assert!(mean > 0.05 && mean < 1.2, "{out}");
    let _ = std::fs::remove_dir_all(&tmp);
}

#[test]
fn sim_config_runs_the_circle_on_the_plant_with_a_measured_accuracy() {
    let (o, tmp) = run_circle("configs/sim.toml", "simcfg");
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(out.contains("run 1 (circle): done"), "{out}");
    // The prototype plant is uncalibrated: millimetres of error, but a measured one.
    let mean = accuracy_mm(&out);
    assert!(mean > 0.3 && mean < 10.0, "{out}");
    let files: Vec<_> = std::fs::read_dir(tmp.join("rec"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .collect();
    assert!(files
        .iter()
        .any(|p| p.extension().is_some_and(|e| e == "csv")));
    let svg = files
        .iter()
        .find(|p| p.extension().is_some_and(|e| e == "svg"))
        .expect("figure");
    assert!(std::fs::read_to_string(svg).unwrap().contains("planned"));
    let csv = files
        .iter()
        .find(|p| p.extension().is_some_and(|e| e == "csv"))
        .unwrap();
    assert!(std::fs::read_to_string(csv)
        .unwrap()
        .contains("# source = pcr-supervisor, simulated plant"));
    let _ = std::fs::remove_dir_all(&tmp);
}

#[test]
fn fil_config_runs_the_circle_through_the_emulated_firmware() {
    let (o, tmp) = run_circle("configs/sim-fil.toml", "filcfg");
    let out = String::from_utf8_lossy(&o.stdout);
    let err = String::from_utf8_lossy(&o.stderr);
    if out.contains("run 1 (circle): drive fault") {
        // A starved emulator lets the firmware's host watchdog trip (as on the real board): the
        // run must then end as a drive fault, not hang or pass.
        eprintln!("NOTE: the emulated firmware faulted (machine overloaded)");
        assert_eq!(o.status.code(), Some(1), "{out}\n{err}");
    } else {
        assert!(o.status.success(), "{out}\n{err}");
        assert!(out.contains("run 1 (circle): done"), "{out}");
        let mean = accuracy_mm(&out);
        assert!(mean > 0.3 && mean < 10.0, "{out}");
        let csv = std::fs::read_dir(tmp.join("rec"))
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .find(|p| p.extension().is_some_and(|e| e == "csv"))
            .unwrap();
        assert!(std::fs::read_to_string(csv)
            .unwrap()
            .contains("firmware in the loop"));
    }
    let _ = std::fs::remove_dir_all(&tmp);
}
