//! `pcr.read_recording` / `pcr.write_recording`: the recording format
//! (`shared/spec/recording.md`) read and written by `pcr-recording`, exactly as the tools read
//! it (metadata, the timing declaration `command_delay_s`, extra columns kept as text).

use crate::arrays::vec1;
use crate::errors::{err, invalid};
use numpy::{PyArray1, PyReadonlyArray1};
use pcr_recording::{Recording, Row, Split, KNOWN_COLUMNS};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// A recording (native part of `pcr.read_recording`; the tools' input type).
#[pyclass(name = "Recording", module = "pcr._pcr", frozen)]
pub struct PyRecording {
    /// The recording.
    pub rec: Recording,
    /// The name it is reported by (the file, or `<DataFrame>`).
    pub origin: String,
}

/// The value of known column `k` (4..=18) of a row.
fn cell(row: &Row, k: usize) -> Option<f64> {
    match k {
        4..=6 => row.pose[k - 4],
        7..=12 => row.m[(k - 7) / 2][(k - 7) % 2],
        13..=15 => row.planned[k - 13],
        16 => row.pose_id.map(|v| v as f64),
        17 => row.rep.map(|v| v as f64),
        18 => row.settled.map(|v| f64::from(u8::from(v))),
        _ => None,
    }
}

/// A whole number >= 0 of a count column, or an error naming row and column.
fn count(v: f64, row: usize, name: &str, max: Option<f64>) -> PyResult<u64> {
    if v.fract() != 0.0 || v < 0.0 || v > max.unwrap_or(2f64.powi(53)) {
        return Err(invalid(format!(
            "row {row}, column `{name}`: {v} is not a valid value"
        )));
    }
    Ok(v as u64)
}

#[pymethods]
impl PyRecording {
    /// Reads a recording file as the tools read it (errors name file, line and column).
    #[staticmethod]
    fn read(py: Python<'_>, path: PathBuf) -> PyResult<PyRecording> {
        let origin = path.display().to_string();
        let rec = py.detach(|| Recording::read_path(&path)).map_err(err)?;
        Ok(PyRecording { rec, origin })
    }

