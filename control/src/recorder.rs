//! Recorder: writes a run in the recording format of `shared/spec/recording.md`
//! (`t_s, q1, q2, q3, x_mm, y_mm, phi_deg, m1x_mm .. m3y_mm, xp_mm, yp_mm, phip_deg`, one row per
//! driver cycle). The measured columns come from the driver state's pose sensor, or, where the
//! configuration has a capture system, from the motion-capture bridge ([`Measured`]).

use pcr_messages::{driver_flags, DriverStateMsg};
use std::io::{self, Write};

/// The header row.
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

/// Writes rows of driver-state messages; times are made relative to the first row and rows that
/// would not be strictly increasing in time are skipped.
#[derive(Debug)]
pub struct Recorder<W: Write> {
    out: W,
    t0: Option<f64>,
    last_t: f64,
    rows: u64,
}

impl<W: Write> Recorder<W> {
    /// Starts a recording: `# key = value` metadata lines, then the header.
    pub fn new(mut out: W, meta: &[(&str, &str)]) -> io::Result<Self> {
        for (k, v) in meta {
            writeln!(out, "# {k} = {v}")?;
        }
        writeln!(out, "{HEADER}")?;
        Ok(Self {
            out,
            t0: None,
            last_t: f64::NEG_INFINITY,
            rows: 0,
        })
    }

    /// Rows written.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Writes one row with the driver backend's measured pose (skipped if its time does not
    /// increase).
    pub fn row(&mut self, s: &DriverStateMsg) -> io::Result<()> {
        self.row_with(s, &Measured::of_state(s))
    }

    /// Writes one row with the given measurement (skipped if its time does not increase).
    pub fn row_with(&mut self, s: &DriverStateMsg, m: &Measured) -> io::Result<()> {
        let t0 = *self.t0.get_or_insert(s.t_s);
        let t = s.t_s - t0;
        if t <= self.last_t || !t.is_finite() {
            return Ok(());
        }
        self.last_t = t;
        self.rows += 1;
        let q = s.commanded;
        write!(self.out, "{t:.6},{},{},{},", q[0], q[1], q[2])?;
        match m.pose.filter(|p| p.iter().all(|v| v.is_finite())) {
            Some(p) => write!(
                self.out,
                "{:.4},{:.4},{:.5},",
                p[0],
                p[1],
                p[2].to_degrees()
            )?,
            None => write!(self.out, ",,,")?,
        }
        for j in m.joints {
            match j.filter(|p| p.iter().all(|v| v.is_finite())) {
                Some(p) => write!(self.out, "{:.4},{:.4},", p[0], p[1])?,
                None => write!(self.out, ",,")?,
            }
        }
        let p = s.planned;
        if p.iter().all(|v| v.is_finite()) {
            writeln!(self.out, "{:.4},{:.4},{:.5}", p[0], p[1], p[2].to_degrees())
        } else {
            writeln!(self.out, ",,")
        }
    }

    /// Flushes and returns the writer.
    pub fn finish(mut self) -> io::Result<W> {
        self.out.flush()?;
        Ok(self.out)
    }
}
