//! `pcr convert`: any recording of the format (here one "from another program": its own
//! metadata, an extra column, labels, rows with and without measurements) to MCAP, checked with
//! an independent reader (the `mcap` Python package of the test venv, `tests/py/check_mcap.py`):
//! the channels and schemas, one message per row, every CSV cell equal on the row channel. Bad
//! input is an error naming it, never a panic.

use pcr_integration_tests::{check_mcap, workspace as repo};
use std::process::{Command, Output};

fn pcr(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pcr"))
        .args(args)
        .current_dir(repo())
        .output()
        .expect("pcr runs")
}

/// A recording as another lab's logger might write it: its own metadata, the optional columns
/// in another order, an extra column, rows without measurement.
const OTHER_PROGRAM: &str = "\
# robot = someone else's prototype
# source = lab logger 2.1
# command_delay_s = 0.02
t_s,q1,q2,q3,xp_mm,yp_mm,phip_deg,x_mm,y_mm,phi_deg,m1x_mm,m1y_mm,m2x_mm,m2y_mm,m3x_mm,m3y_mm,pose_id,rep,settled,set,operator
0,0,0,0,0,0,0,0.012,-0.004,0.01,,,,,,,0,0,0,train,ana
0.02,12,-8,3,0.5,0.1,0.2,,,,,,,,,,0,0,0,train,
0.04,25,-15,6,1,0.2,0.4,1.01,0.19,0.41,61.5,-20.25,-12,55.5,-50,-35.125,1,0,1,test,ana
0.06,25,-15,6,1,0.2,0.4,1.02,0.21,0.39,61.4,-20.2,-12.1,55.4,-50.1,-35.1,1,1,1,test,ana
0.1,30,-18,7,,,,1.5e-7,2,0.5,,,,,,,,,,,
";

#[test]
fn any_recording_converts_to_an_mcap_the_reader_matches_with_the_csv() {
    let d = tempfile::tempdir().unwrap();
    let csv = d.path().join("other.csv");
    std::fs::write(&csv, OTHER_PROGRAM).unwrap();
    // With the robot drawn.
    let mcap = d.path().join("other.mcap");
    let o = pcr(&[
        "convert",
        csv.to_str().unwrap(),
        "--mcap",
        mcap.to_str().unwrap(),
        "--robot",
        "configs/robot.toml",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        said.contains("5 rows (4 planned, 4 measured poses), robot drawn"),
        "{said}"
    );
    let r = check_mcap(&mcap, &csv, &["--scene"]);
    assert!(r.contains("5 rows of 5"), "{r}");
    // Without a robot: no scene, the rest the same.
    let bare = d.path().join("bare.mcap");
    let o = pcr(&[
        "convert",
        csv.to_str().unwrap(),
        "--mcap",
        bare.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = check_mcap(&bare, &csv, &[]);
    assert!(!r.contains("\"/robot\""), "{r}");
}

#[test]
fn a_planned_program_converts_with_its_planned_poses_only() {
    // `pcr plan`'s output is a recording of the format: planned poses, commanded steps and
    // further columns (speed, curvatures), nothing measured.
    let d = tempfile::tempdir().unwrap();
    let csv = repo().join("docs/figures/plan_circle.csv");
    let mcap = d.path().join("circle.mcap");
    let o = pcr(&[
        "convert",
        "docs/figures/plan_circle.csv",
        "--mcap",
        mcap.to_str().unwrap(),
        "--robot",
        "configs/robot.toml",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = check_mcap(&mcap, &csv, &["--scene"]);
    assert!(!r.contains("/pose/measured"), "{r}");
}

#[test]
fn bad_input_is_an_error_naming_it() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("x.mcap");
    let out = out.to_str().unwrap();
    let expect_error = |args: &[&str], needles: &[&str]| {
        let o = pcr(args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(!err.contains("panicked"), "{err}");
        for n in needles {
            assert!(err.contains(n), "{args:?}: {n:?} not in {err}");
        }
    };
    expect_error(&["convert", "no/such.csv", "--mcap", out], &["no/such.csv"]);
    let bad = d.path().join("bad.csv");
    std::fs::write(&bad, "t_s,q1,q2,q3,x_mm\n0,0,0,0,1.5\n0.02,1,2,3,abc\n").unwrap();
    expect_error(
        &["convert", bad.to_str().unwrap(), "--mcap", out],
        &["bad.csv", "line 3", "x_mm"],
    );
    let no_q = d.path().join("noq.csv");
    std::fs::write(&no_q, "t_s,x_mm\n0,1\n").unwrap();
    expect_error(
        &["convert", no_q.to_str().unwrap(), "--mcap", out],
        &["noq.csv", "q1"],
    );
    let good = d.path().join("good.csv");
    std::fs::write(&good, OTHER_PROGRAM).unwrap();
    expect_error(
        &[
            "convert",
            good.to_str().unwrap(),
            "--mcap",
            out,
            "--robot",
            "no/robot.toml",
        ],
        &["no/robot.toml"],
    );
    expect_error(
        &[
            "convert",
            good.to_str().unwrap(),
            "--mcap",
            d.path().join("x.csv").to_str().unwrap(),
        ],
        &["--mcap", ".mcap"],
    );
    expect_error(
        &[
            "convert",
            good.to_str().unwrap(),
            "--mcap",
            "/no/such/dir/x.mcap",
        ],
        &["/no/such/dir/x.mcap"],
    );
}
