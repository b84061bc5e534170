//! A series of 20 ms setpoints through the time-stepped simulated plant, as a recording: what
//! `pcr plant run` writes and `pcr.Plant.run` returns.
//!
//! Every setpoint is one row: the plant catches up to its time, the row records what the
//! capture system has reported by then (robot base frame, or the capture frame) and the true
//! state in extra columns, then the command is sent for the period up to the next setpoint.
//! A setpoint the plant cannot follow is held and flagged in the `fault` column (or ends the
//! run with `stop_on_fault`).

use crate::error::{ErrorKind, OfflineError};
use pcr_driver::{Driver, MotorCommand};
use pcr_plant::{Plant, TrueState};
use pcr_recording::Row;

/// Recording columns copied from the setpoints when present.
pub const PASS_THROUGH: [&str; 6] = ["xp_mm", "yp_mm", "phip_deg", "pose_id", "rep", "settled"];

/// The measured columns of the format a run writes.
pub const MEASURED: [&str; 9] = [
    "x_mm", "y_mm", "phi_deg", "m1x_mm", "m1y_mm", "m2x_mm", "m2y_mm", "m3x_mm", "m3y_mm",
];

/// Extra columns of a run: raw capture-frame values and the true state.
pub const RUN_EXTRA: [&str; 37] = [
    "xc_mm",
    "yc_mm",
    "phic_deg",
    "m1xc_mm",
    "m1yc_mm",
    "m2xc_mm",
    "m2yc_mm",
    "m3xc_mm",
    "m3yc_mm",
    "x_true_mm",
    "y_true_mm",
    "phi_true_deg",
    "m1x_true_mm",
    "m1y_true_mm",
    "m2x_true_mm",
    "m2y_true_mm",
    "m3x_true_mm",
    "m3y_true_mm",
    "q1_drive",
    "q2_drive",
    "q3_drive",
    "q1_motor",
    "q2_motor",
    "q3_motor",
    "q1_out",
    "q2_out",
    "q3_out",
    "dl1_mm",
    "dl2_mm",
    "dl3_mm",
    "bend1_deg",
    "bend2_deg",
    "bend3_deg",
    "f1_n",
    "f2_n",
    "f3_n",
    "fault",
];

/// Options of a run beyond its setpoints.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RunOptions {
    /// Record x_mm .. m3y_mm in the capture frame (as the capture system reports them, for
    /// registration) instead of the robot base frame.
    pub capture_frame: bool,
    /// End the run at the first setpoint the plant cannot follow (else the plant holds its
    /// position, the row's `fault` is 1 and the run goes on).
    pub stop_on_fault: bool,
}

/// One recorded cycle, handed to the caller's sink.
pub struct Cycle<'a> {
    /// Index of the setpoint.
    pub index: usize,
    /// The row (the setpoint's row with what was measured).
    pub row: &'a Row,
    /// The cells of [`RUN_EXTRA`].
    pub extra: &'a [Option<f64>],
    /// The plant's true state at the row's time.
    pub state: &'a TrueState,
    /// The plant.
    pub plant: &'a Plant,
}

/// Checks setpoints: times finite, not negative, strictly increasing. `at(k)` names setpoint k
/// in messages.
pub fn check_setpoints(rows: &[Row], at: &dyn Fn(usize) -> String) -> Result<(), OfflineError> {
    for (k, r) in rows.iter().enumerate() {
        if !r.t_s.is_finite() {
            return Err(OfflineError::invalid(format!(
                "{}: t_s {} is not a finite number",
                at(k),
                r.t_s
            )));
        }
        if k == 0 && r.t_s < 0.0 {
            return Err(OfflineError::invalid(format!(
                "{}: t_s must be >= 0",
                at(k)
            )));
        }
        if k > 0 && r.t_s <= rows[k - 1].t_s {
            return Err(OfflineError::invalid(format!(
                "{}, column `t_s`: {} does not increase (previous {})",
                at(k),
                r.t_s,
                rows[k - 1].t_s
            )));
        }
    }
    Ok(())
}

/// The recording's metadata of a run. `command_delay_s` is [`command_delay_s`] of the
/// setpoints.
pub fn metadata(
    robot: &str,
    plant: &str,
    seed: u64,
    opts: RunOptions,
    setpoints: &str,
    command_delay_s: f64,
    created: &str,
) -> Vec<(String, String)> {
    vec![
        ("source".into(), "pcr plant run".into()),
        ("robot".into(), robot.into()),
        ("plant".into(), plant.into()),
        ("seed".into(), seed.to_string()),
        (
            "frame".into(),
            if opts.capture_frame {
                "capture"
            } else {
                "robot"
            }
            .into(),
        ),
        ("setpoints".into(), setpoints.into()),
        (
            pcr_recording::COMMAND_DELAY_KEY.into(),
            pcr_recording::number(command_delay_s),
        ),
        ("created".into(), created.into()),
    ]
}

