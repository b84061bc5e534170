//! The simulated plant as a QTM: turns the plant's capture view ([`pcr_plant::Measurement`]:
//! platform pose and joints M_i in the capture frame, with the plant's noise, dropouts and
//! latency) into QTM frames for a [`pcr_mocap_bridge::QtmServer`]: the platform as the 6DOF
//! body `platform` (Euler angles (0, 0, phi)), and the labelled markers B1..B3 (the plant's
//! true base points in the capture frame, with the capture noise and dropouts) and M1..M3.
//! The capture frame is planar (the plant's `[capture] frame_*`); markers lie at
//! [`MARKER_HEIGHT_MM`] above it.

use pcr_mocap_bridge::{Body, Frame, Marker, Parameters};
use pcr_plant::{Measurement, Plant};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Height of every marker and of the body above the capture frame's xy plane, mm.
pub const MARKER_HEIGHT_MM: f64 = 0.0;
/// Name of the platform's 6DOF body.
pub const PLATFORM_BODY: &str = "platform";
/// Labels of the simulated markers, in stream order.
pub const LABELS: [&str; 6] = ["B1", "B2", "B3", "M1", "M2", "M3"];

/// What the simulated QTM declares at capture rate `rate_hz`.
pub fn sim_parameters(rate_hz: f64) -> Parameters {
    Parameters {
        version: None,
        frequency_hz: Some(rate_hz),
        labels: LABELS.iter().map(|s| s.to_string()).collect(),
        bodies: vec![PLATFORM_BODY.into()],
    }
}

/// Plant capture samples to QTM frames.
#[derive(Debug, Clone)]
pub struct CaptureFeed {
    base: [[f64; 2]; 3],
    sigma_mm: f64,
    dropout: f64,
    rng: ChaCha8Rng,
    frame: Frame,
    next_frame: u32,
}

impl CaptureFeed {
    /// The feed of a plant (its true base points, capture frame, noise and dropouts).
    pub fn new(plant: &Plant) -> Self {
        let cm = plant.capture_model();
        let base = std::array::from_fn(|i| cm.frame.to_capture(plant.truth().robot.legs[i].base));
        Self {
            base,
            sigma_mm: cm.sigma.0,
            dropout: cm.dropout,
            rng: ChaCha8Rng::seed_from_u64(plant.config().seed ^ 0x5174_6d00),
            frame: Frame::default(),
            next_frame: 1,
        }
    }

    /// The frame of one capture sample (QTM timestamp = the sample's plant time).
    pub fn frame_of(&mut self, m: &Measurement) -> &Frame {
        let f = &mut self.frame;
        f.timestamp_us = (m.t_s.max(0.0) * 1e6).round() as u64;
        f.frame_number = self.next_frame;
        self.next_frame = self.next_frame.wrapping_add(1);
        f.has_bodies = true;
        f.has_markers = true;
        f.bodies.clear();
        f.bodies.push(m.pose.map(|p| Body {
            position_mm: [p[0], p[1], MARKER_HEIGHT_MM],
            euler_deg: [0.0, 0.0, p[2].to_degrees()],
            residual_mm: Some(self.sigma_mm.max(0.05)),
        }));
        f.markers.clear();
        for b in self.base {
            let seen = self.dropout <= 0.0 || self.rng.random::<f64>() >= self.dropout;
            let mut noise = || {
                if self.sigma_mm > 0.0 {
                    // Box-Muller, one coordinate at a time
                    let u1: f64 = 1.0 - self.rng.random::<f64>();
                    let u2: f64 = self.rng.random::<f64>();
                    self.sigma_mm * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
                } else {
                    0.0
                }
            };
            let p = [b[0] + noise(), b[1] + noise(), MARKER_HEIGHT_MM + noise()];
            f.markers.push(seen.then_some(Marker {
                position_mm: p,
                residual_mm: Some(self.sigma_mm.max(0.05)),
            }));
        }
        for mi in m.m {
            f.markers.push(mi.map(|p| Marker {
                position_mm: [p[0], p[1], MARKER_HEIGHT_MM],
                residual_mm: Some(self.sigma_mm.max(0.05)),
            }));
        }
        &self.frame
    }
}
