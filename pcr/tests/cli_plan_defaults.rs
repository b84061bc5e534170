//! `pcr plan circle` and `pcr plan square` without a size or speed plan the paper's shapes
//! (50 mm radius or side at 50 mm/s), as the README's `pcr plan square --blend-radius 8` expects.

use std::process::Command;

/// The plan's CSV of `pcr plan <args>` (on standard output).
fn plan(args: &[&str]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_pcr"))
        .arg("plan")
        .args(args)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .output()
        .expect("pcr runs");
    assert!(
        o.status.success(),
        "pcr plan {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout).unwrap()
}

#[test]
fn the_shapes_default_to_the_papers_size_and_speed() {
    let square = plan(&["square", "--blend-radius", "8"]);
    assert!(square.lines().count() > 100, "{square}");
    assert_eq!(
        square,
        plan(&[
            "square",
            "--side",
            "50",
            "--speed",
            "50",
            "--blend-radius",
            "8"
        ])
    );
    assert_eq!(
        plan(&["square"]),
        plan(&["square", "--side", "50", "--speed", "50"])
    );
    assert_eq!(
        plan(&["circle"]),
        plan(&["circle", "--radius", "50", "--speed", "50"])
    );
    // A size still changes the plan.
    assert_ne!(
        square,
        plan(&["square", "--side", "40", "--blend-radius", "8"])
    );
}
