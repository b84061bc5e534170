//! `pcr calibrate`, `pcr calibrate leg` and `pcr evaluate` from the command line: outputs that
//! load and run, and clear errors on bad input. Data come from the constant-curvature model of a
//! robot with known deviations (the plant-based accuracy tests are in tests/).

use pcr_kinematics::{Pose, Robot};
use pcr_robot::{RobotConfig, TendonMapKind, TendonMapSpec};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn pcr(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pcr"))
        .args(args)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .output()
        .unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A robot that differs from the nominal one.
fn deviated() -> RobotConfig {
    let mut r = RobotConfig::nominal();
    for (i, l) in r.legs.iter_mut().enumerate() {
        l.psi_deg += [0.3, -0.2, 0.25][i];
        l.l_c_mm += [0.4, -0.3, 0.2][i];
        l.r_p_mm += [-0.2, 0.1, 0.3][i];
        l.theta_p_deg += [0.3, -0.2, -0.1][i];
        l.tendon_map = TendonMapSpec::symmetric(
            TendonMapKind::Affine,
            vec![1e-5 * (i as f64 + 1.0), 1.0 / 900.0],
        );
    }
    r
}

/// A static recording of `truth` driven by the nominal model's IK: `n` poses on rings, three
/// settled rows each (tiny deterministic noise), every third pose in the test set.
fn recording(truth: &RobotConfig, n: usize) -> String {
    let nominal = Robot::new(&RobotConfig::nominal()).unwrap();
    let tr = Robot::new(truth).unwrap();
    let mut s = String::from(
        "# source = cli test\nt_s,q1,q2,q3,x_mm,y_mm,phi_deg,m1x_mm,m1y_mm,m2x_mm,m2y_mm,m3x_mm,m3y_mm,xp_mm,yp_mm,phip_deg,pose_id,settled,set\n",
    );
    let mut t = 0.0;
    let mut k = 0;
    let mut id = 0;
    while id < n {
        let r = 12.0 + 40.0 * ((k % 3) as f64) / 2.0;
        let a = (k as f64 * 47.0).to_radians();
        let phi = [0.0, 8.0, -8.0][k % 3];
        k += 1;
        let target = Pose::from_mm_deg(r * a.cos(), r * a.sin(), phi);
        let Ok(sol) = nominal.ik(&target) else {
            continue;
        };
        let q: [f64; 3] =
            std::array::from_fn(|i| nominal.kappa_to_steps(i, sol.kappa[i]).unwrap().round());
        let kappa: [f64; 3] = std::array::from_fn(|i| tr.steps_to_kappa(i, q[i]));
        let Ok(p) = tr.fk(&kappa) else { continue };
        let set = if id % 3 == 1 { "test" } else { "train" };
        for j in 0..3 {
            t += 0.02;
            let e = 0.01 * (j as f64 - 1.0);
            let m: Vec<String> = (0..3)
                .flat_map(|i| {
                    let m = tr.joint_m(i, kappa[i]);
                    [format!("{}", m[0] + e), format!("{}", m[1] - e)]
                })
                .collect();
            s += &format!(
                "{t:.2},{},{},{},{},{},{},{},{},{},{},{id},1,{set}\n",
                q[0],
                q[1],
                q[2],
                p.x + e,
                p.y - e,
                p.phi_deg() + e,
                m.join(","),
                target.x,
                target.y,
                phi
            );
        }
        t += 0.02;
        s += &format!(
            "{t:.2},{},{},{},,,,,,,,,,,,,{id},0,{set}\n",
            q[0], q[1], q[2]
        );
        id += 1;
    }
    s
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn calibrate_writes_a_robot_that_loads_json_and_report() {
    let d = tempfile::tempdir().unwrap();
    let rec = write(d.path(), "cal.csv", &recording(&deviated(), 45));
    let out = d.path().join("calibrated.toml");
    let json = d.path().join("cal.json");
    let report = d.path().join("report");
    let o = pcr(&[
        "calibrate",
        "--data",
        rec.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(!text.to_lowercase().contains("nan"));
    let cal = RobotConfig::load(&out).unwrap();
    let robot = Robot::new(&cal).unwrap();
    // The calibrated model reproduces the truth on a pose it never saw.
    let truth = Robot::new(&deviated()).unwrap();
    let pose = Pose::from_mm_deg(-20.0, 15.0, 3.0);
    let s = robot.ik(&pose).unwrap();
    let q: [f64; 3] = std::array::from_fn(|i| robot.kappa_to_steps(i, s.kappa[i]).unwrap());
    let kt: [f64; 3] = std::array::from_fn(|i| truth.steps_to_kappa(i, q[i]));
    let reached = truth.fk(&kt).unwrap();
    assert!(reached.position_distance(&pose) < 0.05, "{reached:?}");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["table1"].as_array().unwrap().len(), 13);
    assert_eq!(v["table1"][12]["form"], "k0 + k1 dl + k2 dl^2 + k3 ln(dl)");
    assert!(
        v["after"]["test"]["pose"]["position_rms_mm"]
            .as_f64()
            .unwrap()
            < 0.05
    );
    assert!(v["step1"][0]["params"][0]["std"].as_f64().unwrap() > 0.0);
    // By default the two steps are refined jointly; both results are reported.
    assert_eq!(v["options"]["method"], "joint");
    assert_eq!(v["used"], "joint");
    let joint = &v["joint"];
    assert!(joint["fit"]["params"][0]["std"].as_f64().unwrap() > 0.0);
    assert_eq!(joint["fit"]["params"][0]["name"], "psi_deg[1]");
    let paper_test = v["paper"]["test"]["pose"]["position_rms_mm"]
        .as_f64()
        .unwrap();
    let joint_test = joint["accuracy"]["test"]["pose"]["position_rms_mm"]
        .as_f64()
        .unwrap();
    assert_eq!(
        Some(joint_test),
        v["after"]["test"]["pose"]["position_rms_mm"].as_f64()
    );
    assert!(
        paper_test < 0.05 && joint_test < 0.05,
        "{paper_test} {joint_test}"
    );
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(md.contains("## Joint refinement") && md.contains("| joint, **test** |"));
    for f in [
        "report.md",
        "table1.svg",
        "poses.svg",
        "maps.svg",
        "errors.svg",
    ] {
        assert!(report.join(f).exists(), "{f}");
    }
    // The calibrated file drives the other tools unchanged.
    let o = pcr(&[
        "fk",
        "--robot",
        out.to_str().unwrap(),
        "--input",
        "/dev/null",
    ]);
    assert!(
        !stderr(&o).contains("robot configuration"),
        "{}",
        stderr(&o)
    );
}

/// `--method paper` stops after the paper's two steps: no joint fit, the robot of step 2.
#[test]
fn calibrate_method_paper_keeps_the_two_steps() {
    let d = tempfile::tempdir().unwrap();
    let rec = write(d.path(), "cal.csv", &recording(&deviated(), 45));
    let json = d.path().join("cal.json");
    let o = pcr(&[
        "calibrate",
        "--data",
        rec.to_str().unwrap(),
        "--method",
        "paper",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["options"]["method"], "paper");
    assert_eq!(v["used"], "paper");
    assert!(v["joint"].is_null());
    assert_eq!(v["after"], v["paper"]);
    let o = pcr(&[
        "calibrate",
        "--data",
        rec.to_str().unwrap(),
        "--method",
        "both",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--method"), "{}", stderr(&o));
}

#[test]
fn calibrate_refuses_bad_recordings_with_clear_errors() {
    let d = tempfile::tempdir().unwrap();
    let good = recording(&deviated(), 30);
    let run = |name: &str, text: &str| -> String {
        let p = write(d.path(), name, text);
        let out = d.path().join(format!("{name}.toml"));
        let o = pcr(&[
            "calibrate",
            "--data",
            p.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(!o.status.success(), "{name} was accepted");
        assert!(!out.exists(), "{name}: a robot file was written");
        stderr(&o)
    };
    // No M_i columns at all.
    let no_m: String = good
        .lines()
        .map(|l| {
            if l.starts_with('#') {
                return format!("{l}\n");
            }
            let c: Vec<&str> = l.split(',').collect();
            format!("{},{}\n", c[..7].join(","), c[13..].join(","))
        })
        .collect();
    let e = run("no_m.csv", &no_m);
    assert!(e.contains("m1x_mm") && e.contains("no_m.csv"), "{e}");
    // M2 empty in every row.
    let no_m2: String = good
        .lines()
        .map(|l| {
            if l.starts_with('#') || l.starts_with("t_s") {
                return format!("{l}\n");
            }
            let mut c: Vec<&str> = l.split(',').collect();
            c[9] = "";
            c[10] = "";
            format!("{}\n", c.join(","))
        })
        .collect();
    let e = run("no_m2.csv", &no_m2);
    assert!(e.contains("M2") && e.contains("m2x_mm"), "{e}");
    // No settled rows.
    let unsettled = good
        .replace(",1,train\n", ",0,train\n")
        .replace(",1,test\n", ",0,test\n");
    let e = run("unsettled.csv", &unsettled);
    assert!(e.contains("settled"), "{e}");
    // Time going backwards.
    let mut lines: Vec<&str> = good.lines().collect();
    lines.swap(4, 5);
    let e = run("backwards.csv", &(lines.join("\n") + "\n"));
    assert!(e.contains("backwards.csv") && e.contains("line"), "{e}");
    // Too few poses for the parameters.
    let few: String = good
        .lines()
        .take(2 + 4 * 3)
        .map(|l| format!("{l}\n"))
        .collect();
    let e = run("few.csv", &few);
    assert!(e.contains("few.csv"), "{e}");
    assert!(
        e.contains("training points") || e.contains("training poses"),
        "{e}"
    );
    // A bad number names line and column.
    let bad = good.replacen(",1,train\n", ",yes,train\n", 1);
    let e = run("bad.csv", &bad);
    assert!(e.contains("settled") && e.contains("line"), "{e}");
}

#[test]
fn calibrate_leg_finds_a_segment_that_bends_differently_each_way() {
    let d = tempfile::tempdir().unwrap();
    // A 125 mm segment whose quadratic term is even (k2 dl^2 taken literally on both signs):
    // it bends less one way than the other.
    let mut text = String::from("dl_mm,mx_mm,my_mm\n");
    for k in 0..60 {
        let dl: f64 = -3.0 + 0.19 * k as f64;
        let kappa = 2e-5 + 1.1e-3 * dl + 4e-5 * dl * dl;
        let th = kappa * 125.0;
        let (mx, my) = ((1.0 - th.cos()) / kappa, th.sin() / kappa);
        text += &format!("{dl},{mx},{my}\n");
    }
    let p = write(d.path(), "leg.csv", &text);
    let json = d.path().join("leg.json");
    let o = pcr(&[
        "calibrate",
        "leg",
        "--data",
        p.to_str().unwrap(),
        "--l-c-mm",
        "125",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let f = v["functions"].as_array().unwrap();
    let (sym, asym) = (&f[4], &f[5]);
    assert_eq!((&sym["label"], &asym["label"]), (&"3".into(), &"3a".into()));
    // The asymmetric reading of function 3 holds the truth: k_neg = (k1, -k2).
    assert!(asym["test_rms_mm"].as_f64().unwrap() < 1e-6, "{asym}");
    assert!((asym["coefficients_neg"][1].as_f64().unwrap() + 4e-5).abs() < 1e-9);
    assert!(sym["test_rms_mm"].as_f64().unwrap() > 0.1, "{sym}");
    assert!(v["best"].as_str().unwrap().ends_with('a'), "{}", v["best"]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("asymmetric"), "{out}");
}

#[test]
fn calibrate_leg_fits_a_segment_file() {
    let d = tempfile::tempdir().unwrap();
    // A 110 mm segment with a 20 mm extension, curvature 1e-4 + 1.1e-3 dl + 2e-4 sqrt(dl).
    let mut text = String::from("dl_mm,mx_mm,my_mm\n");
    for k in 0..40 {
        let dl: f64 = 0.25 + 0.2 * k as f64;
        let kappa = 1e-4 + 1.1e-3 * dl + 2e-4 * dl.sqrt();
        let th = kappa * 110.0;
        let (mx, my) = (
            (1.0 - th.cos()) / kappa + 20.0 * th.sin(),
            th.sin() / kappa + 20.0 * th.cos(),
        );
        text += &format!("{dl},{mx},{my}\n");
    }
    let p = write(d.path(), "leg.csv", &text);
    let json = d.path().join("leg.json");
    let o = pcr(&[
        "calibrate",
        "leg",
        "--data",
        p.to_str().unwrap(),
        "--l-c-mm",
        "110",
        "--l-ce-mm",
        "20",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let f = v["functions"].as_array().unwrap();
    // Every function in both readings; dl > 0 only, so the asymmetric ones are refused.
    assert_eq!(f.len(), 26);
    assert_eq!(
        (&f[8]["index"], &f[8]["reading"]),
        (&5.into(), &"symmetric".into())
    );
    assert!(f[8]["test_rms_mm"].as_f64().unwrap() < 1e-6, "{}", f[8]);
    assert!((f[8]["coefficients"][2].as_f64().unwrap() - 2e-4).abs() < 1e-9);
    assert!(
        f[9]["error"].as_str().unwrap().contains("dl < 0"),
        "{}",
        f[9]
    );
    assert!(v["best"].as_str().is_some());
    assert_eq!(v["n_test"], 13);
    // q1 without --robot, and a missing column, are refused by name.
    let p = write(d.path(), "q.csv", "q1,mx_mm,my_mm\n1,2,3\n");
    let o = pcr(&[
        "calibrate",
        "leg",
        "--data",
        p.to_str().unwrap(),
        "--l-c-mm",
        "110",
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("--robot"),
        "{}",
        stderr(&o)
    );
    let p = write(d.path(), "m.csv", "dl_mm,mx_mm\n1,2\n");
    let o = pcr(&[
        "calibrate",
        "leg",
        "--data",
        p.to_str().unwrap(),
        "--l-c-mm",
        "110",
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("my_mm"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn evaluate_prints_table_two_and_writes_json() {
    let d = tempfile::tempdir().unwrap();
    let a = write(d.path(), "a.csv", &recording(&deviated(), 12));
    let json = d.path().join("e.json");
    let report = d.path().join("rep");
    let arg = format!("uncalibrated={}", a.display());
    let o = pcr(&[
        "evaluate",
        "--data",
        &arg,
        "--json",
        json.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("pose uncalibrated") && out.contains("mean dr (mm)"),
        "{out}"
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let p = &v["evaluations"][0]["pose_accuracy"];
    assert_eq!(p["poses"], 12);
    assert!(p["position_mm"]["mean"].as_f64().unwrap() > 0.1);
    assert!(report.join("report.md").exists());
    let o = pcr(&["evaluate"]);
    assert!(!o.status.success() && stderr(&o).contains("--data"));
}
