//! The time-stepped plant: motor setpoints every control cycle, sub-stepped statics with
//! history (backlash, friction, creep), the true state and motion-capture samples. Implements
//! [`pcr_driver::Driver`].

use crate::actuator::{Actuator, GearTerm, StepperParams};
use crate::capture::{CaptureModel, Measurement};
use crate::config::{PlantConfig, PlantConfigError};
use crate::segment::{self, SegmentParams};
use crate::statics::{
    joint_anchor_after, support_anchor_after, Equilibrium, FrictionAnchors, FrictionParams,
    JacobianCache, Loads, StaticsError,
};
use crate::truth::TruthModel;
use pcr_driver::{Driver, DriverError, DriverState, MotorCommand};
use pcr_robot::geometry::{add, Vec2};
use pcr_robot::RobotConfig;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::collections::VecDeque;

/// Why the plant could not be built or stepped.
#[derive(Debug, thiserror::Error)]
pub enum PlantError {
    /// Bad configuration.
    #[error(transparent)]
    Config(#[from] PlantConfigError),
    /// No equilibrium (the plant holds its last state).
    #[error(transparent)]
    Statics(#[from] StaticsError),
}

/// The true state of the plant at one instant (robot base frame).
#[derive(Debug, Clone, PartialEq)]
pub struct TrueState {
    /// Simulated time, s.
    pub t_s: f64,
    /// Firmware step counters (what the drive reports), steps.
    pub counter: [i32; 3],
    /// Motor rotor positions (counter minus missed steps), steps.
    pub motor: [i32; 3],
    /// Gear output positions (after backlash), steps.
    pub output: [f64; 3],
    /// Tendon creep elongation, mm.
    pub creep_mm: [f64; 3],
    /// Effective tendon displacements dl_i = output * mm/step - creep, mm.
    pub tendon_mm: [f64; 3],
    /// Bending phi_b,i from the true tendon map, rad.
    pub bending: [f64; 3],
    /// The equilibrium (pose, M_i, P_i, forces, ...).
    pub eq: Equilibrium,
}

/// One motor step made outside the plant's stepper model (e.g. decoded from the coil pins of
/// an emulated firmware), for [`Plant::advance_with_steps`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorStep {
    /// Time of the step, s (plant time).
    pub t_s: f64,
    /// Motor (leg) index, 0..3.
    pub motor: usize,
    /// Motor position after the step, steps.
    pub pos: i32,
}

/// The simulated robot.
pub struct Plant {
    truth: TruthModel,
    cfg: PlantConfig,
    /// Stepper parameters per leg.
    stepper: [StepperParams; 3],
    friction: Option<FrictionParams>,
    capture: CaptureModel,
    rng_stepper: ChaCha8Rng,
    rng_capture: ChaCha8Rng,
    act: [Actuator; 3],
    creep: [f64; 3],
    anchors: FrictionAnchors,
    state: TrueState,
    /// True states at the sub-step times (for latency and sampling).
    history: VecDeque<(f64, [f64; 3], [Vec2; 3])>,
    next_sample: u64,
    measurements: VecDeque<Measurement>,
    last_drained: Option<Measurement>,
    enabled: bool,
    limited: bool,
    fault: bool,
    target: [i32; 3],
    name: String,
    fallbacks: u64,
    jac_cache: Option<JacobianCache>,
    /// The times a cycle solves its statics at (kept to spare the cycle an allocation).
    substep_times: Vec<f64>,
    /// Sign of det(Jacobian) of the statics at home (with this plant's friction): stable.
    stable_sign: f64,
    /// The last cycle run: its start state, period and command (for taking it back).
    last_cycle: Option<CycleRecord>,
    /// Start of the earliest cycle taken back since the last [`Plant::take_withdrawn`]: its
    /// measurements after that time were made again.
    withdrawn: Option<f64>,
}

/// What [`Plant::rewind_to`] needs of the last cycle: the state at its start, its period and
/// command.
#[derive(Debug, Clone)]
struct CycleRecord {
    act: [Actuator; 3],
    creep: [f64; 3],
    anchors: FrictionAnchors,
    state: TrueState,
    history_len: usize,
    measurements_len: usize,
    next_sample: u64,
    period: f64,
    cmd: MotorCommand,
}

impl Plant {
    /// A plant at rest at its home motor positions at t = 0.
    pub fn new(robot: &RobotConfig, cfg: &PlantConfig) -> Result<Plant, PlantError> {
        cfg.validate("plant configuration")?;
        let truth = TruthModel::new(robot, cfg)?;
        let home = truth.robot.home_steps;
        let s = &cfg.stepper;
        let stepper = std::array::from_fn(|i| StepperParams {
            max_rate: s
                .rate_limit
                .then_some(robot.legs[i].actuation.max_step_rate),
            pull_out_rate: s.missed_steps.then_some(s.pull_out_rate),
            miss_probability: if s.missed_steps {
                s.miss_probability
            } else {
                0.0
            },
        });
        let f = &cfg.friction;
        let friction = (f.joints || f.supports).then_some(FrictionParams {
            joint_torque: if f.joints { f.joint_torque_n_mm } else { 0.0 },
            joint_stiffness: f.joint_stick_stiffness_n_mm_per_rad,
            support_force: if f.supports { f.support_force_n } else { 0.0 },
            support_stiffness: f.support_stick_stiffness_n_per_mm,
        });
        let act: [Actuator; 3] = std::array::from_fn(|i| {
            let terms = s
                .periodic
                .iter()
                .filter(|p| usize::from(p.motor) == i + 1)
                .map(|p| GearTerm::new(p.period_steps, p.amplitude_steps, p.phase_deg))
                .collect();
            Actuator::new(home[i], if s.backlash { s.backlash_steps[i] } else { 0.0 })
                .with_gear_errors(terms)
        });
        let output: [f64; 3] = std::array::from_fn(|i| act[i].output);
        let loads = Loads {
            phi_b: truth.robot.bending_of_steps(&output, &[0.0; 3]),
            wrench: truth.wrench,
            friction: None,
        };
        let eq = truth.solve_loads(&loads)?;
        let anchors = FrictionAnchors {
            gamma: eq.gamma,
            zeta: eq.zeta,
            m: eq.m,
            p: eq.p,
        };
        let state = TrueState {
            t_s: 0.0,
            counter: home,
            motor: home,
            output,
            creep_mm: [0.0; 3],
            tendon_mm: std::array::from_fn(|i| output[i] * truth.robot.mm_per_step[i]),
            bending: loads.phi_b,
            eq,
        };
        let home_loads = Loads {
            friction: friction.map(|f| (f, anchors)),
            ..loads
        };
        let stable_sign = truth
            .statics
            .jacobian_at(&home_loads, &state.eq.z)
            .map_or(1.0, |c| c.det_sign);
        let mut history = VecDeque::new();
        history.push_back((0.0, state.eq.pose, state.eq.m));
        let mut plant = Plant {
            stepper,
            friction,
            capture: CaptureModel::new(&cfg.capture),
            rng_stepper: ChaCha8Rng::seed_from_u64(cfg.seed),
            rng_capture: ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x9e37_79b9_7f4a_7c15),
            act,
            creep: [0.0; 3],
            anchors,
            state,
            history,
            next_sample: 0,
            measurements: VecDeque::new(),
            last_drained: None,
            enabled: true,
            limited: false,
            fault: false,
            target: home,
            name: "plant".into(),
            fallbacks: 0,
            jac_cache: None,
            substep_times: Vec::new(),
            stable_sign,
            last_cycle: None,
            withdrawn: None,
            truth,
            cfg: cfg.clone(),
        };
        plant.sample_until(0.0);
        Ok(plant)
    }