    /// A recording from columns: `numeric` maps each known numeric column the recording has
    /// (t_s, q1..q3 required; NaN = empty cell) to a float array, `set` is the `set` column
    /// (None = absent) and `extra` maps each unknown column to its cells as text (None =
    /// empty), in order; `metadata` are (key, value) pairs in order.
    #[staticmethod]
    #[pyo3(signature = (numeric, set_column, extra, metadata, comments, origin = "<DataFrame>"))]
    fn from_columns(
        numeric: Vec<(String, PyReadonlyArray1<'_, f64>)>,
        set_column: Option<Vec<Option<String>>>,
        extra: Vec<(String, Vec<Option<String>>)>,
        metadata: Vec<(String, String)>,
        comments: Vec<String>,
        origin: &str,
    ) -> PyResult<PyRecording> {
        let mut rec = Recording {
            metadata,
            comments,
            ..Recording::default()
        };
        for (k, v) in &rec.metadata {
            if k.is_empty() || k.contains([' ', '=', '\n']) || v.contains('\n') {
                return Err(invalid(format!(
                    "metadata {k:?} = {v:?}: a key is one word without `=`, a value one line"
                )));
            }
            if k == pcr_recording::COMMAND_DELAY_KEY {
                pcr_recording::parse_command_delay(v)
                    .map_err(|m| invalid(format!("metadata `{k}`: {m} (value {v:?})")))?;
            }
        }
        let mut cols: Vec<(usize, Vec<f64>)> = Vec::new();
        for (name, a) in &numeric {
            let Some(k) = KNOWN_COLUMNS.iter().position(|c| c == name) else {
                return Err(invalid(format!(
                    "`{name}` is not a numeric column of the format"
                )));
            };
            if k == 19 {
                return Err(invalid("`set` is a text column (train/test)"));
            }
            cols.push((k, a.as_array().to_vec()));
        }
        for req in ["t_s", "q1", "q2", "q3"] {
            if !numeric.iter().any(|(n, _)| n == req) {
                return Err(invalid(format!("required column `{req}` is missing")));
            }
        }
        let n = cols[0].1.len();
        if cols.iter().any(|c| c.1.len() != n)
            || set_column.as_ref().is_some_and(|s| s.len() != n)
            || extra.iter().any(|e| e.1.len() != n)
        {
            return Err(invalid("every column must have the same number of rows"));
        }
        cols.sort_by_key(|c| c.0);
        rec.columns = cols
            .iter()
            .map(|c| KNOWN_COLUMNS[c.0].to_string())
            .collect();
        if set_column.is_some() {
            rec.columns.push("set".into());
        }
        rec.extra_columns = extra.iter().map(|e| e.0.clone()).collect();
        for e in &rec.extra_columns {
            if e.is_empty() {
                return Err(invalid("an extra column has no name"));
            }
        }
        for i in 0..n {
            let mut row = Row::default();
            for (k, v) in &cols {
                let (name, x) = (KNOWN_COLUMNS[*k], v[i]);
                if x.is_nan() {
                    if *k < 4 {
                        return Err(invalid(format!(
                            "row {i}, column `{name}`: required cell is empty"
                        )));
                    }
                    continue;
                }
                if !x.is_finite() {
                    return Err(invalid(format!(
                        "row {i}, column `{name}`: {x} is not a finite number"
                    )));
                }
                match k {
                    0 => row.t_s = x,
                    1..=3 => {
                        if x.fract() != 0.0 || x.abs() > f64::from(i32::MAX) {
                            return Err(invalid(format!(
                                "row {i}, column `{name}`: {x} is not a whole number of steps"
                            )));
                        }
                        row.q[k - 1] = x as i32;
                    }
                    4..=6 => row.pose[k - 4] = Some(x),
                    7..=12 => row.m[(k - 7) / 2][(k - 7) % 2] = Some(x),
                    13..=15 => row.planned[k - 13] = Some(x),
                    16 => row.pose_id = Some(count(x, i, name, None)?),
                    17 => row.rep = Some(count(x, i, name, None)?),
                    _ => row.settled = Some(count(x, i, name, Some(1.0))? == 1),
                }
            }
            if i > 0 && row.t_s <= rec.rows[i - 1].t_s {
                return Err(invalid(format!(
                    "row {i}, column `t_s`: {} does not increase (previous {})",
                    row.t_s,
                    rec.rows[i - 1].t_s
                )));
            }
            if let Some(s) = &set_column {
                row.set = match s[i].as_deref() {
                    None | Some("") => None,
                    Some("train") => Some(Split::Train),
                    Some("test") => Some(Split::Test),
                    Some(other) => {
                        return Err(invalid(format!(
                            "row {i}, column `set`: {other:?} must be `train` or `test`"
                        )))
                    }
                };
            }
            row.extra = extra
                .iter()
                .map(|e| e.1[i].clone().filter(|c| !c.is_empty()))
                .collect();
            rec.rows.push(row);
        }
        Ok(PyRecording {
            rec,
            origin: origin.to_string(),
        })
    }

    /// The columns: a dict with `columns` (names in the recording's order: the known ones,
    /// then the unknown), `numeric` (name -> float array, NaN = empty cell), `set` (list of
    /// str or None, or None without the column) and `extra` (name -> list of str or None).
    fn to_columns<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let rows = &self.rec.rows;
        let mut names: Vec<String> = Vec::new();
        let numeric = PyDict::new(py);
        let mut has_set = false;
        for (k, name) in KNOWN_COLUMNS.iter().enumerate() {
            if k >= 4 && !self.rec.columns.iter().any(|c| c == name) {
                continue;
            }
            names.push(name.to_string());
            if k == 19 {
                has_set = true;
                continue;
            }
            let v: Vec<f64> = match k {
                0 => rows.iter().map(|r| r.t_s).collect(),
                1..=3 => rows.iter().map(|r| f64::from(r.q[k - 1])).collect(),
                _ => rows
                    .iter()
                    .map(|r| cell(r, k).unwrap_or(f64::NAN))
                    .collect(),
            };
            let a: Bound<'py, PyArray1<f64>> = vec1(py, v);
            numeric.set_item(*name, a)?;
        }
        d.set_item("numeric", numeric)?;
        if has_set {
            let s: Vec<Option<&str>> = rows.iter().map(|r| r.set.map(Split::as_str)).collect();
            d.set_item("set", s)?;
        } else {
            d.set_item("set", py.None())?;
        }
        let extra = PyDict::new(py);
        for (i, name) in self.rec.extra_columns.iter().enumerate() {
            names.push(name.clone());
            let v: Vec<Option<&str>> = rows
                .iter()
                .map(|r| r.extra.get(i).and_then(|c| c.as_deref()))
                .collect();
            extra.set_item(name, v)?;
        }
        d.set_item("extra", extra)?;
        d.set_item("columns", names)?;
        Ok(d)
    }

    /// Writes the recording (metadata, comments, the columns it has, unknown columns as text).
    fn write(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| self.rec.write_path(&path)).map_err(err)
    }

    /// `# key = value` metadata, in file order.
    #[getter]
    fn metadata(&self) -> Vec<(String, String)> {
        self.rec.metadata.clone()
    }

    /// Other leading comment lines, in file order.
    #[getter]
    fn comments(&self) -> Vec<String> {
        self.rec.comments.clone()
    }

    /// The declared command-to-measurement delay D, s (0 when the file does not declare it).
    #[getter]
    fn command_delay_s(&self) -> PyResult<f64> {
        self.rec
            .command_delay_s()
            .map_err(|e| err(pcr_offline::OfflineError::from(e).context(&self.origin)))
    }

    /// Whether the file declares its command delay (`# command_delay_s = D`).
    #[getter]
    fn declares_command_delay(&self) -> bool {
        self.rec.declares_command_delay()
    }

    /// The name the recording is reported by.
    #[getter]
    fn origin(&self) -> String {
        self.origin.clone()
    }

    /// Number of rows.
    fn __len__(&self) -> usize {
        self.rec.rows.len()
    }
}
