//! `pcr plant run --frames`: a frame sequence of a run.

use std::process::Command;

#[test]
fn run_writes_a_frame_sequence() {
    let d = tempfile::tempdir().unwrap();
    let sp = d.path().join("sp.csv");
    let mut text = String::from("t_s,q1,q2,q3\n");
    for k in 0..30 {
        text.push_str(&format!(
            "{:.2},{},176,{}\n",
            k as f64 * 0.02,
            176 + k,
            176 - k
        ));
    }
    std::fs::write(&sp, text).unwrap();
    let frames = d.path().join("frames");
    let o = Command::new(env!("CARGO_BIN_EXE_pcr"))
        .args([
            "plant",
            "run",
            "--plant",
            "configs/plant-ideal.toml",
            "--input",
        ])
        .arg(&sp)
        .arg("--output")
        .arg(d.path().join("rec.csv"))
        .arg("--frames")
        .arg(&frames)
        .args(["--frame-every", "10"])
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut names: Vec<String> = std::fs::read_dir(&frames)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    assert_eq!(
        names,
        ["frame_00000.svg", "frame_00001.svg", "frame_00002.svg"]
    );
    let svg = std::fs::read_to_string(frames.join("frame_00002.svg")).unwrap();
    assert!(svg.contains("<svg") && svg.contains("t = 0.40 s"));
}
