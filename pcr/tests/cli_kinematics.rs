//! The kinematic CLI tools end to end: `pcr ik`, `pcr fk`, `pcr workspace`.

use std::path::PathBuf;
use std::process::{Command, Output};

fn pcr(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pcr"))
        .args(args)
        .current_dir(repo())
        .output()
        .expect("pcr runs")
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> String {
    let p = dir.path().join(name);
    std::fs::write(&p, text).unwrap();
    p.to_str().unwrap().to_string()
}

fn rows(text: &str) -> Vec<std::collections::HashMap<String, String>> {
    let mut r = csv::Reader::from_reader(text.as_bytes());
    let h = r.headers().unwrap().clone();
    r.records()
        .map(|rec| {
            h.iter()
                .zip(rec.unwrap().iter())
                .map(|(a, b)| (a.to_string(), b.to_string()))
                .collect()
        })
        .collect()
}

#[test]
fn ik_then_fk_round_trip_with_statuses() {
    let d = tempfile::tempdir().unwrap();
    let input = write(
        &d,
        "poses.csv",
        "# check values of geometry.md\nx_mm,y_mm,phi_deg,note\n0,0,0,home\n20,-10,5,a\n-40,30,-10,b\n400,0,0,far\n",
    );
    let out = d.path().join("ik.csv");
    let o = pcr(&[
        "ik",
        "--robot",
        "configs/robot.toml",
        "--input",
        &input,
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&out).unwrap();
    let r = rows(&text);
    assert_eq!(r.len(), 4);
    assert_eq!(r[0]["note"], "home", "input columns are kept");
    assert_eq!(r[0]["status"], "ok");
    let k: f64 = r[1]["kappa1_per_mm"].parse().unwrap();
    assert!((k - 0.00521470).abs() < 5e-9);
    let g: f64 = r[2]["gamma1_deg"].parse().unwrap();
    assert!((g + 100.058).abs() < 1e-3);
    assert_eq!(r[3]["status"], "unreachable");
    assert_eq!(r[3]["kappa1_per_mm"], "");
    // home: 176 steps on each motor
    assert_eq!(r[0]["q1"], "176");

    // FK of the curvatures gives the poses back.
    let fk_out = d.path().join("fk.csv");
    let o = pcr(&[
        "fk",
        "--input",
        out.to_str().unwrap(),
        "--output",
        fk_out.to_str().unwrap(),
    ]);
    // the unreachable row has empty curvatures: a clear error naming its line
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("line 5") && err.contains("kappa1_per_mm"),
        "{err}"
    );
    let text: String = text
        .lines()
        .filter(|l| !l.contains("unreachable"))
        .map(|l| format!("{l}\n"))
        .collect();
    let ok_in = write(&d, "ok.csv", &text);
    let o = pcr(&[
        "fk",
        "--input",
        &ok_in,
        "--output",
        fk_out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The FK output replaces the input's pose columns instead of repeating them.
    let raw = std::fs::read_to_string(&fk_out).unwrap();
    assert_eq!(raw.lines().next().unwrap().matches("x_mm").count(), 1);
    let r = rows(&raw);
    for (row, expect) in r
        .iter()
        .zip([(0.0, 0.0, 0.0), (20.0, -10.0, 5.0), (-40.0, 30.0, -10.0)])
    {
        let x: f64 = row["x_mm"].parse().unwrap();
        let y: f64 = row["y_mm"].parse().unwrap();
        let p: f64 = row["phi_deg"].parse().unwrap();
        assert!(
            (x - expect.0).abs() < 1e-9
                && (y - expect.1).abs() < 1e-9
                && (p - expect.2).abs() < 1e-9
        );
        assert_eq!(row["status"], "ok");
    }
    assert_eq!(r.len(), 3);
}

#[test]
fn fk_from_motor_steps() {
    let d = tempfile::tempdir().unwrap();
    let input = write(&d, "q.csv", "q1,q2,q3\n176,176,176\n0,0,0\n");
    let o = pcr(&["fk", "--input", &input]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = rows(&String::from_utf8_lossy(&o.stdout));
    let x: f64 = r[0]["x_mm"].parse().unwrap();
    assert!(x.abs() < 0.5, "176 steps is near home: {x}");
    assert_eq!(r[0]["status"], "ok");
}

#[test]
fn malformed_inputs_name_the_problem() {
    let d = tempfile::tempdir().unwrap();
    let missing = write(&d, "m.csv", "x_mm,y_mm\n0,0\n");
    let o = pcr(&["ik", "--input", &missing]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("missing column `phi_deg`"));

    let bad = write(&d, "b.csv", "x_mm,y_mm,phi_deg\n0,0,0\n1,abc,0\n");
    let out = d.path().join("o.csv");
    let o = pcr(&["ik", "--input", &bad, "--output", out.to_str().unwrap()]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("line 3") && e.contains("`abc` is not a number"),
        "{e}"
    );
    // the row before the bad one was written
    assert!(std::fs::read_to_string(&out).unwrap().lines().count() >= 2);

    let ragged = write(&d, "r.csv", "x_mm,y_mm,phi_deg\n0,0\n");
    let o = pcr(&["ik", "--input", &ragged]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("line 2"));

    let nan = write(&d, "n.csv", "x_mm,y_mm,phi_deg\nNaN,0,0\n");
    let o = pcr(&["ik", "--input", &nan]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("not a finite number"));

    let cfg = std::fs::read_to_string(repo().join("configs/robot.toml")).unwrap();
    let broken = write(
        &d,
        "robot.toml",
        &cfg.replacen("l_c_mm = 125.0", "l_c_mm = 0.0", 1),
    );
    let o = pcr(&["ik", "--robot", &broken, "--input", &bad]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("legs[1].l_c_mm"));

    let o = pcr(&["fk", "--input", &missing]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("kappa1_per_mm"));
}

#[test]
fn workspace_prints_the_area_last_and_writes_figures() {
    let d = tempfile::tempdir().unwrap();
    let svg = d.path().join("ws.svg");
    let json = d.path().join("ws.json");
    let o = pcr(&[
        "workspace",
        "--phi-deg",
        "0",
        "--res",
        "2",
        "--svg",
        svg.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    let area: f64 = out.lines().last().unwrap().parse().unwrap();
    assert!((19_000.0..22_000.0).contains(&area), "{area}");
    assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(j["alpha"]["area_mm2"].as_f64().unwrap() > 19_000.0);

    let o = pcr(&["workspace", "sweep", "--r-base", "260:300:20", "--res", "4"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(out.lines().count(), 4, "{out}");

    let o = pcr(&["workspace", "sweep", "--r-base", "300:200:20"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--r-base"));
}

#[test]
fn away_from_the_repository_the_tools_use_the_nominal_robot_and_say_so() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("poses.csv");
    std::fs::write(&input, "x_mm,y_mm,phi_deg\n0,0,0\n").unwrap();
    let run = |cwd: &std::path::Path, extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_pcr"))
            .args(["ik", "--input", input.to_str().unwrap()])
            .args(extra)
            .current_dir(cwd)
            .output()
            .unwrap()
    };
    let away = run(dir.path(), &[]);
    assert!(away.status.success(), "{away:?}");
    let err = String::from_utf8_lossy(&away.stderr);
    assert!(err.contains("built-in nominal robot"), "{err}");
    // The nominal robot is configs/robot.toml: the same answer as in the repository.
    let here = run(&repo(), &[]);
    assert_eq!(away.stdout, here.stdout);
    assert!(String::from_utf8_lossy(&here.stderr).contains("robot: configs/robot.toml"));
    // A robot file that does not exist: one clear error, the OS message said once.
    let missing = run(dir.path(), &["--robot", "nope.toml"]);
    assert!(!missing.status.success());
    let err = String::from_utf8_lossy(&missing.stderr);
    assert!(err.contains("nope.toml"), "{err}");
    assert_eq!(err.matches("os error 2").count(), 1, "{err}");
}
