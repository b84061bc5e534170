//! `pcr plan`: checked 20 ms setpoint sequences, and their use by `pcr plant run`.

use std::process::{Command, Output};

fn pcr(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pcr"))
        .args(args)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .output()
        .expect("pcr runs")
}

#[test]
fn the_papers_circle_is_planned_at_20_ms_and_closes() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("circle.csv");
    let o = pcr(&[
        "plan",
        "circle",
        "--radius",
        "50",
        "--speed",
        "50",
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut r = csv::Reader::from_path(&out).unwrap();
    let h = r.headers().unwrap().clone();
    for c in [
        "t_s",
        "xp_mm",
        "yp_mm",
        "phip_deg",
        "kappa1_per_mm",
        "q1",
        "q2",
        "q3",
    ] {
        assert!(h.iter().any(|x| x == c), "missing {c}");
    }
    let rows: Vec<Vec<f64>> = r
        .records()
        .map(|x| x.unwrap().iter().map(|c| c.parse().unwrap()).collect())
        .collect();
    // 20 ms cycle, from home and back to home
    for w in rows.windows(2) {
        assert!((w[1][0] - w[0][0] - 0.02).abs() < 1e-9);
    }
    let first = &rows[0];
    let last = rows.last().unwrap();
    assert_eq!(&first[1..4], &[0.0, 0.0, 0.0]);
    assert!(last[1].abs() < 1e-9 && last[2].abs() < 1e-9);
    assert_eq!(&last[8..11], &[176.0, 176.0, 176.0]);
    // on the circle, the planned points are 50 mm from the centre, and the speed is 50 mm/s
    let on: Vec<_> = rows
        .iter()
        .filter(|r| ((r[1] * r[1] + r[2] * r[2]).sqrt() - 50.0).abs() < 1e-6)
        .collect();
    assert!(on.len() > 300, "{}", on.len());
    assert!(rows.iter().any(|r| (r[4] - 50.0).abs() < 1e-9));
    assert!(rows.iter().all(|r| r[4] <= 50.0 + 1e-9));
}

#[test]
fn violations_name_the_motion_time_pose_and_limit() {
    let o = pcr(&["plan", "circle", "--radius", "50", "--speed", "400"]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("`circle`") && e.contains("at t = ") && e.contains("steps/s"),
        "{e}"
    );
    let o = pcr(&["plan", "line", "--to", "120,0,0", "--speed", "20"]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("`line`") && e.contains("unreachable"), "{e}");
    let o = pcr(&["plan", "square", "--side", "-3", "--speed", "20"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--side"));
    let o = pcr(&["plan", "line", "--to", "1,2", "--speed", "20"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("--to"));
}

#[test]
fn a_plan_runs_on_the_ideal_plant_and_lands_on_the_planned_poses() {
    let d = tempfile::tempdir().unwrap();
    let plan = d.path().join("sq.csv");
    let rec = d.path().join("rec.csv");
    let o = pcr(&[
        "plan",
        "square",
        "--side",
        "50",
        "--speed",
        "50",
        "--output",
        plan.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = pcr(&[
        "plant",
        "run",
        "--plant",
        "configs/plant-ideal.toml",
        "--robot",
        "configs/robot.toml",
        "--input",
        plan.to_str().unwrap(),
        "--output",
        rec.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut r = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_path(&rec)
        .unwrap();
    let h = r.headers().unwrap().clone();
    let col = |n: &str| h.iter().position(|x| x == n).unwrap();
    let (xt, yt, xp, yp) = (
        col("x_true_mm"),
        col("y_true_mm"),
        col("xp_mm"),
        col("yp_mm"),
    );
    let rows: Vec<csv::StringRecord> = r.records().map(|x| x.unwrap()).collect();
    // At the end (at rest) the ideal plant sits where the plan ends, up to step quantisation.
    let last = rows.last().unwrap();
    let f = |c: usize| last[c].parse::<f64>().unwrap();
    assert!(
        (f(xt) - f(xp)).abs() < 0.3 && (f(yt) - f(yp)).abs() < 0.3,
        "{last:?}"
    );
}
