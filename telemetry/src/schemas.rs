//! The JSON schemas of the channels that no Foxglove schema fits (encoding `jsonschema`,
//! messages `json`).

use foxglove::Schema;
use serde_json::{json, Value};

fn schema(name: &str, title: &str, properties: Value, required: &[&str]) -> Schema {
    let s = json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "type": "object",
        "properties": properties,
        "required": required,
    });
    Schema::new(name, "jsonschema", s.to_string().into_bytes())
}

fn opt_number(description: &str) -> Value {
    json!({ "type": ["number", "null"], "description": description })
}

/// `pcr.RecordingRow`: one row of the recording (`shared/spec/recording.md`), every column of the
/// CSV; an empty cell is `null`; extra columns (e.g. an experiment's `segment`) are strings.
pub fn recording_row() -> Schema {
    let mut p = serde_json::Map::new();
    p.insert(
        "t_s".into(),
        json!({"type": "number", "description": "time since the recording's first row, s"}),
    );
    for q in ["q1", "q2", "q3"] {
        p.insert(
            q.into(),
            json!({"type": "integer", "description": "motor position commanded, steps"}),
        );
    }
    for (c, d) in [
        ("x_mm", "measured platform x, mm"),
        ("y_mm", "measured platform y, mm"),
        ("phi_deg", "measured platform orientation, deg"),
        ("m1x_mm", "measured joint M_1 x, mm"),
        ("m1y_mm", "measured joint M_1 y, mm"),
        ("m2x_mm", "measured joint M_2 x, mm"),
        ("m2y_mm", "measured joint M_2 y, mm"),
        ("m3x_mm", "measured joint M_3 x, mm"),
        ("m3y_mm", "measured joint M_3 y, mm"),
        ("xp_mm", "planned platform x, mm"),
        ("yp_mm", "planned platform y, mm"),
        ("phip_deg", "planned platform orientation, deg"),
    ] {
        p.insert(c.into(), opt_number(d));
    }
    p.insert("pose_id".into(), json!({"type": ["integer", "null"]}));
    p.insert("rep".into(), json!({"type": ["integer", "null"]}));
    p.insert(
        "settled".into(),
        json!({"type": ["integer", "null"], "enum": [0, 1, null]}),
    );
    p.insert(
        "set".into(),
        json!({"type": ["string", "null"], "enum": ["train", "test", null]}),
    );
    let mut s = json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "pcr.RecordingRow: one row of a recording (shared/spec/recording.md)",
        "type": "object",
        "properties": Value::Object(p),
        "required": ["t_s", "q1", "q2", "q3"],
        "additionalProperties": {"type": ["string", "null"]},
    });
    s["description"] = json!("extra columns of the CSV are further string properties");
    Schema::new("pcr.RecordingRow", "jsonschema", s.to_string().into_bytes())
}

/// `pcr.DriverState`: the motor commands and the driver's state.
pub fn driver_state() -> Schema {
    schema(
        "pcr.DriverState",
        "pcr.DriverState: motor commands and the driver's state",
        json!({
            "t_s": {"type": "number", "description": "chain time of the cycle, s"},
            "commanded": {"type": "array", "items": {"type": "integer"},
                          "description": "motor positions commanded, steps"},
            "reached": {"type": ["array", "null"], "items": {"type": "integer"},
                        "description": "motor positions reached, steps (null: not known)"},
            "run_id": {"type": ["integer", "null"]},
            "seq": {"type": ["integer", "null"], "description": "seq of the setpoint executed"},
            "enabled": {"type": ["boolean", "null"]},
            "moving": {"type": ["boolean", "null"]},
            "limited": {"type": ["boolean", "null"]},
            "fault": {"type": ["boolean", "null"]},
            "stale_hold": {"type": ["boolean", "null"]},
            "uncorrected": {"type": ["boolean", "null"],
                            "description": "the setpoint went uncorrected (capture data lost)"},
        }),
        &["t_s", "commanded"],
    )
}

/// `pcr.Correction`: the outer loop's task-space correction.
pub fn correction() -> Schema {
    schema(
        "pcr.Correction",
        "pcr.Correction: the correction added to the setpoints",
        json!({
            "t_s": {"type": "number", "description": "chain time, s"},
            "offset_x_mm": {"type": "number"},
            "offset_y_mm": {"type": "number"},
            "offset_phi_deg": {"type": "number"},
            "error_x_mm": {"type": "number", "description": "measured - planned"},
            "error_y_mm": {"type": "number"},
            "error_phi_deg": {"type": "number"},
            "held": {"type": "boolean", "description": "no fresh measurement: offset held"},
        }),
        &["t_s"],
    )
}

/// `pcr.CycleStats`: one process's heartbeat: cycles, deadline misses, cycle and wake-up times.
pub fn cycle_stats() -> Schema {
    schema(
        "pcr.CycleStats",
        "pcr.CycleStats: a process's cycle statistics (from its heartbeat)",
        json!({
            "process": {"type": "string"},
            "pid": {"type": "integer"},
            "cycles": {"type": "integer", "description": "cycles since the process started"},
            "deadline_misses": {"type": "integer", "description": "since the process started"},
            "total_deadline_misses": {"type": "integer",
                                      "description": "summed over the process's restarts"},
            "stale_inputs": {"type": "integer"},
            "holding": {"type": "boolean"},
            "restarts": {"type": "integer"},
            "cycle_p50_us": {"type": "number"},
            "cycle_p99_us": {"type": "number"},
            "cycle_max_us": {"type": "number"},
            "wakeup_p50_us": {"type": "number"},
            "wakeup_p99_us": {"type": "number"},
            "wakeup_max_us": {"type": "number"},
        }),
        &["process", "cycles", "deadline_misses"],
    )
}

/// `pcr.RunEvent`: something that happened to a run or the chain.
pub fn run_event() -> Schema {
    schema(
        "pcr.RunEvent",
        "pcr.RunEvent: start, pause, resume, refusal, restart, end",
        json!({
            "kind": {"type": "string",
                     "enum": ["start", "pause", "resume", "stop", "refusal", "restart",
                              "safe_stop", "end"]},
            "run_id": {"type": ["integer", "null"]},
            "process": {"type": ["string", "null"]},
            "text": {"type": "string"},
        }),
        &["kind", "text"],
    )
}
