//! The simulated plant (`pcr-plant`) as the chain's drive and pose sensor.
//!
//! [`PlantDrive`] forwards the cycle's `write`/`read` to the plant (its elastica statics, stepper,
//! backlash, creep and friction) and keeps the latest motion-capture sample reported by the time
//! of the `read` (the plant simulates the cycle's segment at `write`; its later samples wait for
//! the next cycle, so that the chain never measures its own future);
//! [`PlantSensor`] hands that sample to the driver step as the measured pose. The capture sample
//! is mapped into the robot frame with the plant's capture transform (what a registration would
//! find; the correction step may refine it). The passive joints M_i of the same samples are kept
//! too ([`PlantDrive::joints`]) for the experiment runners, which record them. With
//! [`PlantDrive::serve_qtm`] the same samples are also streamed by a simulated QTM
//! ([`crate::capture_feed`]), so that the chain can take its measurements through the real QTM
//! RT protocol.

use crate::capture_feed::CaptureFeed;
use crate::drive::PoseSensor;
use pcr_driver::{Driver, DriverError, DriverState, MotorCommand};
use pcr_kinematics::Pose;
use pcr_mocap_bridge::QtmServer;
use pcr_plant::{Frame, Plant, PlantConfig, PlantError};
use pcr_robot::RobotConfig;
use pcr_robot::Vec2;
use std::cell::Cell;
use std::rc::Rc;
use std::sync::Arc;

/// The plant behind the driver interface.
pub struct PlantDrive {
    plant: Plant,
    frame: Frame,
    last: Rc<Cell<Option<Pose>>>,
    /// M_i of the capture samples of the last `read`, robot frame.
    joints: [Option<Vec2>; 3],
    /// The caller's time at the first call: the plant's clock starts there (a process's clock
    /// may be far from 0, and the plant would otherwise simulate the whole gap).
    t0: Option<f64>,
    /// The simulated QTM fed with every capture sample.
    qtm: Option<(Arc<QtmServer>, CaptureFeed)>,
    /// Capture samples reported after the time of the last `read` (the plant simulates a whole
    /// cycle at `write`): they are handed out when the chain's clock reaches them, so that a
    /// row stamped t holds what the capture system reported by t.
    pending: std::collections::VecDeque<pcr_plant::Measurement>,
    /// The samples handed out by the last `read`, robot frame, stamped with the time they were
    /// reported on the caller's clock.
    samples: Vec<pcr_plant::Measurement>,
}

/// The plant's motion-capture view, as the driver step's pose sensor.
pub struct PlantSensor {
    last: Rc<Cell<Option<Pose>>>,
}

/// Builds the plant drive and its sensor for a robot and a plant configuration.
pub fn plant_backend(
    robot: &RobotConfig,
    cfg: &PlantConfig,
) -> Result<(PlantDrive, PlantSensor), PlantError> {
    let plant = Plant::new(robot, cfg)?;
    let frame = plant.capture_model().registered;
    let last = Rc::new(Cell::new(None));
    Ok((
        PlantDrive {
            plant,
            frame,
            last: last.clone(),
            joints: [None; 3],
            t0: None,
            qtm: None,
            pending: std::collections::VecDeque::new(),
            samples: Vec::new(),
        },
        PlantSensor { last },
    ))
}

impl PlantDrive {
    /// The plant (true state, configuration).
    pub fn plant(&self) -> &Plant {
        &self.plant
    }

    /// Streams every capture sample from now on through `server` (a simulated QTM whose
    /// parameters are [`crate::capture_feed::sim_parameters`]).
    pub fn serve_qtm(&mut self, server: Arc<QtmServer>) {
        let feed = CaptureFeed::new(&self.plant);
        self.qtm = Some((server, feed));
    }

    /// The simulated QTM, if serving.
    pub fn qtm_server(&self) -> Option<&Arc<QtmServer>> {
        self.qtm.as_ref().map(|q| &q.0)
    }

    /// Home motor positions of the plant, steps.
    pub fn home_steps(&self) -> [i32; 3] {
        self.plant.home_steps()
    }

    /// The passive joints M_i (x mm, y mm, robot frame) as the motion capture saw them during
    /// the last `read`: per joint the latest sample that saw it, `None` where no sample of that
    /// cycle did (dropout, or no sample due in the cycle).
    pub fn joints(&self) -> [Option<Vec2>; 3] {
        self.joints
    }