/// The timing contract of a run: a row's pose is measured before its command is sent, so it
/// answers the command of the row before, one setpoint spacing earlier (the median spacing of
/// the times, s; `fallback` for fewer than two setpoints).
pub fn command_delay_s(times: impl Iterator<Item = f64>, fallback: f64) -> f64 {
    let t: Vec<f64> = times.collect();
    let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    if d.is_empty() {
        return fallback;
    }
    d.sort_by(f64::total_cmp);
    // To the nanosecond: differences of row times carry rounding (0.06 - 0.04).
    (d[d.len() / 2] * 1e9).round() / 1e9
}

/// The known columns a run writes: the measured ones, then those of [`PASS_THROUGH`] the
/// setpoints have.
pub fn known_columns(has: &dyn Fn(&str) -> bool) -> Vec<&'static str> {
    let mut known = MEASURED.to_vec();
    known.extend(PASS_THROUGH.iter().filter(|c| has(c)));
    known
}

/// Runs `setpoints` (rows with `t_s`, `q` and the pass-through cells; checked with
/// [`check_setpoints`]) through `plant`, handing every recorded cycle to `sink`. `at(k)` names
/// setpoint k in messages. Returns the number of setpoints the plant could not follow.
pub fn run_setpoints<E: From<OfflineError>>(
    plant: &mut Plant,
    setpoints: &[Row],
    opts: RunOptions,
    at: &dyn Fn(usize) -> String,
    sink: &mut dyn FnMut(Cycle<'_>) -> Result<(), E>,
) -> Result<usize, E> {
    let cycle_s = plant.config().simulation.cycle_s;
    let frame = plant.capture_model().registered;
    let plant_error = |e: &dyn std::error::Error, k: usize| {
        OfflineError::new(ErrorKind::Plant, format!("{}: plant failed: {e}", at(k)))
    };
    let mut last_meas = None;
    let mut faults = 0usize;
    for (k, base) in setpoints.iter().enumerate() {
        let (t, q) = (base.t_s, base.q);
        // Catch up to t (idle if the setpoints have a gap), then record what is known at t.
        plant.idle_until(t).map_err(|e| plant_error(&e, k))?;
        for m in plant.drain_measurements() {
            last_meas = Some(m);
        }
        let s = plant.true_state().clone();
        let mut row = base.clone();
        if let Some(m) = last_meas {
            let m = if opts.capture_frame {
                m
            } else {
                m.in_robot_frame(&frame)
            };
            if let Some(p) = m.pose {
                row.pose = [Some(p[0]), Some(p[1]), Some(p[2].to_degrees())];
            }
            for i in 0..3 {
                if let Some(p) = m.m[i] {
                    row.m[i] = [Some(p[0]), Some(p[1])];
                }
            }
        }
        let mut extra: Vec<Option<f64>> = Vec::with_capacity(RUN_EXTRA.len());
        let raw = last_meas;
        extra.extend(match raw.and_then(|m| m.pose) {
            Some(p) => [Some(p[0]), Some(p[1]), Some(p[2].to_degrees())],
            None => [None; 3],
        });
        for i in 0..3 {
            match raw.and_then(|m| m.m[i]) {
                Some(p) => extra.extend([Some(p[0]), Some(p[1])]),
                None => extra.extend([None, None]),
            }
        }
        extra.extend([
            Some(s.eq.pose[0]),
            Some(s.eq.pose[1]),
            Some(s.eq.pose[2].to_degrees()),
        ]);
        for m in &s.eq.m {
            extra.extend([Some(m[0]), Some(m[1])]);
        }
        extra.extend(s.counter.map(|v| Some(f64::from(v))));
        extra.extend(s.motor.map(|v| Some(f64::from(v))));
        extra.extend(s.output.map(Some));
        extra.extend(s.tendon_mm.map(Some));
        extra.extend(s.bending.map(|b| Some(b.to_degrees())));
        extra.extend(s.eq.lambda.map(Some));
        let drive = plant.read(t, cycle_s).map_err(|e| plant_error(&e, k))?;
        extra.push(Some(f64::from(u8::from(drive.fault))));
        sink(Cycle {
            index: k,
            row: &row,
            extra: &extra,
            state: &s,
            plant,
        })?;
        let period = setpoints.get(k + 1).map_or(cycle_s, |n| n.t_s - t);
        let cmd = MotorCommand {
            steps: q,
            enable: true,
        };
        if let Err(e) = plant.write(t, period, &cmd) {
            let what = format!("{}: setpoint {q:?}: {e}", at(k));
            if opts.stop_on_fault {
                return Err(OfflineError::new(ErrorKind::Plant, what).into());
            }
            // The plant holds its position and reports a fault, as the real drive would.
            tracing::warn!("{what}");
            faults += 1;
        }
    }
    Ok(faults)
}
