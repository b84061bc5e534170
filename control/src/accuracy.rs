//! Path accuracy: planned vs measured pose over the rows of a run.

use pcr_messages::{driver_flags, task_flags, DriverStateMsg};

/// Running statistics of the position (mm) and orientation (deg) errors.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Accuracy {
    /// Rows counted (a program was active and the pose was measured).
    pub n: u64,
    sum_p: f64,
    sumsq_p: f64,
    /// Largest position error, mm.
    pub max_pos_mm: f64,
    sum_o: f64,
    sumsq_o: f64,
    /// Largest orientation error, deg.
    pub max_phi_deg: f64,
}

impl Accuracy {
    /// Adds a driver-state row if it belongs to an active program and carries a measured pose.
    pub fn add(&mut self, s: &DriverStateMsg) {
        if s.task_flags & task_flags::ACTIVE == 0 || s.flags & driver_flags::POSE_VALID == 0 {
            return;
        }
        let e = (s.measured[0] - s.planned[0]).hypot(s.measured[1] - s.planned[1]);
        let o = (s.measured[2] - s.planned[2]).to_degrees().abs();
        if !(e.is_finite() && o.is_finite()) {
            return;
        }
        self.n += 1;
        self.sum_p += e;
        self.sumsq_p += e * e;
        self.max_pos_mm = self.max_pos_mm.max(e);
        self.sum_o += o;
        self.sumsq_o += o * o;
        self.max_phi_deg = self.max_phi_deg.max(o);
    }

    fn div(a: f64, n: u64) -> f64 {
        if n == 0 {
            0.0
        } else {
            a / n as f64
        }
    }
    /// Mean position error, mm.
    pub fn mean_pos_mm(&self) -> f64 {
        Self::div(self.sum_p, self.n)
    }
    /// RMS position error, mm.
    pub fn rms_pos_mm(&self) -> f64 {
        Self::div(self.sumsq_p, self.n).sqrt()
    }
    /// Mean orientation error, deg.
    pub fn mean_phi_deg(&self) -> f64 {
        Self::div(self.sum_o, self.n)
    }
    /// RMS orientation error, deg.
    pub fn rms_phi_deg(&self) -> f64 {
        Self::div(self.sumsq_o, self.n).sqrt()
    }
}

impl std::fmt::Display for Accuracy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "rows {}: position error mean {:.3} mm, max {:.3} mm, RMS {:.3} mm; orientation error \
             mean {:.3} deg, max {:.3} deg, RMS {:.3} deg",
            self.n,
            self.mean_pos_mm(),
            self.max_pos_mm,
            self.rms_pos_mm(),
            self.mean_phi_deg(),
            self.max_phi_deg,
            self.rms_phi_deg()
        )
    }
}
