//! [`Telemetry`]: the channels of one Foxglove context and what goes on each.

use std::collections::BTreeMap;
use std::sync::Arc;

use foxglove::messages::{FrameTransforms, Log, PoseInFrame, SceneUpdate};
use foxglove::{Channel, Context, PartialMetadata, RawChannel, Schema};
use pcr_messages::{
    correction_flags, driver_flags, task_flags, Correction, DriverStateMsg, Heartbeat,
};
use serde_json::{json, Value};

use crate::row::{row_json, RowSample};
use crate::scene::{self, nanos, RobotScene};
use crate::{schemas, topics, TelemetryError};

/// What happened to a run or the chain ([`Telemetry::event`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunEventKind {
    /// A run started.
    Start,
    /// A run was paused (by the operator or while a process restarts).
    Pause,
    /// A run was resumed.
    Resume,
    /// A run was stopped.
    Stop,
    /// The planner refused a command.
    Refusal,
    /// A process failed and is restarted.
    Restart,
    /// The supervisor went to a safe stop.
    SafeStop,
    /// A run ended (its recording is closed).
    End,
}

impl RunEventKind {
    /// The `kind` of the JSON message.
    pub fn as_str(self) -> &'static str {
        match self {
            RunEventKind::Start => "start",
            RunEventKind::Pause => "pause",
            RunEventKind::Resume => "resume",
            RunEventKind::Stop => "stop",
            RunEventKind::Refusal => "refusal",
            RunEventKind::Restart => "restart",
            RunEventKind::SafeStop => "safe_stop",
            RunEventKind::End => "end",
        }
    }
}

/// A run event.
#[derive(Debug, Clone, Copy)]
pub struct RunEvent<'a> {
    /// What happened.
    pub kind: RunEventKind,
    /// The run, if any.
    pub run_id: Option<u32>,
    /// The process concerned (restarts), if any.
    pub process: Option<&'a str>,
    /// A human-readable line.
    pub text: &'a str,
}

/// A process's heartbeat with the supervisor's totals over its restarts.
#[derive(Debug, Clone, Copy)]
pub struct CycleStats<'a> {
    /// The process's name (`planner`, `ik`, `driver`, ...).
    pub process: &'a str,
    /// Its newest heartbeat.
    pub heartbeat: &'a Heartbeat,
    /// Deadline misses summed over its restarts.
    pub total_deadline_misses: u64,
    /// Its restarts.
    pub restarts: u32,
}

/// The channels of a run, on one Foxglove context; sinks (an [`crate::McapFile`], a
/// [`crate::LiveServer`]) attach to the context and receive every message logged while they are
/// attached. Logging never blocks on a sink's consumer.
pub struct Telemetry {
    ctx: Arc<Context>,
    row: Arc<RawChannel>,
    planned: Channel<PoseInFrame>,
    measured: Channel<PoseInFrame>,
    scene_ch: Channel<SceneUpdate>,
    tf: Channel<FrameTransforms>,
    driver: Arc<RawChannel>,
    correction: Arc<RawChannel>,
    log: Arc<Channel<Log>>,
    events: Arc<RawChannel>,
    stats: BTreeMap<String, Arc<RawChannel>>,
    scene: Option<RobotScene>,
}

impl std::fmt::Debug for Telemetry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Telemetry")
            .field("scene", &self.scene.is_some())
            .finish_non_exhaustive()
    }
}

fn json_channel(
    ctx: &Arc<Context>,
    topic: &str,
    schema: Schema,
) -> Result<Arc<RawChannel>, TelemetryError> {
    ctx.channel_builder(topic)
        .message_encoding("json")
        .schema(schema)
        .build_raw()
        .map_err(|source| TelemetryError::Channel {
            topic: topic.into(),
            source,
        })
}

fn log_json(ch: &RawChannel, v: &Value, t_s: f64) {
    ch.log_with_meta(
        v.to_string().as_bytes(),
        PartialMetadata::with_log_time(nanos(t_s)),
    );
}

impl Telemetry {
    /// The channels on a new context; the robot is drawn when `scene` is given.
    pub fn new(scene: Option<RobotScene>) -> Result<Self, TelemetryError> {
        let ctx = Context::new();
        Ok(Self {
            row: json_channel(&ctx, topics::ROW, schemas::recording_row())?,
            planned: ctx.channel_builder(topics::PLANNED_POSE).build(),
            measured: ctx.channel_builder(topics::MEASURED_POSE).build(),
            scene_ch: ctx.channel_builder(topics::SCENE).build(),
            tf: ctx.channel_builder(topics::TF).build(),
            driver: json_channel(&ctx, topics::DRIVER, schemas::driver_state())?,
            correction: json_channel(&ctx, topics::CORRECTION, schemas::correction())?,
            log: Arc::new(ctx.channel_builder(topics::LOG).build()),
            events: json_channel(&ctx, topics::EVENTS, schemas::run_event())?,
            stats: BTreeMap::new(),
            scene,
            ctx,
        })
    }

    /// The context sinks attach to.
    pub fn context(&self) -> &Arc<Context> {
        &self.ctx
    }

