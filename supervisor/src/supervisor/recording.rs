//! A run's recording: every row goes through one interface, [`RunSink`], to each of the run's
//! sinks: the CSV of `shared/spec/recording.md` ([`CsvSink`], the contract for the tools) and
//! the MCAP beside it, `<same stem>.mcap` ([`McapSink`]: every CSV column on the row channel,
//! plus the poses, the robot drawn, transforms, the driver state, and, while the run lasts, the
//! correction, cycle statistics, log lines and events). The CSV writes every row as one
//! `write(2)`; the MCAP writes a chunk at least every 250 ms: a supervisor killed mid-run leaves
//! both, the MCAP recoverable up to its last chunk.
//!
//! With a capture system the measured columns come from the bridge's sample captured at the
//! row's time ([`CaptureMatch`]); without one, from the driver backend's pose sensor.

use super::lifecycle::{run_over, Run};
use super::live::{say, Level, Live};
use super::Supervisor;
use pcr_control::{simple_command, Measured, Recorder, RowMaker};
use pcr_messages::{command_kind, driver_flags, task_flags, DriverStateMsg, MocapSample};
use pcr_recording::Row;
use pcr_telemetry::{McapFile, RowSample, Telemetry, TelemetryError};
use std::cell::RefCell;
use std::collections::VecDeque;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::time::{Duration, Instant};

/// Samples of the motion-capture bridge kept for matching driver-state rows.
pub(super) const MOCAP_RING: usize = 32;

/// The columns an experiment's recording carries after the standard ones.
pub(super) const EXPERIMENT_COLUMNS: [&str; 7] = [
    "pose_id",
    "rep",
    "settled",
    "set",
    "segment",
    "motor",
    "amplitude_steps",
];

