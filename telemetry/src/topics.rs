//! The channels' topics, in one place (the layout `docs/foxglove-layout.json` refers to them).

/// The recording's row, every column of the CSV (JSON, `pcr.RecordingRow`; mm, degrees, steps,
/// `t_s` relative to the recording's first row as in the CSV).
pub const ROW: &str = "/recording/row";
/// The planned platform pose (`foxglove.PoseInFrame`, frame `base`, m).
pub const PLANNED_POSE: &str = "/pose/planned";
/// The measured platform pose (`foxglove.PoseInFrame`, frame `base`, m), on rows that have one.
pub const MEASURED_POSE: &str = "/pose/measured";
/// The robot drawn (`foxglove.SceneUpdate`, frame `base`, m): legs as constant-curvature arcs of
/// the commanded steps, links, platform, measured markers M_i.
pub const SCENE: &str = "/robot";
/// Frame transforms (`foxglove.FrameTransforms`): `base` -> `platform` (measured) and `base` ->
/// `platform_planned`.
pub const TF: &str = "/tf";
/// Motor commands and driver state (JSON, `pcr.DriverState`; steps).
pub const DRIVER: &str = "/driver/state";
/// The correction of the outer loop (JSON, `pcr.Correction`; mm, degrees).
pub const CORRECTION: &str = "/correction";
/// Log lines of the supervisor (`foxglove.Log`).
pub const LOG: &str = "/log";
/// Run events: start, pause, resume, refusal, restart, end (JSON, `pcr.RunEvent`).
pub const EVENTS: &str = "/events";

/// Per-process cycle statistics and deadline misses (JSON, `pcr.CycleStats`; us):
/// `/process/<name>/stats`.
pub fn process_stats(name: &str) -> String {
    format!("/process/{name}/stats")
}

/// The frame of the robot's base (the recording's frame).
pub const BASE_FRAME: &str = "base";
/// The frame of the measured platform.
pub const PLATFORM_FRAME: &str = "platform";
/// The frame of the planned platform.
pub const PLANNED_FRAME: &str = "platform_planned";