    /// The static truth model behind the plant.
    pub fn truth(&self) -> &TruthModel {
        &self.truth
    }

    /// The configuration.
    pub fn config(&self) -> &PlantConfig {
        &self.cfg
    }

    /// The capture model (frame, noise, latency, rate).
    pub fn capture_model(&self) -> &CaptureModel {
        &self.capture
    }

    /// How many sub-steps needed the continuation fallback (warm Newton failed).
    pub fn fallbacks(&self) -> u64 {
        self.fallbacks
    }

    /// Simulated time, s.
    pub fn time(&self) -> f64 {
        self.state.t_s
    }

    /// The true state now.
    pub fn true_state(&self) -> &TrueState {
        &self.state
    }

    /// Home motor positions, steps.
    pub fn home_steps(&self) -> [i32; 3] {
        self.truth.robot.home_steps
    }

    /// Centre lines of the three segments now (base frame, mm), `segment_steps + 1` points each.
    pub fn segment_shapes(&self) -> [Vec<Vec2>; 3] {
        segment_shapes(&self.truth, &self.state.eq)
    }

    /// Capture samples reported since the last call (capture frame), oldest first.
    pub fn drain_measurements(&mut self) -> Vec<Measurement> {
        let out: Vec<Measurement> = self.measurements.drain(..).collect();
        if let Some(m) = out.last() {
            self.last_drained = Some(*m);
        }
        out
    }

