//! Reader and writer of the recording format (`shared/spec/recording.md`): one CSV for
//! everything the robot measures.
//!
//! - Leading `#` comment lines are kept; `# key = value` lines are metadata (any key).
//! - Known columns are parsed into [`Row`]; unknown columns are kept as text and otherwise ignored.
//! - An empty cell is `None`; a bad number is an error naming its line and column; `NaN` is
//!   rejected; `t_s` must increase strictly.
//! - [`RecordingWriter`] flushes every row, so nothing recorded is lost when a run fails.
//!
//! Units as in the spec: s, steps, mm, degrees.

use std::io::{BufRead, Write};
use std::path::Path;

pub mod settled;
pub use settled::{settled_poses, SettledError, SettledPose};

/// Why a recording could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// File access failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// The CSV structure is broken (quoting, field count).
    #[error("{origin}: line {line}: {message}")]
    Csv {
        /// The file.
        origin: String,
        /// 1-based line in the file.
        line: u64,
        /// What is wrong.
        message: String,
    },
    /// A required column is missing or a column is repeated.
    #[error("{origin}: header (line {line}): {message}")]
    Header {
        /// The file.
        origin: String,
        /// 1-based line of the header.
        line: u64,
        /// What is wrong.
        message: String,
    },
    /// A cell does not hold what its column requires.
    #[error("{origin}: line {line}, column `{column}`: {message} (cell {value:?})")]
    Cell {
        /// The file.
        origin: String,
        /// 1-based line in the file.
        line: u64,
        /// Column name.
        column: String,
        /// The cell text.
        value: String,
        /// What is wrong.
        message: String,
    },
    /// A metadata line whose value is not what its key requires (e.g. `command_delay_s`).
    #[error("{origin}: line {line}: metadata `{key}`: {message} (value {value:?})")]
    Metadata {
        /// The file.
        origin: String,
        /// 1-based line in the file (0 for a recording built in memory).
        line: u64,
        /// The key.
        key: String,
        /// The value text.
        value: String,
        /// What is wrong.
        message: String,
    },
    /// A value that cannot be written (NaN, infinite, time not increasing).
    #[error("cannot write row {row}: {message}")]
    Write {
        /// 0-based row index.
        row: usize,
        /// What is wrong.
        message: String,
    },
}

/// The metadata key of the timing contract (`shared/spec/recording.md`, "Timing"): the pose
/// measured at time t answers the command of row time t - D, seconds. Absent: D = 0.
pub const COMMAND_DELAY_KEY: &str = "command_delay_s";

/// Parses the value of `command_delay_s`: a finite number of seconds, not negative.
pub fn parse_command_delay(value: &str) -> Result<f64, String> {
    let d: f64 = value
        .trim()
        .parse()
        .map_err(|_| "not a number of seconds".to_string())?;
    if !d.is_finite() {
        return Err("must be finite".into());
    }
    if d < 0.0 {
        return Err("must not be negative (a measurement cannot answer a later command)".into());
    }
    if d > 60.0 {
        return Err("more than 60 s: not a drive's execution delay".into());
    }
    Ok(d)
}

/// Every column the format defines, in the recommended order.
pub const KNOWN_COLUMNS: [&str; 20] = [
    "t_s", "q1", "q2", "q3", "x_mm", "y_mm", "phi_deg", "m1x_mm", "m1y_mm", "m2x_mm", "m2y_mm",
    "m3x_mm", "m3y_mm", "xp_mm", "yp_mm", "phip_deg", "pose_id", "rep", "settled", "set",
];

/// The experimenter's split of a row (column `set`): tools that fit use `train` rows and report
/// on `test` rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    /// Used for fitting.
    Train,
    /// Held out: used only to report.
    Test,
}

impl Split {
    /// The cell text (`train` / `test`).
    pub fn as_str(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Test => "test",
        }
    }
}