/// Why a sink could not take a row or close.
#[derive(Debug, thiserror::Error)]
pub enum SinkError {
    /// The CSV could not be written.
    #[error("recording {path}: {source}")]
    Csv {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// The MCAP could not be written.
    #[error("{0}")]
    Mcap(#[from] TelemetryError),
}

/// Where a run's rows go. The recording makes each row once (times relative to its first row,
/// mm and degrees; an experiment's labels) and hands it to every sink in order.
pub trait RunSink {
    /// The file the sink writes.
    fn path(&self) -> &Path;
    /// Takes one row.
    fn row(&mut self, sample: &RowSample<'_>) -> Result<(), SinkError>;
    /// Called every supervision cycle (20 ms): a sink that buffers writes out what is due.
    fn tick(&mut self) -> Result<(), SinkError> {
        Ok(())
    }
    /// Closes the sink (the run is over).
    fn finish(self: Box<Self>) -> Result<(), SinkError>;
}

/// The CSV of the recording format, unbuffered: every row is one `write(2)` as it comes (a
/// supervisor killed mid-run leaves a file whose every row parses).
pub struct CsvSink {
    recorder: Recorder<File>,
    path: PathBuf,
}

impl CsvSink {
    /// Creates the file and writes its metadata lines and header (`columns`: further columns
    /// after the standard ones).
    pub fn create(
        path: &Path,
        meta: &[(String, String)],
        columns: &[&str],
    ) -> Result<Self, SinkError> {
        let err = |source| SinkError::Csv {
            path: path.display().to_string(),
            source,
        };
        let f = File::create(path).map_err(err)?;
        let meta: Vec<(&str, &str)> = meta.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
        let recorder = Recorder::with_extra(f, &meta, columns).map_err(err)?;
        Ok(Self {
            recorder,
            path: path.to_path_buf(),
        })
    }
}

impl RunSink for CsvSink {
    fn path(&self) -> &Path {
        &self.path
    }

    fn row(&mut self, s: &RowSample<'_>) -> Result<(), SinkError> {
        self.recorder
            .write(s.row, s.extra)
            .map_err(|source| SinkError::Csv {
                path: self.path.display().to_string(),
                source,
            })
    }

    fn finish(self: Box<Self>) -> Result<(), SinkError> {
        let path = self.path.display().to_string();
        self.recorder
            .finish()
            .map(drop)
            .map_err(|source| SinkError::Csv { path, source })
    }
}

/// The MCAP beside the CSV: the row on the telemetry channels (shared with the live view),
/// recorded while the run lasts.
pub struct McapSink {
    telemetry: Rc<RefCell<Telemetry>>,
    file: McapFile,
    extra_columns: Vec<String>,
}

impl McapSink {
    /// Creates the file and attaches it to the telemetry channels; `meta` becomes its
    /// `recording` metadata record; `extra_columns` name the row's extra cells.
    pub fn create(
        telemetry: Rc<RefCell<Telemetry>>,
        path: &Path,
        meta: &[(String, String)],
        extra_columns: Vec<String>,
    ) -> Result<Self, SinkError> {
        let file = McapFile::create(&telemetry.borrow(), path, meta)?;
        Ok(Self {
            telemetry,
            file,
            extra_columns,
        })
    }
}

impl RunSink for McapSink {
    fn path(&self) -> &Path {
        self.file.path()
    }

    fn row(&mut self, s: &RowSample<'_>) -> Result<(), SinkError> {
        self.telemetry.borrow_mut().row(s, &self.extra_columns);
        Ok(())
    }

    fn tick(&mut self) -> Result<(), SinkError> {
        Ok(self.file.tick()?)
    }

    fn finish(self: Box<Self>) -> Result<(), SinkError> {
        Ok(self.file.finish()?)
    }
}

/// A run's recording: makes the rows and hands them to its sinks. A sink that fails is
/// reported once and dropped; the others go on.
pub(super) struct RunRecording {
    maker: RowMaker,
    sinks: Vec<Box<dyn RunSink>>,
    csv: PathBuf,
    mcap: Option<PathBuf>,
    rows: u64,
}

impl RunRecording {
    /// Creates `<dir>/<stem>.csv` and, with a telemetry, `<dir>/<stem>.mcap`. `columns` are
    /// further columns after the standard ones (an experiment's labels). The run cannot start
    /// without its CSV; without its MCAP it starts with a warning.
    pub(super) fn open(
        dir: &Path,
        stem: &str,
        meta: &[(String, String)],
        columns: &[&str],
        live: &Live,
    ) -> Result<Self, String> {
        std::fs::create_dir_all(dir).map_err(|e| format!("recording dir {dir:?}: {e}"))?;
        let csv = dir.join(format!("{stem}.csv"));
        let csv_sink = CsvSink::create(&csv, meta, columns).map_err(|e| e.to_string())?;
        let mut sinks: Vec<Box<dyn RunSink>> = vec![Box::new(csv_sink)];
        let mut mcap = None;
        let path = dir.join(format!("{stem}.mcap"));
        let extra: Vec<String> = columns
            .iter()
            .filter(|c| !pcr_recording::KNOWN_COLUMNS.contains(c))
            .map(|c| c.to_string())
            .collect();
        match McapSink::create(live.telemetry(), &path, meta, extra) {
            Ok(s) => {
                sinks.push(Box::new(s));
                mcap = Some(path);
            }
            Err(e) => say(Level::Error, &format!("no MCAP of this run: {e}")),
        }
        Ok(Self {
            maker: RowMaker::new(),
            sinks,
            csv,
            mcap,
            rows: 0,
        })
    }

    /// The CSV.
    pub(super) fn csv_path(&self) -> &Path {
        &self.csv
    }

    /// The MCAP, if there is one.
    pub(super) fn mcap_path(&self) -> Option<&Path> {
        self.mcap.as_deref()
    }

    /// The files, for messages.
    pub(super) fn files_text(&self) -> String {
        match &self.mcap {
            Some(m) => format!("{} and {}", self.csv.display(), m.display()),
            None => self.csv.display().to_string(),
        }
    }

    /// Rows recorded.
    pub(super) fn rows(&self) -> u64 {
        self.rows
    }

    /// The row of a driver state and its measurement, or `None` when its time does not
    /// increase (skipped).
    pub(super) fn row_of(&mut self, st: &DriverStateMsg, m: &Measured) -> Option<Row> {
        self.maker.row_of(st, m)
    }

    fn drop_failed(&mut self, failed: Vec<usize>, what: &str, errors: Vec<SinkError>) {
        for (i, e) in failed.into_iter().rev().zip(errors.into_iter().rev()) {
            say(
                Level::Error,
                &format!(
                    "{what}: {e}; {} no longer written",
                    self.sinks[i].path().display()
                ),
            );
            if self.sinks[i].path() == self.mcap.as_deref().unwrap_or(Path::new("")) {
                self.mcap = None;
            }
            self.sinks.remove(i);
        }
    }

    /// Hands a row to every sink.
    pub(super) fn write(&mut self, s: &RowSample<'_>) {
        let (mut failed, mut errors) = (Vec::new(), Vec::new());
        for (i, sink) in self.sinks.iter_mut().enumerate() {
            if let Err(e) = sink.row(s) {
                failed.push(i);
                errors.push(e);
            }
        }
        self.rows += 1;
        self.drop_failed(failed, "recording", errors);
    }

    /// Lets the sinks write out what is due.
    pub(super) fn tick(&mut self) {
        let (mut failed, mut errors) = (Vec::new(), Vec::new());
        for (i, sink) in self.sinks.iter_mut().enumerate() {
            if let Err(e) = sink.tick() {
                failed.push(i);
                errors.push(e);
            }
        }
        self.drop_failed(failed, "recording", errors);
    }

    /// Closes every sink.
    pub(super) fn finish(self) {
        for s in self.sinks {
            if let Err(e) = s.finish() {
                say(Level::Error, &format!("closing the recording: {e}"));
            }
        }
    }
}

/// How driver-state rows are matched with the bridge's samples.
pub(super) struct CaptureMatch {
    /// Half the chain's period, s.
    half_period_s: f64,
    /// Capture data older than this is not a measurement of the row, s.
    stale_s: f64,
    /// The capture system's declared latency (`[capture] latency_ms`), s.
    latency_s: f64,
}

impl CaptureMatch {
    /// The bridge sample measured at the row's time: the one whose capture time (its chain
    /// time less the declared latency) is nearest the row's time, within half a period.
    fn sample<'a>(
        &self,
        st: &DriverStateMsg,
        ring: &'a VecDeque<MocapSample>,
    ) -> Option<&'a MocapSample> {
        ring.iter()
            .map(|m| ((m.t_s - self.latency_s - st.t_s).abs(), m))
            .filter(|(d, _)| *d <= self.half_period_s.min(self.stale_s))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, m)| m)
    }

    /// Whether the match of a row is final: a sample captured at or after its time has
    /// arrived (later ones are farther), or it has waited longer than the stale limit.
    fn settled(&self, st: &DriverStateMsg, ring: &VecDeque<MocapSample>, waited: Duration) -> bool {
        ring.back()
            .is_some_and(|m| m.t_s - self.latency_s >= st.t_s)
            || waited.as_secs_f64() > self.stale_s + self.latency_s
    }
}

