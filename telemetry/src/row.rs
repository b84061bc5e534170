//! One recorded row as the channels see it, and the JSON of the recording-row channel.

use pcr_messages::DriverStateMsg;
use pcr_recording::Row;
use serde_json::{Map, Value};

/// One row of a recording with what else the chain knew at that cycle.
#[derive(Debug, Clone, Copy)]
pub struct RowSample<'a> {
    /// When the row was measured on the chain's clock (CLOCK_MONOTONIC), s; for a converted
    /// recording, its `t_s`.
    pub chain_t_s: f64,
    /// The row as written to the CSV (mm, degrees, steps).
    pub row: &'a Row,
    /// The cells of the extra columns, in the order of the writer's extra columns.
    pub extra: &'a [Option<&'a str>],
    /// The driver state of the row's cycle (the supervisor's rows; `None` for a converted CSV).
    pub state: Option<&'a DriverStateMsg>,
}

fn num(v: Option<f64>) -> Value {
    v.and_then(serde_json::Number::from_f64)
        .map_or(Value::Null, Value::Number)
}

/// The JSON object of a row: every column of the CSV by name, `null` for an empty cell; numbers
/// are the values the CSV's text reads back to (shortest round-trip text on both sides).
pub fn row_json(row: &Row, extra_names: &[String], extra: &[Option<&str>]) -> Value {
    let mut m = Map::new();
    m.insert("t_s".into(), num(Some(row.t_s)));
    for (i, q) in row.q.iter().enumerate() {
        m.insert(format!("q{}", i + 1), Value::from(*q));
    }
    for (name, v) in ["x_mm", "y_mm", "phi_deg"].iter().zip(row.pose) {
        m.insert((*name).into(), num(v));
    }
    for (i, mi) in row.m.iter().enumerate() {
        m.insert(format!("m{}x_mm", i + 1), num(mi[0]));
        m.insert(format!("m{}y_mm", i + 1), num(mi[1]));
    }
    for (name, v) in ["xp_mm", "yp_mm", "phip_deg"].iter().zip(row.planned) {
        m.insert((*name).into(), num(v));
    }
    m.insert(
        "pose_id".into(),
        row.pose_id.map_or(Value::Null, Value::from),
    );
    m.insert("rep".into(), row.rep.map_or(Value::Null, Value::from));
    m.insert(
        "settled".into(),
        row.settled.map_or(Value::Null, |s| Value::from(s as u8)),
    );
    m.insert(
        "set".into(),
        row.set.map_or(Value::Null, |s| Value::from(s.as_str())),
    );
    for (name, cell) in extra_names.iter().zip(extra) {
        m.insert(name.clone(), cell.map_or(Value::Null, Value::from));
    }
    Value::Object(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_cells_are_null_and_numbers_read_back_as_in_the_csv() {
        let mut row = Row::new(0.02, [1, -2, 3]);
        row.pose = [Some(1.25), None, Some(-0.1)];
        row.planned = [Some(0.1 + 0.2), Some(3.0), Some(0.0)];
        let v = row_json(&row, &["segment".into()], &[Some("approach")]);
        assert_eq!(v["q2"], -2);
        assert!(v["y_mm"].is_null());
        assert!(v["m1x_mm"].is_null());
        let text = v.to_string();
        let back: Value = serde_json::from_str(&text).unwrap();
        let csv_cell = pcr_recording::number(0.1 + 0.2);
        assert_eq!(
            back["xp_mm"].as_f64().unwrap(),
            csv_cell.parse::<f64>().unwrap()
        );
        assert_eq!(back["segment"], "approach");
    }
}