    /// The latest capture sample reported up to now (capture frame), without consuming it.
    pub fn latest_measurement(&self) -> Option<Measurement> {
        self.measurements.back().copied().or(self.last_drained)
    }

    /// Runs one control cycle of length `period` s towards the setpoint `cmd`.
    /// On a failed static solve the motion is rolled back, the drive holds its position for the
    /// cycle, reports `fault` and the error is returned.
    pub fn step_cycle(&mut self, period: f64, cmd: &MotorCommand) -> Result<(), PlantError> {
        self.enabled = cmd.enable;
        self.target = cmd.steps;
        match self.run_cycle(period, cmd) {
            Ok(()) => {
                self.fault = false;
                Ok(())
            }
            Err(e) => {
                // The drive holds its position for the cycle and reports a fault.
                self.fault = true;
                let hold = MotorCommand {
                    steps: self.state.counter,
                    enable: cmd.enable,
                };
                self.run_cycle(period, &hold)?;
                Err(e.into())
            }
        }
    }

    /// One cycle; on a failed solve everything is rolled back to the cycle start.
    fn run_cycle(&mut self, period: f64, cmd: &MotorCommand) -> Result<(), StaticsError> {
        self.run_cycle_until(period, cmd, f64::INFINITY)
    }

    /// One cycle of `period` planned from the present, simulated only up to `until` (a
    /// firmware that gets its next command early starts the next segment there); on a failed
    /// solve everything is rolled back to the cycle start.
    fn run_cycle_until(
        &mut self,
        period: f64,
        cmd: &MotorCommand,
        until: f64,
    ) -> Result<(), StaticsError> {
        let t0 = self.state.t_s;
        let record = CycleRecord {
            act: self.act.clone(),
            creep: self.creep,
            anchors: self.anchors,
            state: self.state.clone(),
            history_len: self.history.len(),
            measurements_len: self.measurements.len(),
            next_sample: self.next_sample,
            period,
            cmd: *cmd,
        };
        let mut limited = false;
        for (i, a) in self.act.iter_mut().enumerate() {
            let target = if cmd.enable { cmd.steps[i] } else { a.counter };
            limited |= a.plan_cycle(t0, period, target, &self.stepper[i]);
        }
        self.limited = limited;
        let n = self.cfg.simulation.substeps_per_cycle.max(1);
        let mut times = std::mem::take(&mut self.substep_times);
        times.clear();
        times.extend((1..=n).map(|k| t0 + period * k as f64 / n as f64));
        // Friction follows the path between the sub-steps: each motor steps on its own within
        // the cycle, so that the joints and supports move in a staircase, not along the chord
        // between two sub-steps (at two sub-steps a cycle the supports' deflection missed that
        // staircase by 0.01 mm). With friction on, the statics are solved at every step's time.
        if self.friction.is_some() {
            times.extend(self.act.iter().flat_map(|a| a.planned_step_times()));
            times.sort_by(f64::total_cmp);
            times.dedup_by(|a, b| (*a - *b).abs() <= 1e-12);
        }
        let mut t_prev = t0;
        let mut result = Ok(());
        for &tk in &times {
            let (t, dt) = if tk <= until + 1e-12 {
                (tk, tk - t_prev)
            } else {
                (until, until - self.state.t_s)
            };
            t_prev = t;
            if dt <= 1e-12 {
                if t >= until {
                    break;
                }
                continue;
            }
            if let Err(e) = self.substep(t, dt) {
                result = Err(e);
                break;
            }
            if t >= until {
                break;
            }
        }
        self.substep_times = times;
        match result {
            Ok(()) => {
                self.last_cycle = Some(record);
                Ok(())
            }
            Err(e) => {
                self.restore(&record);
                Err(e)
            }
        }
    }