/// The measurement of a driver-state row taken from the bridge's sample `sample`: the
/// recording's measured cells.
fn measured_by_bridge(sample: Option<&MocapSample>) -> Measured {
    let mut measured = Measured::default();
    if let Some(m) = sample {
        if let Some(p) = m.pose() {
            measured.pose = Some(p);
        }
        measured.joints = std::array::from_fn(|i| m.joint(i).map(|j| [j[0], j[1]]));
    }
    measured
}

impl Run {
    /// Records one row (and counts it in the accuracy).
    fn record(&mut self, st: &DriverStateMsg, measured: Measured) {
        let mut row = *st;
        row.flags &= !driver_flags::POSE_VALID;
        if let Some(p) = measured.pose {
            row.measured = p;
            row.flags |= driver_flags::POSE_VALID;
        }
        if let Some(mut r) = self.recording.row_of(&row, &measured) {
            let cells = match &mut self.experiment {
                None => Vec::new(),
                Some(x) => x.annotator.annotate(&mut r).extra_cells().to_vec(),
            };
            let cells: Vec<Option<&str>> = cells.iter().map(|c| c.as_deref()).collect();
            self.recording.write(&RowSample {
                chain_t_s: st.t_s,
                row: &r,
                extra: &cells,
                state: Some(&row),
            });
        }
        self.acc.add(&row);
        if st.task_flags & task_flags::UNCORRECTED != 0 {
            self.uncorrected += 1;
        }
        if measured.pose.is_none() {
            self.unmeasured += 1;
        }
    }

