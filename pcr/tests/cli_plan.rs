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
    // The timing contract: a row's pose is measured before its command is sent (one 20 ms
    // setpoint spacing).
    let text = std::fs::read_to_string(&rec).unwrap();
    assert!(
        text.contains("# command_delay_s = 0.02\n"),
        "{}",
        &text[..400]
    );
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

fn read_rows(path: &std::path::Path) -> (csv::StringRecord, Vec<Vec<f64>>) {
    let mut r = csv::Reader::from_path(path).unwrap();
    let h = r.headers().unwrap().clone();
    let rows = r
        .records()
        .map(|x| x.unwrap().iter().map(|c| c.parse().unwrap()).collect())
        .collect();
    (h, rows)
}

#[test]
fn the_slot_program_keeps_its_speed_around_the_slot() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("slot.csv");
    let svg = d.path().join("slot.svg");
    let o = pcr(&[
        "plan",
        "program",
        "--file",
        "configs/programs/slot.toml",
        "--output",
        out.to_str().unwrap(),
        "--svg",
        svg.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(svg.exists());
    let (h, rows) = read_rows(&out);
    let cols: Vec<&str> = h.iter().collect();
    assert_eq!(
        cols,
        [
            "t_s",
            "xp_mm",
            "yp_mm",
            "phip_deg",
            "speed_mm_s",
            "kappa1_per_mm",
            "kappa2_per_mm",
            "kappa3_per_mm",
            "q1",
            "q2",
            "q3"
        ]
    );
    for w in rows.windows(2) {
        assert!((w[1][0] - w[0][0] - 0.02).abs() < 1e-9);
        // Never more than the drive's 600 steps/s (+1 step of rounding) per cycle.
        for c in 8..11 {
            assert!((w[1][c] - w[0][c]).abs() <= 13.0, "{:?}", w[1]);
        }
    }
    assert_eq!(&rows[0][1..4], &[0.0, 0.0, 0.0]);
    // Around the slot (from the lower straight, through both half circles, back to the lower
    // straight) the speed never drops: no stop at the tangent junctions.
    let first = rows
        .iter()
        .position(|r| r[1] > 15.0 && (r[2] + 15.0).abs() < 1e-6)
        .unwrap();
    let back = first
        + rows[first..]
            .iter()
            .position(|r| r[1] < -15.0 && (r[2] + 15.0).abs() < 1e-6)
            .unwrap();
    assert!(back - first > 150, "{first} {back}");
    for r in &rows[first..=back] {
        assert!(r[4] > 39.0 && r[4] <= 40.0 + 1e-9, "{r:?}");
    }
    // The closing corner and the dwell: at rest in the middle of the lower straight.
    assert!(rows
        .iter()
        .any(|r| r[4] == 0.0 && r[1].abs() < 1e-9 && (r[2] + 15.0).abs() < 1e-9));
    // The joint moves reach their targets exactly; the program ends on the last one.
    assert!(rows.iter().any(|r| r[8..11] == [260.0, 140.0, 176.0]));
    assert_eq!(rows.last().unwrap()[8..11], [176.0, 176.0, 176.0]);
}

#[test]
fn a_joint_move_is_synchronised_and_ends_on_its_target() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("joint.csv");
    let o = pcr(&[
        "plan",
        "joint",
        "--steps",
        "476,76,276",
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (_, rows) = read_rows(&out);
    assert_eq!(rows[0][8..11], [176.0, 176.0, 176.0]);
    assert_eq!(rows.last().unwrap()[8..11], [476.0, 76.0, 276.0]);
    // 300 steps at <= 600 steps/s: at least 0.5 s.
    assert!(rows.last().unwrap()[0] >= 0.5);
    // All motors move until (about) the end: the last change of each is within 3 cycles.
    let last_change: Vec<usize> = (8..11)
        .map(|c| rows.windows(2).rposition(|w| w[1][c] != w[0][c]).unwrap())
        .collect();
    let (lo, hi) = (
        *last_change.iter().min().unwrap(),
        *last_change.iter().max().unwrap(),
    );
    assert!(hi - lo <= 3, "{last_change:?}");
    for w in rows.windows(2) {
        for c in 8..11 {
            assert!((w[1][c] - w[0][c]).abs() <= 13.0);
        }
    }
    // The pose follows by FK: it moves away from home and the speed column is filled.
    assert!(rows.iter().any(|r| r[1].abs() > 5.0));
    assert!(rows.iter().any(|r| r[4] > 10.0));
    // From explicit start steps.
    let o = pcr(&[
        "plan",
        "joint",
        "--from-steps",
        "476,76,276",
        "--steps",
        "176,176,176",
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (_, rows) = read_rows(&out);
    assert_eq!(rows[0][8..11], [476.0, 76.0, 276.0]);
    assert_eq!(rows.last().unwrap()[8..11], [176.0, 176.0, 176.0]);
}

#[test]
fn program_and_joint_errors_name_the_file_key_and_segment() {
    let d = tempfile::tempdir().unwrap();
    let write = |name: &str, text: &str| {
        let p = d.path().join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_string()
    };
    let run = |file: &str| {
        let o = pcr(&["plan", "program", "--file", file]);
        assert!(!o.status.success());
        String::from_utf8_lossy(&o.stderr).to_string()
    };
    let f = write(
        "unknown.toml",
        "[limits]\nspeed = 20\n[[segment]]\ntype = \"line\"\nto = [10, 0]\nsped = 3\n",
    );
    let e = run(&f);
    assert!(
        e.contains("unknown.toml") && e.contains("`segment[0].sped`"),
        "{e}"
    );
    let f = write(
        "bad.toml",
        "[limits]\nspeed = 20\n[[segment]]\ntype = \"line\"\nto = [10, 0]\n[[segment]]\ntype = \"arc\"\ncenter = [10, 5]\nsweep_deg = 0\n",
    );
    let e = run(&f);
    assert!(
        e.contains("bad.toml") && e.contains("segment[1] (arc)"),
        "{e}"
    );
    // A geometric error is named by its segment too.
    let f = write(
        "zero.toml",
        "[limits]\nspeed = 20\n[[segment]]\ntype = \"line\"\nto = [10, 0]\n[[segment]]\ntype = \"line\"\nto = [10, 0]\n",
    );
    let e = run(&f);
    assert!(
        e.contains("zero.toml") && e.contains("segment[1] (line)"),
        "{e}"
    );
    // Leaving the workspace names the segment, time and pose.
    let f = write(
        "far.toml",
        "[limits]\nspeed = 20\n[[segment]]\ntype = \"line\"\nto = [10, 0]\n[[segment]]\ntype = \"line\"\nto = [10, 200]\n",
    );
    let e = run(&f);
    assert!(
        e.contains("`segment[1] (line)`") && e.contains("at t = ") && e.contains("pose ("),
        "{e}"
    );
    let f = write(
        "farjoint.toml",
        "[limits]\nspeed = 20\n[[segment]]\ntype = \"dwell\"\nseconds = 1\n[[segment]]\ntype = \"joint\"\nsteps = [3000, -3000, 176]\n",
    );
    let e = run(&f);
    assert!(
        e.contains("`segment[1] (joint)`") && e.contains("at t = "),
        "{e}"
    );
    let o = pcr(&["plan", "joint", "--steps", "1,2"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--steps"));
}

#[test]
fn a_blended_square_keeps_moving_through_its_corners() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("sq.csv");
    let o = pcr(&[
        "plan",
        "square",
        "--side",
        "50",
        "--speed",
        "50",
        "--blend-radius",
        "8",
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (_, rows) = read_rows(&out);
    let n = rows.len();
    // From home and back to home, never at rest in between (approach, corners, return).
    assert_eq!(&rows[0][1..4], &[0.0, 0.0, 0.0]);
    assert!(rows[n - 1][1].abs() < 1e-9 && rows[n - 1][2].abs() < 1e-9);
    for r in &rows[25..n - 25] {
        assert!(r[4] > 35.0 && r[4] <= 50.0 + 1e-9, "{r:?}");
    }
    // The corners are rounded: the square's corner points themselves are never visited.
    assert!(rows
        .iter()
        .all(|r| (r[1] - 25.0).abs() > 1.0 || (r[2] - 25.0).abs() > 1.0));
    let o = pcr(&[
        "plan",
        "square",
        "--side",
        "50",
        "--speed",
        "50",
        "--blend-radius",
        "-1",
    ]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("--blend-radius"));
}

#[test]
fn a_stop_request_brakes_along_the_circle_as_the_chain_does() {
    let d = tempfile::tempdir().unwrap();
    let (full, stopped) = (d.path().join("full.csv"), d.path().join("stop.csv"));
    for (out, extra) in [(&full, None), (&stopped, Some("3"))] {
        let mut args = vec![
            "plan",
            "circle",
            "--radius",
            "50",
            "--speed",
            "50",
            "--output",
            out.to_str().unwrap(),
        ];
        if let Some(t) = extra {
            args.extend(["--stop-at", t]);
        }
        let o = pcr(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let (_, a) = read_rows(&full);
    let (_, b) = read_rows(&stopped);
    // the same cycles up to the request, then braking on the circle to rest
    assert!(b.len() < a.len() - 100, "{} of {}", b.len(), a.len());
    assert_eq!(a[..150], b[..150]);
    let after: Vec<_> = b[150..].iter().collect();
    assert!(after.len() > 5, "stopped at once");
    for r in &after {
        assert!(
            ((r[1] * r[1] + r[2] * r[2]).sqrt() - 50.0).abs() < 1e-6,
            "{r:?}"
        );
    }
    for w in after.windows(2) {
        assert!(w[1][4] <= w[0][4] + 1e-9, "speeds up while braking: {w:?}");
    }
    assert_eq!(b.last().unwrap()[4], 0.0);
}
