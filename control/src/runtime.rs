//! The in-process runtime: all steps of the chain in one thread on a simulated clock, faster
//! than real time and deterministic (same inputs, same outputs, bit for bit).

use crate::accuracy::Accuracy;
use crate::correction::CorrectionStep;
use crate::drive::{max_step_rate, safety_stack, FkPoseSensor, IdealDrive, PoseSensor, SafeDriver};
use crate::driver_step::DriverStep;
use crate::ik::IkStep;
use crate::interpolator::{CommandError, InterpolatorStep};
use crate::planned::{MotionLimits, PlannerSource};
use crate::plant_drive::{plant_backend, PlantDrive, PlantSensor};
use crate::setpoint::{InterimPathSource, SetpointSource};
use pcr_driver::{Driver, DriverError};
use pcr_kinematics::{Pose, Robot};
use pcr_messages::{planner_state, Command, DriverStateMsg, JointSetpoint, TaskSetpoint};
use pcr_plant::PlantConfig;
use pcr_robot::RobotConfig;

/// What one cycle produced.
#[derive(Debug, Clone, Copy)]
pub struct CycleOutput {
    /// Interpolator output.
    pub task: TaskSetpoint,
    /// IK output.
    pub joint: JointSetpoint,
    /// Driver output (with the measured pose).
    pub state: DriverStateMsg,
}

