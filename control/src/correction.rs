//! The correction step: the outer loop on the measured pose (motion capture).
//!
//! The pose measured at chain time `t` shows the robot as it was `latency_s` earlier (capture
//! and transport latency). The step keeps the recent planned (nominal) poses, compares the
//! measurement with the pose planned at the measurement's own time, and integrates that error
//! into a task-space offset that the interpolator adds to later setpoints:
//! `offset <- clamp(offset - gain * (measured - planned(t - latency)))`. With `gain = 0` it is a
//! pass-through that still reports the tracking error. What it can remove is the slowly varying
//! error between model and robot (geometry, tendon map, creep); what it cannot remove is what
//! changes faster than a few cycles (backlash reversals, friction jumps, capture noise).

use pcr_messages::{correction_flags, Correction, DriverStateMsg, MeasuredPose, PROTOCOL_VERSION};

/// Planned poses remembered for matching a delayed measurement (64 cycles = 1.28 s at 20 ms).
const HISTORY: usize = 64;

/// Settings of the correction step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CorrectionConfig {
    /// Integral gain per cycle, 0..=1 (0 = pass-through).
    pub gain: f64,
    /// Bound of the offset, mm (the orientation offset is bounded by `limit_mm / 100` rad).
    pub limit_mm: f64,
    /// Age of a measurement when it is reported, s (the capture system's latency).
    pub latency_s: f64,
}

impl Default for CorrectionConfig {
    fn default() -> Self {
        Self {
            gain: 0.0,
            limit_mm: 5.0,
            latency_s: 0.0,
        }
    }
}

/// Invalid correction settings.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("correction setting {key} = {value} is out of range ({range})")]
pub struct CorrectionConfigError {
    /// The setting.
    pub key: &'static str,
    /// Its value.
    pub value: f64,
    /// What is allowed.
    pub range: &'static str,
}

impl CorrectionConfig {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), CorrectionConfigError> {
        let bad = |key, value, range| Err(CorrectionConfigError { key, value, range });
        if !(0.0..=1.0).contains(&self.gain) {
            return bad("gain", self.gain, "0..=1 per cycle");
        }
        if !(self.limit_mm.is_finite() && self.limit_mm >= 0.0) {
            return bad("limit_mm", self.limit_mm, ">= 0");
        }
        if !(0.0..=1.0).contains(&self.latency_s) {
            return bad("latency_s", self.latency_s, "0..=1 s");
        }
        Ok(())
    }
}

/// Integral task-space correction from measured poses.
#[derive(Debug, Clone)]
pub struct CorrectionStep {
    cfg: CorrectionConfig,
    offset: [f64; 3],
    /// (chain time s, planned pose) ring, newest at `head - 1`.
    history: [(f64, [f64; 3]); HISTORY],
    head: usize,
    len: usize,
}

impl CorrectionStep {
    /// A correction with the given settings (see [`CorrectionConfig::validate`]; values out of
    /// range are clamped).
    pub fn new(cfg: CorrectionConfig) -> Self {
        let cfg = CorrectionConfig {
            gain: cfg.gain.clamp(0.0, 1.0),
            limit_mm: cfg.limit_mm.max(0.0),
            latency_s: cfg.latency_s.clamp(0.0, 1.0),
        };
        Self {
            cfg,
            offset: [0.0; 3],
            history: [(0.0, [0.0; 3]); HISTORY],
            head: 0,
            len: 0,
        }
    }

    /// The pass-through (gain 0): reports the error, corrects nothing.
    pub fn pass_through() -> Self {
        Self::new(CorrectionConfig::default())
    }

    /// The settings.
    pub fn config(&self) -> &CorrectionConfig {
        &self.cfg
    }

    /// The current offset (x mm, y mm, phi rad).
    pub fn offset(&self) -> [f64; 3] {
        self.offset
    }

    /// The planned pose at chain time `t` (linear between remembered cycles); `None` outside
    /// the remembered span.
    fn planned_at(&self, t: f64) -> Option<[f64; 3]> {
        let at = |k: usize| self.history[(self.head + HISTORY - 1 - k) % HISTORY];
        let newest = at(0);
        if self.len == 0 || t > newest.0 + 1e-9 {
            return None;
        }
        for k in 0..self.len {
            let (t0, p0) = at(k);
            if t0 <= t + 1e-9 {
                if k == 0 {
                    return Some(p0);
                }
                let (t1, p1) = at(k - 1);
                let u = if t1 > t0 { (t - t0) / (t1 - t0) } else { 1.0 };
                return Some(std::array::from_fn(|i| p0[i] + (p1[i] - p0[i]) * u));
            }
        }
        None
    }

    /// Remembers the planned (nominal) pose of the setpoint executed at chain time `t_s`.
    pub fn observe(&mut self, t_s: f64, planned: &[f64; 3]) {
        self.history[self.head] = (t_s, *planned);
        self.head = (self.head + 1) % HISTORY;
        self.len = (self.len + 1).min(HISTORY);
    }

    /// Integrates one measurement against the pose planned at its own time (less the
    /// latency). An invalid measurement (not seen in this frame) changes nothing.
    /// Allocation-free.
    pub fn measure(&mut self, m: &MeasuredPose) -> Correction {
        let mut error = [0.0; 3];
        let reference = self.planned_at(m.t_s - self.cfg.latency_s);
        if let (true, Some(reference)) = (m.valid != 0, reference) {
            for k in 0..3 {
                error[k] = m.pose[k] - reference[k];
                let lim = if k == 2 {
                    self.cfg.limit_mm / 100.0
                } else {
                    self.cfg.limit_mm
                };
                self.offset[k] = (self.offset[k] - self.cfg.gain * error[k]).clamp(-lim, lim);
            }
        }
        Correction {
            t_s: m.t_s,
            offset: self.offset,
            error,
            seq: m.seq,
            version: PROTOCOL_VERSION,
            flags: 0,
        }
    }

