//! Recorder: writes a run in the recording format of `shared/spec/recording.md`
//! (`t_s, q1, q2, q3, x_mm, y_mm, phi_deg, m1x_mm .. m3y_mm, xp_mm, yp_mm, phip_deg`, one row per
//! driver cycle) through the recording crate's [`RecordingWriter`], which writes and flushes
//! every row as it comes: a recorder killed mid-run leaves a file whose every row parses. The
//! measured columns come from the driver state's pose sensor, or, where the configuration has a
//! capture system, from the motion-capture bridge ([`Measured`]).

use pcr_messages::{driver_flags, DriverStateMsg};
use pcr_recording::{RecordingWriter, Row};
use std::io::{self, Write};

/// The columns of a run's recording, in order.
pub const COLUMNS: [&str; 16] = [
    "t_s", "q1", "q2", "q3", "x_mm", "y_mm", "phi_deg", "m1x_mm", "m1y_mm", "m2x_mm", "m2y_mm",
    "m3x_mm", "m3y_mm", "xp_mm", "yp_mm", "phip_deg",
];

/// The header row (without extra columns).
pub const HEADER: &str =
    "t_s,q1,q2,q3,x_mm,y_mm,phi_deg,m1x_mm,m1y_mm,m2x_mm,m2y_mm,m3x_mm,m3y_mm,xp_mm,yp_mm,phip_deg";

/// What was measured for one row (robot base frame); `None` = not measured (empty cells).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Measured {
    /// Platform pose: x mm, y mm, phi rad.
    pub pose: Option<[f64; 3]>,
    /// Passive joints M_1..M_3: x mm, y mm.
    pub joints: [Option<[f64; 2]>; 3],
}

impl Measured {
    /// The pose measured by the driver backend's pose sensor (no joints).
    pub fn of_state(s: &DriverStateMsg) -> Measured {
        Measured {
            pose: (s.flags & driver_flags::POSE_VALID != 0).then_some(s.measured),
            joints: [None; 3],
        }
    }
}

fn io_error(e: pcr_recording::RecordingError) -> io::Error {
    match e {
        pcr_recording::RecordingError::Io { source, .. } => source,
        e => io::Error::other(e.to_string()),
    }
}

/// Writes rows of driver-state messages; times are made relative to the first row and rows that
/// would not be strictly increasing in time are skipped. Every row is flushed to `W` when it is
/// written (give it an unbuffered file: the row is then one `write` to the operating system).
pub struct Recorder<W: Write> {
    out: RecordingWriter<W>,
    rows: RowMaker,
}

/// Makes the rows of driver states: times relative to the first row (s), poses in mm and
/// degrees, non-finite values left empty; a row whose time does not increase is skipped. The
/// [`Recorder`] writes its rows to the CSV; a recording with further sinks (the supervisor's
/// MCAP) makes each row once and hands it to every sink.
#[derive(Debug, Clone, Copy)]
pub struct RowMaker {
    t0: Option<f64>,
    last_t: f64,
}

impl Default for RowMaker {
    fn default() -> Self {
        Self::new()
    }
}

impl RowMaker {
    /// Before the first row.
    pub fn new() -> Self {
        Self {
            t0: None,
            last_t: f64::NEG_INFINITY,
        }
    }

    /// The row a driver state and a measurement make (time relative to the first row), or
    /// `None` when its time does not increase (a row to skip). Write it with
    /// [`Recorder::write`] (e.g. after an experiment's annotator has labelled it).
    pub fn row_of(&mut self, s: &DriverStateMsg, m: &Measured) -> Option<Row> {
        let t0 = *self.t0.get_or_insert(s.t_s);
        let t = s.t_s - t0;
        if t <= self.last_t || !t.is_finite() {
            return None;
        }
        self.last_t = t;
        let finite3 = |p: [f64; 3]| p.iter().all(|v| v.is_finite());
        let mut row = Row::new(t, s.commanded);
        if let Some(p) = m.pose.filter(|p| finite3(*p)) {
            row.pose = [Some(p[0]), Some(p[1]), Some(p[2].to_degrees())];
        }
        for (cell, j) in row.m.iter_mut().zip(m.joints) {
            if let Some(p) = j.filter(|p| p.iter().all(|v| v.is_finite())) {
                *cell = [Some(p[0]), Some(p[1])];
            }
        }
        let p = s.planned;
        if finite3(p) {
            row.planned = [Some(p[0]), Some(p[1]), Some(p[2].to_degrees())];
        }
        Some(row)
    }
}

impl<W: Write> std::fmt::Debug for Recorder<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("rows", &self.out.rows_written())
            .field("last_t", &self.rows.last_t)
            .finish()
    }
}

impl<W: Write> Recorder<W> {
    /// Starts a recording: `# key = value` metadata lines, then the header.
    pub fn new(out: W, meta: &[(&str, &str)]) -> io::Result<Self> {
        Self::with_extra(out, meta, &[])
    }

