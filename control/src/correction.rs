//! The correction step (outer loop on the measured pose). PLACEHOLDER until the mocap bridge
//! exists: it computes the tracking error and, with the default gain 0, a zero offset (pure
//! pass-through); a small integral gain closes the loop in task space.

use pcr_messages::{Correction, DriverStateMsg, MeasuredPose, PROTOCOL_VERSION};

/// Integral task-space correction; `gain = 0` is a pass-through.
#[derive(Debug, Clone)]
pub struct CorrectionStep {
    gain: f64,
    limit_mm: f64,
    offset: [f64; 3],
}

impl CorrectionStep {
    /// A correction with integral gain `gain` (per cycle, 0..1) and an offset bound of
    /// `limit_mm` (mm; rad x 100 for the orientation).
    pub fn new(gain: f64, limit_mm: f64) -> Self {
        Self {
            gain,
            limit_mm,
            offset: [0.0; 3],
        }
    }

    /// The pass-through placeholder.
    pub fn pass_through() -> Self {
        Self::new(0.0, 0.0)
    }

    /// One cycle: a measurement and the planned pose it belongs to. Allocation-free.
    pub fn step(&mut self, m: &MeasuredPose, planned: &[f64; 3]) -> Correction {
        let mut error = [0.0; 3];
        if m.valid != 0 {
            for k in 0..3 {
                error[k] = m.pose[k] - planned[k];
                let lim = if k == 2 {
                    self.limit_mm / 100.0
                } else {
                    self.limit_mm
                };
                self.offset[k] = (self.offset[k] - self.gain * error[k]).clamp(-lim, lim);
            }
        }
        Correction {
            t_s: m.t_s,
            offset: self.offset,
            error,
            seq: m.seq,
            version: PROTOCOL_VERSION,
            reserved: 0,
        }
    }
}

/// The measured pose carried by a driver-state message.
pub fn measured_of(s: &DriverStateMsg) -> MeasuredPose {
    MeasuredPose {
        t_s: s.t_s,
        pose: s.measured,
        seq: s.seq,
        valid: u32::from(s.flags & pcr_messages::driver_flags::POSE_VALID != 0),
        version: PROTOCOL_VERSION,
    }
}
