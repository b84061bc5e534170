//! The driver step: writes the cycle's joint setpoint to a [`Driver`], reads its state, measures
//! the pose, and holds position when setpoints go stale.

use crate::drive::PoseSensor;
use pcr_driver::{Driver, DriverError, MotorCommand};
use pcr_messages::{driver_flags, DriverStateMsg, JointSetpoint, Stamps, PROTOCOL_VERSION};

/// Cycles without a new setpoint after which the step holds position (stops the motors).
pub const STALE_CYCLES: u32 = 2;

/// The driver step (ros2_control style `write` then `read` each cycle).
#[derive(Debug)]
pub struct DriverStep<D, P> {
    drv: D,
    sensor: P,
    period_s: f64,
    last_sp: Option<JointSetpoint>,
    last_seq: u64,
    reached: Option<[i32; 3]>,
    missed: u32,
    holding: bool,
    cycle: u64,
    stale_cycles: u64,
    /// Capture-frame correction of the measured pose (`[effects.frame]`).
    frame: Option<pcr_robot::effects::FrameCorrection>,
}

impl<D: Driver, P: PoseSensor> DriverStep<D, P> {
    /// A step around `drv` (usually a [`crate::SafeDriver`]) and a pose sensor, for a cycle of
    /// `period_s`.
    pub fn new(drv: D, sensor: P, period_s: f64) -> Self {
        Self {
            drv,
            sensor,
            period_s,
            last_sp: None,
            last_seq: 0,
            reached: None,
            missed: 0,
            holding: false,
            cycle: 0,
            stale_cycles: 0,
            frame: None,
        }
    }

    /// Corrects every measured pose by a capture-frame correction (`[effects.frame]`).
    pub fn set_frame_correction(&mut self, f: Option<pcr_robot::effects::FrameCorrection>) {
        self.frame = f;
    }

    /// The driver.
    pub fn driver(&self) -> &D {
        &self.drv
    }

    /// The driver, mutable.
    pub fn driver_mut(&mut self) -> &mut D {
        &mut self.drv
    }

    /// Whether the step currently holds position because setpoints went stale.
    pub fn holding(&self) -> bool {
        self.holding
    }

    /// Cycles run with a stale or missing setpoint.
    pub fn stale_cycles(&self) -> u64 {
        self.stale_cycles
    }

    /// One cycle at chain time `t_s` with the newest setpoint received since the last cycle
    /// (`None`, or the same seq again, when none arrived). Allocation-free.
    pub fn step(
        &mut self,
        t_s: f64,
        input: Option<&JointSetpoint>,
    ) -> Result<DriverStateMsg, DriverError> {
        self.cycle += 1;
        let fresh = input.filter(|sp| sp.seq != self.last_seq || self.last_sp.is_none());
        match fresh {
            Some(sp) => {
                self.last_sp = Some(*sp);
                self.last_seq = sp.seq;
                self.missed = 0;
                self.holding = false;
            }
            None => {
                self.missed += 1;
                self.stale_cycles += 1;
                if self.missed >= STALE_CYCLES && !self.holding {
                    self.holding = true;
                    tracing::warn!(
                        missed = self.missed,
                        "no setpoint for {STALE_CYCLES} cycles: holding position"
                    );
                }
            }
        }
        let mut stamps = self.last_sp.map(|s| s.stamps).unwrap_or_default();
        let cmd = match (self.holding, self.last_sp, self.reached) {
            // Stale: stop the motors where they are.
            (true, _, Some(r)) => Some(MotorCommand {
                steps: r,
                enable: true,
            }),
            (false, Some(sp), _) => Some(MotorCommand {
                steps: sp.steps,
                enable: sp.enable != 0,
            }),
            _ => None,
        };
        if let Some(c) = &cmd {
            self.drv.write(t_s, self.period_s, c)?;
            if fresh.is_some() {
                stamps.drv_cmd_ns = pcr_messages::monotonic_ns();
            }
        }
        let st = self.drv.read(t_s, self.period_s)?;
        self.reached = Some(st.steps);
        let pose = self.sensor.measure(t_s, &st).map(|p| match &self.frame {
            Some(f) => pcr_kinematics::Pose::from_array(f.apply(p.to_array())),
            None => p,
        });
        let mut flags = 0;
        for (on, bit) in [
            (st.enabled, driver_flags::ENABLED),
            (st.moving, driver_flags::MOVING),
            (st.limited, driver_flags::LIMITED),
            (st.fault, driver_flags::FAULT),
            (self.holding, driver_flags::STALE_HOLD),
            (pose.is_some(), driver_flags::POSE_VALID),
        ] {
            if on {
                flags |= bit;
            }
        }
        let sp = self.last_sp.unwrap_or_default();
        Ok(DriverStateMsg {
            t_s,
            commanded: cmd.map_or(st.steps, |c| c.steps),
            flags,
            steps: st.steps,
            run_id: sp.run_id,
            measured: pose.map_or([0.0; 3], |p| p.to_array()),
            planned: sp.planned,
            seq: sp.seq,
            cycle: self.cycle,
            task_flags: if fresh.is_some() { sp.flags } else { 0 },
            version: PROTOCOL_VERSION,
            stamps: if fresh.is_some() {
                stamps
            } else {
                Stamps::default()
            },
        })
    }
}