    /// Starts a recording whose rows carry further columns after the standard ones (e.g. an
    /// experiment's `pose_id, rep, settled, set, segment ...`): names of the format's optional
    /// columns are written as such, others as extra columns.
    pub fn with_extra(out: W, meta: &[(&str, &str)], more: &[&str]) -> io::Result<Self> {
        let meta: Vec<(String, String)> = meta
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        let known: Vec<&str> = COLUMNS
            .iter()
            .copied()
            .chain(
                more.iter()
                    .copied()
                    .filter(|c| pcr_recording::KNOWN_COLUMNS.contains(c)),
            )
            .collect();
        let extra: Vec<&str> = more
            .iter()
            .copied()
            .filter(|c| !pcr_recording::KNOWN_COLUMNS.contains(c))
            .collect();
        Ok(Self {
            out: RecordingWriter::new(out, &meta, &known, &extra).map_err(io_error)?,
            rows: RowMaker::new(),
        })
    }

    /// Rows written.
    pub fn rows(&self) -> u64 {
        self.out.rows_written() as u64
    }

    /// Writes one row with the driver backend's measured pose (skipped if its time does not
    /// increase).
    pub fn row(&mut self, s: &DriverStateMsg) -> io::Result<()> {
        self.row_with(s, &Measured::of_state(s))
    }

    /// Writes one row with the given measurement (skipped if its time does not increase).
    pub fn row_with(&mut self, s: &DriverStateMsg, m: &Measured) -> io::Result<()> {
        match self.row_of(s, m) {
            Some(row) => self.write(&row, &[]),
            None => Ok(()),
        }
    }

    /// The row a driver state and a measurement make (time relative to the first row), or
    /// `None` when its time does not increase (a row to skip). Write it with [`Self::write`]
    /// (e.g. after an experiment's annotator has labelled it).
    pub fn row_of(&mut self, s: &DriverStateMsg, m: &Measured) -> Option<Row> {
        self.rows.row_of(s, m)
    }

    /// Writes (and flushes) a row made by [`Self::row_of`]; `extra` holds the cells of the
    /// extra columns given to [`Self::with_extra`].
    pub fn write(&mut self, row: &Row, extra: &[Option<&str>]) -> io::Result<()> {
        self.out.write_row_text(row, extra).map_err(io_error)
    }

    /// Flushes and returns the writer.
    pub fn finish(self) -> io::Result<W> {
        let mut w = self.out.into_inner().map_err(io_error)?;
        w.flush()?;
        Ok(w)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(t: f64, q: [i32; 3]) -> DriverStateMsg {
        DriverStateMsg {
            t_s: t,
            commanded: q,
            planned: [1.5, -2.25, 0.1],
            measured: [1.0, 2.0, 0.0],
            flags: driver_flags::POSE_VALID,
            ..Default::default()
        }
    }

    #[test]
    fn rows_read_back_with_the_recording_reader() {
        let mut buf = Vec::new();
        let mut rec = Recorder::new(&mut buf, &[("source", "test")]).unwrap();
        rec.row(&state(10.0, [1, 2, 3])).unwrap();
        rec.row(&state(10.0, [1, 2, 3])).unwrap(); // not later: skipped
        let mut unmeasured = state(10.02, [4, 5, 6]);
        unmeasured.flags = 0;
        rec.row(&unmeasured).unwrap();
        assert_eq!(rec.rows(), 2);
        rec.finish().unwrap();
        let text = String::from_utf8(buf).unwrap();
        assert_eq!(text.lines().nth(1), Some(HEADER));
        let r = pcr_recording::Recording::read(text.as_bytes(), "test").unwrap();
        assert_eq!(r.rows.len(), 2);
        assert_eq!(r.rows[0].t_s, 0.0);
        assert_eq!(r.rows[0].pose, [Some(1.0), Some(2.0), Some(0.0)]);
        assert_eq!(r.rows[1].q, [4, 5, 6]);
        assert_eq!(r.rows[1].pose, [None; 3]);
        assert!((r.rows[1].planned[2].unwrap() - 0.1f64.to_degrees()).abs() < 1e-12);
    }

    #[test]
    fn extra_columns_carry_labels() {
        let mut buf = Vec::new();
        let mut rec =
            Recorder::with_extra(&mut buf, &[], &["pose_id", "settled", "segment"]).unwrap();
        let mut row = rec
            .row_of(&state(0.0, [0, 0, 0]), &Measured::default())
            .unwrap();
        row.pose_id = Some(7);
        row.settled = Some(true);
        rec.write(&row, &[Some("approach")]).unwrap();
        rec.finish().unwrap();
        let r = pcr_recording::Recording::read(buf.as_slice(), "test").unwrap();
        assert_eq!(r.rows[0].pose_id, Some(7));
        assert_eq!(r.rows[0].settled, Some(true));
        assert_eq!(r.extra_columns, vec!["segment".to_string()]);
    }
}