    /// Puts the plant back to the start of a recorded cycle.
    fn restore(&mut self, r: &CycleRecord) {
        self.act = r.act.clone();
        self.creep = r.creep;
        self.anchors = r.anchors;
        self.state = r.state.clone();
        self.history.truncate(r.history_len.min(self.history.len()));
        self.measurements
            .truncate(r.measurements_len.min(self.measurements.len()));
        self.next_sample = r.next_sample;
        self.jac_cache = None;
    }

    /// After a `write` that came early and took back part of a cycle: the start of that cycle.
    /// Measurements later than this that were already drained were made again (with new noise)
    /// and must be dropped by whoever holds them. Cleared by the call.
    pub fn take_withdrawn(&mut self) -> Option<f64> {
        self.withdrawn.take()
    }

    /// Takes back the part of the last cycle after `t` (a time inside it): the plant is put
    /// back to the cycle's start and the cycle is simulated again up to `t` only, as a firmware
    /// that receives its next command early starts the next segment from where the motors are.
    /// Without this, a command that comes early (a late one followed by one on time) would leave
    /// the plant a cycle ahead of the clock for good, its motion late against the commands.
    /// Returns the start time of the cycle taken back (measurements after it are made again).
    /// `None` when `t` is not inside the last cycle (nothing is changed then).
    fn rewind_to(&mut self, t: f64) -> Result<Option<f64>, PlantError> {
        let Some(r) = self.last_cycle.take() else {
            return Ok(None);
        };
        let t0 = r.state.t_s;
        if !(t + 1e-9 < self.state.t_s && t >= t0 - 1e-9) {
            self.last_cycle = Some(r);
            return Ok(None);
        }
        self.restore(&r);
        if t > t0 + 1e-12 && self.run_cycle_until(r.period, &r.cmd, t).is_err() {
            // As a failed cycle: hold the motors where they are up to `t`.
            let hold = MotorCommand {
                steps: self.state.counter,
                enable: r.cmd.enable,
            };
            self.run_cycle(t - t0, &hold)?;
            self.fault = true;
        }
        Ok(Some(t0))
    }

    /// Lets time pass without new steps until `t` (whole sub-steps of the cycle length).
    pub fn idle_until(&mut self, t: f64) -> Result<(), PlantError> {
        let period = self.cfg.simulation.cycle_s;
        while self.state.t_s + 1e-9 < t {
            let dt = (t - self.state.t_s).min(period);
            let cmd = MotorCommand {
                steps: self.state.counter,
                enable: self.enabled,
            };
            self.run_cycle(dt, &cmd)?;
        }
        Ok(())
    }

    /// Advances the plant to `t_end` (s) driven by motor steps given from outside (firmware in
    /// the loop) instead of its own stepper model: the rate limit and missed steps are bypassed,
    /// while backlash, creep, friction, the statics and the capture model stay the plant's.
    /// Time advances in sub-steps of at most `cycle_s / substeps_per_cycle`; each step (sorted
    /// by time) is applied at the end of the first sub-step at or after its time (steps dated
    /// before the plant's present time are applied at the first sub-step). `enable` is the
    /// coil state reported by [`Driver::read`]. On a failed static solve everything done by
    /// this call is rolled back, the motors hold their previous positions until `t_end`, the
    /// plant reports `fault` and the error is returned.
    pub fn advance_with_steps(
        &mut self,
        t_end: f64,
        steps: &[MotorStep],
        enable: bool,
    ) -> Result<(), PlantError> {
        self.enabled = enable;
        match self.run_external(t_end, steps) {
            Ok(()) => {
                self.fault = false;
                self.limited = false;
                self.target = self.state.counter;
                Ok(())
            }
            Err(e) => {
                self.fault = true;
                self.run_external(t_end, &[])?;
                Err(e.into())
            }
        }
    }