    /// One recorded row: the row channel (every CSV column), the planned and measured poses
    /// (where the row has them), the robot, the transforms and the driver state (from the
    /// driver message where there is one, else the commanded steps of the row).
    pub fn row(&mut self, s: &RowSample<'_>, extra_names: &[String]) {
        let t = s.chain_t_s;
        let ns = nanos(t);
        let row = s.row;
        log_json(&self.row, &row_json(row, extra_names, s.extra), t);
        let rad = |p: [f64; 3]| [p[0], p[1], p[2].to_radians()];
        let planned = scene::planned_pose(row).map(rad);
        let measured = row.measured_pose().map(rad);
        if let Some(p) = planned {
            self.planned.log_with_time(&scene::pose_in_frame(p, t), ns);
        }
        if let Some(p) = measured {
            self.measured.log_with_time(&scene::pose_in_frame(p, t), ns);
        }
        if let Some(sc) = &mut self.scene {
            if self.scene_ch.has_sinks() {
                self.scene_ch.log_with_time(&sc.of_row(row, t), ns);
            } else {
                // Keep the FK warm start following the robot.
                let _ = sc.of_row(row, t);
            }
        }
        self.tf
            .log_with_time(&scene::transforms(measured, planned, t), ns);
        let driver = match s.state {
            Some(st) => driver_json(st),
            None => json!({ "t_s": t, "commanded": row.q }),
        };
        log_json(&self.driver, &driver, t);
    }

    /// A driver state outside a run (live view only: no recording is attached then).
    pub fn idle_state(&mut self, st: &DriverStateMsg) {
        let t = st.t_s;
        let ns = nanos(t);
        let pose_valid = st.flags & driver_flags::POSE_VALID != 0;
        let measured = pose_valid.then_some(st.measured);
        self.planned
            .log_with_time(&scene::pose_in_frame(st.planned, t), ns);
        if let Some(p) = measured {
            self.measured.log_with_time(&scene::pose_in_frame(p, t), ns);
        }
        if let Some(sc) = &mut self.scene {
            if self.scene_ch.has_sinks() {
                let u = sc.update(st.commanded, measured, [None; 3], Some(st.planned), t);
                self.scene_ch.log_with_time(&u, ns);
            }
        }
        self.tf
            .log_with_time(&scene::transforms(measured, Some(st.planned), t), ns);
        log_json(&self.driver, &driver_json(st), t);
    }

    /// The outer loop's correction.
    pub fn correction(&self, c: &Correction) {
        let v = json!({
            "t_s": c.t_s,
            "offset_x_mm": c.offset[0],
            "offset_y_mm": c.offset[1],
            "offset_phi_deg": c.offset[2].to_degrees(),
            "error_x_mm": c.error[0],
            "error_y_mm": c.error[1],
            "error_phi_deg": c.error[2].to_degrees(),
            "held": c.flags & correction_flags::HELD != 0,
        });
        log_json(&self.correction, &v, c.t_s);
    }

    /// A process's cycle statistics (on `/process/<name>/stats`), at chain time `t_s`.
    pub fn cycle_stats(&mut self, s: &CycleStats<'_>, t_s: f64) -> Result<(), TelemetryError> {
        let ch = match self.stats.get(s.process) {
            Some(ch) => ch,
            None => {
                let ch = json_channel(
                    &self.ctx,
                    &topics::process_stats(s.process),
                    schemas::cycle_stats(),
                )?;
                self.stats.entry(s.process.to_string()).or_insert(ch)
            }
        };
        let h = s.heartbeat;
        let us = |ns: u64| ns as f64 / 1e3;
        let v = json!({
            "process": s.process,
            "pid": h.pid,
            "cycles": h.cycles,
            "deadline_misses": h.deadline_misses,
            "total_deadline_misses": s.total_deadline_misses,
            "stale_inputs": h.stale_inputs,
            "holding": h.holding != 0,
            "restarts": s.restarts,
            "cycle_p50_us": us(h.cycle_ns[0]),
            "cycle_p99_us": us(h.cycle_ns[1]),
            "cycle_max_us": us(h.cycle_ns[2]),
            "wakeup_p50_us": us(h.jitter_ns[0]),
            "wakeup_p99_us": us(h.jitter_ns[1]),
            "wakeup_max_us": us(h.jitter_ns[2]),
        });
        log_json(ch, &v, t_s);
        Ok(())
    }

    /// The log channel, to log lines from anywhere (`foxglove.Log`; it can be sent to other
    /// threads).
    pub fn log_lines(&self) -> LogLines {
        LogLines(self.log.clone())
    }

    /// A run event at chain time `t_s`.
    pub fn event(&self, e: &RunEvent<'_>, t_s: f64) {
        let v = json!({
            "kind": e.kind.as_str(),
            "run_id": e.run_id,
            "process": e.process,
            "text": e.text,
        });
        log_json(&self.events, &v, t_s);
    }
}

/// The log channel of a [`Telemetry`] (`foxglove.Log`).
#[derive(Clone)]
pub struct LogLines(Arc<Channel<Log>>);

impl std::fmt::Debug for LogLines {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogLines").finish_non_exhaustive()
    }
}

/// The level of a log line.
pub use foxglove::messages::log::Level as LogLevel;

impl LogLines {
    /// A line of `name` (the supervisor or a process) at chain time `t_s`.
    pub fn line(&self, level: LogLevel, name: &str, message: &str, t_s: f64) {
        let m = Log {
            timestamp: Some(scene::timestamp(t_s)),
            level: level as i32,
            message: message.into(),
            name: name.into(),
            file: String::new(),
            line: 0,
        };
        self.0.log_with_time(&m, nanos(t_s));
    }
}

fn driver_json(st: &DriverStateMsg) -> Value {
    let f = |bit: u32| st.flags & bit != 0;
    json!({
        "t_s": st.t_s,
        "commanded": st.commanded,
        "reached": st.steps,
        "run_id": st.run_id,
        "seq": st.seq,
        "enabled": f(driver_flags::ENABLED),
        "moving": f(driver_flags::MOVING),
        "limited": f(driver_flags::LIMITED),
        "fault": f(driver_flags::FAULT),
        "stale_hold": f(driver_flags::STALE_HOLD),
        "uncorrected": st.task_flags & task_flags::UNCORRECTED != 0,
    })
}