    /// No fresh measurement: the offset is held (not integrated) and the correction says so
    /// ([`correction_flags::HELD`]).
    pub fn hold(&self, t_s: f64, seq: u64) -> Correction {
        Correction {
            t_s,
            offset: self.offset,
            error: [0.0; 3],
            seq,
            version: PROTOCOL_VERSION,
            flags: correction_flags::HELD,
        }
    }

    /// One cycle: the measurement reported in this cycle and the planned (nominal) pose of the
    /// setpoint executed in this cycle at chain time `t_s`. Allocation-free.
    pub fn step(&mut self, m: &MeasuredPose, t_s: f64, planned: &[f64; 3]) -> Correction {
        self.observe(t_s, planned);
        self.measure(m)
    }

    /// One cycle from a driver state (its measured pose and the planned pose it executed).
    pub fn step_state(&mut self, s: &DriverStateMsg) -> Correction {
        self.step(&measured_of(s), s.t_s, &s.planned)
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

#[cfg(test)]
mod tests {
    use super::*;

    fn meas(t_s: f64, pose: [f64; 3]) -> MeasuredPose {
        MeasuredPose {
            t_s,
            pose,
            seq: 0,
            valid: 1,
            version: PROTOCOL_VERSION,
        }
    }

    #[test]
    fn a_delayed_measurement_is_compared_with_the_pose_planned_at_its_time() {
        // moving at 50 mm/s in x, measured exactly but 30 ms late: no error to correct
        let mut c = CorrectionStep::new(CorrectionConfig {
            gain: 0.5,
            limit_mm: 5.0,
            latency_s: 0.03,
        });
        for k in 0..50 {
            let t = k as f64 * 0.02;
            let x = |t: f64| 50.0 * t;
            let out = c.step(&meas(t, [x(t - 0.03), 0.0, 0.0]), t, &[x(t), 0.0, 0.0]);
            if k > 2 {
                assert!(out.error[0].abs() < 1e-9, "{k}: {:?}", out.error);
            }
        }
        assert!(c.offset()[0].abs() < 1e-6);
        // without the latency the same data looks like a lag of 1.5 mm
        let mut naive = CorrectionStep::new(CorrectionConfig {
            latency_s: 0.0,
            ..*c.config()
        });
        let out = naive.step(&meas(1.0, [50.0 * 0.97, 0.0, 0.0]), 1.0, &[50.0, 0.0, 0.0]);
        assert!((out.error[0] + 1.5).abs() < 1e-9);
    }

    #[test]
    fn a_constant_model_error_is_integrated_away_within_the_bound() {
        // the robot lands 1.2 mm to the right and 0.01 rad off of what is commanded
        let mut c = CorrectionStep::new(CorrectionConfig {
            gain: 0.3,
            limit_mm: 5.0,
            latency_s: 0.0,
        });
        let mut offset = [0.0; 3];
        for k in 0..60 {
            let t = k as f64 * 0.02;
            let planned = [10.0, 5.0, 0.1];
            let measured = [
                planned[0] + offset[0] + 1.2,
                planned[1] + offset[1],
                planned[2] + offset[2] + 0.01,
            ];
            offset = c.step(&meas(t, measured), t, &planned).offset;
        }
        assert!((offset[0] + 1.2).abs() < 1e-6, "{offset:?}");
        assert!(offset[1].abs() < 1e-12 && (offset[2] + 0.01).abs() < 1e-6);
        // a larger error saturates at the bound
        let mut c = CorrectionStep::new(CorrectionConfig {
            gain: 1.0,
            limit_mm: 2.0,
            latency_s: 0.0,
        });
        let o = c.step(&meas(0.0, [9.0, 0.0, 0.0]), 0.0, &[0.0; 3]).offset;
        assert_eq!(o[0], -2.0);
    }

    #[test]
    fn a_held_correction_keeps_the_offset_and_says_so() {
        let mut c = CorrectionStep::new(CorrectionConfig {
            gain: 0.5,
            ..Default::default()
        });
        let o = c.step(&meas(0.0, [2.0, 0.0, 0.0]), 0.0, &[0.0; 3]).offset;
        let h = c.hold(0.02, 7);
        assert_eq!((h.offset, h.flags), (o, correction_flags::HELD));
        assert_eq!(c.offset(), o);
        // measurements resume: integration goes on from the held offset
        c.observe(0.04, &[0.0; 3]);
        let r = c.measure(&meas(0.04, [1.0 + o[0], 0.0, 0.0]));
        assert_eq!(r.flags, 0);
        assert!((r.offset[0] - (o[0] - 0.5 * (1.0 + o[0]))).abs() < 1e-12);
    }

    #[test]
    fn pass_through_and_invalid_measurements_change_nothing() {
        let mut c = CorrectionStep::pass_through();
        let out = c.step(&meas(0.0, [3.0, 0.0, 0.0]), 0.0, &[0.0; 3]);
        assert_eq!((out.offset, out.error[0]), ([0.0; 3], 3.0));
        let mut c = CorrectionStep::new(CorrectionConfig {
            gain: 0.5,
            ..Default::default()
        });
        let mut m = meas(0.0, [3.0, 0.0, 0.0]);
        m.valid = 0;
        assert_eq!(c.step(&m, 0.0, &[0.0; 3]).offset, [0.0; 3]);
        let bad = CorrectionConfig {
            gain: 1.5,
            ..Default::default()
        };
        assert_eq!(bad.validate().unwrap_err().key, "gain");
    }
}
