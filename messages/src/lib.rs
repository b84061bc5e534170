//! Message types and service names of the process chain (one place for both).
//!
//! Every message is `#[repr(C)]`, self-contained (no pointers) and derives iceoryx2's
//! [`ZeroCopySend`] with an explicit, versioned `type_name`, so that the same struct travels
//! through shared memory between the process binaries and is passed by value inside the
//! in-process runtime.
//!
//! Units: millimetres, radians inside messages (degrees only in files and logs), seconds for
//! the chain's clock (`t_s`), nanoseconds of `CLOCK_MONOTONIC` for latency stamps (`*_ns`),
//! motor steps as signed integers, curvatures in 1/mm.
//!
//! Versioning: [`PROTOCOL_VERSION`] is part of every service name ([`service_name`]) and of every
//! message, and a process announces it on the unversioned [`PROTOCOL_SERVICE`] with
//! [`ProtocolHello`] (a type that must never change). A process that hears a different version
//! there exits with [`version_mismatch_message`]; the supervisor also refuses heartbeats that
//! carry a different version.

use iceoryx2::prelude::ZeroCopySend;

/// Version of the chain's protocol (message layouts and service names). Bump on any change.
pub const PROTOCOL_VERSION: u32 = 4;

/// The unversioned service on which every process announces its protocol version.
pub const PROTOCOL_SERVICE: &str = "pcr/protocol";

/// Base names of the versioned services (see [`service_name`]).
pub mod services {
    /// Interpolator -> IK: [`crate::TaskSetpoint`] (publish-subscribe + event of the same name).
    pub const TASK_SETPOINT: &str = "task_setpoint";
    /// IK -> driver: [`crate::JointSetpoint`].
    pub const JOINT_SETPOINT: &str = "joint_setpoint";
    /// Driver -> recorder, correction: [`crate::DriverStateMsg`].
    pub const DRIVER_STATE: &str = "driver_state";
    /// Pose sensor / mocap -> correction, recorder: [`crate::MeasuredPose`].
    pub const MEASURED_POSE: &str = "measured_pose";
    /// Correction -> interpolator: [`crate::Correction`].
    pub const CORRECTION: &str = "correction";
    /// Every process -> supervisor: [`crate::Heartbeat`].
    pub const HEARTBEAT: &str = "heartbeat";
    /// Motion-capture bridge (`pcr-qtm`) -> correction, recorder: [`crate::MocapSample`]
    /// (publish-subscribe + event of the same name).
    pub const MOCAP: &str = "mocap";
    /// Supervisor -> interpolator: [`crate::Command`].
    pub const COMMAND: &str = "command";
    /// Interpolator -> supervisor: [`crate::PlannerStatus`].
    pub const STATUS: &str = "status";
    /// Interpolator -> supervisor: [`crate::Refusal`], why a command was refused.
    pub const REFUSAL: &str = "refusal";
}

/// The full, versioned iceoryx2 service name of a base name: `pcr/v{PROTOCOL_VERSION}/{base}`.
pub fn service_name(base: &str) -> String {
    service_name_for(PROTOCOL_VERSION, base)
}

/// The service name of `base` under protocol `version`.
pub fn service_name_for(version: u32, base: &str) -> String {
    format!("pcr/v{version}/{base}")
}

/// The error text a process prints (and exits with) when it meets another protocol version.
pub fn version_mismatch_message(mine: u32, theirs: u32, who: &str) -> String {
    format!(
        "protocol version mismatch: this binary speaks pcr protocol v{mine}, but {who} speaks \
         v{theirs}; refusing to connect (rebuild all chain binaries from one revision)"
    )
}

