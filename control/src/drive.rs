//! The interim plant: [`IdealDrive`] (a [`Driver`]) and [`FkPoseSensor`] (a [`PoseSensor`]),
//! plus the standard safety stack around any driver.
//!
//! The physical simulated plant (`pcr-plant`) plugs in by implementing
//! [`pcr_driver::Driver`] (motor side) and [`PoseSensor`] (what the motion capture would
//! measure); the serial backend implements `Driver` only (the pose then comes from mocap).

use pcr_driver::{
    Driver, DriverError, DriverState, MotorCommand, PositionLimit, RateLimit, Watchdog,
};
use pcr_kinematics::{Pose, Robot};

/// Something that measures the platform pose at the end of a driver cycle.
pub trait PoseSensor {
    /// A short name for logs.
    fn name(&self) -> &str;
    /// The pose (mm, rad) for the drive state just read, or `None` when not measured this
    /// cycle. Called once per cycle; must not allocate.
    fn measure(&mut self, time_s: f64, state: &DriverState) -> Option<Pose>;
}

/// INTERIM plant: an ideal stepper drive that moves each motor towards its target at no more
/// than `max_step_rate` steps/s and reports where it is. No physics, no backlash, no load.
#[derive(Debug, Clone)]
pub struct IdealDrive {
    pos: [i32; 3],
    target: [i32; 3],
    /// Fractional step budget carried between cycles.
    budget: [f64; 3],
    max_step_rate: f64,
    enabled: bool,
    limited: bool,
    last_t: Option<f64>,
}

impl IdealDrive {
    /// A drive at `start` steps, limited to `max_step_rate` steps/s.
    pub fn new(start: [i32; 3], max_step_rate: f64) -> Self {
        Self {
            pos: start,
            target: start,
            budget: [0.0; 3],
            max_step_rate,
            enabled: false,
            limited: false,
            last_t: None,
        }
    }
}

impl Driver for IdealDrive {
    fn name(&self) -> &str {
        "ideal-drive"
    }
    fn write(&mut self, _t: f64, _p: f64, cmd: &MotorCommand) -> Result<(), DriverError> {
        self.enabled = cmd.enable;
        if cmd.enable {
            self.target = cmd.steps;
        }
        Ok(())
    }
    fn read(&mut self, time_s: f64, period_s: f64) -> Result<DriverState, DriverError> {
        // Advance by the time since the last read (or one period for the first).
        let dt = self.last_t.map_or(period_s, |l| (time_s - l).max(0.0));
        self.last_t = Some(time_s);
        self.limited = false;
        let mut moving = false;
        if self.enabled {
            for i in 0..3 {
                let allow = self.max_step_rate * dt + self.budget[i];
                let need = (self.target[i] - self.pos[i]) as f64;
                if need.abs() <= allow.floor() {
                    self.pos[i] = self.target[i];
                    self.budget[i] = 0.0;
                } else {
                    let n = allow.floor();
                    self.pos[i] += (n * need.signum()) as i32;
                    self.budget[i] = allow - n;
                    self.limited = true;
                    moving = true;
                }
            }
        }
        Ok(DriverState {
            time_s,
            steps: self.pos,
            enabled: self.enabled,
            moving,
            limited: self.limited,
            fault: false,
        })
    }
}

/// INTERIM pose sensor: the FK (constant-curvature model) of the reported motor positions,
/// warm-started at the previous pose. Stands in for the motion capture on the interim plant.
#[derive(Debug)]
pub struct FkPoseSensor {
    robot: Robot,
    last: Pose,
}

impl FkPoseSensor {
    /// A sensor for `robot`, starting at the home pose.
    pub fn new(robot: Robot) -> Self {
        Self {
            robot,
            last: Pose::default(),
        }
    }
}

impl PoseSensor for FkPoseSensor {
    fn name(&self) -> &str {
        "fk-of-steps"
    }
    fn measure(&mut self, _t: f64, state: &DriverState) -> Option<Pose> {
        let kappa: [f64; 3] =
            std::array::from_fn(|i| self.robot.steps_to_kappa(i, state.steps[i] as f64));
        let p = self.robot.fk_warm(&kappa, &self.last).ok()?;
        self.last = p;
        Some(p)
    }
}

/// A sensor that never measures (serial backend without mocap).
#[derive(Debug, Default, Clone, Copy)]
pub struct NoPoseSensor;

impl PoseSensor for NoPoseSensor {
    fn name(&self) -> &str {
        "none"
    }
    fn measure(&mut self, _t: f64, _s: &DriverState) -> Option<Pose> {
        None
    }
}

/// The standard safety stack: `Watchdog(PositionLimit(RateLimit(drv)))`.
pub type SafeDriver<D> = Watchdog<PositionLimit<RateLimit<D>>>;

/// Wraps `drv` in the standard safety stack for `robot`: rate limit at the smallest leg's
/// `max_step_rate`, positions within the bending range, watchdog after `watchdog_s`.
pub fn safety_stack<D: Driver>(drv: D, robot: &Robot, watchdog_s: f64) -> SafeDriver<D> {
    let cfg = robot.config();
    let rate = cfg
        .legs
        .iter()
        .map(|l| l.actuation.max_step_rate)
        .fold(f64::INFINITY, f64::min);
    let mut lo = [0i32; 3];
    let mut hi = [0i32; 3];
    for i in 0..3 {
        let kmax = robot.limits.bending_max / cfg.legs[i].l_c_mm;
        let a = robot.kappa_to_steps(i, -kmax).unwrap_or(-1e6);
        let b = robot.kappa_to_steps(i, kmax).unwrap_or(1e6);
        lo[i] = a.min(b).floor() as i32;
        hi[i] = a.max(b).ceil() as i32;
    }
    Watchdog::new(
        PositionLimit::new(RateLimit::new(drv, rate), lo, hi),
        watchdog_s,
    )
}

/// The maximum step rate of the slowest leg, steps/s.
pub fn max_step_rate(robot: &Robot) -> f64 {
    robot
        .config()
        .legs
        .iter()
        .map(|l| l.actuation.max_step_rate)
        .fold(f64::INFINITY, f64::min)
}
