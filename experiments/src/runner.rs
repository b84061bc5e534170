//! The in-process runner: a design's program on [`SimChain`] (the planner, IK and driver steps
//! of the real chain on the simulated plant, simulated clock), recorded one row per control
//! cycle in the recording format with the annotator's labels.
//!
//! The chain is driven by the model `RunSetup::model` (planning, IK, safety limits); the plant
//! is the truth: `RunSetup::plant` on top of its own nominal robot `RunSetup::plant_robot`, so
//! a calibrated model drives the same plant as the nominal one. Measured columns come from the
//! plant's motion-capture view in the robot frame (the pose through the driver step's pose
//! sensor, the M_i from [`pcr_control::PlantDrive::joints`]); a cell is empty when no capture
//! sample of that cycle saw the body. Rows are labelled by [`Annotator`] from the row alone,
//! as a live recording would be. Same design, configurations and seeds: same bytes.

use crate::annotate::{Annotator, Tolerances, EXTRA_COLUMNS};
use crate::calibration::round_dec;
use crate::design::Design;
use crate::program::{program_of, ProgramCommand, ProgramError};
use pcr_control::{
    command_of_moves, AlignedSample, CaptureAligner, CommandError, PlanError, SimChain,
};
use pcr_messages::{driver_flags, planner_state, DriverStateMsg};
use pcr_plant::PlantConfig;
use pcr_recording::{RecordingError, RecordingWriter, Row, KNOWN_COLUMNS};
use pcr_robot::{RobotConfig, Vec2};
use std::io::Write;

/// Simulated time a command may overrun its planned duration before the run is abandoned, s.
pub const OVERRUN_S: f64 = 30.0;

/// What the runner needs besides the design.
#[derive(Debug, Clone)]
pub struct RunSetup {
    /// The model that drives the robot (e.g. a calibrated robot).
    pub model: RobotConfig,
    /// The plant's nominal robot (its deviations apply on top).
    pub plant_robot: RobotConfig,
    /// The plant (the truth); its `seed` drives the random effects.
    pub plant: PlantConfig,
    /// Control period, s (the recording has one row per period).
    pub period_s: f64,
    /// The seed recorded as `seed` (the split's, for the static experiments).
    pub seed: u64,
    /// Metadata written after `experiment` (e.g. `robot`, `plant`, `source`, `created`).
    pub metadata: Vec<(String, String)>,
    /// Tolerances of the annotator.
    pub tolerances: Tolerances,
    /// The capture system's declared latency, s (the supervisor configuration's
    /// `[capture] latency_ms`): with it, each row's measured cells hold the capture sample
    /// measured nearest to the row's time ([`pcr_control::CaptureAligner`]); without it, the
    /// latest sample reported by the row's time.
    pub capture_latency_s: Option<f64>,
}

/// What a run produced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunSummary {
    /// Rows written.
    pub rows: usize,
    /// Simulated duration, s.
    pub duration_s: f64,
    /// Commands run.
    pub commands: usize,
    /// Items of the design (visits, paths, blocks) found by the annotator.
    pub found: usize,
    /// Rows marked settled.
    pub settled_rows: usize,
    /// Rows without a measured platform pose (capture dropouts).
    pub pose_dropouts: usize,
}

/// Why a run failed. The rows recorded up to the failure are in the output.
#[derive(Debug, thiserror::Error)]
pub enum RunnerError {
    /// The design could not be turned into commands.
    #[error(transparent)]
    Program(#[from] ProgramError),
    /// The chain could not be built.
    #[error("simulated chain: {0}")]
    Chain(String),
    /// The chain refused a command (the planner's checks name the move).
    #[error("command {command} of {commands} ({what}) refused: {why}")]
    Refused {
        /// 1-based command number.
        command: usize,
        /// Number of commands.
        commands: usize,
        /// What the refused move does.
        what: String,
        /// The planner's reason.
        why: String,
    },
    /// The drive failed.
    #[error("at t = {t_s:.2} s: {message}")]
    Driver {
        /// Simulated time, s.
        t_s: f64,
        /// The drive's error.
        message: String,
    },
    /// A command did not finish in time.
    #[error("command {command} ({what}) did not finish {OVERRUN_S} s after its planned end")]
    Timeout {
        /// 1-based command number.
        command: usize,
        /// What it covers.
        what: String,
    },
    /// The recording could not be written.
    #[error(transparent)]
    Recording(#[from] RecordingError),
    /// The annotator did not find every item of the design.
    #[error(
        "the run ended with {found} of {expected} items labelled; still waiting for {waiting}"
    )]
    Incomplete {
        /// Items found.
        found: usize,
        /// Items designed.
        expected: usize,
        /// The first item not found.
        waiting: String,
    },
}