/// Monotonic clock (CLOCK_MONOTONIC) in nanoseconds: the time base of the latency stamps, the
/// same in every process of the machine.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc_timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes into the struct we pass; CLOCK_MONOTONIC always exists.
    unsafe { clock_gettime(CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

#[repr(C)]
struct libc_timespec {
    tv_sec: i64,
    tv_nsec: i64,
}
const CLOCK_MONOTONIC: i32 = 1;
extern "C" {
    fn clock_gettime(clk: i32, ts: *mut libc_timespec) -> i32;
}

/// Which process sent a heartbeat or hello.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NodeKind {
    /// The 20 ms interpolator (`pcr-planner`).
    Planner = 1,
    /// The IK step (`pcr-ik`).
    Ik = 2,
    /// The driver (`pcr-driver`).
    Driver = 3,
    /// The mocap / correction step (`pcr-mocap`).
    Mocap = 4,
    /// The supervisor.
    Supervisor = 5,
    /// A test or benchmark client.
    Tool = 6,
    /// The motion-capture bridge (`pcr-qtm`).
    Qtm = 7,
}

impl NodeKind {
    /// From the wire value.
    pub fn from_u32(v: u32) -> Option<NodeKind> {
        Some(match v {
            1 => NodeKind::Planner,
            2 => NodeKind::Ik,
            3 => NodeKind::Driver,
            4 => NodeKind::Mocap,
            5 => NodeKind::Supervisor,
            6 => NodeKind::Tool,
            7 => NodeKind::Qtm,
            _ => return None,
        })
    }
    /// Short name (`planner`, `ik`, `driver`, `mocap`, `supervisor`, `tool`, `qtm`).
    pub fn name(self) -> &'static str {
        match self {
            NodeKind::Planner => "planner",
            NodeKind::Ik => "ik",
            NodeKind::Driver => "driver",
            NodeKind::Mocap => "mocap",
            NodeKind::Supervisor => "supervisor",
            NodeKind::Tool => "tool",
            NodeKind::Qtm => "qtm",
        }
    }
}

/// Protocol announcement on [`PROTOCOL_SERVICE`]. Its layout must never change.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("pcr::ProtocolHello")]
pub struct ProtocolHello {
    /// The sender's [`PROTOCOL_VERSION`].
    pub version: u32,
    /// The sender's [`NodeKind`] as u32.
    pub kind: u32,
    /// The sender's process id.
    pub pid: u32,
    /// Reserved, 0.
    pub reserved: u32,
}

/// Latency stamps carried along the chain (CLOCK_MONOTONIC ns; 0 = not stamped).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("pcr::v1::Stamps")]
pub struct Stamps {
    /// The interpolator published the task setpoint.
    pub interp_pub_ns: u64,
    /// The IK process received it.
    pub ik_rx_ns: u64,
    /// The IK process published the joint setpoint.
    pub ik_pub_ns: u64,
    /// The driver process received the joint setpoint.
    pub drv_rx_ns: u64,
    /// The driver wrote the command to the drive.
    pub drv_cmd_ns: u64,
}

/// Bits of [`TaskSetpoint::flags`].
pub mod task_flags {
    /// A program is running (the setpoint moves or is part of a motion).
    pub const ACTIVE: u32 = 1;
    /// The program is paused (the setpoint holds).
    pub const PAUSED: u32 = 2;
    /// This is the last setpoint of the program.
    pub const DONE: u32 = 4;
    /// The motion-capture correction is held (no fresh measurement): the setpoint carries the
    /// last offset, not a corrected one.
    pub const UNCORRECTED: u32 = 8;
}

/// Interpolator output: the task-space setpoint of one cycle.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pcr::v1::TaskSetpoint")]
pub struct TaskSetpoint {
    /// Chain time of the setpoint, s.
    pub t_s: f64,
    /// Platform x, mm.
    pub x_mm: f64,
    /// Platform y, mm.
    pub y_mm: f64,
    /// Platform orientation, rad.
    pub phi_rad: f64,
    /// The planned pose before the motion-capture correction (x mm, y mm, phi rad): what the
    /// path accuracy is measured against. Equal to the commanded pose without correction.
    pub nominal: [f64; 3],
    /// Cycle counter of the interpolator (strictly increasing).
    pub seq: u64,
    /// Program run id (0 = none).
    pub run_id: u32,
    /// [`task_flags`].
    pub flags: u32,
    /// Latency stamps.
    pub stamps: Stamps,
    /// [`PROTOCOL_VERSION`] of the sender.
    pub version: u32,
    /// Reserved, 0.
    pub reserved: u32,
}

