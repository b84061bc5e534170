//! The driver interface shared by every backend.

/// Number of motors (one per leg).
pub const N_MOTORS: usize = 3;

/// The setpoint for one control cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MotorCommand {
    /// Motor positions to reach by the end of the cycle, in steps (signed, 0 = straight segment).
    pub steps: [i32; N_MOTORS],
    /// Whether the coils are energised.
    pub enable: bool,
}

/// What a drive reports after a cycle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DriverState {
    /// Time of the report, s (the caller's clock).
    pub time_s: f64,
    /// Motor positions the drive has reached, in steps.
    pub steps: [i32; N_MOTORS],
    /// Whether the coils are energised.
    pub enabled: bool,
    /// Whether the drive is still moving towards the last setpoint.
    pub moving: bool,
    /// Whether the last setpoint had to be limited (rate or range).
    pub limited: bool,
    /// Whether the drive is in a fault state and holds position.
    pub fault: bool,
}

/// Why a driver call failed.
#[derive(Debug, thiserror::Error)]
pub enum DriverError {
    /// The transport (serial port, plant) is gone or failed.
    #[error("driver transport: {0}")]
    Transport(String),
    /// The drive answered with an error or did not answer in time.
    #[error("driver protocol: {0}")]
    Protocol(String),
    /// The command was refused by a safety limit.
    #[error("driver safety limit: {0}")]
    Limit(String),
}

/// A hardware interface called once per control cycle (ros2_control style).
pub trait Driver {
    /// A short name for logs (`serial:/dev/ttyACM0`, `plant`).
    fn name(&self) -> &str;
    /// Sends the cycle's setpoint. `time_s` is the caller's clock, `period_s` the cycle length.
    fn write(&mut self, time_s: f64, period_s: f64, cmd: &MotorCommand) -> Result<(), DriverError>;
    /// Reads the drive's state at the end of the cycle.
    fn read(&mut self, time_s: f64, period_s: f64) -> Result<DriverState, DriverError>;
    /// Diagnostic counters for monitoring, as `(name, value)` pairs (bad frames, refusals,
    /// timeouts, safety interventions...). Safety wrappers append theirs to the wrapped
    /// driver's. The default reports none.
    fn diagnostics(&self) -> Vec<(String, u64)> {
        Vec::new()
    }
}

/// A boxed driver is a driver, so that a backend chosen at run time can sit inside the safety
/// wrappers.
impl<D: Driver + ?Sized> Driver for Box<D> {
    fn name(&self) -> &str {
        (**self).name()
    }
    fn write(&mut self, time_s: f64, period_s: f64, cmd: &MotorCommand) -> Result<(), DriverError> {
        (**self).write(time_s, period_s, cmd)
    }
    fn read(&mut self, time_s: f64, period_s: f64) -> Result<DriverState, DriverError> {
        (**self).read(time_s, period_s)
    }
    fn diagnostics(&self) -> Vec<(String, u64)> {
        (**self).diagnostics()
    }
}