/// Why a run failed.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The program was refused.
    #[error(transparent)]
    Command(#[from] CommandError),
    /// The driver failed.
    #[error(transparent)]
    Driver(#[from] DriverError),
    /// The program did not finish in the allotted simulated time.
    #[error("program not finished after {0} s of simulated time")]
    Timeout(f64),
}

/// The whole chain in one process: interpolator -> IK -> driver (+ pose sensor) -> correction.
pub struct InProcessChain<S, D, P> {
    /// The interpolator step.
    pub interp: InterpolatorStep<S>,
    /// The IK step.
    pub ik: IkStep,
    /// The driver step.
    pub driver: DriverStep<D, P>,
    /// The correction step (its output is fed back to the interpolator).
    pub correction: CorrectionStep,
    period_s: f64,
    t_s: f64,
}

/// The chain on the interim parts: [`InterimPathSource`], [`IdealDrive`] in the safety stack,
/// [`FkPoseSensor`], correction with gain 0 (error reported only).
pub type InterimChain = InProcessChain<InterimPathSource, SafeDriver<IdealDrive>, FkPoseSensor>;

impl InterimChain {
    /// The interim chain for `robot` at `period_s`, starting at home.
    pub fn interim(robot: Robot, period_s: f64) -> Self {
        ideal_chain(InterimPathSource::new(), robot, period_s)
    }
}

/// The chain on the planner's jerk-limited paths ([`PlannerSource`]) and the ideal drive
/// ([`IdealDrive`] in the safety stack, [`FkPoseSensor`], correction with gain 0): what it
/// records as planned poses is what `pcr plan` ([`crate::offline`]) plans.
pub type IdealChain = InProcessChain<PlannerSource, SafeDriver<IdealDrive>, FkPoseSensor>;

impl IdealChain {
    /// The chain for `robot` with path `limits` at `period_s` on the ideal drive, at home.
    pub fn ideal(robot: Robot, limits: MotionLimits, period_s: f64) -> Self {
        ideal_chain(PlannerSource::new(robot.clone(), limits), robot, period_s)
    }
}

fn ideal_chain<S: SetpointSource>(
    source: S,
    robot: Robot,
    period_s: f64,
) -> InProcessChain<S, SafeDriver<IdealDrive>, FkPoseSensor> {
    let ik = IkStep::new(robot.clone());
    let home: [i32; 3] = std::array::from_fn(|i| {
        robot
            .kappa_to_steps(i, robot.home_kappa[i])
            .map_or(0, |s| s.round() as i32)
    });
    let drive = safety_stack(
        IdealDrive::new(home, max_step_rate(&robot)),
        &robot,
        5.0 * period_s,
    );
    let sensor = FkPoseSensor::new(robot);
    InProcessChain::new(
        InterpolatorStep::new(source, Pose::default()),
        ik,
        DriverStep::new(drive, sensor, period_s),
        CorrectionStep::pass_through(),
        period_s,
    )
}

/// The chain on the real parts: the planner's jerk-limited paths ([`PlannerSource`]), the
/// simulated plant in the safety stack, its motion-capture view as the pose sensor.
pub type SimChain = InProcessChain<PlannerSource, SafeDriver<PlantDrive>, PlantSensor>;

impl SimChain {
    /// The chain for a robot configuration (the model that drives, with the effects it
    /// compensates) and a plant configuration (the truth, deviating from its own drawing) at
    /// `period_s`, starting at the plant's home motor positions.
    pub fn simulated(
        robot_cfg: &RobotConfig,
        plant_cfg: &PlantConfig,
        period_s: f64,
    ) -> Result<Self, SimChainError> {
        // The plant deviates from its own drawing, never from the model that drives it.
        let drawing = plant_cfg
            .drawing()
            .map_err(|e| SimChainError::Plant(e.to_string()))?;
        Self::simulated_on(robot_cfg, &drawing, plant_cfg, period_s)
    }

    /// The chain driven by the model `model_cfg` (planner, IK, safety limits, and the effects it
    /// compensates: e.g. a calibrated or extended robot) on a plant whose nominal geometry is
    /// `plant_robot_cfg` with the deviations of `plant_cfg` on top (the truth, which does not
    /// change when the model does), at `period_s`, starting at the plant's home motor positions.
    pub fn simulated_on(
        model_cfg: &RobotConfig,
        plant_robot_cfg: &RobotConfig,
        plant_cfg: &PlantConfig,
        period_s: f64,
    ) -> Result<Self, SimChainError> {
        let robot = Robot::new(model_cfg).map_err(|e| SimChainError::Robot(e.to_string()))?;
        let (drive, sensor) = plant_backend(plant_robot_cfg, plant_cfg)
            .map_err(|e| SimChainError::Plant(e.to_string()))?;
        let drive = safety_stack(drive, &robot, 5.0 * period_s);
        let mut interp = InterpolatorStep::new(
            PlannerSource::new(robot.clone(), MotionLimits::default()),
            Pose::default(),
        );
        let effects = &model_cfg.effects;
        interp.set_lead(crate::compensation::command_lead(model_cfg, period_s));
        let mut driver = DriverStep::new(drive, sensor, period_s);
        driver.set_frame_correction(effects.frame.clone());
        Ok(InProcessChain::new(
            interp,
            IkStep::new(robot),
            driver,
            CorrectionStep::pass_through(),
            period_s,
        ))
    }
}

impl SimChain {
    /// The plant drive inside the safety stack (true state, last capture sample's M_i).
    pub fn plant_drive(&self) -> &PlantDrive {
        self.driver.driver().inner().inner().inner()
    }
}

/// Why the simulated chain could not be built.
#[derive(Debug, thiserror::Error)]
pub enum SimChainError {
    /// The robot model.
    #[error("robot model: {0}")]
    Robot(String),
    /// The plant.
    #[error("plant: {0}")]
    Plant(String),
}

impl<S: SetpointSource, D: Driver, P: PoseSensor> InProcessChain<S, D, P> {
    /// Assembles a chain from its steps; the simulated clock starts at 0.
    pub fn new(
        interp: InterpolatorStep<S>,
        ik: IkStep,
        driver: DriverStep<D, P>,
        correction: CorrectionStep,
        period_s: f64,
    ) -> Self {
        Self {
            interp,
            ik,
            driver,
            correction,
            period_s,
            t_s: 0.0,
        }
    }

    /// The chain with another correction step (e.g. a non-zero gain).
    pub fn with_correction(mut self, correction: CorrectionStep) -> Self {
        self.correction = correction;
        self
    }

    /// Simulated time, s.
    pub fn time_s(&self) -> f64 {
        self.t_s
    }

    /// One cycle; with `drop_setpoint` the joint setpoint is lost on its way to the driver
    /// (fault injection).
    pub fn cycle_with(&mut self, drop_setpoint: bool) -> Result<CycleOutput, DriverError> {
        let t = self.t_s;
        let task = self.interp.step(t);
        let joint = self.ik.step(&task);
        let state = self
            .driver
            .step(t, if drop_setpoint { None } else { Some(&joint) })?;
        let corr = self.correction.step_state(&state);
        self.interp.set_correction(&corr);
        self.t_s += self.period_s;
        Ok(CycleOutput { task, joint, state })
    }

    /// One normal cycle.
    pub fn cycle(&mut self) -> Result<CycleOutput, DriverError> {
        self.cycle_with(false)
    }

    /// Runs a command's program to its end (at most `max_s` of simulated time), handing every
    /// driver-state row to `on_row`; returns the path accuracy.
    pub fn run(
        &mut self,
        cmd: &Command,
        max_s: f64,
        mut on_row: impl FnMut(&DriverStateMsg),
    ) -> Result<Accuracy, RunError> {
        self.interp.command(cmd)?;
        let mut acc = Accuracy::default();
        let end = self.t_s + max_s;
        loop {
            let out = self.cycle()?;
            acc.add(&out.state);
            on_row(&out.state);
            if self.interp.status(self.t_s).state != planner_state::RUNNING
                && self.interp.status(self.t_s).state != planner_state::PAUSED
            {
                return Ok(acc);
            }
            if self.t_s > end {
                return Err(RunError::Timeout(max_s));
            }
        }
    }
}
