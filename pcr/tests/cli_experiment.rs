//! `pcr experiment`: the pose set, reduced runs of every experiment, and bad input.

use pcr_recording::{settled_poses, Recording};
use std::path::Path;
use std::process::{Command, Output};

fn pcr_env(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_pcr"));
    c.args(args)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .env_remove("SOURCE_DATE_EPOCH");
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().expect("pcr runs")
}

fn pcr(args: &[&str]) -> Output {
    pcr_env(args, &[])
}

fn ok(o: &Output) -> String {
    assert!(
        o.status.success(),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The command failed cleanly (no panic) with an error containing every `needle`.
fn fails_with(o: &Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "succeeded: {err}");
    assert!(!err.contains("panicked"), "{err}");
    for n in needles {
        assert!(err.contains(n), "`{n}` not in: {err}");
    }
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A reduced calibration set: 2 orientations x 1 scale x 3 points.
const SMALL: [&str; 14] = [
    "--points",
    "3",
    "--scales",
    "0.5",
    "--phis-deg",
    "0,-10",
    "--test-per-group",
    "1",
    "--settle",
    "0.3",
    "--measure",
    "0.2",
    "--speed",
    "50",
];

#[test]
fn design_calibration_writes_the_189_poses_and_the_figure() {
    let d = tempfile::tempdir().unwrap();
    let (out, svg) = (d.path().join("poses.csv"), d.path().join("fig5.svg"));
    let text = ok(&pcr(&[
        "experiment",
        "design",
        "calibration",
        "--robot",
        "configs/robot.toml",
        "--out",
        s(&out),
        "--svg",
        s(&svg),
        "--seed",
        "3",
    ]));
    assert!(
        text.contains("189 poses (126 train, 63 test, seed 3)"),
        "{text}"
    );
    let mut r = csv::Reader::from_path(&out).unwrap();
    assert_eq!(
        r.headers().unwrap(),
        vec!["pose_id", "x_mm", "y_mm", "phi_deg", "scale", "point", "set"]
    );
    let rows: Vec<csv::StringRecord> = r.records().map(Result::unwrap).collect();
    assert_eq!(rows.len(), 189);
    assert_eq!(rows.iter().filter(|r| &r[6] == "test").count(), 63);
    assert_eq!(&rows[188][0], "188");
    assert_eq!((&rows[126][3], &rows[126][4]), ("-10", "0.75"));
    let fig = std::fs::read_to_string(&svg).unwrap();
    assert!(fig.contains("<svg") && fig.contains("phi = +10 deg") && fig.contains("test (21)"));
}

#[test]
fn a_reduced_calibration_run_records_one_settled_group_per_pose() {
    let d = tempfile::tempdir().unwrap();
    // (the output's folder is created)
    let out = d.path().join("new").join("cal.csv");
    let mut args = vec![
        "experiment",
        "calibration",
        "--config",
        "configs/sim.toml",
        "--plant",
        "configs/plant-ideal.toml",
        "--seed",
        "4",
        "--out",
        s(&out),
    ];
    args.extend(SMALL);
    let text = ok(&pcr(&args));
    assert!(text.contains("calibration: 6 items"), "{text}");
    let rec = Recording::read_path(&out).unwrap();
    assert_eq!(rec.meta("experiment"), Some("calibration"));
    assert_eq!(rec.meta("robot"), Some("configs/robot.toml"));
    assert_eq!(rec.meta("plant"), Some("configs/plant-ideal.toml"));
    assert_eq!(rec.meta("seed"), Some("4"));
    assert_eq!(rec.meta("phis_deg"), Some("0 -10"));
    assert!(rec.meta("created").is_some() && rec.meta("source").is_some());
    assert_eq!(rec.extra_columns, ["segment", "motor", "amplitude_steps"]);
    let g = settled_poses(&rec, "cal.csv").unwrap();
    assert_eq!(g.len(), 6);
    for (k, g) in g.iter().enumerate() {
        assert_eq!((g.pose_id, g.rep), (Some(k as u64), Some(0)));
        let (p, t) = (g.pose.unwrap(), g.planned.unwrap());
        assert!((p[0] - t[0]).hypot(p[1] - t[1]) < 0.3, "{}", g.label());
    }
}

#[test]
fn the_model_can_be_replaced_without_changing_the_plant() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("cal.csv");
    let mut args = vec![
        "experiment",
        "repeatability",
        "--config",
        "configs/sim.toml",
        "--robot",
        "configs/robot.toml",
        "--plant",
        "configs/plant-ideal.toml",
        "--reps",
        "2",
        "--out",
        s(&out),
    ];
    args.extend(SMALL);
    let text = ok(&pcr(&args));
    assert!(text.contains("repeatability: 6 items"), "{text}");
    let rec = Recording::read_path(&out).unwrap();
    assert_eq!(rec.meta("plant_robot"), Some("configs/robot.toml"));
    assert_eq!(rec.meta("reps"), Some("2"));
    let ids: Vec<_> = settled_poses(&rec, "r.csv")
        .unwrap()
        .iter()
        .map(|g| (g.pose_id.unwrap(), g.rep.unwrap()))
        .collect();
    assert_eq!(ids, [(0, 0), (0, 1), (1, 0), (1, 1), (2, 0), (2, 1)]);
}

#[test]
fn paths_and_backlash_runs_label_their_rows_and_are_reproducible() {
    let d = tempfile::tempdir().unwrap();
    // a supervisor config whose driver is the ideal `sim` backend: the ideal plant
    let cfg = d.path().join("sup.toml");
    std::fs::write(
        &cfg,
        "robot = \"configs/robot.toml\"\nperiod_ms = 20.0\n[[process]]\nname = \"planner\"\n\
         [[process]]\nname = \"driver\"\nbackend = \"sim\"\n",
    )
    .unwrap();
    let paths = d.path().join("paths.csv");
    ok(&pcr(&[
        "experiment",
        "paths",
        "--config",
        s(&cfg),
        "--out",
        s(&paths),
    ]));
    let rec = Recording::read_path(&paths).unwrap();
    assert!(rec.meta("plant").unwrap().starts_with("ideal"));
    let seg = rec.extra_index("segment").unwrap();
    for name in ["circle", "square"] {
        assert!(rec
            .rows
            .iter()
            .any(|r| r.extra[seg].as_deref() == Some(name)));
    }
    // backlash on the prototype plant, twice with the same SOURCE_DATE_EPOCH: same bytes
    let run = |name: &str| {
        let out = d.path().join(name);
        ok(&pcr_env(
            &[
                "experiment",
                "backlash",
                "--config",
                "configs/sim.toml",
                "--motors",
                "3",
                "--max-steps",
                "2",
                "--periods",
                "2",
                "--out",
                s(&out),
            ],
            &[("SOURCE_DATE_EPOCH", "1767225600")],
        ));
        std::fs::read(out).unwrap()
    };
    let (a, b) = (run("b1.csv"), run("b2.csv"));
    assert!(a == b, "two runs differ");
    let rec = Recording::read(&a[..], "b1.csv").unwrap();
    assert_eq!(rec.meta("created"), Some("2026-01-01T00:00:00Z"));
    assert_eq!(rec.meta("home_steps"), Some("176 176 176"));
    let (m, n) = (
        rec.extra_index("motor").unwrap(),
        rec.extra_index("amplitude_steps").unwrap(),
    );
    let blocks: Vec<(String, String)> = rec
        .rows
        .iter()
        .filter_map(|r| Some((r.extra[m].clone()?, r.extra[n].clone()?)))
        .collect();
    assert!(blocks.iter().all(|b| b.0 == "3"));
    assert!(blocks.iter().any(|b| b.1 == "1") && blocks.iter().any(|b| b.1 == "2"));
}

#[test]
fn bad_input_is_refused_naming_the_file_or_option() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("x.csv");
    let o = s(&out);
    // missing files
    fails_with(
        &pcr(&["experiment", "paths", "--config", "nope.toml", "--out", o]),
        &["--config nope.toml", "cannot read"],
    );
    fails_with(
        &pcr(&[
            "experiment",
            "paths",
            "--config",
            "configs/sim.toml",
            "--plant",
            "configs/nope.toml",
            "--out",
            o,
        ]),
        &["--plant configs/nope.toml"],
    );
    fails_with(
        &pcr(&[
            "experiment",
            "paths",
            "--config",
            "configs/sim.toml",
            "--robot",
            "nope-robot.toml",
            "--out",
            o,
        ]),
        &["--robot nope-robot.toml"],
    );
    // an output whose folder is a file
    let blocker = d.path().join("file");
    std::fs::write(&blocker, "").unwrap();
    let bad_out = blocker.join("x.csv");
    fails_with(
        &pcr(&[
            "experiment",
            "paths",
            "--config",
            "configs/sim.toml",
            "--out",
            s(&bad_out),
        ]),
        &[&format!("--out {}", bad_out.display())],
    );
    // a config without a simulated plant
    fails_with(
        &pcr(&[
            "experiment",
            "paths",
            "--config",
            "configs/lab.toml",
            "--out",
            o,
        ]),
        &["configs/lab.toml", "serial", "--plant"],
    );
    // bad numbers and ranges
    fails_with(
        &pcr(&[
            "experiment",
            "design",
            "calibration",
            "--out",
            o,
            "--scales",
            "0.5,abc",
        ]),
        &["--scales"],
    );
    fails_with(
        &pcr(&[
            "experiment",
            "calibration",
            "--config",
            "configs/sim.toml",
            "--out",
            o,
            "--speed=-3",
        ]),
        &["speed_mm_s"],
    );
    fails_with(
        &pcr(&[
            "experiment",
            "design",
            "calibration",
            "--out",
            o,
            "--test-per-group",
            "30",
        ]),
        &["test_per_group"],
    );
    fails_with(
        &pcr(&[
            "experiment",
            "backlash",
            "--config",
            "configs/sim.toml",
            "--out",
            o,
            "--freq-hz",
            "40",
        ]),
        &["half a period"],
    );
    // an infeasible design lists its poses
    fails_with(
        &pcr(&[
            "experiment",
            "design",
            "calibration",
            "--out",
            o,
            "--phis-deg",
            "0",
            "--scales",
            "1",
            "--points",
            "8",
            "--test-per-group",
            "2",
            "--singularity-margin",
            "300",
        ]),
        &["not feasible", "pose_id 0 ", "conditioning"],
    );
}