/// One row (one control cycle). Empty cells are `None`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Row {
    /// Time since the start, s.
    pub t_s: f64,
    /// Commanded motor positions, steps.
    pub q: [i32; 3],
    /// Measured platform pose: x mm, y mm, phi degrees (robot base frame).
    pub pose: [Option<f64>; 3],
    /// Measured passive joints M_i: (x mm, y mm) each.
    pub m: [[Option<f64>; 2]; 3],
    /// Planned pose: x mm, y mm, phi degrees.
    pub planned: [Option<f64>; 3],
    /// Static target index.
    pub pose_id: Option<u64>,
    /// Repetition index.
    pub rep: Option<u64>,
    /// Measured at rest at a target.
    pub settled: Option<bool>,
    /// The experimenter's train/test split.
    pub set: Option<Split>,
    /// Cells of the unknown columns, in the order of [`Recording::extra_columns`].
    pub extra: Vec<Option<String>>,
}

impl Row {
    /// A row with only the required cells.
    pub fn new(t_s: f64, q: [i32; 3]) -> Row {
        Row {
            t_s,
            q,
            ..Row::default()
        }
    }

    /// The measured pose if all three components are present.
    pub fn measured_pose(&self) -> Option<[f64; 3]> {
        Some([self.pose[0]?, self.pose[1]?, self.pose[2]?])
    }
}

/// A whole recording.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Recording {
    /// `# key = value` lines, in file order.
    pub metadata: Vec<(String, String)>,
    /// Other leading comment lines (without the `#`), in file order.
    pub comments: Vec<String>,
    /// Known columns present in the file, in file order.
    pub columns: Vec<String>,
    /// Unknown columns, in file order.
    pub extra_columns: Vec<String>,
    /// The rows.
    pub rows: Vec<Row>,
}