    fn run_external(&mut self, t_end: f64, steps: &[MotorStep]) -> Result<(), StaticsError> {
        if steps.is_empty() && t_end <= self.state.t_s {
            return Ok(());
        }
        let backup = (
            self.act.clone(),
            self.creep,
            self.anchors,
            self.state.clone(),
        );
        let marks = (
            self.history.len(),
            self.measurements.len(),
            self.next_sample,
        );
        // Drop whatever the plant's own stepper model still had planned.
        let hold = StepperParams {
            max_rate: None,
            pull_out_rate: None,
            miss_probability: 0.0,
        };
        for a in &mut self.act {
            let c = a.counter;
            a.plan_cycle(self.state.t_s, 1.0, c, &hold);
        }
        let h = self.cfg.simulation.cycle_s / self.cfg.simulation.substeps_per_cycle.max(1) as f64;
        let mut next = 0;
        let t_start = self.state.t_s;
        let mut t_prev = t_start;
        let mut k = 1u64;
        loop {
            // The regular sub-steps stay on their grid from the start, whatever else cuts them.
            while t_start + k as f64 * h <= t_prev + 1e-12 {
                k += 1;
            }
            let mut t = (t_start + k as f64 * h).min(t_end).max(t_prev);
            // With friction on, the statics are also solved at each step's own time (as in
            // `run_cycle_until`): the staircase of the steps, not the chord between sub-steps.
            if self.friction.is_some() {
                if let Some(s) = steps[next..].iter().find(|s| s.t_s > t_prev + 1e-12) {
                    t = t.min(s.t_s);
                }
            }
            while next < steps.len() && (steps[next].t_s <= t + 1e-12 || t >= t_end) {
                let s = steps[next];
                if let Some(a) = self.act.get_mut(s.motor) {
                    a.external_step(s.pos);
                }
                next += 1;
            }
            if let Err(e) = self.settle_substep(t, t - t_prev) {
                (self.act, self.creep, self.anchors, self.state) = backup;
                self.history.truncate(marks.0.min(self.history.len()));
                self.measurements
                    .truncate(marks.1.min(self.measurements.len()));
                self.next_sample = marks.2;
                self.jac_cache = None;
                return Err(e);
            }
            t_prev = t;
            if t >= t_end {
                return Ok(());
            }
        }
    }

    fn substep(&mut self, t: f64, dt: f64) -> Result<(), StaticsError> {
        for (a, p) in self.act.iter_mut().zip(&self.stepper) {
            a.advance_to(t, p.miss_probability, &mut self.rng_stepper);
        }
        self.settle_substep(t, dt)
    }

    /// The tendons' elongation at `t`: creep, the steady drift grown since the plant's start and
    /// the temperature cycle's part, mm.
    fn elongation(&self, t: f64) -> [f64; 3] {
        let d = &self.cfg.drift;
        let th = &self.cfg.thermal;
        let t = t.max(0.0);
        let cycle = if th.enabled {
            let ph = th.phase_deg.to_radians();
            (std::f64::consts::TAU * t / th.period_s + ph).sin() - ph.sin()
        } else {
            0.0
        };
        std::array::from_fn(|i| {
            let drift = if d.enabled {
                d.rate_mm_per_s[i] * t
            } else {
                0.0
            };
            self.creep[i] + drift + th.amplitude_mm[i] * cycle
        })
    }

