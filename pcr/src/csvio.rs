//! Streaming CSV helpers shared by the CSV tools: column lookup and numeric cells with errors
//! that name the file, line and column.

use anyhow::{anyhow, bail, Context, Result};
use std::io::{Read, Write};

/// Opens a CSV reader on a path, or on standard input for "-".
pub fn reader(path: &str) -> Result<csv::Reader<Box<dyn Read>>> {
    let src: Box<dyn Read> = if path == "-" {
        Box::new(std::io::stdin())
    } else {
        Box::new(std::fs::File::open(path).with_context(|| format!("cannot open input {path}"))?)
    };
    Ok(csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .trim(csv::Trim::All)
        .flexible(false)
        .from_reader(src))
}

/// Opens a CSV writer on a path, or on standard output for None / "-".
pub fn writer(path: Option<&str>) -> Result<csv::Writer<Box<dyn Write>>> {
    let dst: Box<dyn Write> = match path {
        None | Some("-") => Box::new(std::io::stdout()),
        Some(p) => {
            Box::new(std::fs::File::create(p).with_context(|| format!("cannot create output {p}"))?)
        }
    };
    Ok(csv::Writer::from_writer(dst))
}

/// Index of a required column, with an error naming the file and listing what is there.
pub fn column(headers: &csv::StringRecord, name: &str, file: &str) -> Result<usize> {
    headers.iter().position(|h| h == name).ok_or_else(|| {
        anyhow!(
            "{file}: missing column `{name}` (header has: {})",
            headers.iter().collect::<Vec<_>>().join(", ")
        )
    })
}

/// Index of an optional column.
pub fn optional_column(headers: &csv::StringRecord, name: &str) -> Option<usize> {
    headers.iter().position(|h| h == name)
}

/// A finite number from a cell, or an error naming file, line and column.
pub fn number(rec: &csv::StringRecord, idx: usize, name: &str, file: &str) -> Result<f64> {
    let line = rec.position().map_or(0, |p| p.line());
    let cell = rec.get(idx).unwrap_or("");
    if cell.is_empty() {
        bail!("{file} line {line}: column `{name}` is empty");
    }
    let v: f64 = cell
        .parse()
        .map_err(|_| anyhow!("{file} line {line}: column `{name}`: `{cell}` is not a number"))?;
    if !v.is_finite() {
        bail!("{file} line {line}: column `{name}`: `{cell}` is not a finite number");
    }
    Ok(v)
}

/// Formats a float for output with enough digits to round-trip.
pub fn fmt(v: f64) -> String {
    format!("{v}")
}

/// Reads a CSV record, turning a csv error into one that names the file and line.
pub fn next_record(
    rdr: &mut csv::Reader<Box<dyn Read>>,
    rec: &mut csv::StringRecord,
    file: &str,
) -> Result<bool> {
    rdr.read_record(rec).map_err(|e| match e.position() {
        Some(p) => anyhow!("{file} line {}: {e}", p.line()),
        None => anyhow!("{file}: {e}"),
    })
}

/// Output columns = the input's columns followed by the added ones; an added column that the
/// input already has replaces the input's cell instead of appearing twice.
pub struct Layout {
    /// The output header.
    pub header: Vec<String>,
    /// For each added column, its index in the output row.
    pub slots: Vec<usize>,
}

impl Layout {
    /// Lays out the input header and the added column names.
    pub fn new(input: &csv::StringRecord, added: &[String]) -> Layout {
        let mut header: Vec<String> = input.iter().map(str::to_string).collect();
        let slots = added
            .iter()
            .map(|a| match header.iter().position(|h| h == a) {
                Some(i) => i,
                None => {
                    header.push(a.clone());
                    header.len() - 1
                }
            })
            .collect();
        Layout { header, slots }
    }

    /// Fills `row` with the input record and then the added values (one per added column).
    pub fn fill(
        &self,
        row: &mut Vec<String>,
        rec: &csv::StringRecord,
        values: impl IntoIterator<Item = String>,
    ) {
        row.clear();
        row.extend(rec.iter().map(str::to_string));
        row.resize(self.header.len(), String::new());
        for (slot, v) in self.slots.iter().zip(values) {
            row[*slot] = v;
        }
    }
}
