//! `docs/foxglove-layout.json` shows what the channels carry: every topic it names is one of
//! the telemetry's, and every field a plot reads is a property of that channel's JSON schema.

use pcr_telemetry::{schemas, topics};
use serde_json::Value;

fn layout() -> Value {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/foxglove-layout.json");
    let text = std::fs::read_to_string(path).expect("docs/foxglove-layout.json");
    serde_json::from_str(&text).expect("the layout is JSON")
}

fn properties(schema: foxglove::Schema) -> Vec<String> {
    let v: Value = serde_json::from_slice(&schema.data).unwrap();
    v["properties"]
        .as_object()
        .unwrap()
        .keys()
        .cloned()
        .collect()
}

/// The JSON schema's properties of a topic (`None`: a Foxglove schema, not checked here).
fn fields_of(topic: &str) -> Option<Vec<String>> {
    match topic {
        topics::ROW => Some(properties(schemas::recording_row())),
        topics::DRIVER => Some(properties(schemas::driver_state())),
        topics::CORRECTION => Some(properties(schemas::correction())),
        topics::EVENTS => Some(properties(schemas::run_event())),
        t if t.starts_with("/process/") && t.ends_with("/stats") => {
            Some(properties(schemas::cycle_stats()))
        }
        _ => None,
    }
}

fn known(topic: &str) -> bool {
    let fixed = [
        topics::ROW,
        topics::PLANNED_POSE,
        topics::MEASURED_POSE,
        topics::SCENE,
        topics::TF,
        topics::DRIVER,
        topics::CORRECTION,
        topics::LOG,
        topics::EVENTS,
    ];
    fixed.contains(&topic)
        || ["planner", "ik", "driver", "mocap", "qtm"]
            .iter()
            .any(|p| topics::process_stats(p) == topic)
}

#[test]
fn the_layout_names_only_the_telemetry_s_topics_and_fields() {
    let l = layout();
    let panels = l["configById"].as_object().expect("configById");
    assert!(panels.keys().any(|k| k.starts_with("3D!")), "no 3D panel");
    let mut plots = 0;
    for (id, cfg) in panels {
        if id.starts_with("Plot!") {
            for p in cfg["paths"].as_array().unwrap() {
                let path = p["value"].as_str().unwrap();
                let (topic, field) = path.split_once('.').unwrap();
                assert!(known(topic), "{id}: unknown topic {topic}");
                let field = field.split('[').next().unwrap();
                if let Some(fields) = fields_of(topic) {
                    assert!(
                        fields.iter().any(|f| f == field),
                        "{id}: {topic} has no {field}"
                    );
                }
                plots += 1;
            }
        }
        if let Some(t) = cfg["topics"].as_object() {
            for topic in t.keys() {
                assert!(known(topic), "{id}: unknown topic {topic}");
            }
        }
        if let Some(t) = cfg["topicToRender"].as_str() {
            assert!(known(t), "{id}: unknown topic {t}");
        }
    }
    assert!(plots >= 10, "{plots} plotted paths");
    // Every panel of the arrangement is configured.
    fn leaves(v: &Value, out: &mut Vec<String>) {
        match v {
            Value::String(s) => out.push(s.clone()),
            Value::Object(o) => {
                for k in ["first", "second"] {
                    if let Some(c) = o.get(k) {
                        leaves(c, out);
                    }
                }
            }
            _ => {}
        }
    }
    let mut ids = Vec::new();
    leaves(&l["layout"], &mut ids);
    for id in &ids {
        assert!(
            panels.contains_key(id),
            "{id} is arranged but not configured"
        );
    }
    assert_eq!(ids.len(), panels.len());
}
