//! `pcr loop` end to end on the prototype plant (small pose sets): the extended model found by
//! the residual analysis runs the robot and lowers the path error of the re-run, the calibrated
//! model lowers the nominal one, and every artefact of the loop is written.

use std::path::PathBuf;
use std::process::Command;

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pcr-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn the_loop_extends_the_model_and_the_rerun_is_better() {
    let dir = out_dir("loop");
    let o = Command::new(env!("CARGO_BIN_EXE_pcr"))
        .args([
            "loop",
            "--config",
            "configs/sim.toml",
            "--points",
            "5",
            "--test-per-group",
            "2",
            "--check-points",
            "3",
            "--out",
        ])
        .arg(&dir)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in [
        "1-calibration.csv",
        "1-paths.csv",
        "1-check.csv",
        "calibrated.toml",
        "2-paths.csv",
        "2-check.csv",
        "extended.toml",
        "residuals.json",
        "3-paths.csv",
        "3-check.csv",
        "loop.md",
        "loop.json",
        "loop_errors.svg",
        "calibration/report.md",
        "residuals/report.md",
        "evaluation/report.md",
    ] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("loop.json")).unwrap()).unwrap();
    let effects: Vec<&str> = j["effects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e.as_str().unwrap())
        .collect();
    // The prototype plant's gear play is the largest effect the calibration cannot absorb.
    assert!(effects.contains(&"backlash"), "effects {effects:?}");
    let stage = |m: &str| {
        j["robot"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["model"] == m)
            .unwrap()
            .clone()
    };
    let path = |s: &serde_json::Value, name: &str| {
        s["path_rms_mm"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p[0] == name)
            .unwrap()[1]
            .as_f64()
            .unwrap()
    };
    let (nom, cal, ext) = (stage("nominal"), stage("calibrated"), stage("extended"));
    for name in ["circle", "square"] {
        let (n, c, e) = (path(&nom, name), path(&cal, name), path(&ext, name));
        assert!(c < 0.6 * n, "{name}: calibrated {c} vs nominal {n}");
        assert!(e < 0.5 * c, "{name}: extended {e} vs calibrated {c}");
    }
    // The check poses (seen by no fit) stay at the calibrated level.
    let check = |s: &serde_json::Value| s["check_position_rms_mm"].as_f64().unwrap();
    assert!(check(&cal) < 0.3 * check(&nom));
    assert!(check(&ext) < 1.3 * check(&cal) + 0.05);
    // The residual JSON: every effect with its parameters, their uncertainties and evidence;
    // every candidate tried with its score; before and after.
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("residuals.json")).unwrap())
            .unwrap();
    for e in r["effects"].as_array().unwrap() {
        let params = e["params"].as_array().unwrap();
        let u = e["uncertainty"].as_object().unwrap();
        assert_eq!(u.len(), params.len());
        for p in params {
            // An assumed value (a bending stiffness, a pre-sliding travel) is not estimated.
            let name = p["name"].as_str().unwrap();
            if name.ends_with("(assumed)") {
                assert!(u[name].is_null(), "{name}: {}", u[name]);
                continue;
            }
            assert!(u[name].as_f64().unwrap() > 0.0, "{name}: {}", u[name]);
        }
        assert!(e["evidence"]["p_value"].as_f64().unwrap() < 0.01);
    }
    assert!(r["candidates"].as_array().unwrap().len() >= 9);
    // The analysis makes the calibration again from the drawing with its effects in the model,
    // from the loop's calibration poses, as `pcr residuals` does.
    assert_eq!(r["options"]["from_drawing"], serde_json::Value::Bool(true));
    for k in [
        "position_mean_mm",
        "position_max_mm",
        "position_rms_mm",
        "orientation_rms_deg",
    ] {
        assert!(
            r["before"][k].as_f64().unwrap() > r["after"][k].as_f64().unwrap(),
            "{k}"
        );
    }
    assert!(["explained", "partly_explained"].contains(&r["verdict"].as_str().unwrap()));
    // The extended robot file names what was added.
    let ext_toml = std::fs::read_to_string(dir.join("extended.toml")).unwrap();
    assert!(ext_toml.contains("[effects.backlash]"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_loop_refuses_a_serial_configuration() {
    let dir = out_dir("loop-serial");
    let o = Command::new(env!("CARGO_BIN_EXE_pcr"))
        .args(["loop", "--config", "configs/lab.toml", "--out"])
        .arg(&dir)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("serial"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