/// IK output: the joint-space setpoint of one cycle.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pcr::v1::JointSetpoint")]
pub struct JointSetpoint {
    /// Chain time (of the task setpoint), s.
    pub t_s: f64,
    /// Motor positions to reach, steps.
    pub steps: [i32; 3],
    /// 1 = coils enabled.
    pub enable: u32,
    /// Curvatures, 1/mm.
    pub kappa: [f64; 3],
    /// The task setpoint this came from (planned pose for the recorder): x mm, y mm, phi rad.
    pub planned: [f64; 3],
    /// Seq of the task setpoint.
    pub seq: u64,
    /// Program run id.
    pub run_id: u32,
    /// [`task_flags`] of the task setpoint.
    pub flags: u32,
    /// 1 when IK failed and this repeats the last valid setpoint.
    pub ik_failed: u32,
    /// [`PROTOCOL_VERSION`] of the sender.
    pub version: u32,
    /// Latency stamps.
    pub stamps: Stamps,
}

/// Bits of [`DriverStateMsg::flags`].
pub mod driver_flags {
    /// Coils energised.
    pub const ENABLED: u32 = 1;
    /// Still moving to the setpoint.
    pub const MOVING: u32 = 2;
    /// The setpoint was limited (rate or range).
    pub const LIMITED: u32 = 4;
    /// The drive is in fault and holds.
    pub const FAULT: u32 = 8;
    /// Setpoints are stale (none for two cycles): holding position, motors stopped.
    pub const STALE_HOLD: u32 = 16;
    /// The measured pose fields are valid.
    pub const POSE_VALID: u32 = 32;
}

/// Driver output: what was commanded and reached this cycle, plus the measured pose when the
/// backend has a pose sensor.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pcr::v1::DriverState")]
pub struct DriverStateMsg {
    /// Chain time of the cycle, s.
    pub t_s: f64,
    /// Motor positions commanded to the drive, steps.
    pub commanded: [i32; 3],
    /// [`driver_flags`].
    pub flags: u32,
    /// Motor positions reached, steps.
    pub steps: [i32; 3],
    /// Program run id of the setpoint.
    pub run_id: u32,
    /// Measured platform pose: x mm, y mm, phi rad (valid if [`driver_flags::POSE_VALID`]).
    pub measured: [f64; 3],
    /// Planned pose of the setpoint executed: x mm, y mm, phi rad.
    pub planned: [f64; 3],
    /// Seq of the setpoint executed.
    pub seq: u64,
    /// Driver cycle counter.
    pub cycle: u64,
    /// [`task_flags`] of the setpoint executed.
    pub task_flags: u32,
    /// [`PROTOCOL_VERSION`] of the sender.
    pub version: u32,
    /// Latency stamps.
    pub stamps: Stamps,
}

/// A measured platform pose (pose sensor or motion capture).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pcr::v1::MeasuredPose")]
pub struct MeasuredPose {
    /// Chain time of the measurement, s.
    pub t_s: f64,
    /// x mm, y mm, phi rad.
    pub pose: [f64; 3],
    /// Seq of the driver cycle it belongs to.
    pub seq: u64,
    /// 1 = valid.
    pub valid: u32,
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
}

/// Bits of [`Correction::flags`].
pub mod correction_flags {
    /// No fresh measurement (the capture data stopped or went stale): the offset is held and
    /// not integrated; setpoints are flagged [`crate::task_flags::UNCORRECTED`].
    pub const HELD: u32 = 1;
}

/// Task-space correction added to the interpolator's setpoint (outer loop).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pcr::v3::Correction")]
pub struct Correction {
    /// Chain time, s.
    pub t_s: f64,
    /// Offset x mm, y mm, phi rad.
    pub offset: [f64; 3],
    /// Last tracking error (measured - planned): x mm, y mm, phi rad.
    pub error: [f64; 3],
    /// Seq of the measurement.
    pub seq: u64,
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
    /// [`correction_flags`].
    pub flags: u32,
}

/// Bits of [`MocapSample::valid`]: which fields were measured in this frame.
pub mod mocap_valid {
    /// The platform pose.
    pub const POSE: u32 = 1;
    /// Base marker B_i: `BASE << i`.
    pub const BASE: u32 = 2;
    /// Joint marker M_i: `JOINT << i`.
    pub const JOINT: u32 = 16;
    /// The bridge is connected and streaming (0 in a sample announcing a lost link).
    pub const LINK: u32 = 128;
}