    /// Every capture sample the last `read` handed out (robot frame), each stamped with the
    /// time it was reported on the caller's clock (measurement time + the capture latency):
    /// what a recorder aligns by measurement time ([`crate::CaptureAligner`]).
    pub fn samples(&self) -> &[pcr_plant::Measurement] {
        &self.samples
    }
}

impl PlantDrive {
    fn plant_time(&mut self, time_s: f64) -> f64 {
        let t0 = *self.t0.get_or_insert(time_s - self.plant.time());
        (time_s - t0).max(0.0)
    }
}

impl Driver for PlantDrive {
    fn name(&self) -> &str {
        "plant"
    }

    fn write(&mut self, time_s: f64, period_s: f64, cmd: &MotorCommand) -> Result<(), DriverError> {
        let t = self.plant_time(time_s);
        let r = self.plant.write(t, period_s, cmd);
        // An early command took back part of a cycle (the plant's firmware rule): its samples
        // after that were made again.
        if let Some(t0) = self.plant.take_withdrawn() {
            self.pending.retain(|m| m.t_s <= t0 + 1e-12);
        }
        r
    }

    fn read(&mut self, time_s: f64, period_s: f64) -> Result<DriverState, DriverError> {
        let t = self.plant_time(time_s);
        let mut s = self.plant.read(t, period_s)?;
        s.time_s = time_s;
        self.joints = [None; 3];
        self.samples.clear();
        let offset = time_s - t;
        self.pending.extend(self.plant.drain_measurements());
        while self.pending.front().is_some_and(|m| m.t_s <= t + 1e-9) {
            let Some(m) = self.pending.pop_front() else {
                break;
            };
            if let Some((server, feed)) = &mut self.qtm {
                server.push(feed.frame_of(&m));
            }
            let m = m.in_robot_frame(&self.frame);
            self.samples.push(pcr_plant::Measurement {
                t_s: m.t_s + offset,
                ..m
            });
            if let Some(p) = m.pose {
                self.last.set(Some(Pose::new(p[0], p[1], p[2])));
            }
            for (j, seen) in self.joints.iter_mut().zip(m.m) {
                if seen.is_some() {
                    *j = seen;
                }
            }
        }
        Ok(s)
    }

    fn diagnostics(&self) -> Vec<(String, u64)> {
        vec![("plant.fallbacks".into(), self.plant.fallbacks())]
    }
}

impl PoseSensor for PlantSensor {
    fn name(&self) -> &str {
        "plant-capture"
    }

    fn measure(&mut self, _time_s: f64, _state: &DriverState) -> Option<Pose> {
        self.last.take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_early_command_follows_the_firmware_rule() {
        let (mut d, _s) =
            plant_backend(&RobotConfig::nominal(), &PlantConfig::ideal()).expect("plant");
        let home = d.home_steps();
        let a = MotorCommand {
            steps: [home[0] + 20, home[1] - 10, home[2]],
            enable: true,
        };
        let b = MotorCommand {
            steps: [home[0] + 30, home[1] - 15, home[2] + 5],
            enable: true,
        };
        let t0 = 100.0; // a process clock far from 0
        d.write(t0, 0.02, &a).unwrap();
        d.read(t0, 0.02).unwrap();
        let end = d.plant.time();
        assert!((end - 0.02).abs() < 1e-9, "{end}");
        // The same target early: the running segment finishes, nothing is simulated again.
        d.write(t0 + 0.005, 0.02, &a).unwrap();
        assert_eq!(d.plant.time(), end);
        // A new target early: a new segment from now, the plant one period ahead of now only.
        d.write(t0 + 0.010, 0.02, &b).unwrap();
        assert!((d.plant.time() - 0.030).abs() < 1e-9, "{}", d.plant.time());
        // Samples reach the caller in time order, none from the future.
        let mut last = f64::NEG_INFINITY;
        for k in 1..20 {
            let t = t0 + 0.010 + 0.02 * k as f64;
            d.write(t, 0.02, &b).unwrap();
            d.read(t, 0.02).unwrap();
            for m in d.samples() {
                assert!(
                    m.t_s > last && m.t_s <= t + 1e-9,
                    "{} after {last} at {t}",
                    m.t_s
                );
                last = m.t_s;
            }
        }
        let st = d.read(t0 + 0.5, 0.02).unwrap();
        assert_eq!(st.steps, b.steps);
    }
}
