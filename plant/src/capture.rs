//! The motion-capture system: samples the true platform pose and joints M_i at a fixed rate,
//! with latency, Gaussian noise, dropouts, in its own frame.

use crate::config::Capture;
use pcr_robot::geometry::{add, rot, sub, Vec2};
use rand::Rng;
use rand_distr_lite::standard_normal;

/// The rigid transform from the robot base frame to the capture frame:
/// `p_capture = R(dphi) p_robot + d`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Frame {
    /// Offset, mm.
    pub d: Vec2,
    /// Rotation, rad.
    pub dphi: f64,
}

impl Frame {
    /// Robot-frame point to capture frame.
    pub fn to_capture(&self, p: Vec2) -> Vec2 {
        add(rot(self.dphi, p), self.d)
    }

    /// Capture-frame point to robot frame.
    pub fn to_robot(&self, p: Vec2) -> Vec2 {
        rot(-self.dphi, sub(p, self.d))
    }

    /// Robot-frame pose (x, y, phi rad) to capture frame.
    pub fn pose_to_capture(&self, x: [f64; 3]) -> [f64; 3] {
        let p = self.to_capture([x[0], x[1]]);
        [p[0], p[1], x[2] + self.dphi]
    }

    /// Capture-frame pose to robot frame.
    pub fn pose_to_robot(&self, x: [f64; 3]) -> [f64; 3] {
        let p = self.to_robot([x[0], x[1]]);
        [p[0], p[1], x[2] - self.dphi]
    }
}

/// One capture sample. `None` = that rigid body was not seen (dropout).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// Time the sample is reported, s.
    pub t_s: f64,
    /// Platform pose (x mm, y mm, phi rad) in the frame named by `frame_is_robot`.
    pub pose: Option<[f64; 3]>,
    /// Passive joints M_i, mm.
    pub m: [Option<Vec2>; 3],
}

impl Measurement {
    /// The same sample expressed in the robot frame, given the capture frame.
    pub fn in_robot_frame(&self, frame: &Frame) -> Measurement {
        Measurement {
            t_s: self.t_s,
            pose: self.pose.map(|p| frame.pose_to_robot(p)),
            m: self.m.map(|m| m.map(|p| frame.to_robot(p))),
        }
    }
}

/// The capture model built from the configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct CaptureModel {
    /// Capture frame.
    pub frame: Frame,
    /// The capture frame as the measuring side registered it (the true one unless the
    /// configuration declares a registration error): measurements are mapped into the robot
    /// frame with this one.
    pub registered: Frame,
    /// Noise sigma of positions (mm) and angle (rad); zero when off.
    pub sigma: (f64, f64),
    /// Dropout probability per body and sample.
    pub dropout: f64,
    /// Latency, s.
    pub latency: f64,
    /// Sample period, s.
    pub period: f64,
}

impl CaptureModel {
    /// From the configuration.
    pub fn new(c: &Capture) -> CaptureModel {
        CaptureModel {
            frame: Frame {
                d: [c.frame_dx_mm, c.frame_dy_mm],
                dphi: c.frame_dphi_deg.to_radians(),
            },
            registered: Frame {
                d: [
                    c.frame_dx_mm + c.registration_error_dx_mm,
                    c.frame_dy_mm + c.registration_error_dy_mm,
                ],
                dphi: (c.frame_dphi_deg + c.registration_error_dphi_deg).to_radians(),
            },
            sigma: if c.noise {
                (c.sigma_mm, c.sigma_deg.to_radians())
            } else {
                (0.0, 0.0)
            },
            dropout: c.dropout_probability,
            latency: c.latency_s,
            period: 1.0 / c.rate_hz,
        }
    }

    /// Turns the true state (robot frame) into a sample reported at `t_s`.
    pub fn measure<R: Rng>(
        &self,
        t_s: f64,
        pose: [f64; 3],
        m: [Vec2; 3],
        rng: &mut R,
    ) -> Measurement {
        let (sp, sa) = self.sigma;
        let mut noise = |s: f64| {
            if s > 0.0 {
                s * standard_normal(rng)
            } else {
                0.0
            }
        };
        let pc = self.frame.pose_to_capture(pose);
        let pose_n = [pc[0] + noise(sp), pc[1] + noise(sp), pc[2] + noise(sa)];
        let m_n: [Vec2; 3] = std::array::from_fn(|i| {
            let q = self.frame.to_capture(m[i]);
            [q[0] + noise(sp), q[1] + noise(sp)]
        });
        let mut seen = || self.dropout <= 0.0 || rng.random::<f64>() >= self.dropout;
        let pose_seen = seen();
        let m_seen = [seen(), seen(), seen()];
        Measurement {
            t_s,
            pose: pose_seen.then_some(pose_n),
            m: std::array::from_fn(|i| m_seen[i].then_some(m_n[i])),
        }
    }
}

/// A standard normal variate by Box-Muller (keeps the dependency list short).
mod rand_distr_lite {
    use rand::Rng;

    /// One N(0, 1) sample.
    pub fn standard_normal<R: Rng>(rng: &mut R) -> f64 {
        let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1]
        let u2: f64 = rng.random::<f64>();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}