/// One motion-capture frame in the robot base frame, published by the bridge (`pcr-qtm`) at
/// the capture rate.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pcr::v3::MocapSample")]
pub struct MocapSample {
    /// Chain time of the capture (QTM's timestamp mapped onto CLOCK_MONOTONIC), s.
    pub t_s: f64,
    /// CLOCK_MONOTONIC ns of the socket read that delivered the frame.
    pub rx_ns: u64,
    /// CLOCK_MONOTONIC ns of the publication.
    pub pub_ns: u64,
    /// QTM's timestamp, microseconds since its capture started.
    pub qtm_timestamp_us: u64,
    /// Sample counter of the bridge (strictly increasing).
    pub seq: u64,
    /// QTM's frame number.
    pub frame_number: u32,
    /// [`mocap_valid`] bits.
    pub valid: u32,
    /// Platform pose: x mm, y mm, phi rad.
    pub pose: [f64; 3],
    /// Base markers B_1..B_3: x, y, z mm.
    pub base: [[f64; 3]; 3],
    /// Joint markers M_1..M_3: x, y, z mm.
    pub joints: [[f64; 3]; 3],
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
    /// Reserved, 0.
    pub reserved: u32,
}

impl MocapSample {
    /// The platform pose, if measured.
    pub fn pose(&self) -> Option<[f64; 3]> {
        (self.valid & mocap_valid::POSE != 0).then_some(self.pose)
    }
    /// Joint marker M_i (0-based), if measured.
    pub fn joint(&self, i: usize) -> Option<[f64; 3]> {
        (i < 3 && self.valid & (mocap_valid::JOINT << i) != 0).then(|| self.joints[i])
    }
    /// Base marker B_i (0-based), if measured.
    pub fn base_point(&self, i: usize) -> Option<[f64; 3]> {
        (i < 3 && self.valid & (mocap_valid::BASE << i) != 0).then(|| self.base[i])
    }
}

/// Cycle statistics and liveness of one process, published every heartbeat period.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("pcr::v1::Heartbeat")]
pub struct Heartbeat {
    /// [`PROTOCOL_VERSION`] of the sender.
    pub version: u32,
    /// [`NodeKind`] as u32.
    pub kind: u32,
    /// Process id.
    pub pid: u32,
    /// 1 = the process is in a safe hold (stale input, fault).
    pub holding: u32,
    /// Heartbeat counter.
    pub seq: u64,
    /// Cycles run.
    pub cycles: u64,
    /// Cycles whose work exceeded the period (or, for periodic steps, woke later than a period).
    pub deadline_misses: u64,
    /// Cycles with stale or missing input.
    pub stale_inputs: u64,
    /// Cycle (work) time percentiles, ns: p50, p99, max.
    pub cycle_ns: [u64; 3],
    /// Wake-up latency percentiles (actual wake - release of the cycle), ns: p50, p99, max.
    pub jitter_ns: [u64; 3],
}

/// Kinds of [`Command`].
pub mod command_kind {
    /// Run the program in [`crate::Command::moves`] / [`crate::Command::program`].
    pub const RUN: u32 = 1;
    /// Pause (hold the setpoint, keep the program).
    pub const PAUSE: u32 = 2;
    /// Resume after a pause.
    pub const RESUME: u32 = 3;
    /// Stop (brake along the path, then drop the program).
    pub const STOP: u32 = 4;
    /// Re-plan run `run_id`'s program (same program fields as RUN) from
    /// [`crate::Command::origin`] and continue it, paused, at the program time near
    /// [`crate::Command::resume_s`] whose planned pose is [`crate::Command::executed`] (after a
    /// planner restart; a RESUME then continues the motion).
    pub const RECOVER: u32 = 5;
}

/// Built-in programs of [`Command::program`].
pub mod program_id {
    /// The moves listed in the command.
    pub const MOVES: u32 = 0;
    /// The paper's circle (r = 50 mm at 50 mm/s) then square (50 mm side, rest-to-rest).
    pub const PAPER: u32 = 1;
    /// The paper's circle only.
    pub const CIRCLE: u32 = 2;
    /// The paper's square only.
    pub const SQUARE: u32 = 3;
}

/// Maximum number of moves in one [`Command`].
pub const MAX_MOVES: usize = 32;