impl Recording {
    /// The value of a metadata key.
    pub fn meta(&self, key: &str) -> Option<&str> {
        self.metadata
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// The declared command-to-measurement delay D of the timing contract, s: the pose measured
    /// at t answers the command of row time t - D. 0 when the file does not declare it.
    pub fn command_delay_s(&self) -> Result<f64, RecordingError> {
        match self.meta(COMMAND_DELAY_KEY) {
            None => Ok(0.0),
            Some(v) => parse_command_delay(v).map_err(|message| RecordingError::Metadata {
                origin: String::new(),
                line: 0,
                key: COMMAND_DELAY_KEY.into(),
                value: v.into(),
                message,
            }),
        }
    }

    /// Whether the file declares its command delay (`# command_delay_s = D`).
    pub fn declares_command_delay(&self) -> bool {
        self.meta(COMMAND_DELAY_KEY).is_some()
    }

    /// Index of an unknown column.
    pub fn extra_index(&self, name: &str) -> Option<usize> {
        self.extra_columns.iter().position(|c| c == name)
    }

    /// Reads a file.
    pub fn read_path(path: impl AsRef<Path>) -> Result<Recording, RecordingError> {
        let path = path.as_ref();
        let origin = path.display().to_string();
        let f = std::fs::File::open(path).map_err(|source| RecordingError::Io {
            path: origin.clone(),
            source,
        })?;
        Self::read(std::io::BufReader::new(f), &origin)
    }

    /// Reads from any reader; `origin` names the source in errors.
    pub fn read<R: BufRead>(mut r: R, origin: &str) -> Result<Recording, RecordingError> {
        let mut rec = Recording::default();
        let io = |source| RecordingError::Io {
            path: origin.to_string(),
            source,
        };
        // Leading comment lines.
        let mut line_no: u64 = 0;
        let mut first = String::new();
        loop {
            first.clear();
            if r.read_line(&mut first).map_err(io)? == 0 {
                return Err(RecordingError::Header {
                    origin: origin.into(),
                    line: line_no + 1,
                    message: "no header row".into(),
                });
            }
            line_no += 1;
            let l = first.trim_end_matches(['\n', '\r']);
            let l = l.strip_prefix('\u{feff}').unwrap_or(l);
            if let Some(c) = l.strip_prefix('#') {
                match c.split_once('=') {
                    Some((k, v)) if !k.trim().is_empty() && !k.trim().contains(' ') => {
                        let (k, v) = (k.trim(), v.trim());
                        if k == COMMAND_DELAY_KEY {
                            if let Err(message) = parse_command_delay(v) {
                                return Err(RecordingError::Metadata {
                                    origin: origin.into(),
                                    line: line_no,
                                    key: k.into(),
                                    value: v.into(),
                                    message,
                                });
                            }
                        }
                        rec.metadata.push((k.to_string(), v.to_string()))
                    }
                    _ => rec
                        .comments
                        .push(c.strip_prefix(' ').unwrap_or(c).to_string()),
                }
            } else if l.trim().is_empty() {
                continue;
            } else {
                first = l.to_string();
                break;
            }
        }
        let header_line = line_no;
        let header: Vec<String> = first.split(',').map(|s| s.trim().to_string()).collect();
        // Map known columns to slots, unknown to extra.
        let mut slot_of: Vec<Option<usize>> = Vec::with_capacity(header.len());
        let mut seen = [false; KNOWN_COLUMNS.len()];
        for (i, name) in header.iter().enumerate() {
            if header[..i].contains(name) {
                return Err(RecordingError::Header {
                    origin: origin.into(),
                    line: header_line,
                    message: format!("column `{name}` appears twice"),
                });
            }
            match KNOWN_COLUMNS.iter().position(|c| c == name) {
                Some(k) => {
                    seen[k] = true;
                    rec.columns.push(name.clone());
                    slot_of.push(Some(k));
                }
                None => {
                    rec.extra_columns.push(name.clone());
                    slot_of.push(None);
                }
            }
        }
        for req in ["t_s", "q1", "q2", "q3"] {
            let k = KNOWN_COLUMNS.iter().position(|c| *c == req).unwrap();
            if !seen[k] {
                return Err(RecordingError::Header {
                    origin: origin.into(),
                    line: header_line,
                    message: format!("required column `{req}` is missing"),
                });
            }
        }
        let mut csv_r = csv::ReaderBuilder::new()
            .has_headers(false)
            .comment(Some(b'#'))
            .trim(csv::Trim::All)
            .flexible(true)
            .from_reader(r);
        let mut prev_t: Option<f64> = None;
        let mut record = csv::StringRecord::new();
        loop {
            let ok = csv_r
                .read_record(&mut record)
                .map_err(|e| RecordingError::Csv {
                    origin: origin.into(),
                    line: header_line + e.position().map_or(0, |p| p.line()),
                    message: e.to_string(),
                })?;
            if !ok {
                break;
            }
            let line = header_line + record.position().map_or(0, |p| p.line());
            if record.len() == 1 && record[0].is_empty() {
                continue;
            }
            if record.len() != header.len() {
                return Err(RecordingError::Csv {
                    origin: origin.into(),
                    line,
                    message: format!(
                        "{} cells, but the header has {} columns",
                        record.len(),
                        header.len()
                    ),
                });
            }
            let mut row = Row::default();
            let mut have_t = false;
            let mut have_q = [false; 3];
            for (cell, (name, slot)) in record.iter().zip(header.iter().zip(&slot_of)) {
                let Some(k) = *slot else {
                    row.extra.push((!cell.is_empty()).then(|| cell.to_string()));
                    continue;
                };
                if cell.is_empty() {
                    continue;
                }
                let bad = |message: &str| RecordingError::Cell {
                    origin: origin.into(),
                    line,
                    column: name.clone(),
                    value: cell.to_string(),
                    message: message.to_string(),
                };
                let num = || -> Result<f64, RecordingError> {
                    let v: f64 = cell.parse().map_err(|_| bad("not a number"))?;
                    if v.is_nan() {
                        return Err(bad("NaN is not allowed (leave the cell empty)"));
                    }
                    if !v.is_finite() {
                        return Err(bad("not a finite number"));
                    }
                    Ok(v)
                };
                let int = || -> Result<i64, RecordingError> {
                    let v = num()?;
                    if v.fract() != 0.0 || v.abs() > 2f64.powi(53) {
                        return Err(bad("not an integer"));
                    }
                    Ok(v as i64)
                };
                match k {
                    0 => {
                        row.t_s = num()?;
                        have_t = true;
                    }
                    1..=3 => {
                        let v = int()?;
                        row.q[k - 1] = i32::try_from(v).map_err(|_| bad("out of the i32 range"))?;
                        have_q[k - 1] = true;
                    }
                    4..=6 => row.pose[k - 4] = Some(num()?),
                    7..=12 => row.m[(k - 7) / 2][(k - 7) % 2] = Some(num()?),
                    13..=15 => row.planned[k - 13] = Some(num()?),
                    16 | 17 => {
                        let v = int()?;
                        if v < 0 {
                            return Err(bad("must be >= 0"));
                        }
                        if k == 16 {
                            row.pose_id = Some(v as u64);
                        } else {
                            row.rep = Some(v as u64);
                        }
                    }
                    18 => {
                        row.settled = Some(match cell {
                            "0" => false,
                            "1" => true,
                            _ => return Err(bad("must be 0 or 1")),
                        })
                    }
                    _ => {
                        row.set = Some(match cell {
                            "train" => Split::Train,
                            "test" => Split::Test,
                            _ => return Err(bad("must be `train` or `test`")),
                        })
                    }
                }
            }
            let missing = |column: &str| RecordingError::Cell {
                origin: origin.into(),
                line,
                column: column.to_string(),
                value: String::new(),
                message: "required cell is empty".into(),
            };
            if !have_t {
                return Err(missing("t_s"));
            }
            for (i, h) in have_q.iter().enumerate() {
                if !h {
                    return Err(missing(&format!("q{}", i + 1)));
                }
            }
            if let Some(p) = prev_t {
                if row.t_s <= p {
                    return Err(RecordingError::Cell {
                        origin: origin.into(),
                        line,
                        column: "t_s".into(),
                        value: row.t_s.to_string(),
                        message: format!("time must increase strictly (previous row: {p})"),
                    });
                }
            }
            prev_t = Some(row.t_s);
            rec.rows.push(row);
        }
        Ok(rec)
    }
}

impl Recording {
    /// Writes the whole recording (metadata, other comments, the columns it has, unknown
    /// columns with their cells as read) to a file.
    pub fn write_path(&self, path: impl AsRef<Path>) -> Result<(), RecordingError> {
        let path = path.as_ref();
        let f = std::fs::File::create(path).map_err(|source| RecordingError::Io {
            path: path.display().to_string(),
            source,
        })?;
        self.write(std::io::BufWriter::new(f))
    }

