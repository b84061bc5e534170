//! `pcr residuals` from the command line on recordings of the simulated plant with an effect
//! strong enough to bend the static poses the calibration starts from: a tendon that shortens
//! by 0.002 mm/s while the 713 s calibration recording is made (1.4 mm by its end). The
//! calibration absorbs part of it as geometry; the analysis must find the drift with its rate,
//! make the calibration again from the drawing with the drift in the model, and end at the
//! capture noise with nothing else named.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn pcr(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pcr"))
        .args(args)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .output()
        .unwrap()
}

/// `text` (a TOML file) with `key = value` set in `[section]`.
fn set_key(text: &str, section: &str, key: &str, value: &str) -> String {
    let mut current = String::new();
    text.lines()
        .map(|l| {
            let t = l.trim_start();
            if t.starts_with('[') {
                current = t.split(']').next().unwrap_or("").to_string() + "]";
            }
            let k = t.split('=').next().unwrap_or("").trim();
            if current == format!("[{section}]") && k == key && t.contains('=') {
                format!("{key} = {value}")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The ideal plant with capture noise, the 10 ms capture latency configs/sim.toml declares,
/// and leg 3's tendon drifting at `rate` mm/s.
fn drifting_plant(dir: &Path, rate: f64) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut t = std::fs::read_to_string(root.join("configs/plant-ideal.toml")).unwrap();
    t = set_key(&t, "capture", "noise", "true");
    t = set_key(&t, "capture", "latency_s", "0.01");
    t = set_key(&t, "drift", "enabled", "true");
    t = set_key(&t, "drift", "rate_mm_per_s", &format!("[0.0, 0.0, {rate}]"));
    let p = dir.join("plant.toml");
    std::fs::write(&p, t).unwrap();
    p
}

fn record(plant: &Path, out: &Path, extra: &[&str]) {
    let mut args = vec![
        "experiment",
        "calibration",
        "--config",
        "configs/sim.toml",
        "--plant",
        plant.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend(extra);
    let o = pcr(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn a_drift_that_bent_the_calibration_is_found_and_the_rest_is_noise() {
    let d = tempfile::tempdir().unwrap();
    let plant = drifting_plant(d.path(), -0.002);
    let (cal, hold) = (d.path().join("cal.csv"), d.path().join("hold.csv"));
    // 713 s: 17 points per scaled boundary.
    record(&plant, &cal, &["--points", "17"]);
    record(
        &plant,
        &hold,
        &[
            "--points",
            "6",
            "--test-per-group",
            "3",
            "--plant-seed",
            "7",
            "--seed",
            "2",
        ],
    );
    let json = d.path().join("residuals.json");
    let o = pcr(&[
        "residuals",
        "--data",
        cal.to_str().unwrap(),
        "--holdout",
        hold.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let names: Vec<&str> = v["effects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["name"].as_str().unwrap())
        .collect();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(names, ["drift"], "{stdout}");
    let rate = v["effects"][0]["params"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == "rate leg 3")
        .unwrap();
    let (value, std) = (
        rate["value"].as_f64().unwrap(),
        rate["std"].as_f64().unwrap(),
    );
    assert!(
        (value + 0.002).abs() <= (3.0 * std).max(0.02 * 0.002),
        "rate {value} +- {std} mm/s against -0.002"
    );
    // The floor: the capture noise of a row in the plane (0.05 mm per coordinate).
    let noise = v["noise"].as_array().unwrap();
    let floor = noise[0].as_f64().unwrap().hypot(noise[1].as_f64().unwrap());
    let (before, after) = (
        v["before"]["position_rms_mm"].as_f64().unwrap(),
        v["after"]["position_rms_mm"].as_f64().unwrap(),
    );
    assert!(before > 2.0, "before {before} mm");
    assert!(
        after <= 1.5 * floor,
        "after {after} mm, floor {floor} mm: {stdout}"
    );
    assert!(v["removed"].as_array().unwrap().is_empty());
}