    /// Records the waiting rows whose capture sample is known (all of them with `all`).
    fn record_pending(
        &mut self,
        ring: &VecDeque<MocapSample>,
        c: &CaptureMatch,
        now: Instant,
        all: bool,
    ) {
        while let Some((st, at)) = self.pending.front().copied() {
            if !all && !c.settled(&st, ring, now - at) {
                break;
            }
            self.pending.pop_front();
            let measured = measured_by_bridge(c.sample(&st, ring));
            self.record(&st, measured);
        }
    }
}

impl Supervisor {
    /// How rows are matched with the capture system's samples (configurations with one).
    fn capture_match(&self) -> Option<CaptureMatch> {
        self.cfg.capture.as_ref().map(|c| CaptureMatch {
            half_period_s: self.cfg.period_ms * 0.5e-3,
            stale_s: c.stale_ms * 1e-3,
            latency_s: c.latency_ms.unwrap_or(0.0) * 1e-3,
        })
    }

    /// Takes the bridge's samples into the ring rows are matched with.
    pub(super) fn drain_mocap(&mut self, now: Instant) {
        if let Some(sub) = &self.sub_mocap {
            while let Ok(Some(smp)) = sub.receive() {
                if self.mocap.len() == MOCAP_RING {
                    self.mocap.pop_front();
                }
                self.mocap.push_back(*smp.payload());
                self.mocap_at = Some(now);
            }
        }
    }

    /// Driver states: recorded (with a capture system, once the sample measured at the row's
    /// time has arrived); outside a run they go to the live view only. A drive fault ends the
    /// run.
    pub(super) fn drain_driver_states(&mut self, now: Instant) {
        let mut stop = false;
        let capture = self.capture_match();
        while let Ok(Some(smp)) = self.sub_state.receive() {
            let st = smp.payload();
            let Some(run) = &mut self.run else {
                self.live.idle_state(st);
                continue;
            };
            if st.run_id != run.id || run_over(run, now) {
                continue;
            }
            run.executed = Some(st.planned);
            run.settled = st.flags & driver_flags::MOVING == 0;
            if st.flags & driver_flags::FAULT != 0 && run.ended.is_none() {
                run.ended = Some((now, "drive fault"));
                say(
                    Level::Error,
                    &format!(
                        "run {} stopped: drive fault (latched in the drive, which holds \
                         position; clear it at the drive)",
                        run.id
                    ),
                );
                stop = true;
            }
            match &capture {
                Some(_) => run.pending.push_back((*st, now)),
                None => run.record(st, Measured::of_state(st)),
            }
        }
        if let (Some(run), Some(c)) = (&mut self.run, &capture) {
            run.record_pending(&self.mocap, c, now, false);
        }
        if stop {
            let _ = pcr_nodes::publish(&self.pub_cmd, simple_command(command_kind::STOP, 0, 0));
        }
    }

    /// Records every row still waiting for its capture sample (the run ends).
    pub(super) fn record_pending_now(&self, run: &mut Run) {
        if let Some(c) = self.capture_match() {
            run.record_pending(&self.mocap, &c, Instant::now(), true);
        }
    }

    /// Lets the run's sinks write out what is due (the MCAP's chunk).
    pub(super) fn tick_recording(&mut self) {
        if let Some(run) = &mut self.run {
            run.recording.tick();
        }
    }
}
