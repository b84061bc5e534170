//! `pcr calibrate` on the simulated plant's calibration set says in one line which parameter
//! pairs the data hardly separate (not one warning per pair), and the report lists each pair
//! with its correlation coefficient.

use std::path::PathBuf;
use std::process::{Command, Output};

fn pcr(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pcr"))
        .args(args)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .output()
        .unwrap()
}

fn ok(o: &Output) -> String {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pcr-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn correlated_parameters_are_one_line_with_the_detail_in_the_report() {
    let dir = out_dir("calibrate-warnings");
    let rec = dir.join("calibration.csv");
    let report = dir.join("report");
    let json = dir.join("calibration.json");
    let s = |p: &PathBuf| p.to_str().unwrap().to_string();
    ok(&pcr(&[
        "experiment",
        "calibration",
        "--config",
        "configs/sim.toml",
        "--points",
        "5",
        "--test-per-group",
        "2",
        "--out",
        &s(&rec),
    ]));
    let stderr = ok(&pcr(&[
        "calibrate",
        "--data",
        &s(&rec),
        "--report",
        &s(&report),
        "--json",
        &s(&json),
    ]));
    // The pairs of the fits, from the JSON.
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let mut pairs = Vec::new();
    for fit in j["step1"]
        .as_array()
        .unwrap()
        .iter()
        .chain(std::iter::once(&j["step2"]))
        .chain(j["joint"].get("fit"))
    {
        for c in fit["correlated"].as_array().unwrap() {
            pairs.push(format!(
                "{}/{}",
                c["a"].as_str().unwrap(),
                c["b"].as_str().unwrap()
            ));
        }
    }
    // The plant's tendon maps make some coefficients of the selected map correlate.
    assert!(!pairs.is_empty(), "no correlated pairs: {stderr}");
    let lines: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("correlated"))
        .collect();
    assert_eq!(lines.len(), 1, "{stderr}");
    let line = lines[0];
    assert!(
        line.starts_with(&format!(
            "warning: {} strongly correlated parameter pairs",
            pairs.len()
        )),
        "{line}"
    );
    for p in &pairs {
        assert!(line.contains(p.as_str()), "{p} missing from: {line}");
    }
    assert!(line.contains("report.md"), "{line}");
    // The report has the table: one row per pair, with rho.
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    let table = md
        .split("## Strongly correlated parameters")
        .nth(1)
        .expect("a section on the correlated parameters");
    let rows: Vec<&str> = table
        .lines()
        .filter(|l| {
            l.starts_with("| leg") || l.starts_with("| platform") || l.starts_with("| joint fit")
        })
        .collect();
    assert_eq!(rows.len(), pairs.len(), "{table}");
    for r in &rows {
        let rho: f64 = r.split('|').nth(3).unwrap().trim().parse().unwrap();
        assert!(rho.abs() > 0.95 && rho.abs() <= 1.0, "{r}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