/// The recording's row of a driver cycle at recording time `t_s`: commanded steps, measured
/// pose (if the capture saw the platform this cycle), the captured M_i (`joints`, robot frame),
/// the planned pose; positions rounded to 1e-4 mm, angles to 1e-5 deg. Unlabelled: pass it to
/// [`crate::Annotator::annotate`]. The supervisor can build its rows of a live run the same way.
pub fn row_of_state(t_s: f64, st: &DriverStateMsg, joints: [Option<Vec2>; 3]) -> Row {
    let mut row = Row::new(t_s, st.commanded);
    let mm = |v: f64| Some(round_dec(v, 4));
    let deg = |v: f64| Some(round_dec(v.to_degrees(), 5));
    let m = st.measured;
    if st.flags & driver_flags::POSE_VALID != 0 && m.iter().all(|v| v.is_finite()) {
        row.pose = [mm(m[0]), mm(m[1]), deg(m[2])];
    }
    for (cell, j) in row.m.iter_mut().zip(joints) {
        if let Some(p) = j.filter(|p| p.iter().all(|v| v.is_finite())) {
            *cell = [mm(p[0]), mm(p[1])];
        }
    }
    let p = st.planned;
    if p.iter().all(|v| v.is_finite()) {
        row.planned = [mm(p[0]), mm(p[1]), deg(p[2])];
    }
    row
}

/// What one capture sample saw: the platform pose (x mm, y mm, phi rad) and the M_i.
type CaptureCells = (Option<[f64; 3]>, [Option<Vec2>; 3]);

fn push_samples(a: &mut CaptureAligner<Row, CaptureCells>, samples: &[pcr_plant::Measurement]) {
    for m in samples {
        a.push_sample(m.t_s, (m.pose, m.m));
    }
}

/// The row's measured cells from the samples measured near its time (nearest first): per body
/// the nearest sample that saw it; empty where none did.
fn fill_measured(row: &mut Row, cands: &[AlignedSample<CaptureCells>]) {
    let mm = |v: f64| Some(round_dec(v, 4));
    let deg = |v: f64| Some(round_dec(v.to_degrees(), 5));
    row.pose = [None; 3];
    if let Some(p) = cands
        .iter()
        .find_map(|s| s.value.0)
        .filter(|p| p.iter().all(|v| v.is_finite()))
    {
        row.pose = [mm(p[0]), mm(p[1]), deg(p[2])];
    }
    for (i, cell) in row.m.iter_mut().enumerate() {
        *cell = [None; 2];
        if let Some(p) = cands
            .iter()
            .find_map(|s| s.value.1[i])
            .filter(|p| p.iter().all(|v| v.is_finite()))
        {
            *cell = [mm(p[0]), mm(p[1])];
        }
    }
}

/// What a refused command's offending move does.
fn refused_what(cmd: &ProgramCommand, e: &CommandError) -> String {
    let index = match e {
        CommandError::Plan(PlanError::Rejected { index, .. })
        | CommandError::Plan(PlanError::Invalid { index, .. })
        | CommandError::Plan(PlanError::InvalidMove { index, .. }) => Some(*index),
        _ => None,
    };
    index
        .and_then(|i| cmd.labels.get(i).cloned())
        .unwrap_or_else(|| cmd.describe())
}