    /// Writes the whole recording to any writer (see [`Recording::write_path`]).
    pub fn write<W: Write>(&self, mut w: W) -> Result<(), RecordingError> {
        for (k, v) in &self.metadata {
            writeln!(w, "# {k} = {v}").map_err(io_err)?;
        }
        for c in &self.comments {
            writeln!(w, "# {c}").map_err(io_err)?;
        }
        let known: Vec<usize> = KNOWN_COLUMNS
            .iter()
            .enumerate()
            .filter(|(k, c)| *k < 4 || self.columns.iter().any(|x| x == *c))
            .map(|(k, _)| k)
            .collect();
        let mut out = csv::WriterBuilder::new().from_writer(w);
        let header: Vec<&str> = known
            .iter()
            .map(|&k| KNOWN_COLUMNS[k])
            .chain(self.extra_columns.iter().map(String::as_str))
            .collect();
        out.write_record(&header).map_err(io_err)?;
        for (n, row) in self.rows.iter().enumerate() {
            let mut cells = known_cells(row, &known)
                .map_err(|message| RecordingError::Write { row: n, message })?;
            for i in 0..self.extra_columns.len() {
                cells.push(row.extra.get(i).cloned().flatten().unwrap_or_default());
            }
            out.write_record(&cells).map_err(io_err)?;
        }
        out.flush().map_err(io_err)?;
        Ok(())
    }
}

/// A finite number as written: the shortest text that reads back to the same value, in
/// exponent form for very small or very large magnitudes (e.g. `1.5e-27`, never `NaN`).
pub fn number(x: f64) -> String {
    let a = x.abs();
    if x == 0.0 {
        "0".into()
    } else if (1e-6..1e15).contains(&a) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// The cells of the known columns `idx` of a row.
fn known_cells(row: &Row, idx: &[usize]) -> Result<Vec<String>, String> {
    let fmt = |name: &str, v: Option<f64>| -> Result<String, String> {
        match v {
            None => Ok(String::new()),
            Some(x) if x.is_finite() => Ok(number(x)),
            Some(x) => Err(format!("{name} = {x} (write None instead)")),
        }
    };
    let mut cells = Vec::with_capacity(idx.len());
    for &k in idx {
        let name = KNOWN_COLUMNS[k];
        cells.push(match k {
            0 => number(row.t_s),
            1..=3 => row.q[k - 1].to_string(),
            4..=6 => fmt(name, row.pose[k - 4])?,
            7..=12 => fmt(name, row.m[(k - 7) / 2][(k - 7) % 2])?,
            13..=15 => fmt(name, row.planned[k - 13])?,
            16 => row.pose_id.map_or(String::new(), |v| v.to_string()),
            17 => row.rep.map_or(String::new(), |v| v.to_string()),
            18 => row.settled.map_or(String::new(), |v| (v as u8).to_string()),
            _ => row.set.map_or(String::new(), |v| v.as_str().to_string()),
        });
    }
    Ok(cells)
}

/// Writes a recording row by row, flushing each row.
pub struct RecordingWriter<W: Write> {
    out: csv::Writer<W>,
    columns: Vec<usize>,
    n_extra: usize,
    rows: usize,
    prev_t: Option<f64>,
}

impl RecordingWriter<std::fs::File> {
    /// Creates (truncates) a file and writes the comments and the header.
    pub fn create(
        path: impl AsRef<Path>,
        metadata: &[(String, String)],
        columns: &[&str],
        extra_columns: &[&str],
    ) -> Result<Self, RecordingError> {
        let path = path.as_ref();
        let f = std::fs::File::create(path).map_err(|source| RecordingError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::new(f, metadata, columns, extra_columns)
    }
}

fn io_err(e: impl Into<std::io::Error>) -> RecordingError {
    RecordingError::Io {
        path: "recording output".into(),
        source: e.into(),
    }
}

impl<W: Write> RecordingWriter<W> {
    /// Writes metadata comments and the header. `columns` are known columns (t_s, q1..q3 are
    /// always written first, whether listed or not); `extra_columns` follow them.
    pub fn new(
        mut w: W,
        metadata: &[(String, String)],
        columns: &[&str],
        extra_columns: &[&str],
    ) -> Result<Self, RecordingError> {
        for (k, v) in metadata {
            if k.is_empty() || k.contains([' ', '=', '\n']) || v.contains('\n') {
                return Err(RecordingError::Write {
                    row: 0,
                    message: format!("bad metadata {k:?} = {v:?}"),
                });
            }
            writeln!(w, "# {k} = {v}").map_err(io_err)?;
        }
        let mut idx: Vec<usize> = vec![0, 1, 2, 3];
        for c in columns {
            match KNOWN_COLUMNS.iter().position(|k| k == c) {
                Some(k) if !idx.contains(&k) => idx.push(k),
                Some(_) => {}
                None => {
                    return Err(RecordingError::Write {
                        row: 0,
                        message: format!("`{c}` is not a column of the format (use extra_columns)"),
                    })
                }
            }
        }
        for e in extra_columns {
            if KNOWN_COLUMNS.contains(e) || e.is_empty() {
                return Err(RecordingError::Write {
                    row: 0,
                    message: format!("extra column `{e}` is empty or a known column"),
                });
            }
        }
        let mut out = csv::WriterBuilder::new().from_writer(w);
        let header: Vec<&str> = idx
            .iter()
            .map(|&k| KNOWN_COLUMNS[k])
            .chain(extra_columns.iter().copied())
            .collect();
        out.write_record(&header).map_err(io_err)?;
        out.flush().map_err(io_err)?;
        Ok(RecordingWriter {
            out,
            columns: idx,
            n_extra: extra_columns.len(),
            rows: 0,
            prev_t: None,
        })
    }

    /// Writes one row and flushes it. `extra` holds the cells of the extra columns.
    pub fn write_row(&mut self, row: &Row, extra: &[Option<f64>]) -> Result<(), RecordingError> {
        let bad = |message: String| RecordingError::Write {
            row: self.rows,
            message,
        };
        if extra.len() != self.n_extra {
            return Err(bad(format!(
                "{} extra cells for {} extra columns",
                extra.len(),
                self.n_extra
            )));
        }
        if !row.t_s.is_finite() {
            return Err(bad(format!("t_s = {}", row.t_s)));
        }
        if let Some(p) = self.prev_t {
            if row.t_s <= p {
                return Err(bad(format!("t_s = {} after {p}: must increase", row.t_s)));
            }
        }
        let mut cells = known_cells(row, &self.columns).map_err(bad)?;
        let fmt = |name: &str, v: Option<f64>| -> Result<String, RecordingError> {
            match v {
                None => Ok(String::new()),
                Some(x) if x.is_finite() => Ok(number(x)),
                Some(x) => Err(bad(format!("{name} = {x} (write None instead)"))),
            }
        };
        for (i, v) in extra.iter().enumerate() {
            cells.push(fmt(&format!("extra column {}", i + 1), *v)?);
        }
        self.out.write_record(&cells).map_err(io_err)?;
        self.out.flush().map_err(io_err)?;
        self.prev_t = Some(row.t_s);
        self.rows += 1;
        Ok(())
    }

    /// Writes one row whose extra cells are text (e.g. a label column) and flushes it. `extra`
    /// holds the cells of the extra columns (`None`: empty); a cell must not contain a line
    /// break.
    pub fn write_row_text(
        &mut self,
        row: &Row,
        extra: &[Option<&str>],
    ) -> Result<(), RecordingError> {
        let bad = |message: String| RecordingError::Write {
            row: self.rows,
            message,
        };
        if extra.len() != self.n_extra {
            return Err(bad(format!(
                "{} extra cells for {} extra columns",
                extra.len(),
                self.n_extra
            )));
        }
        if !row.t_s.is_finite() {
            return Err(bad(format!("t_s = {}", row.t_s)));
        }
        if let Some(p) = self.prev_t {
            if row.t_s <= p {
                return Err(bad(format!("t_s = {} after {p}: must increase", row.t_s)));
            }
        }
        let mut cells = known_cells(row, &self.columns).map_err(bad)?;
        for (i, v) in extra.iter().enumerate() {
            let v = v.unwrap_or("");
            if v.contains(['\n', '\r']) {
                return Err(bad(format!("extra column {}: line break in {v:?}", i + 1)));
            }
            cells.push(v.to_string());
        }
        self.out.write_record(&cells).map_err(io_err)?;
        self.out.flush().map_err(io_err)?;
        self.prev_t = Some(row.t_s);
        self.rows += 1;
        Ok(())
    }

    /// Rows written so far.
    pub fn rows_written(&self) -> usize {
        self.rows
    }

    /// Flushes and returns the inner writer.
    pub fn into_inner(self) -> Result<W, RecordingError> {
        self.out
            .into_inner()
            .map_err(|e| io_err(std::io::Error::other(e.to_string())))
    }
}