/// Kinds of [`MoveMsg`].
pub mod move_kind {
    /// Straight line to `a` (x, y mm, phi rad), rest to rest, mean speed `b[0]` mm/s.
    pub const LINE: u32 = 1;
    /// Full circle of centre (a[0], a[1]) mm, radius b[0] mm at b[1] mm/s, phi a[2].
    pub const CIRCLE: u32 = 2;
    /// Dwell b[0] s.
    pub const DWELL: u32 = 3;
    /// Line segment of a composite path (no stop at its end if the next move continues it):
    /// to (a[0], a[1]) mm, orientation a[2] rad (kept if [`crate::move_flags::KEEP_PHI`]), own
    /// speed limit b[0] mm/s (0: the program's), blend radius of the corner at its end b[1] mm
    /// (< 0: the program's). Limits in [`crate::Command::limits`].
    pub const PATH_LINE: u32 = 4;
    /// Arc segment of a composite path: centre (a[0], a[1]) mm, end orientation a[2] rad (kept if
    /// [`crate::move_flags::KEEP_PHI`]), own speed limit b[0] mm/s (0: the program's), signed
    /// sweep b[1] rad (positive: counter-clockwise); the radius is the distance from the current
    /// point.
    pub const ARC: u32 = 5;
    /// Synchronised joint move of the motors to the steps (a[0], a[1], a[2]) (integers), from
    /// rest to rest, with the joint limits of [`crate::Command::limits`].
    pub const JOINT: u32 = 6;
}

/// Bits of [`MoveMsg::flags`].
pub mod move_flags {
    /// A [`crate::move_kind::PATH_LINE`] or [`crate::move_kind::ARC`] that continues the
    /// previous line or arc without stopping (one composite motion: continuous speed through
    /// tangent junctions, corners rounded by the blend radius).
    pub const CONTINUES: u32 = 1;
    /// Keep the orientation (a[2] is ignored): the end orientation of the previous segment.
    pub const KEEP_PHI: u32 = 2;
}

/// Limits of the composite paths and joint moves of a [`Command`] (ignored by the rest-to-rest
/// LINE, CIRCLE and DWELL moves).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pcr::v2::ProgramLimits")]
pub struct ProgramLimits {
    /// Path speed, mm/s (combined metric).
    pub speed_mm_s: f64,
    /// Path acceleration (tangential and centripetal), mm/s^2.
    pub accel_mm_s2: f64,
    /// Path jerk, mm/s^3.
    pub jerk_mm_s3: f64,
    /// Default corner blend radius, mm (0: stop at corners).
    pub blend_radius_mm: f64,
    /// Rotation radius of the combined metric, mm/rad.
    pub rotation_radius_mm: f64,
    /// Joint moves: motor acceleration, steps/s^2.
    pub joint_accel: f64,
    /// Joint moves: motor jerk, steps/s^3.
    pub joint_jerk: f64,
}

/// One move of a program on the wire.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pcr::v1::Move")]
pub struct MoveMsg {
    /// [`move_kind`].
    pub kind: u32,
    /// [`move_flags`].
    pub flags: u32,
    /// First argument triple (see [`move_kind`]).
    pub a: [f64; 3],
    /// Second argument pair.
    pub b: [f64; 2],
}

/// Supervisor -> interpolator command.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pcr::v1::Command")]
pub struct Command {
    /// [`command_kind`].
    pub kind: u32,
    /// [`program_id`] for RUN.
    pub program: u32,
    /// Run id assigned by the supervisor (echoed in setpoints and status).
    pub run_id: u32,
    /// Number of valid entries in `moves`.
    pub n_moves: u32,
    /// RECOVER: the pose the program was first planned from (x mm, y mm, phi rad).
    pub origin: [f64; 3],
    /// RECOVER: the planned pose of the last setpoint the drive executed.
    pub executed: [f64; 3],
    /// RECOVER: the program time last reported for the run, s (a hint).
    pub resume_s: f64,
    /// The moves for [`program_id::MOVES`].
    pub moves: [MoveMsg; MAX_MOVES],
    /// Limits of the composite paths and joint moves among `moves`.
    pub limits: ProgramLimits,
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
    /// Reserved.
    pub reserved: u32,
}