/// Runs `design` on the simulated chain and writes the recording to `out`. `progress` is
/// called now and then with the fraction done (0..=1).
pub fn run_in_process<W: Write>(
    design: &Design,
    setup: &RunSetup,
    out: W,
    progress: &mut dyn FnMut(f64),
) -> Result<RunSummary, RunnerError> {
    if !(setup.period_s.is_finite() && setup.period_s > 0.0) {
        return Err(RunnerError::Chain(format!(
            "control period {} s (must be > 0)",
            setup.period_s
        )));
    }
    let program = program_of(design, &setup.model)?;
    let mut chain = SimChain::simulated_on(
        &setup.model,
        &setup.plant_robot,
        &setup.plant,
        setup.period_s,
    )
    .map_err(|e| RunnerError::Chain(e.to_string()))?;
    let mut meta = design.metadata(setup.seed);
    let rest = meta.split_off(1);
    meta.extend(setup.metadata.iter().cloned());
    meta.extend(rest);
    meta.push(("period_s".into(), pcr_recording::number(setup.period_s)));
    // The timing contract: the drive executes a row's command over the next cycle, so the pose
    // of a row answers the command of the row before.
    meta.push((
        pcr_recording::COMMAND_DELAY_KEY.into(),
        pcr_recording::number(setup.period_s),
    ));
    meta.push(("plant_seed".into(), setup.plant.seed.to_string()));
    meta.push(("commands".into(), program.commands.len().to_string()));
    if let Some(l) = setup.capture_latency_s {
        meta.push(("capture_latency_s".into(), pcr_recording::number(l)));
        meta.push((
            "measured_at".into(),
            "capture time (each row holds the sample measured nearest its t_s)".into(),
        ));
    }
    let mut w = RecordingWriter::new(out, &meta, &KNOWN_COLUMNS, &EXTRA_COLUMNS)?;
    let mut ann = Annotator::new(design, setup.tolerances);
    let n_cmd = program.commands.len();
    let mut k: u64 = 0;
    let mut summary = RunSummary {
        rows: 0,
        duration_s: 0.0,
        commands: n_cmd,
        found: 0,
        settled_rows: 0,
        pose_dropouts: 0,
    };
    // Capture samples are 10 ms apart in the plant (100 Hz); a row takes a sample measured
    // within half a control period of its time.
    let mut aligner: Option<CaptureAligner<Row, CaptureCells>> = setup
        .capture_latency_s
        .map(|l| CaptureAligner::new(l, 0.5 * setup.period_s));
    let mut emit =
        |row: &mut Row, ann: &mut Annotator, summary: &mut RunSummary| -> Result<(), RunnerError> {
            let label = ann.annotate(row);
            let cells = label.extra_cells();
            let cells: [Option<&str>; 3] = std::array::from_fn(|i| cells[i].as_deref());
            w.write_row_text(row, &cells)?;
            summary.rows += 1;
            summary.settled_rows += usize::from(label.settled);
            summary.pose_dropouts += usize::from(row.pose[0].is_none());
            Ok(())
        };
    for (c, cmd) in program.commands.iter().enumerate() {
        let refused = |why: String, what: String| RunnerError::Refused {
            command: c + 1,
            commands: n_cmd,
            what,
            why,
        };
        let wire = command_of_moves(c as u32 + 1, &cmd.moves)
            .map_err(|e| refused(e.to_string(), cmd.describe()))?;
        chain
            .interp
            .command(&wire)
            .map_err(|e| refused(e.to_string(), refused_what(cmd, &e)))?;
        let duration = chain.interp.status(chain.time_s()).duration_s;
        let t_start = chain.time_s();
        loop {
            let t_s = chain.time_s();
            let o = chain.cycle().map_err(|e| RunnerError::Driver {
                t_s,
                message: e.to_string(),
            })?;
            let t_row = round_dec(k as f64 * setup.period_s, 6);
            let mut row = row_of_state(t_row, &o.state, chain.plant_drive().joints());
            k += 1;
            match &mut aligner {
                None => emit(&mut row, &mut ann, &mut summary)?,
                Some(a) => {
                    // The drive read at t_s: samples reported by t_s are in.
                    push_samples(a, chain.plant_drive().samples());
                    a.push_row(t_s, row);
                    for (_, mut row, cands) in a.ready(t_s) {
                        fill_measured(&mut row, &cands);
                        emit(&mut row, &mut ann, &mut summary)?;
                    }
                }
            }
            let st = chain.interp.status(chain.time_s());
            if st.state != planner_state::RUNNING && st.state != planner_state::PAUSED {
                break;
            }
            if chain.time_s() > t_start + duration + OVERRUN_S {
                return Err(RunnerError::Timeout {
                    command: c + 1,
                    what: cmd.describe(),
                });
            }
            if k.is_multiple_of(256) && duration > 0.0 {
                let f = ((chain.time_s() - t_start) / duration).min(1.0);
                progress((c as f64 + f) / n_cmd as f64);
            }
        }
        progress((c + 1) as f64 / n_cmd as f64);
    }
    // The last rows wait for the samples measured at their time: run the chain (at rest) until
    // they have been reported, without new rows.
    if let Some(a) = &mut aligner {
        let t_end = chain.time_s();
        while a.waiting() > 0 {
            let t_s = chain.time_s();
            chain.cycle().map_err(|e| RunnerError::Driver {
                t_s,
                message: e.to_string(),
            })?;
            push_samples(a, chain.plant_drive().samples());
            for (_, mut row, cands) in a.ready(t_s) {
                fill_measured(&mut row, &cands);
                emit(&mut row, &mut ann, &mut summary)?;
            }
            if t_s > t_end + 1.0 + a.delay_s() {
                break;
            }
        }
        for (_, mut row, cands) in a.flush() {
            fill_measured(&mut row, &cands);
            emit(&mut row, &mut ann, &mut summary)?;
        }
    }
    w.into_inner()?;
    summary.duration_s = chain.time_s();
    summary.found = ann.found();
    if !ann.finished() {
        return Err(RunnerError::Incomplete {
            found: ann.found(),
            expected: ann.total(),
            waiting: ann.waiting_for().unwrap_or_default(),
        });
    }
    Ok(summary)
}