    /// The statics, creep and friction at `t` with the actuators as they are.
    fn settle_substep(&mut self, t: f64, dt: f64) -> Result<(), StaticsError> {
        let output: [f64; 3] = std::array::from_fn(|i| self.act[i].output);
        if self.cfg.creep.enabled {
            let c = &self.cfg.creep;
            let w = 1.0 - (-dt / c.time_constant_s).exp();
            for i in 0..3 {
                let tension = self.state.eq.tendon_moment[i] / self.truth.robot.tendon_offset[i];
                let target = -c.compliance_mm_per_n * tension;
                self.creep[i] += (target - self.creep[i]) * w;
            }
        }
        let elongation = self.elongation(t);
        let bending = self.truth.robot.bending_of_steps(&output, &elongation);
        let loads = Loads {
            phi_b: bending,
            wrench: self.truth.wrench,
            friction: self.friction.map(|f| (f, self.anchors)),
        };
        // Unchanged bending: the same equilibrium (a slipped friction anchor keeps its force).
        let unchanged = bending == self.state.bending;
        let eq = if unchanged {
            self.state.eq.clone()
        } else {
            let prev = &self.state.eq;
            // A warm solve that lands far away has jumped to another branch (snap-through):
            // follow the path in small steps instead, which fails at a limit point.
            let jumped = |eq: &Equilibrium| {
                (eq.pose[0] - prev.pose[0]).hypot(eq.pose[1] - prev.pose[1]) > MAX_JUMP_MM
                    || (eq.pose[2] - prev.pose[2]).abs() > MAX_JUMP_RAD
            };
            let warm = self
                .truth
                .statics
                .solve_warm_cached(&loads, &prev.z, &mut self.jac_cache)
                .ok()
                .filter(|eq| !jumped(eq));
            let eq = match warm {
                Some(eq) => eq,
                None => {
                    self.fallbacks += 1;
                    let mut from = loads;
                    from.phi_b = self.state.bending;
                    self.truth.statics.solve_path(&from, prev, &loads)?
                }
            };
            // Stability: the tangent stiffness keeps the sign it has at home. The fresh
            // Jacobian also serves the next warm solve.
            let fresh = self.truth.statics.jacobian_at(&loads, &eq.z);
            match &fresh {
                Some(c) if c.det_sign == self.stable_sign => {}
                _ => return Err(StaticsError::Unstable),
            }
            self.jac_cache = fresh;
            eq
        };
        if eq.det_a.signum() != self.state.eq.det_a.signum() {
            return Err(StaticsError::AssemblyMode {
                from: self.state.eq.det_a,
                to: eq.det_a,
            });
        }
        if let Some(f) = self.friction {
            self.update_anchors(&f, &eq);
        }
        self.state = TrueState {
            t_s: t,
            counter: std::array::from_fn(|i| self.act[i].counter),
            motor: std::array::from_fn(|i| self.act[i].motor),
            output,
            creep_mm: self.creep,
            tendon_mm: std::array::from_fn(|i| {
                output[i] * self.truth.robot.mm_per_step[i] - elongation[i]
            }),
            bending,
            eq,
        };
        self.history
            .push_back((t, self.state.eq.pose, self.state.eq.m));
        self.sample_until(t);
        Ok(())
    }

    fn update_anchors(&mut self, f: &FrictionParams, eq: &Equilibrium) {
        let a = &mut self.anchors;
        for i in 0..3 {
            if f.joint_torque > 0.0 {
                let (k, l) = (f.joint_stiffness, f.joint_torque);
                a.gamma[i] = joint_anchor_after(k, l, eq.gamma[i], a.gamma[i]);
                a.zeta[i] = joint_anchor_after(k, l, eq.zeta[i], a.zeta[i]);
            }
            if f.support_force > 0.0 {
                let (k, l) = (f.support_stiffness, f.support_force);
                a.m[i] = support_anchor_after(k, l, eq.m[i], a.m[i]);
                a.p[i] = support_anchor_after(k, l, eq.p[i], a.p[i]);
            }
        }
    }