/// States of [`PlannerStatus::state`].
pub mod planner_state {
    /// No program.
    pub const IDLE: u32 = 0;
    /// Running a program.
    pub const RUNNING: u32 = 1;
    /// Paused.
    pub const PAUSED: u32 = 2;
    /// The program finished.
    pub const DONE: u32 = 3;
    /// Stopped by command.
    pub const STOPPED: u32 = 4;
    /// The command was refused (bad program).
    pub const REFUSED: u32 = 5;
    /// The program of a RUN command is being planned and checked (off the cycle).
    pub const PLANNING: u32 = 6;
}

/// Interpolator -> supervisor status (every cycle's state change and every heartbeat).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("pcr::v1::PlannerStatus")]
pub struct PlannerStatus {
    /// Chain time, s.
    pub t_s: f64,
    /// Program time elapsed, s.
    pub progress_s: f64,
    /// Program duration, s.
    pub duration_s: f64,
    /// The pose the running program was planned from (x mm, y mm, phi rad).
    pub origin: [f64; 3],
    /// Run id.
    pub run_id: u32,
    /// [`planner_state`].
    pub state: u32,
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
    /// Reserved.
    pub reserved: u32,
}

/// Bytes of a [`Refusal`]'s reason.
pub const REFUSAL_TEXT_LEN: usize = 240;

/// Interpolator -> supervisor: why the command of run `run_id` was refused (UTF-8 text, cut at
/// a character boundary to [`REFUSAL_TEXT_LEN`] bytes), sent once when it is refused.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("pcr::v1::Refusal")]
pub struct Refusal {
    /// Chain time of the refusal, s.
    pub t_s: f64,
    /// Run id of the refused command.
    pub run_id: u32,
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
    /// Bytes of `text` used.
    pub len: u32,
    /// Reserved, 0.
    pub reserved: u32,
    /// The reason, UTF-8.
    pub text: [u8; REFUSAL_TEXT_LEN],
}

impl Default for Refusal {
    fn default() -> Self {
        Refusal {
            t_s: 0.0,
            run_id: 0,
            version: PROTOCOL_VERSION,
            len: 0,
            reserved: 0,
            text: [0; REFUSAL_TEXT_LEN],
        }
    }
}

impl Refusal {
    /// The refusal of run `run_id` for `reason` (cut at a character boundary if too long).
    pub fn new(t_s: f64, run_id: u32, reason: &str) -> Refusal {
        let mut n = reason.len().min(REFUSAL_TEXT_LEN);
        while !reason.is_char_boundary(n) {
            n -= 1;
        }
        let mut r = Refusal {
            t_s,
            run_id,
            len: n as u32,
            ..Refusal::default()
        };
        r.text[..n].copy_from_slice(&reason.as_bytes()[..n]);
        r
    }

    /// The reason (empty if the bytes are not valid UTF-8 or the length is out of range).
    pub fn reason(&self) -> &str {
        self.text
            .get(..self.len as usize)
            .and_then(|b| std::str::from_utf8(b).ok())
            .unwrap_or("")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn service_names_carry_the_version() {
        assert_eq!(
            service_name(services::HEARTBEAT),
            format!("pcr/v{PROTOCOL_VERSION}/heartbeat")
        );
        assert_ne!(
            service_name_for(PROTOCOL_VERSION + 1, services::TASK_SETPOINT),
            service_name(services::TASK_SETPOINT)
        );
    }

    #[test]
    fn a_refusal_carries_its_reason_cut_at_a_character_boundary() {
        let r = Refusal::new(1.0, 7, "leg 1: pose unreachable");
        assert_eq!((r.run_id, r.reason()), (7, "leg 1: pose unreachable"));
        let long = "\u{e9}".repeat(REFUSAL_TEXT_LEN);
        let r = Refusal::new(0.0, 1, &long);
        assert!(r.reason().len() <= REFUSAL_TEXT_LEN && !r.reason().is_empty());
        assert!(r.reason().chars().all(|c| c == '\u{e9}'));
    }

    #[test]
    fn monotonic_clock_advances() {
        let a = monotonic_ns();
        let b = monotonic_ns();
        assert!(b >= a && a > 0);
    }

    #[test]
    fn hello_layout_is_frozen() {
        assert_eq!(std::mem::size_of::<ProtocolHello>(), 16);
    }

    #[test]
    fn mismatch_message_names_both_versions() {
        let m = version_mismatch_message(1, 2, "pcr-driver");
        assert!(m.contains("v1") && m.contains("v2") && m.contains("mismatch"));
    }
}