    /// Emits the capture samples due up to `t` from the history (linear interpolation).
    fn sample_until(&mut self, t: f64) {
        let period = self.capture.period;
        loop {
            let ts = self.next_sample as f64 * period;
            if ts > t + 1e-9 {
                break;
            }
            let (pose, m) = self.history_at(ts - self.capture.latency);
            let meas = self.capture.measure(ts, pose, m, &mut self.rng_capture);
            self.measurements.push_back(meas);
            self.next_sample += 1;
        }
        // Keep enough history for the latency.
        let keep_from = t - self.capture.latency - 2.0 * period - self.cfg.simulation.cycle_s;
        while self.history.len() > 2 && self.history[1].0 < keep_from {
            self.history.pop_front();
        }
    }

    fn history_at(&self, t: f64) -> ([f64; 3], [Vec2; 3]) {
        let h = &self.history;
        if t <= h[0].0 {
            return (h[0].1, h[0].2);
        }
        for w in 1..h.len() {
            let (t1, p1, m1) = &h[w];
            if *t1 >= t - 1e-12 {
                let (t0, p0, m0) = &h[w - 1];
                let s = if t1 > t0 { (t - t0) / (t1 - t0) } else { 1.0 };
                let lerp = |a: f64, b: f64| a + s * (b - a);
                let pose = std::array::from_fn(|k| lerp(p0[k], p1[k]));
                let m =
                    std::array::from_fn(|i| [lerp(m0[i][0], m1[i][0]), lerp(m0[i][1], m1[i][1])]);
                return (pose, m);
            }
        }
        let last = h.back().expect("history is never empty");
        (last.1, last.2)
    }
}

/// Largest platform translation in one sub-step of a warm solve before it counts as a jump to
/// another branch, mm.
const MAX_JUMP_MM: f64 = 3.0;
/// Largest platform rotation in one sub-step of a warm solve, rad.
const MAX_JUMP_RAD: f64 = 0.03;

/// Centre lines of the three segments of an equilibrium (base frame, mm).
pub fn segment_shapes(truth: &TruthModel, eq: &Equilibrium) -> [Vec<Vec2>; 3] {
    std::array::from_fn(|i| {
        let g = &truth.statics.legs[i];
        let p = SegmentParams {
            theta0: g.theta0,
            length: g.l_c,
            ei: truth.statics.ei,
            steps: truth.statics.steps,
        };
        segment::shape(&p, eq.z[9 + i], eq.tip_load[i])
            .into_iter()
            .map(|(q, _)| add(g.base, q))
            .collect()
    })
}

impl Driver for Plant {
    fn name(&self) -> &str {
        &self.name
    }

    /// A command that comes before the end of the simulated cycle (the one before came late) is
    /// treated as the firmware treats it (`driver/firmware/main.c`, `on_setpoint`): an unchanged
    /// target lets the running segment finish, a new one starts a new segment at once (the rest
    /// of the cycle is taken back); otherwise the plant would stay a cycle ahead of the clock.
    fn write(&mut self, time_s: f64, period_s: f64, cmd: &MotorCommand) -> Result<(), DriverError> {
        if time_s + 1e-9 < self.state.t_s {
            if cmd.steps == self.target && cmd.enable == self.enabled {
                return Ok(());
            }
            let limit = |e: PlantError| DriverError::Limit(e.to_string());
            if let Some(t0) = self.rewind_to(time_s).map_err(limit)? {
                self.withdrawn = Some(self.withdrawn.map_or(t0, |w| w.min(t0)));
            }
        } else if time_s > self.state.t_s + 1e-9 {
            self.idle_until(time_s)
                .map_err(|e| DriverError::Limit(e.to_string()))?;
        }
        self.step_cycle(period_s, cmd)
            .map_err(|e| DriverError::Limit(e.to_string()))
    }

    fn read(&mut self, time_s: f64, _period_s: f64) -> Result<DriverState, DriverError> {
        if time_s > self.state.t_s + 1e-9 {
            self.idle_until(time_s)
                .map_err(|e| DriverError::Limit(e.to_string()))?;
        }
        Ok(DriverState {
            time_s,
            steps: self.state.counter,
            enabled: self.enabled,
            moving: self.act.iter().any(|a| a.moving()) || self.state.counter != self.target,
            limited: self.limited,
            fault: self.fault,
        })
    }
}
